//! `presrs` argument types: McapArgs, ViewArgs.

use std::path::PathBuf;

#[derive(clap::Args)]
pub struct McapArgs {
    /// candump log (`candump -L` format, as `candump -L any > run.log` writes it).
    pub log: PathBuf,
    /// The MCAP file to write (with --ros2: the rosbag2 directory, which must not exist).
    #[arg(long)]
    pub out: PathBuf,
    /// Write a ROS 2 bag instead: `--out DIR` becomes a rosbag2 directory (MCAP with CDR
    /// messages and `metadata.yaml`), the same messages `presrs bridge` publishes.
    #[arg(long)]
    pub ros2: bool,
    /// With --ros2: the robot's ROS 2 namespace in the bag's topic names.
    #[arg(long, value_name = "NS", default_value = "", requires = "ros2")]
    pub namespace: String,
    /// Also run the node with this model on the way: its TerrainClass per step goes on
    /// `/footN/terrain/model` (with --ros2: `footN/terrain/model` in the bag), beside any
    /// TerrainClass already in the log; the same decisions `presrs node --replay --csv` lists.
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Node config (TOML): identifiers, feet, stance timing (see `examples/node.toml`).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Print the counts as JSON.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub terrains: protocol::TerrainsArg,
}

#[derive(clap::Args)]
pub struct ViewArgs {
    /// An MCAP recording (`presrs mcap`, or `--mcap` of node, sim or demo).
    pub recording: PathBuf,
    /// The PNG to write.
    #[arg(long)]
    pub out: PathBuf,
    /// The foot to show.
    #[arg(long, default_value_t = 0)]
    pub foot: u8,
    /// Show the image nearest this time, s from the start. Default: the stance that says most
    /// about the run, its first step called unknown (the model's decisions first), else its
    /// middle step; the title names it.
    #[arg(long, value_name = "S")]
    pub at: Option<f64>,
}
