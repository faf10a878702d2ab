//! The paper's experiments as a report: Markdown sections with the paper's numbers beside
//! ours, and their figures (PNG, drawn with `plotters`).
//!
//! [`Report::markdown`] runs the experiments asked for ([`Experiment`]) on the simulator, or on a
//! lab's own dataset ([`UserData`]) where one set suffices (Table 1, Figure 5, Figure 16,
//! Table 6), and returns the sections; the figures go to [`Report::figures`]. `presrs
//! experiment` writes them to `docs/results.md`. Every number comes from a run of this code;
//! nothing is copied from the paper except the "paper" columns.
//!
//! One file per section (`static_table`, `resolution`, `dynamic`, `gaits`, `damage` with the
//! lifespan, `adaptation`, `open_set`); `plot` draws what they share.

use std::path::PathBuf;

use node::classifier::Model;
use node::classifier::features::FeatureExtractor;
use node::classifier::image::Crop;
use plotters::prelude::*;
use sim::dataset::Kind;
use sim::terrain::Terrain;

use crate::LabError;
use crate::simdata::TrainingSet;
use crate::study::{Curves, DEAD_AFTER_STANCES, dataset, train_on};
use tools::eval::confusion;

/// One section of the report.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Experiment {
    /// Table 1 and Figure 5: static classification and its feature vectors.
    Static,
    /// Full resolution against 10x10, similar and dissimilar terrains.
    Resolution,
    /// Figure 13: mean dynamic feature vectors per terrain and gait.
    Dynamic,
    /// Table 5 and Table 3: classifiers per gait across gaits; speeds.
    Gaits,
    /// Figure 16: accuracy against sensor damage, four repair arms.
    Damage,
    /// Table 6: life span at >= 90% accuracy (uses the damage curves).
    Lifespan,
    /// Gait adaptation on the default track (the demo's closed loop).
    Adaptation,
    /// Unknown terrain: leave-one-terrain-out with the calibrated rejection.
    OpenSet,
}

/// The experiments a command asks for: one by its name, or `all` (parsed from the command
/// line: `presrs lab experiment open-set`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Selection(pub Vec<Experiment>);

impl Selection {
    /// Every name a selection takes, `all` first.
    pub const NAMES: [&str; 9] = [
        "all",
        "static",
        "resolution",
        "dynamic",
        "gaits",
        "damage",
        "lifespan",
        "adaptation",
        "open-set",
    ];

    /// Its name as given on the command line: `all`, or the experiment's.
    pub fn name(&self) -> &'static str {
        match self.0.as_slice() {
            [one] => one.name(),
            _ => "all",
        }
    }
}

impl std::str::FromStr for Selection {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        if s == "all" {
            return Ok(Selection(Experiment::ALL.to_vec()));
        }
        Experiment::ALL
            .iter()
            .find(|e| e.name() == s)
            .map(|e| Selection(vec![*e]))
            .ok_or_else(|| format!("`{s}`: expected one of {}", Self::NAMES.join(", ")))
    }
}

impl Experiment {
    /// Its name on the command line and in file names: `open-set`.
    pub fn name(self) -> &'static str {
        match self {
            Experiment::Static => "static",
            Experiment::Resolution => "resolution",
            Experiment::Dynamic => "dynamic",
            Experiment::Gaits => "gaits",
            Experiment::Damage => "damage",
            Experiment::Lifespan => "lifespan",
            Experiment::Adaptation => "adaptation",
            Experiment::OpenSet => "open-set",
        }
    }

    /// Every section, in the report's order.
    pub const ALL: [Experiment; 8] = [
        Experiment::Static,
        Experiment::Resolution,
        Experiment::Dynamic,
        Experiment::Gaits,
        Experiment::Damage,
        Experiment::Lifespan,
        Experiment::Adaptation,
        Experiment::OpenSet,
    ];
}

/// A lab's own dataset (`DIR/<class>/<images>`, as `presrs train` reads it).
pub struct UserData {
    /// Where it was read from (named in the report).
    pub dir: PathBuf,
    /// The images and their classes.
    pub set: TrainingSet,
    /// The crop its images get.
    pub crop: Crop,
    /// Scale each image to the set's mean load (the paper's intensity scaling; foot stances).
    pub normalize_load: bool,
}

/// Why a report could not be made.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// Training or running the loop.
    #[error(transparent)]
    Lab(#[from] LabError),
    /// Drawing or writing a figure.
    #[error(transparent)]
    Plot(#[from] tools::plot::PlotError),
    /// The figures folder.
    #[error("creating {path}: {source}")]
    Folder {
        /// The folder.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The simulated hopper fell while measuring its cadence.
    #[error("the G2 hopper fell")]
    Fell,
    /// An open-set `--unknown-rate` out of range, or 0 (the rejection off).
    #[error(
        "--unknown-rate {0}: the open-set experiment needs a share above 0 and at most {max} \
         (0.02 is 2%; 0 turns the rejection it measures off)",
        max = node::classifier::model::MAX_UNKNOWN_RATE
    )]
    OpenSetRate(f64),
    /// The demo model for the adaptation section.
    #[error("the demo model: {0}")]
    DemoModel(#[source] Box<dyn std::error::Error + Send + Sync>),
}

mod adaptation;
mod damage;
mod dynamic;
mod gaits;
mod open_set;
mod open_set_seeds;
mod plot;
mod resolution;
mod static_table;

use adaptation::adaptation;
use damage::{damage, lifespan};
use dynamic::dynamic_features;
use gaits::gaits;
use open_set::open_set;
use plot::{draw_features, feature_plot};
pub(crate) use plot::{legend, pe, register_font};
use resolution::resolution;
use static_table::static_table;

/// The experiments' settings and where their figures go.
pub struct Report {
    /// Folder of the figures (created by [`Report::new`]).
    pub figures: PathBuf,
    /// Fewer images and steps: a check that everything runs, not results to quote.
    pub quick: bool,
    /// Seed of every simulated set and split.
    pub seed: u64,
    /// A lab's own dataset for the sections one set suffices for.
    pub user: Option<UserData>,
    /// More sources for the open-set section (a public dataset, another lab's set).
    pub extra: Vec<UserData>,
    /// Seeds the open-set section runs, from `seed` on: more than one adds the spread of its
    /// figures over them.
    pub open_set_seeds: u64,
    /// How the open-set section trains its models.
    pub open_set_models: OpenSetModels,
}

/// How the open-set section trains its models, where they may differ from `train`'s defaults
/// (checked when made, so that a bad value is refused before any section runs).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct OpenSetModels {
    /// Images drawn per class and, of them, trained on (the rest validate); `None` is the
    /// paper's 20 and 13. More than a run's images per class stores the whole training run
    /// and leaves none of it to the calibration: see `node::unknown::novelty`, "How many
    /// images to store".
    split: Option<(usize, usize)>,
    /// `--unknown-rate` (`None`: the default, 0.02).
    unknown_rate: Option<f64>,
    /// `--check-texture`: the models carry the texture check.
    check_texture: bool,
}

impl OpenSetModels {
    /// `split` as (per class, trained on) and `unknown_rate`, refused where no model could be
    /// trained with them, or where the rate turns off the rejection the section measures.
    pub fn new(
        split: Option<(usize, usize)>,
        unknown_rate: Option<f64>,
        check_texture: bool,
    ) -> Result<Self, ReportError> {
        let m = Self {
            split,
            unknown_rate,
            check_texture,
        };
        let o = m.options();
        if !(o.unknown_rate > 0.0 && o.unknown_rate <= node::classifier::model::MAX_UNKNOWN_RATE) {
            return Err(ReportError::OpenSetRate(o.unknown_rate));
        }
        o.check().map_err(LabError::from)?;
        Ok(m)
    }

    /// `train`'s defaults with these models' split and rate.
    pub fn options(&self) -> node::classifier::train::TrainOptions {
        let mut o = node::classifier::train::TrainOptions::default();
        if let Some((per_class, train)) = self.split {
            (o.per_class, o.train) = (per_class, train);
        }
        if let Some(r) = self.unknown_rate {
            o.unknown_rate = r;
        }
        o.check_texture = self.check_texture;
        o
    }

    /// The split, as the section's text names it.
    fn describe_split(&self) -> String {
        match self.split {
            None => "paper's split".to_string(),
            Some((p, t)) => format!(
                "{p} images per class drawn from the training run, {t} of them trained on, \
                 `--per-class {p} --train {t}`"
            ),
        }
    }
}

/// The command that regenerates a report: `presrs` and the `args` given after the binary's
/// name, each holding a space quoted for a POSIX shell.
pub fn command_line(args: impl IntoIterator<Item = String>) -> String {
    std::iter::once("presrs".to_string())
        .chain(
            args.into_iter()
                .map(|a| if a.contains(' ') { format!("'{a}'") } else { a }),
        )
        .collect::<Vec<_>>()
        .join(" ")
}

impl Report {
    /// The document's opening: where its data came from (the simulator, the lab's `--data`,
    /// the `extra` sources for the open-set section), and `command`, which regenerates it
    /// (this run took `secs`).
    pub fn provenance(&self, command: &str, secs: f64) -> String {
        use std::fmt::Write as _;
        let mut source = match &self.user {
            None => "# Reproducing the paper on simulated data\n\n\
                     Every number and figure below comes from the simulator in `sim/` (hopper, \
                     terrains, skin), **not** from the PreSRS hardware: read them as a check \
                     that the method and this code behave as the paper describes, not as new \
                     measurements of the sensor."
                .to_string(),
            Some(u) => format!(
                "# The paper's experiments on {}\n\n\
                 Table 1, Figure 5, Figure 16 and Table 6 come from the dataset `{}` ({} images, \
                 {} classes). The other sections need several datasets (sandpaper, one per \
                 gait, a closed loop) and come from the simulator in `sim/`; Table 6 uses the \
                 simulated hopper's step length and period.",
                u.dir.display(),
                u.dir.display(),
                u.set.images.len(),
                u.set.classes.len()
            ),
        };
        if !self.extra.is_empty() {
            let _ = write!(
                source,
                " One exception: the unknown-terrain section also runs on {}, data this project \
                 did not make (a SpeedPP2D folder holds the `jiku-data` package's real \
                 plantar-pressure maps, written by `python3 scripts/speedpp2d.py --out DIR`).",
                self.extra
                    .iter()
                    .map(|d| format!("`{}`", d.dir.display()))
                    .collect::<Vec<_>>()
                    .join(", ")
            );
        }
        format!(
            "{source} The paper's numbers are given beside ours. Regenerate with `{command}` \
             (this run: {secs:.0} s).\n\n"
        )
    }
}

impl Report {
    /// A report drawing into `figures` (created), with the bundled font registered.
    pub fn new(
        figures: PathBuf,
        quick: bool,
        seed: u64,
        user: Option<UserData>,
    ) -> Result<Self, ReportError> {
        std::fs::create_dir_all(&figures).map_err(|source| ReportError::Folder {
            path: figures.clone(),
            source,
        })?;
        register_font()?;
        Ok(Self {
            figures,
            quick,
            seed,
            user,
            extra: Vec::new(),
            open_set_seeds: 1,
            open_set_models: OpenSetModels::default(),
        })
    }

    /// Runs `list` in order and joins their sections (each followed by a blank line).
    /// `demo_model` gives the adaptation section its model; `progress` hears each section
    /// before it runs.
    pub fn markdown(
        &self,
        list: &[Experiment],
        demo_model: &mut dyn FnMut() -> Result<Model, Box<dyn std::error::Error + Send + Sync>>,
        progress: &mut dyn FnMut(Experiment),
    ) -> Result<String, ReportError> {
        let mut md = String::new();
        let mut damage_curves = None;
        for &w in list {
            progress(w);
            let section = match w {
                Experiment::Static => static_table(self)?,
                Experiment::Resolution => resolution(self)?,
                Experiment::Dynamic => dynamic_features(self)?,
                Experiment::Gaits => gaits(self)?,
                Experiment::Damage => {
                    let (s, c) = damage(self)?;
                    damage_curves = Some(c);
                    s
                }
                Experiment::Lifespan => {
                    let curves = match damage_curves.take() {
                        Some(c) => c,
                        None => damage(self)?.1,
                    };
                    lifespan(self, &curves)?
                }
                Experiment::Adaptation => {
                    adaptation(self, demo_model().map_err(ReportError::DemoModel)?)?
                }
                Experiment::OpenSet => open_set(self)?,
            };
            md.push_str(&section);
            md.push('\n');
        }
        Ok(md)
    }
}

const FOOT_CROP: Crop = Crop {
    top: 0,
    bottom: 3,
    left: 6,
    right: 0,
};
const STATIC_CROP: Crop = Crop {
    top: 2,
    bottom: 2,
    left: 2,
    right: 2,
};
/// The dynamic classifiers (Table 5, Figure 16) use the paper's intensity scaling, as the node's
/// models do: a stance's load at 70 ms varies with gait and terrain changes, its texture does not.
const NORMALIZE_DYNAMIC: bool = true;
/// The paper's damage rate: 1 row and 2 columns of the 41x38 crop (7%, eq. 6) in 961 steps.
const DAMAGE_PCT_PER_STEP: f64 = 7.0 / 961.0;

fn pct(x: f64) -> String {
    format!("{:.1}%", 100.0 * x)
}

#[cfg(test)]
mod selection_tests {
    use super::*;

    #[test]
    fn every_name_parses_back_to_itself() {
        for n in Selection::NAMES {
            let sel: Selection = n.parse().unwrap();
            assert_eq!(sel.name(), n);
        }
        assert_eq!(
            "all".parse::<Selection>().unwrap().0,
            Experiment::ALL.to_vec()
        );
        let e = "openset".parse::<Selection>().unwrap_err();
        assert!(e.contains("open-set"), "{e}");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_command_line_quotes_what_a_shell_would_split() {
        let args = ["lab", "experiment", "all", "--out", "my docs"].map(String::from);
        assert_eq!(
            command_line(args),
            "presrs lab experiment all --out 'my docs'"
        );
        assert_eq!(command_line([]), "presrs");
    }
}
