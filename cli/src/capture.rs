//! `presrs` argument types: CaptureArgs.

use std::path::PathBuf;

#[derive(clap::Args)]
pub struct CaptureArgs {
    /// A candump log (`candump -L`) of the robot's run.
    #[arg(long, required_unless_present = "iface", conflicts_with = "iface")]
    pub replay: Option<PathBuf>,
    /// Capture live from a CAN interface until SIGINT/SIGTERM.
    #[arg(long)]
    pub iface: Option<String>,
    /// Every step is this terrain (a name from the catalog).
    #[arg(long, required_unless_present = "labels", conflicts_with = "labels")]
    pub label: Option<String>,
    /// A CSV of `start_s,end_s,terrain[,foot]` in the log's timestamps, for a run that crosses
    /// terrains; steps outside every range or spanning two are skipped and counted.
    #[arg(long)]
    pub labels: Option<PathBuf>,
    /// The training-set folder: `DIR/<terrain>/*.pgm` (what `presrs train` reads) and
    /// `DIR/manifest.csv` (each step's run and, where the bus carried the controller's
    /// GaitStatus, its gait). Capturing the same log again adds nothing.
    #[arg(long)]
    pub out: PathBuf,
    /// Node config (TOML): debounce, sample time, repair, feet, CAN ids, terrains.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// The source name the manifest keys steps by (default: the log's file name, or
    /// `IFACE-<unix time>` live).
    #[arg(long)]
    pub source: Option<String>,
    /// Print the summary as one JSON object.
    #[arg(long)]
    pub json: bool,
    /// Overrides the config's `terrains` key.
    #[command(flatten)]
    pub terrains: protocol::TerrainsArg,
}
