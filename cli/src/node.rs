//! `presrs` argument types: NodeArgs.

use std::path::PathBuf;

#[derive(clap::Args)]
// One of the two: the usage line says so (`<--iface <IFACE>|--replay <REPLAY>>`).
#[command(group(clap::ArgGroup::new("source").required(true).args(["iface", "replay"])))]
pub struct NodeArgs {
    /// CAN interface (can0, vcan0).
    #[arg(long)]
    pub iface: Option<String>,
    /// Run the pipeline on a candump log (`candump -L` format) instead of a bus, with the log's
    /// timestamps, and print the TerrainClass stream.
    #[arg(long)]
    pub replay: Option<PathBuf>,
    /// Model file from `presrs train`.
    #[arg(long)]
    pub model: PathBuf,
    /// Node config (TOML); see `examples/node.toml`.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Replay: print each TerrainClass as a JSON line (`t_us`: when the node decided the step,
    /// on the log's clock, µs; `step`: the foot's step counter, as on the bus).
    #[arg(long, help_heading = "Replay a log")]
    pub json: bool,
    /// One CSV row per step and foot, live or on a replay: foot, step (the bus's counter,
    /// numbered as `capture`'s manifest), touchdown_s (the debounced touchdown) and
    /// decision_s (when the node decided), both on the log's clock (its timestamps; live, the
    /// bus's receive clock), terrain, unknown_reason, confidence_pct (empty for unknown
    /// ground: no terrain was chosen) and gait (the controller's, empty before its first
    /// GaitStatus).
    #[arg(long, value_name = "FILE")]
    pub csv: Option<PathBuf>,
    /// Keep every stance called unknown on its image (novelty, load, texture or energy) in DIR,
    /// as `capture` writes a set: DIR/unknown/<name>.pgm, DIR/manifest.csv, and DIR/kept.csv
    /// with each stance's reason. Off the node's thread; an existing DIR is added to.
    #[arg(long, value_name = "DIR")]
    pub keep_unknown: Option<PathBuf>,
    /// With --replay: the run's true terrain (a labels CSV, `start_s,end_s,terrain[,foot]`, as
    /// `capture --labels` reads and `demo --truth` writes it): the node's decisions per true
    /// terrain, known ground called unknown and new ground found.
    #[arg(
        long,
        value_name = "CSV",
        requires = "replay",
        help_heading = "Replay a log"
    )]
    pub truth: Option<PathBuf>,
    /// Overrides the config's `terrains` key.
    #[command(flatten)]
    pub terrains: protocol::TerrainsArg,
    #[command(flatten, next_help_heading = "Record and view")]
    pub live: record::LiveOptions,
    /// `--ros2`: the node's bus as ROS 2 topics on Zenoh; `--ros2-bag DIR`: as a rosbag2.
    #[command(flatten, next_help_heading = "ROS 2 (Zenoh, rmw_zenoh)")]
    pub ros2: ros2::Ros2Options,
}
