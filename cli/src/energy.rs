//! `presrs` argument types: EnergyArgs.

use std::path::PathBuf;

#[derive(clap::Args)]
pub struct EnergyArgs {
    /// The trained model (`presrs train`) whose energy check is fitted.
    #[arg(long)]
    pub model: PathBuf,
    /// A candump log (`candump -L`) of a closed-loop run (the controller switching gaits) on
    /// known ground; repeat for several runs.
    #[arg(long, required = true)]
    pub replay: Vec<PathBuf>,
    /// Every step of every run is this terrain (a name from the catalog).
    #[arg(long, conflicts_with = "labels")]
    pub label: Option<String>,
    /// A CSV of `start_s,end_s,terrain[,foot]` in the log's timestamps (as `presrs capture`
    /// reads it); one per `--replay`, in the same order.
    #[arg(long)]
    pub labels: Vec<PathBuf>,
    /// Where the model with its energy check goes (may be `--model` itself).
    #[arg(long)]
    pub out: PathBuf,
    /// Node config (TOML): debounce, sample time, feet, CAN ids, terrains.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Print what was fitted as one JSON object.
    #[arg(long)]
    pub json: bool,
    /// Overrides the config's `terrains` key.
    #[command(flatten)]
    pub terrains: protocol::TerrainsArg,
}
