//! The model the demo, the experiments and the benchmarks use when none is given: trained once
//! on simulated stances of the three gaits, then cached.

use std::path::{Path, PathBuf};

use node::NodeConfig;
use node::classifier::train::TrainOptions;
use node::classifier::{Crop, Model};

use crate::LabError;

/// Bumped when training's rejection of unknown terrain changes (1: per-class thresholds
/// calibrated to `--unknown-rate`; 2, 3: the opt-in load check; 4: the distance margin; 5: the
/// novelty score, calibrated on a second run; 6: that run's images as references and its
/// nuisance directions; 7: the energy check, fitted on a closed-loop run; 8: the checks chosen
/// by measurement, `node::training::choice`), so that a cached model is retrained with it.
pub const OPEN_SET_VERSION: u32 = 8;

/// Where the model trained on first run is kept: `$XDG_CACHE_HOME/presrs` (or `~/.cache`),
/// named by the model format and simulator versions so that either change retrains.
pub fn cache_path() -> PathBuf {
    let base = std::env::var_os("XDG_CACHE_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache")))
        .unwrap_or_else(std::env::temp_dir);
    base.join("presrs").join(format!(
        "demo-model-v{}-sim{}-open{}.json",
        node::classifier::model::MODEL_VERSION,
        sim::SIM_VERSION,
        OPEN_SET_VERSION
    ))
}

/// A model for the dynamic terrains from simulator data of all three gaits, its unknown-terrain
/// rejection calibrated on a second run (other stances of the same foot), as a lab would.
pub fn sim_model(seed: u64) -> Result<Model, LabError> {
    let run = |seed: u64, n: usize| {
        let mut samples = Vec::new();
        for (i, g) in controller::Gait::paper_gaits().into_iter().enumerate() {
            let opts = sim::dataset::Options {
                kind: sim::dataset::Kind::Dynamic,
                n: Some(n),
                gait: g,
                damage_pct: 0.0,
                // The sensor the demo's foot wears (SimConfig's default).
                sensor: sim::DEFAULT_SENSOR,
                seed: seed + i as u64,
            };
            samples.extend(sim::dataset::generate(&opts));
        }
        crate::simdata::training_set(samples, &sim::dataset::Kind::Dynamic.terrains())
    };
    let set = run(seed, 30);
    // Load-normalised (the paper's intensity scaling): a gait switch or a terrain change
    // changes the load at 70 ms for a few steps, and the texture should decide, not the load.
    let opts = TrainOptions {
        per_class: 45,
        train: 30,
        normalize_load: true,
        crop: Crop {
            top: 0,
            bottom: 3,
            left: 6,
            right: 0,
        }
        .into(),
        seed,
        ..Default::default()
    };
    let cal = run(seed + 1000, 15);
    let names = [format!("simulator run, seed {}", seed + 1000)];
    let mut m = set.train_calibrated(&opts, Some((&cal, &names)))?.model;
    fit_energy_on_sim(&mut m, seed + 2000, ENERGY_FIT_STEPS, None)?;
    Ok(m)
}

/// Steps of the closed-loop run the demo model's energy check is fitted on: about 100 stances
/// per terrain of the default track.
pub const ENERGY_FIT_STEPS: usize = 400;

/// Fits `m`'s energy check ([`node::unknown::energy`]) as a lab would on its robot: a
/// closed-loop run of `steps` steps on the default track (the controller switching gaits, so
/// that stances are entered at several energies), labelled with the simulator's truth.
///
/// The map is the leg's as much as the ground's: `leg` the leg of motors the robot runs (none:
/// the simulator's direct leg; docs/decisions/figures-behind-comments.md, energy-per-leg).
pub fn fit_energy_on_sim(
    m: &mut Model,
    seed: u64,
    steps: usize,
    leg: Option<leg::LegConfig>,
) -> Result<node::unknown::energy_fit::EnergyFitReport, LabError> {
    let ctrl = controller::ControllerConfig::default();
    fit_energy_on_sim_with(m, seed, steps, leg, &ctrl)
}

/// [`fit_energy_on_sim`] with the controller `ctrl` on the run (its gaits, its sweep).
pub fn fit_energy_on_sim_with(
    m: &mut Model,
    seed: u64,
    steps: usize,
    leg: Option<leg::LegConfig>,
    ctrl: &controller::ControllerConfig,
) -> Result<node::unknown::energy_fit::EnergyFitReport, LabError> {
    let track = sim::runner::Track::default();
    let mut p = crate::LoopParams::with_controller(ctrl, steps, seed);
    p.leg = leg;
    let mut log = Vec::new();
    let stop = std::sync::atomic::AtomicBool::new(false);
    let run = crate::closed_loop::run_to(
        &track,
        m.clone(),
        &p,
        |_| {},
        crate::closed_loop::DemoOutputs {
            live: None,
            log: Some(&mut log),
            paced: false,
            stop: &stop,
        },
    )?;
    let records = protocol::candump::read_log(&log[..]).map_err(|e| {
        LabError::Log(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            e.to_string(),
        ))
    })?;
    // Labelled as a lab labels its runs, and as `presrs demo --truth` writes them.
    let end_us = run.truth.last().map_or(0, |s| s.touchdown_us) + 1_000_000;
    let text = sim::runner::truth_labels(&run.truth, end_us);
    let labelling = node::capture::Labelling::Ranges(node::capture::parse_labels(
        &text,
        "the run's truth",
        &protocol::TerrainCatalog::paper(),
    )?);
    let label = |foot: u8, t0: u64, t1: u64| labelling.label(foot, t0, t1);
    let mut records = records.into_iter();
    let mut runs = [node::unknown::energy_fit::EnergyRun {
        name: format!("closed-loop simulator run, seed {seed}"),
        records: &mut records,
        label: &label,
    }];
    Ok(node::unknown::energy_fit::fit_energy(
        &NodeConfig::default(),
        m,
        &mut runs,
    )?)
}

/// Where [`load_or_train`]'s model came from.
#[derive(Debug)]
pub enum Source {
    /// The file given.
    Given,
    /// The cache, from an earlier run.
    Cached(PathBuf),
    /// Trained now and cached (`Ok(path)`), or trained now and not cached (why).
    Trained(Result<PathBuf, node::classifier::model::ModelError>),
}

impl Source {
    /// What to tell the user about where the model came from (nothing for a file they gave).
    pub fn describe(&self) -> Option<String> {
        match self {
            Source::Given => None,
            Source::Cached(p) => Some(format!("using the cached demo model {}", p.display())),
            Source::Trained(Ok(p)) => Some(format!("cached the model at {}", p.display())),
            Source::Trained(Err(e)) => Some(format!(
                "could not cache the model ({e}); it will be trained again next time"
            )),
        }
    }
}

/// The model at `path`, or without one the cached simulator model, trained and cached on
/// first use (`before_training` runs first: training takes a while, say so).
pub fn load_or_train(
    path: Option<&Path>,
    before_training: impl FnOnce(),
) -> Result<(Model, Source), LabError> {
    if let Some(p) = path {
        return Ok((Model::load(p)?, Source::Given));
    }
    let cache = cache_path();
    if let Ok(m) = Model::load(&cache) {
        return Ok((m, Source::Cached(cache)));
    }
    before_training();
    let m = sim_model(11)?;
    if let Some(dir) = cache.parent() {
        let _ = std::fs::create_dir_all(dir);
    }
    let saved = m.save(&cache).map(|()| cache);
    Ok((m, Source::Trained(saved)))
}

/// The demo model's energy check fitted for a leg of motors (`kind` names it in the cache; the
/// energy check is the leg's as much as the ground's, see [`fit_energy_on_sim`]), cached beside
/// the model; `cache` false fits it afresh (a leg config of the user's).
pub fn with_leg_energy(
    mut m: Model,
    leg: leg::LegConfig,
    kind: &str,
    cache: bool,
) -> Result<Model, LabError> {
    let base = cache_path();
    let path = base.with_file_name(format!(
        "{}-leg-{kind}.json",
        base.file_stem()
            .map_or("demo-model".into(), |s| s.to_string_lossy())
    ));
    if cache && let Ok(c) = Model::load(&path) {
        return Ok(c);
    }
    tracing::info!("fitting the demo model's energy check on the {kind} leg (first run only)");
    fit_energy_on_sim(&mut m, 11 + 2000, ENERGY_FIT_STEPS, Some(leg))?;
    if cache {
        let _ = m.save(&path);
    }
    Ok(m)
}

/// [`load_or_train`], saying on the log (`tracing`, info) that it trains (it takes a while) and
/// where the model came from: what a command-line tool wants.
pub fn load_or_train_logged(path: Option<&Path>) -> Result<Model, LabError> {
    let (m, source) = load_or_train(path, || {
        tracing::info!("no model given: training one on simulated G1-G3 stances (first run only)")
    })?;
    if let Some(said) = source.describe() {
        tracing::info!("{said}");
    }
    Ok(m)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn where_the_model_came_from_is_said_unless_the_user_gave_it() {
        assert_eq!(Source::Given.describe(), None);
        let p = PathBuf::from("/c/m.json");
        let said = Source::Cached(p.clone()).describe().unwrap();
        assert!(said.contains("cached demo model /c/m.json"), "{said}");
        let said = Source::Trained(Ok(p)).describe().unwrap();
        assert!(said.contains("cached the model at /c/m.json"), "{said}");
        // A file given is that file or an error naming it, never the cached model instead.
        let e = load_or_train_logged(Some(Path::new("/nonexistent/m.json"))).unwrap_err();
        assert!(e.to_string().contains("/nonexistent/m.json"), "{e}");
    }
}
