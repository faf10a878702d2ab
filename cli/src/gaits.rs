//! `presrs` argument types: GaitsArgs.

#[derive(clap::Args)]
pub struct GaitsArgs {
    /// Grounds to hop on (catalog names the simulator models). Default: the paper's dynamic
    /// set (wood, carpet, clay, grass) and sand, the demo's unknown ground.
    #[arg(long, value_delimiter = ',')]
    pub terrains: Vec<String>,
    /// A payload the hopper carries, kg (0 to 2).
    #[arg(long, default_value_t = 0.0)]
    pub payload: f64,
    /// The table as JSON on stdout (the safe gait's line still goes to stderr).
    #[arg(long)]
    pub json: bool,
}
