//! The README's own-robot path walked on feet that are not the paper's (`presrs lab feet`).
//!
//! Every rule fitted to one foot has failed on the next, so each foot gets the path a lab walks
//! on its first try, with `train`'s defaults: two small sessions of three known terrains
//! (`capture`, `train`), then a third session with a fourth terrain the model never saw
//! (`node --replay` against the truth). The table per foot says what `train` chose (the
//! deciding frame and why, the crop), how much known ground the third session got right and
//! sent to the safe gait, how much new ground it found, and how far the node's touchdown times
//! lie from the truth; the worst foot gets its own line.
//!
//! The feet are the simulator's ([`sim::foot_model::FootModel::presets`]: the hopper wears
//! them) and, where `python3` and the foot emulator are found, the independent foot board in
//! `../shared/foot-emulator/foot.py`, written from the spec by someone else, streaming the
//! simulator's terrain images (and, with `--speedpp2d DIR`, real plantar-pressure maps) as its
//! feet press them.

mod emulator;
mod new_ground;
mod session;
mod walk;

use std::path::PathBuf;

pub use emulator::{EMULATOR_FEET, Emulator};
pub use new_ground::Learned;
pub use session::{Recording, Session};
pub use walk::{Trial, walk};

/// A foot the path is walked on.
#[derive(Clone, Debug)]
pub enum Foot {
    /// The simulated hopper wearing this foot.
    Sim(sim::foot_model::FootModel),
    /// The shared foot emulator with these flags (`--roll --ramp 0.12`, ...).
    Emulator {
        /// Its name in the table.
        name: String,
        /// The emulator's flags.
        flags: Vec<String>,
    },
}

impl Foot {
    /// The foot's name in the table.
    pub fn name(&self) -> String {
        match self {
            Foot::Sim(m) => format!("sim: {}", m.name),
            Foot::Emulator { name, .. } => format!("emulator: {name}"),
        }
    }
}

/// Where the terrain images of an emulator foot come from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Source {
    /// The simulator's terrains (wood, carpet, clay known; grass new).
    Simulator,
    /// SpeedPP2D's people as terrains, from `scripts/speedpp2d.py`'s folder.
    SpeedPp2d(PathBuf),
}

impl Source {
    /// Its name in the table.
    pub fn name(&self) -> &'static str {
        match self {
            Source::Simulator => "simulator",
            Source::SpeedPp2d(_) => "SpeedPP2D",
        }
    }
}

/// How the path is walked.
#[derive(Clone, Debug)]
pub struct FeetOptions {
    /// The seeds (each a new set of sessions).
    pub seeds: Vec<u64>,
    /// Stances per known terrain in each of the two training sessions.
    pub steps: usize,
    /// Stances per terrain in the mixed third session (the new terrain's too).
    pub third_steps: usize,
    /// Scratch folder (the captured sets, the emulator's logs); each trial's is removed
    /// unless `keep`.
    pub scratch: PathBuf,
    /// Keep each trial's folder (its images, logs, set and `model.json`).
    pub keep: bool,
    /// How `discover` groups the kept stances (its defaults; others to measure them).
    pub grouping: node::unknown::discover::Grouping,
}

impl Default for FeetOptions {
    fn default() -> Self {
        Self {
            seeds: (1..=5).collect(),
            steps: 25,
            third_steps: 20,
            scratch: std::env::temp_dir().join(format!("presrs-feet-{}", std::process::id())),
            keep: false,
            grouping: Default::default(),
        }
    }
}

/// Why a trial could not run.
#[derive(Debug, thiserror::Error)]
pub enum FeetError {
    /// The emulator failed or its output could not be read.
    #[error("foot emulator: {0}")]
    Emulator(String),
    /// A scratch file.
    #[error("{0}: {1}")]
    Io(String, #[source] std::io::Error),
    /// Capturing a session.
    #[error(transparent)]
    Capture(#[from] node::capture::CaptureError),
    /// Reading the captured set back.
    #[error(transparent)]
    Load(#[from] node::training::LoadError),
    /// Training.
    #[error(transparent)]
    Train(#[from] node::training::TrainCalibratedError),
    /// The node refused the model.
    #[error(transparent)]
    Node(#[from] node::ServiceError),
    /// A terrains file or catalog.
    #[error(transparent)]
    Catalog(#[from] protocol::terrain::CatalogError),
}

/// Every trial's row, and the table `presrs lab feet` prints: per foot and source the spread
/// over seeds, and the worst foot on its own line.
#[derive(Clone, Debug, Default)]
pub struct FeetTable {
    /// One per foot, source and seed.
    pub trials: Vec<Trial>,
}

impl FeetTable {
    /// The trials of each foot and source, in the order first met.
    fn groups(&self) -> Vec<(String, &'static str, Vec<&Trial>)> {
        let mut out: Vec<(String, &'static str, Vec<&Trial>)> = Vec::new();
        for t in &self.trials {
            match out
                .iter_mut()
                .find(|(f, s, _)| *f == t.foot && *s == t.source)
            {
                Some(g) => g.2.push(t),
                None => out.push((t.foot.clone(), t.source, vec![t])),
            }
        }
        out
    }

    /// The worst trial: the least known ground right, then the most of it unknown.
    pub fn worst(&self) -> Option<&Trial> {
        self.trials
            .iter()
            .filter(|t| t.error.is_none())
            .min_by(|a, b| {
                a.known_right()
                    .total_cmp(&b.known_right())
                    .then(b.known_unknown().total_cmp(&a.known_unknown()))
            })
    }

    /// The table as JSON: every trial.
    pub fn to_json(&self) -> serde_json::Value {
        serde_json::Value::Array(self.trials.iter().map(Trial::to_json).collect())
    }
}

impl std::fmt::Display for FeetTable {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let pct = |v: &[f64]| {
            let mut v: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
            v.sort_by(|a, b| a.total_cmp(b));
            match (v.first(), v.get(v.len() / 2), v.last()) {
                (Some(lo), Some(m), Some(hi)) if v.len() > 1 => {
                    format!("{:.1}% ({:.1}-{:.1})", 100.0 * m, 100.0 * lo, 100.0 * hi)
                }
                (Some(m), _, _) => format!("{:.1}%", 100.0 * m),
                _ => "-".into(),
            }
        };
        writeln!(
            f,
            "known ground right and called unknown, new ground found: the median over seeds \
             (lowest-highest); frames and crops as `train` chose them per seed"
        )?;
        writeln!(
            f,
            "{:<42} {:<10} {:<18} {:<18} {:<18} {:>9}  frame (ms) / crop",
            "foot", "source", "known right", "known unknown", "new found", "td err ms"
        )?;
        for (foot, source, ts) in self.groups() {
            let ok: Vec<&&Trial> = ts.iter().filter(|t| t.error.is_none()).collect();
            let col = |g: &dyn Fn(&Trial) -> f64| pct(&ok.iter().map(|t| g(t)).collect::<Vec<_>>());
            let td = ok
                .iter()
                .filter_map(|t| t.touchdown_err_ms)
                .fold(None::<f64>, |m, e| Some(m.map_or(e, |m| m.max(e))));
            let frames: Vec<String> = ok
                .iter()
                .map(|t| {
                    format!(
                        "{}/{}",
                        t.frame_ms.map_or("-".into(), |m| m.to_string()),
                        t.crop
                    )
                })
                .collect();
            writeln!(
                f,
                "{:<42} {:<10} {:<18} {:<18} {:<18} {:>9}  {}",
                foot,
                source,
                col(&Trial::known_right),
                col(&Trial::known_unknown),
                col(&Trial::new_found),
                td.map_or("-".into(), |e| format!("{e:.1}")),
                frames.join(" ")
            )?;
            write_details(f, &ok, &ts)?;
        }
        if let Some(w) = self.worst() {
            writeln!(
                f,
                "worst: {} on {} seed {}: known ground {:.1}% right, {:.1}% unknown; new ground \
                 {:.1}% found; frame {} ms ({}), crop {}",
                w.foot,
                w.source,
                w.seed,
                100.0 * w.known_right(),
                100.0 * w.known_unknown(),
                100.0 * w.new_found(),
                w.frame_ms.map_or("-".into(), |m| m.to_string()),
                w.frame_why,
                w.crop
            )?;
        }
        Ok(())
    }
}

/// The lines under a foot's row: where a crop was kept, what the same path gave without one;
/// the confidence; new ground per seed; each seed that failed.
fn write_details(
    f: &mut std::fmt::Formatter<'_>,
    ok: &[&&Trial],
    ts: &[&Trial],
) -> std::fmt::Result {
    // Where a crop was kept: what the same path gave without one.
    let cropped: Vec<&&&Trial> = ok.iter().filter(|t| t.uncropped.is_some()).collect();
    if !cropped.is_empty() {
        let (with, without) = cropped.iter().fold((0.0, 0.0), |(a, b), t| {
            let (n, r) = t.uncropped.unwrap_or((1, 0));
            (a + t.known_right(), b + r as f64 / n.max(1) as f64)
        });
        let n = cropped.len() as f64;
        writeln!(
            f,
            "  {} of {} seeds kept a crop: known ground right {:.1}% with it, {:.1}% \
             with none (the mean of those seeds)",
            cropped.len(),
            ok.len(),
            100.0 * with / n,
            100.0 * without / n
        )?;
    }
    let (new_conf, new_steps) = ok
        .iter()
        .fold((0, 0), |(c, n), t| (c + t.new_confident, n + t.new.0));
    let ece: Vec<f64> = ok.iter().filter_map(|t| t.calibration_error()).collect();
    writeln!(
        f,
        "  confidence: new ground taken for known at 90% or more {new_conf} of {new_steps} \
         steps; known ground's calibration error {} points (worst seed)",
        ece.iter()
            .copied()
            .fold(None::<f64>, |m, e| Some(m.map_or(e, |m| m.max(e))))
            .map_or("-".into(), |e| format!("{:.1}", 100.0 * e))
    )?;
    // New ground: kept, grouped, added, met again (per seed).
    let each: Vec<String> = ok
        .iter()
        .filter_map(|t| t.learned.as_ref().map(|l| (t, l)))
        .map(|(t, l)| {
            let group = l.group.map_or("no group".into(), |(n, of)| {
                format!("group {of}/{n} of {}", t.new.0)
            });
            let (nn, nr) = l.fresh_new;
            let (kn, kb, ka) = l.fresh_known;
            format!(
                "seed {}: {group}, by {}; then new {nr}/{nn}, known {kb}->{ka} of {kn}",
                t.seed, l.added_by
            )
        })
        .collect();
    if !each.is_empty() {
        writeln!(f, "  new ground: {}", each.join("; "))?;
    }
    for t in ts.iter().filter(|t| t.error.is_some()) {
        writeln!(f, "  seed {}: {}", t.seed, t.error.as_deref().unwrap_or(""))?;
    }
    Ok(())
}

/// Walks every foot in `feet` with every seed (and each emulator foot on every source in
/// `sources`); `progress` hears each trial as it ends.
pub fn run(
    feet: &[Foot],
    sources: &[Source],
    emulator: Option<&Emulator>,
    opts: &FeetOptions,
    progress: &mut dyn FnMut(&Trial),
) -> FeetTable {
    let mut table = FeetTable::default();
    for foot in feet {
        let srcs: Vec<&Source> = match foot {
            Foot::Sim(_) => vec![&Source::Simulator],
            Foot::Emulator { .. } => sources.iter().collect(),
        };
        for source in srcs {
            for &seed in &opts.seeds {
                let t = walk(foot, source, emulator, seed, opts);
                progress(&t);
                table.trials.push(t);
            }
        }
    }
    table
}
