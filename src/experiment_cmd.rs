//! `presrs lab experiment`: the paper's tables and figures ([`lab::report`]) written to
//! `OUT/results.md` (or `OUT/WHICH.md`) with `OUT/figures/`, under a header saying where the
//! data came from and how to regenerate it.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result};
use lab::report::{OpenSetModels, Report, UserData};
use lab::simdata::TrainingSet;
use node::classifier::image::Crop;
use presrs_cli::experiment::ExperimentArgs;

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
