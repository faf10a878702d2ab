//! `presrs` argument types: ExperimentArgs.

use lab::report::Selection;
use node::classifier::image::Crop;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct ExperimentArgs {
    /// all, static, resolution, dynamic, gaits, damage, lifespan, adaptation or open-set.
    #[arg(value_name = "EXPERIMENT")]
    pub which: Selection,
    /// Output directory: results.md (or WHICH.md) and figures/. Not `docs` by default (in a
    /// checkout that would overwrite the project's docs/results.md); `--out docs` does that.
    #[arg(long, default_value = "results")]
    pub out: PathBuf,
    /// Fewer images and steps: a check that everything runs, not results to quote.
    #[arg(long)]
    pub quick: bool,
    /// The simulator's random seed: the same seed, the same run.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// With open-set: run it on N seeds from --seed on and add each figure's median and range
    /// over them, with the seeds that miss a target (one seed can be a kind one), and the
    /// mean with its 95% interval: the rate to expect over runs
    #[arg(long, value_name = "N", default_value_t = 1,
          value_parser = clap::value_parser!(u64).range(1..=100), help_heading = "The open-set section")]
    pub seeds: u64,
    /// With open-set: images per class drawn from each training run for the model (default
    /// the paper's 20). A lab that stores every image of its training run leaves none of it
    /// to the calibration: this shows what that does to the next run's false unknowns.
    #[arg(
        long,
        value_name = "N",
        requires = "train",
        help_heading = "The open-set section"
    )]
    pub per_class: Option<usize>,
    /// With open-set and --per-class: of those, images trained on; the rest validate the
    /// kernel width (the paper: 13 of 20).
    #[arg(
        long,
        value_name = "N",
        requires = "per_class",
        help_heading = "The open-set section"
    )]
    pub train: Option<usize>,
    /// With open-set: the share of known images the models may call unknown, as `train
    /// --unknown-rate` (default 0.02): to see what a lower or higher rate trades on your set.
    #[arg(long, value_name = "R", help_heading = "The open-set section")]
    pub unknown_rate: Option<f64>,
    /// With open-set: the models also carry the texture check (`train --check-texture`), to
    /// see what it finds and costs on your set.
    #[arg(long, help_heading = "The open-set section")]
    pub check_texture: bool,
    /// Your own dataset (DIR/<class>/<images>, as `presrs train` reads it) for Table 1,
    /// Figure 5, Figure 16 and Table 6. The other experiments need several sets (sandpaper,
    /// one per gait, a closed loop) and run on the simulator.
    #[arg(long, value_name = "DIR", help_heading = "Your own data")]
    pub data: Option<PathBuf>,
    /// Crop of the `--data` images (top,bottom,left,right); default none.
    #[arg(
        long,
        value_name = "T,B,L,R",
        requires = "data",
        help_heading = "Your own data"
    )]
    pub crop: Option<Crop>,
    /// With `--data` or `--extra-source`: scale each image to the set's mean load before its
    /// features, as `train --normalize-load` does: for images taken at several loads (a foot
    /// hopping or walking at several speeds, e.g. SpeedPP2D). Used by the open-set section.
    #[arg(long, help_heading = "Your own data")]
    pub normalize_load: bool,
    /// With `--data`: go on past unreadable images and count them.
    #[arg(long, requires = "data", help_heading = "Your own data")]
    pub skip_bad: bool,
    /// More datasets for the open-set section (repeatable), each split by the runs of its
    /// capture manifest: e.g. the real SpeedPP2D pressure maps that `scripts/speedpp2d.py`
    /// writes (with `--terrains DIR/terrains.toml`).
    #[arg(long, value_name = "DIR", help_heading = "Your own data")]
    pub extra_source: Vec<PathBuf>,
    /// With `--data` or `--extra-source`: the catalog its class folders are named in.
    #[command(flatten, next_help_heading = "Your own data")]
    pub terrains: protocol::TerrainsArg,
}
