//! `presrs` argument types: FeetArgs.

use std::path::PathBuf;

#[derive(clap::Args)]
pub struct FeetArgs {
    /// Seeds to walk each foot with: `1-5` or `1,3,7` (each a new set of sessions).
    #[arg(long, default_value = "1-5")]
    pub seeds: String,
    /// Stances per known terrain in each of the two training sessions.
    #[arg(long, default_value_t = 25)]
    pub steps: usize,
    /// Stances per terrain in the mixed third session (the new terrain's too).
    #[arg(long, default_value_t = 20)]
    pub third_steps: usize,
    /// The independent foot emulator (default: ../shared/foot-emulator/foot.py, when there and
    /// python3 has numpy); its feet are walked beside the simulator's.
    #[arg(long, value_name = "FOOT.PY")]
    pub emulator: Option<PathBuf>,
    /// Also stream SpeedPP2D's people through the emulator's feet as terrains: the folder
    /// `python3 scripts/speedpp2d.py --out DIR` writes (real maps whose load fills the array).
    #[arg(long, value_name = "DIR")]
    pub speedpp2d: Option<PathBuf>,
    /// Only these feet: names containing any of these words (`roll`, `paper`, `emulator`).
    #[arg(long, value_delimiter = ',')]
    pub only: Vec<String>,
    /// Keep each trial's images, captured set and model in DIR/<foot>-<source>-<seed>/ (by
    /// default a scratch folder, removed).
    #[arg(long, value_name = "DIR")]
    pub keep: Option<PathBuf>,
    /// Every trial as one JSON array on stdout (the table still goes to stderr).
    #[arg(long)]
    pub json: bool,
    /// `discover` without its link of neighbouring steps (to measure it).
    #[arg(long, hide = true, conflicts_with = "patch_link")]
    pub no_patches: bool,
    /// `discover`'s link factor for neighbouring steps (to measure it).
    #[arg(long, hide = true)]
    pub patch_link: Option<f64>,
}
