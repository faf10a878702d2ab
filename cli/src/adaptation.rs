//! `presrs` argument types: AdaptationArgs.

use std::path::PathBuf;

#[derive(clap::Args)]
pub struct AdaptationArgs {
    /// candump log of a run with FootContact, LegState, GaitStatus and TerrainClass on the bus
    /// (`candump -L any > run.log`, or `--log` of sim, demo or node).
    pub log: PathBuf,
    /// Write the table (adaptation.md) and every stride (strides.csv) into this directory.
    /// Default: the table on stdout only.
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Node config (TOML) with the bus's identifiers (see `examples/node.toml`).
    #[arg(long)]
    pub config: Option<PathBuf>,
    #[command(flatten)]
    pub terrains: protocol::TerrainsArg,
}
