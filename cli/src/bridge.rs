//! `presrs` argument types: BridgeArgs.

#[derive(clap::Args)]
pub struct BridgeArgs {
    /// The robot's CAN interface (can0, vcan0).
    #[arg(long)]
    pub iface: String,
    /// Node config (TOML): the identifiers and terrains the bus uses (`examples/node.toml`).
    #[arg(long)]
    pub config: Option<std::path::PathBuf>,
    #[command(flatten)]
    pub terrains: protocol::TerrainsArg,
    /// Where to publish (`--ros2` is implied: the bridge always publishes on Zenoh).
    #[command(flatten)]
    pub ros2: ros2::Ros2Options,
}
