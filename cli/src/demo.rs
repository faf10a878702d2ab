//! `presrs` argument types: DemoArgs.

use std::path::PathBuf;

#[derive(clap::Args)]
pub struct DemoArgs {
    /// Steps to run.
    #[arg(long, default_value_t = 120)]
    pub steps: usize,
    /// Track file (TOML: diameter_m, [[segments]] terrain, length_m); default: wood, grass,
    /// clay, carpet.
    #[arg(long)]
    pub track: Option<PathBuf>,
    /// Model file; default: one trained on simulated data on first run, then cached.
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Print the summary as one JSON object.
    #[arg(long)]
    pub json: bool,
    /// Write every step to this CSV (time, step, true and classified terrain, confidence,
    /// gait, speed); nothing is written without it.
    #[arg(long, value_name = "FILE")]
    pub csv: Option<PathBuf>,
    /// The simulator's random seed: the terrains' patches and the skin's noise (the hopper's
    /// dynamics and the track are the same for every seed). The same seed, the same run.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Run the simulator, the node and the controller as three concurrent tasks on the wall
    /// clock (the node with its own receive/pipeline/send threads), as they run as processes
    /// on CAN, instead of in lock-step simulated time.
    #[arg(long, help_heading = "The run's settings")]
    pub realtime: bool,
    /// No controller: the hopper holds this gait (G1, G2 or G3) on every terrain, as in the
    /// paper's data collection; the node still classifies every step.
    #[arg(
        long,
        value_name = "GAIT",
        conflicts_with = "realtime",
        help_heading = "The run's settings"
    )]
    pub fixed_gait: Option<controller::Gait>,
    /// The node's configuration (as `presrs node --config`); default: the node's defaults.
    #[arg(long, value_name = "FILE", help_heading = "The run's settings")]
    pub node_config: Option<PathBuf>,
    /// Sensor damage from the start, percent of sensels on dead rows and columns (eq. 6).
    #[arg(
        long,
        default_value_t = 0.0,
        value_name = "PCT",
        help_heading = "The run's settings"
    )]
    pub damage: f64,
    /// Also reject stances whose load lies outside the class's training range (`train
    /// --check-load`): catches ground that reads like a known terrain but yields differently.
    #[arg(long, help_heading = "The run's settings")]
    pub check_load: bool,
    /// For the track's terrain names and the node's and controller's catalogs.
    #[command(flatten, next_help_heading = "The run's settings")]
    pub terrains: protocol::TerrainsArg,
    /// The leg through motors: the simulated leg answers as two motors of this protocol
    /// (moteus, odrive, mit) and a leg bridge (`presrs leg`) stands between the controller and
    /// them.
    #[arg(
        long,
        value_name = "PROTOCOL",
        conflicts_with = "realtime",
        help_heading = "The run's settings"
    )]
    pub leg: Option<leg::DriverKind>,
    /// The leg's config for `--leg` (default: a prismatic leg on that protocol's motors,
    /// `LegConfig::example`).
    #[arg(
        long,
        value_name = "FILE",
        requires = "leg",
        help_heading = "The run's settings"
    )]
    pub leg_config: Option<PathBuf>,
    /// `--mcap FILE` records every frame on the bus and the simulator's truth; `--foxglove`
    /// serves them live, with the loop paced to real time so there is something to watch.
    #[command(flatten, next_help_heading = "Record and view")]
    pub live: record::LiveOptions,
    /// `--ros2`: the demo's bus as ROS 2 topics on Zenoh (it waits up to 5 s for the router,
    /// and delivers every message before it exits); `--ros2-bag DIR`: as a rosbag2.
    #[command(flatten, next_help_heading = "ROS 2 (Zenoh, rmw_zenoh)")]
    pub ros2: ros2::Ros2Options,
    /// Every frame of the demo's bus (motor frames included) as a candump log (`candump -L`
    /// format, interface can0, as `presrs lab sim --log` writes): `canplayer vcan0=can0 -I FILE`
    /// replays it, `presrs mcap` and python-can read it.
    #[arg(
        long,
        value_name = "FILE",
        conflicts_with = "realtime",
        help_heading = "Record and view"
    )]
    pub candump: Option<PathBuf>,
    /// Mass the hopper carries, kg (0 to 2; its body is 2 kg): a load the demo model and its
    /// energy maps were not made with (the controller is not told either).
    #[arg(
        long,
        value_name = "KG",
        default_value_t = 0.0,
        help_heading = "The run's settings"
    )]
    pub payload: f64,
    /// With --candump: the true terrain of every step as a labels CSV in the log's timestamps
    /// (`start_s,end_s,terrain,foot`, as `presrs lab sim --truth` writes it), for `presrs capture
    /// --labels` and `presrs lab energy --labels`.
    #[arg(
        long,
        value_name = "FILE",
        requires = "candump",
        help_heading = "Record and view"
    )]
    pub truth: Option<PathBuf>,
    /// The controller runs every gait for STEPS steps on each terrain it meets, the safe gait
    /// first (its `sweep_steps`): with --candump, `presrs lab adaptation` tables the run.
    #[arg(long, value_name = "STEPS", help_heading = "The run's settings")]
    pub sweep: Option<u32>,
}
