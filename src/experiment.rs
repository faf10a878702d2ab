//! `presrs lab experiment`: the paper's tables and figures ([`lab::report`]) written to
//! `OUT/results.md` (or `OUT/WHICH.md`) with `OUT/figures/`, under a header saying where the
//! data came from and how to regenerate it.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result};
use lab::report::{OpenSetModels, Report, Selection, UserData};
use lab::simdata::TrainingSet;
use node::classifier::image::Crop;

#[derive(clap::Args)]
pub struct ExperimentArgs {
    /// all, static, resolution, dynamic, gaits, damage, lifespan, adaptation or open-set.
    #[arg(value_name = "EXPERIMENT")]
    pub which: Selection,
    /// Output directory: results.md (or WHICH.md) and figures/. (Not `docs` by default: run in
    /// a checkout, that overwrote the project's own docs/results.md; pass `--out docs` to.)
    #[arg(long, default_value = "results")]
    pub out: PathBuf,
    /// Fewer images and steps: a check that everything runs, not results to quote.
    #[arg(long)]
    pub quick: bool,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// With open-set: run it on N seeds from --seed on and add each figure's median and range
    /// over them, with the seeds that miss a target (one seed can be a kind one), and the
    /// mean with its 95% interval: the rate to expect over runs
    #[arg(long, value_name = "N", default_value_t = 1,
          value_parser = clap::value_parser!(u64).range(1..=100))]
    pub seeds: u64,
    /// With open-set: images per class drawn from each training run for the model (default
    /// the paper's 20). A lab that stores every image of its training run leaves none of it
    /// to the calibration: this shows what that does to the next run's false unknowns.
    #[arg(long, value_name = "N", requires = "train")]
    pub per_class: Option<usize>,
    /// With open-set and --per-class: of those, images trained on; the rest validate the
    /// kernel width (the paper: 13 of 20).
    #[arg(long, value_name = "N", requires = "per_class")]
    pub train: Option<usize>,
    /// With open-set: the share of known images the models may call unknown, as `train
    /// --unknown-rate` (default 0.02): to see what a lower or higher rate trades on your set.
    #[arg(long, value_name = "R")]
    pub unknown_rate: Option<f64>,
    /// With open-set: the models also carry the texture check (`train --check-texture`), to
    /// see what it finds and costs on your set.
    #[arg(long)]
    pub check_texture: bool,
    /// Your own dataset (DIR/<class>/<images>, as `presrs train` reads it) for Table 1,
    /// Figure 5, Figure 16 and Table 6. The other experiments need several sets (sandpaper,
    /// one per gait, a closed loop) and run on the simulator.
    #[arg(long, value_name = "DIR")]
    pub data: Option<PathBuf>,
    /// Crop of the `--data` images (top,bottom,left,right); default none.
    #[arg(long, value_name = "T,B,L,R", requires = "data")]
    pub crop: Option<Crop>,
    /// With `--data` or `--extra-source`: scale each image to the set's mean load before its
    /// features, as `train --normalize-load` does: for images taken at several loads (a foot
    /// hopping or walking at several speeds, e.g. SpeedPP2D). Used by the open-set section.
    #[arg(long)]
    pub normalize_load: bool,
    /// With `--data`: go on past unreadable images and count them.
    #[arg(long, requires = "data")]
    pub skip_bad: bool,
    /// More datasets for the open-set section (repeatable), each split by the runs of its
    /// capture manifest: e.g. the real SpeedPP2D pressure maps that `scripts/speedpp2d.py`
    /// writes (with `--terrains DIR/terrains.toml`).
    #[arg(long, value_name = "DIR")]
    pub extra_source: Vec<PathBuf>,
    /// With `--data` or `--extra-source`: the catalog its class folders are named in.
    #[command(flatten)]
    pub terrains: protocol::TerrainsArg,
}

pub fn run(a: ExperimentArgs) -> Result<ExitCode> {
    // Refused before any section runs (the open-set section, which uses them, is the last).
    let open_set_models =
        OpenSetModels::new(a.per_class.zip(a.train), a.unknown_rate, a.check_texture)?;
    // One dataset folder (`--data` or an `--extra-source`), named by its flag in errors.
    let load = |flag: &str, dir: &PathBuf, crop: Crop| -> Result<UserData> {
        let (set, _) = TrainingSet::load(dir, &a.terrains.catalog()?, a.skip_bad)
            .with_context(|| format!("reading {flag} {}", dir.display()))?;
        Ok(UserData {
            dir: dir.clone(),
            set,
            crop,
            normalize_load: a.normalize_load,
        })
    };
    let user = match &a.data {
        Some(dir) => Some(load("the dataset --data", dir, a.crop.unwrap_or_default())?),
        None => None,
    };
    let extra = a
        .extra_source
        .iter()
        .map(|dir| load("--extra-source", dir, Crop::default()))
        .collect::<Result<Vec<_>>>()?;
    let mut ctx = Report::new(a.out.join("figures"), a.quick, a.seed, user)?;
    ctx.extra = extra;
    ctx.open_set_seeds = a.seeds;
    ctx.open_set_models = open_set_models;
    let t0 = std::time::Instant::now();
    let md = ctx.markdown(
        &a.which.0,
        &mut || lab::model::load_or_train_logged(None).map_err(Into::into),
        &mut |w| eprintln!("experiment {w:?}..."),
    )?;
    let name = match a.which.name() {
        "all" => "results.md".to_string(),
        one => format!("{one}.md"),
    };
    // The command as given (its binary named `presrs`): what regenerates this file.
    let command = lab::report::command_line(std::env::args().skip(1));
    let head = ctx.provenance(&command, t0.elapsed().as_secs_f64());
    let path = a.out.join(name);
    std::fs::write(&path, head + &md).with_context(|| format!("writing {}", path.display()))?;
    eprintln!(
        "wrote {} and its figures in {}",
        path.display(),
        ctx.figures.display()
    );
    Ok(ExitCode::SUCCESS)
}
