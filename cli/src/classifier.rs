//! `presrs` argument types: TrainArgs, EvalArgs, ClassifyArgs, FeaturesArgs, RepairArgs, DbcArgs, DatasetArgs.

use node::classifier::Crop;
use node::classifier::train::TrainOptions;
use std::path::PathBuf;

/// `presrs train`.
#[derive(clap::Args)]
pub struct TrainArgs {
    /// The images: DIR/<terrain>/<images> (PGM, CSV, TekScan ASCII), as `capture` writes them.
    #[arg(long, value_name = "DIR")]
    pub data: PathBuf,
    /// The model file to write (JSON).
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    #[command(flatten)]
    pub opts: TrainOptions,
    /// Skip unreadable files (counted) instead of stopping.
    #[arg(long)]
    pub skip_bad: bool,
    /// The whole account: the images per session, every candidate of the unknown-ground
    /// choice with its figures, and why each setting was chosen (default: a short summary).
    #[arg(long)]
    pub verbose: bool,
    /// Calibrate the unknown-terrain rejection on this dataset (DIR/<terrain>/<images>: another
    /// run of terrains the model knows, e.g. a second `presrs capture`). Without it, a --data
    /// folder whose manifest names two or more runs of a terrain calibrates on its last run;
    /// else on the session itself, in time blocks, with a margin measured on its last quarter.
    #[arg(long, value_name = "DIR")]
    pub calibrate: Option<PathBuf>,
    #[command(flatten)]
    pub terrains: protocol::TerrainsArg,
}

/// `presrs eval`.
#[derive(clap::Args)]
pub struct EvalArgs {
    /// The model file (`presrs train --out`).
    #[arg(long)]
    pub model: PathBuf,
    /// The dataset: DIR/<terrain>/<images>, as `capture` writes it.
    #[arg(long)]
    pub data: PathBuf,
    #[command(flatten)]
    pub spec: tools::eval::EvalSpec,
    /// Print the confusion matrix and accuracy as one JSON object.
    #[arg(long)]
    pub json: bool,
    /// Skip unreadable files (counted) instead of stopping.
    #[arg(long)]
    pub skip_bad: bool,
    #[command(flatten)]
    pub terrains: protocol::TerrainsArg,
}

/// `presrs lab classify`.
#[derive(clap::Args)]
pub struct ClassifyArgs {
    /// The model file (`presrs train --out`).
    #[arg(long)]
    pub model: PathBuf,
    /// Images to classify (PGM, CSV or a TekScan ASCII export).
    pub files: Vec<PathBuf>,
    /// One JSON object per line: `file`, `terrain`, `confidence`, `novelty` (larger = less
    /// like any known terrain) and `threshold` (above it: unknown), so that the score's
    /// ROC can be drawn on your own images.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub terrains: protocol::TerrainsArg,
}

/// `presrs lab features`.
#[derive(clap::Args)]
pub struct FeaturesArgs {
    /// The image (PGM, CSV or a TekScan ASCII export).
    pub file: PathBuf,
    /// Rows and columns cut off before the features: TOP,BOTTOM,LEFT,RIGHT.
    #[arg(long, default_value = "0,0,0,0")]
    pub crop: Crop,
    /// Print the feature vector as a JSON array.
    #[arg(long)]
    pub json: bool,
}

/// `presrs lab repair`.
#[derive(clap::Args)]
pub struct RepairArgs {
    /// The image (PGM, CSV or a TekScan ASCII export).
    pub file: PathBuf,
    /// The repaired image's file (PGM).
    #[arg(long)]
    pub out: PathBuf,
}

/// `presrs lab dbc`.
#[derive(clap::Args)]
pub struct DbcArgs {
    /// TOML file with the identifier map (`extended`, `leg_command`, ... `tactile_frame_classic`).
    #[arg(long)]
    pub ids: Option<PathBuf>,
    /// Output file (stdout when absent).
    #[arg(long)]
    pub out: Option<PathBuf>,
    #[command(flatten)]
    pub terrains: protocol::TerrainsArg,
}

/// `presrs lab dataset`.
#[derive(clap::Args)]
pub struct DatasetArgs {
    /// static (section 4), sandpaper (section 5) or dynamic (section 7, on the hopper).
    #[arg(value_enum)]
    pub kind: sim::dataset::Kind,
    /// The folder to write DIR/<terrain>/<n>.pgm into.
    #[arg(long)]
    pub out: PathBuf,
    /// Images per terrain (default: the paper's counts; Table 4 for dynamic).
    #[arg(long)]
    pub n: Option<usize>,
    #[command(flatten)]
    pub foot: sim::FootOptions,
    /// The simulator's random seed: the same seed, the same images.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    // Checked like every command's; the simulator generates the paper's terrains, which every
    // catalog holds.
    #[command(flatten)]
    pub terrains: protocol::TerrainsArg,
}
