//! Fitting a model's energy check ([`crate::unknown::energy`]) from the robot's closed-loop runs
//! on known ground (`presrs lab energy`): each run's candump log goes through the node's own stance
//! logic and classifier; each stance whose label and texture agree gives its class one
//! (flight before, flight after) pair.
//!
//! Closed-loop runs, not steady hopping at one gait: a return map needs stances entered at
//! several energies (gait switches, terrain changes), as the robot meets them. Fitted on steady
//! hopping only, a map is a constant that the first stance after a gait switch leaves.

use protocol::Terrain;
use protocol::candump::LogRecord;

#[cfg(doc)]
use crate::capture::Labelling;
use crate::capture::Skip;
use crate::classifier::Model;
use crate::config::NodeConfig;
use crate::stance::{Decided, StancePipeline};
use crate::unknown::energy::{self, ReturnMap};

/// Why no energy check could be fitted.
#[derive(Debug, thiserror::Error)]
pub enum EnergyFitError {
    /// No run was given.
    #[error("no runs: give the candump logs of closed-loop runs on known ground")]
    NoRuns,
    /// A run's labels name a terrain the model has no class for.
    #[error(
        "{run}: its labels name {terrain}, which the model does not know; label only terrains the model was trained on, or train it with them"
    )]
    UnknownTerrain {
        /// The run.
        run: String,
        /// The terrain's name.
        terrain: String,
    },
    /// Not one class got enough stances.
    #[error(
        "{runs}: no class got {min} stances with both flights and the texture agreeing with the label ({used} stances in all, {skipped}); record longer closed-loop runs on known ground"
    )]
    TooFew {
        /// The runs, for the message.
        runs: String,
        /// [`energy::MIN_STANCES`].
        min: usize,
        /// Stances that qualified.
        used: usize,
        /// Why the rest did not, for the message.
        skipped: String,
    },
}

/// One closed-loop run: its log and its labels.
pub struct EnergyRun<'a> {
    /// The run's name (its log's path), for messages.
    pub name: String,
    /// The log's records, streamed (a [`protocol::candump::LogFile`]'s, or a slice's).
    pub records: &'a mut dyn Iterator<Item = LogRecord>,
    /// The terrain of each stance from its foot and its span in the log's time (touchdown to
    /// the next touchdown): a capture's [`Labelling::label`], or a simulator's truth.
    pub label: &'a dyn Fn(u8, u64, u64) -> Result<Terrain, Skip>,
}

/// What a fit used and skipped, per the model's classes.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct EnergyFitReport {
    /// Stances judged (every touchdown after the first).
    pub stances: usize,
    /// Per class: stances the map was fitted on.
    pub used: Vec<usize>,
    /// Skipped: a flight missing or not a hop (standing, lost edges).
    pub no_flights: usize,
    /// Skipped: outside every label, or spanning two.
    pub unlabelled: usize,
    /// Skipped: the texture said another terrain or unknown (the node would not hold the
    /// stance against the label's map).
    pub texture_disagrees: usize,
    /// Per class: the share of its fitting stances outside the fitted map (the calibration's
    /// own check; about the model's unknown rate or less).
    pub outside: Vec<f64>,
}

impl EnergyFitReport {
    /// One line for a person: what was judged, fitted and skipped.
    pub fn summary(&self) -> String {
        format!(
            "{} stances judged: {} fitted, {}",
            self.stances,
            self.used.iter().sum::<usize>(),
            self.skipped()
        )
    }

    fn skipped(&self) -> String {
        format!(
            "{} without two plausible flights, {} unlabelled, {} where the texture said otherwise",
            self.no_flights, self.unlabelled, self.texture_disagrees
        )
    }
}

/// Fits `model`'s energy check (its `energy` key) on `runs`, the node's stance logic set by
/// `cfg`; the band's tails at the model's `unknown_rate` (2% when it has none).
pub fn fit_energy(
    cfg: &NodeConfig,
    model: &mut Model,
    runs: &mut [EnergyRun],
) -> Result<EnergyFitReport, EnergyFitError> {
    if runs.is_empty() {
        return Err(EnergyFitError::NoRuns);
    }
    let n = model.classes.len();
    let mut rep = EnergyFitReport {
        used: vec![0; n],
        ..Default::default()
    };
    let mut stances: Vec<(usize, f64, f64)> = Vec::new();
    let mut plain = model.clone();
    plain.unknown.energy = None;
    let mut cfg = cfg.clone();
    cfg.refit = cfg.refit.reproducible();
    for run in runs.iter_mut() {
        let mut p = StancePipeline::new(cfg.clone(), Some(plain.clone()));
        let mut last = vec![None; cfg.feet as usize];
        for r in &mut *run.records {
            p.tick(r.stamped.t_us, &mut |_: Decided| {});
            p.on_frame(&r.stamped, &mut |_: Decided| {});
            for foot in 0..cfg.feet {
                let o = p.energy_observation(foot);
                if o.is_none() || o == last[foot as usize] {
                    continue;
                }
                last[foot as usize] = o;
                let Some(o) = o else { continue };
                rep.stances += 1;
                let label = match (run.label)(foot, o.span_rx_us.0, o.span_rx_us.1) {
                    Ok(t) => t,
                    Err(Skip::Unlabelled | Skip::SpansLabels) => {
                        rep.unlabelled += 1;
                        continue;
                    }
                    Err(_) => continue,
                };
                let Some(k) = model
                    .classes
                    .iter()
                    .position(|c| c.terrain_id == label.id())
                else {
                    return Err(EnergyFitError::UnknownTerrain {
                        run: run.name.clone(),
                        terrain: label.name().to_string(),
                    });
                };
                let Some((b, a)) = o.flights_s() else {
                    rep.no_flights += 1;
                    continue;
                };
                if o.class != Some(k) {
                    rep.texture_disagrees += 1;
                    continue;
                }
                rep.used[k] += 1;
                stances.push((k, b, a));
            }
        }
    }
    let rate = model.unknown.rate;
    let maps = energy::fit(&stances, n, rate);
    if maps.iter().all(Option::is_none) {
        return Err(EnergyFitError::TooFew {
            runs: runs
                .iter()
                .map(|r| r.name.as_str())
                .collect::<Vec<_>>()
                .join(", "),
            min: energy::MIN_STANCES,
            used: stances.len(),
            skipped: rep.skipped(),
        });
    }
    rep.outside = (0..n)
        .map(|k| {
            let Some(m) = maps[k] else { return 0.0 };
            let mine: Vec<_> = stances.iter().filter(|s| s.0 == k).collect();
            let out = mine.iter().filter(|s| !m.passes(s.1, s.2)).count();
            out as f64 / mine.len().max(1) as f64
        })
        .collect();
    model.unknown.energy = Some(maps);
    Ok(rep)
}

/// The fitted maps, one line per class for a person.
pub fn describe(model: &Model, rep: &EnergyFitReport) -> Vec<String> {
    let maps: &[Option<ReturnMap>] = model.unknown.energy.as_deref().unwrap_or(&[]);
    model
        .classes
        .iter()
        .enumerate()
        .map(|(k, c)| match maps.get(k).copied().flatten() {
            Some(m) => format!(
                "{}: flight after = {:.4} s + {:.3} x flight before, residual {:+.1}..{:+.1} ms, {} stances ({:.1}% outside)",
                c.name,
                m.intercept_s,
                m.slope,
                m.residual_s[0] * 1e3,
                m.residual_s[1] * 1e3,
                m.stances,
                100.0 * rep.outside.get(k).copied().unwrap_or(0.0)
            ),
            None => format!(
                "{}: no map ({} stances, want {}): its steps are not checked",
                c.name,
                rep.used.get(k).copied().unwrap_or(0),
                energy::MIN_STANCES
            ),
        })
        .collect()
}
