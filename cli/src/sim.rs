//! `presrs` argument types: SimArgs.

use std::path::PathBuf;

#[derive(clap::Args)]
pub struct SimArgs {
    /// CAN interface (vcan0, can0). Must carry CAN FD (MTU 72): the tactile frames are FD.
    #[arg(long, required_unless_present = "log", conflicts_with = "log")]
    pub iface: Option<String>,
    /// No bus: write what the robot sends to this candump log (`candump -L` format), in
    /// simulated time, as fast as it computes; needs --duration. The robot holds its gait.
    #[arg(long, requires = "duration")]
    pub log: Option<PathBuf>,
    /// With --log: write the true terrain of every step as a labels CSV for `presrs capture
    /// --labels` (start_s,end_s,terrain,foot in the log's timestamps).
    #[arg(long, requires = "log")]
    pub truth: Option<PathBuf>,
    /// Track file (TOML: diameter_m, [[segments]] terrain, length_m); default: a quarter each of
    /// wood, grass, clay and carpet on the paper's 2.8 m circle.
    #[arg(long)]
    pub track: Option<PathBuf>,
    /// Legs, each with its foot sensor (foot ids 0..N).
    #[arg(long, default_value_t = 1)]
    pub feet: u8,
    /// Simulated time per wall-clock time: 1 is real time, 2 twice as fast.
    #[arg(long, default_value_t = 1.0)]
    pub speed: f64,
    #[command(flatten)]
    pub foot: sim::FootOptions,
    /// Stop after this much simulated time, s (default: run until SIGINT/SIGTERM).
    #[arg(long)]
    pub duration: Option<f64>,
    /// Write the per-step record (truth, what the node said, the gait run) as JSON at exit.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// The simulator's random seed: the terrains' patches and the skin's noise (the hopper's
    /// dynamics and the track are the same for every seed). The same seed, the same run.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Track terrains and reported names come from this catalog.
    #[command(flatten)]
    pub terrains: protocol::TerrainsArg,
    /// The leg as two motors of this protocol (moteus, odrive, mit): the simulator takes their
    /// commands from a leg bridge (`presrs leg`) instead of LegCommand and answers as the
    /// drivers do; LegState is then the bridge's.
    #[arg(
        long,
        value_name = "PROTOCOL",
        conflicts_with = "log",
        help_heading = "The leg through motors"
    )]
    pub leg: Option<leg::DriverKind>,
    /// The leg's config for `--leg` (the same file `presrs leg` runs with); default: the
    /// built-in prismatic leg on that protocol's motors.
    #[arg(
        long,
        value_name = "FILE",
        requires = "leg",
        help_heading = "The leg through motors"
    )]
    pub leg_config: Option<PathBuf>,
    /// Mass the hopper carries, kg (0 to 2; its body is 2 kg): the robot's run with a load its
    /// model and energy maps were not made with.
    #[arg(long, value_name = "KG", default_value_t = 0.0)]
    pub payload: f64,
    /// Fault drill for `--leg`: the length joint's driver goes silent at this robot time (s).
    #[arg(
        long,
        value_name = "SECONDS",
        requires = "leg",
        help_heading = "The leg through motors"
    )]
    pub leg_silent_at: Option<f64>,
    /// `--mcap FILE`: every frame on the bus (or, with --log, every frame the robot sends) and
    /// the simulator's truth per leg (`/sim/legN`: speed, position, true terrain) as MCAP;
    /// `--foxglove`: the same live.
    #[command(flatten, next_help_heading = "Record and view")]
    pub live: record::LiveOptions,
    /// `--ros2`: the bus as ROS 2 topics on Zenoh; `--ros2-bag DIR`: as a rosbag2.
    #[command(flatten, next_help_heading = "ROS 2 (Zenoh, rmw_zenoh)")]
    pub ros2: ros2::Ros2Options,
}
