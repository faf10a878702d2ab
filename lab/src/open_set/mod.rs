//! Unknown ground: leave one class out, per source of images, and judge the rejection where it
//! matters: on a left-out class (called unknown: the goal) and on a *fresh* run of the known
//! classes (called unknown: the cost, a robot sent to the safe gait on ground it knows).
//!
//! A source is up to three runs of the same classes: the run the model is trained on, a run to
//! calibrate the rejection on ([`node::classifier::train::calibrate_on_runs`]), and a run
//! neither saw. Without a calibration run the model calibrates on its training run's unused
//! images (with the measured margin); without a fresh run the known test images are the
//! training run's unused ones (and the "fresh" figure is a same-run figure: the report says so).
//!
//! Beside our novelty score each row gives two others on the same images, so that a reader
//! sees what the score is worth: the Parzen log density of the earlier models (the best
//! class's density less its threshold), and the plain nearest-neighbour distance in the model's
//! PCA space (no calibration: the ceiling a simple distance reaches on the source).

use node::classifier::pwe::Classifier;
use node::classifier::train::TrainOptions;
use node::classifier::{Model, PressureImage};

use node::classifier::options::{Candidate, Dims, UnknownChecks};
use node::unknown::novelty::NoveltyScore;

use crate::LabError;
use crate::simdata::TrainingSet;

mod aggregate;
#[cfg(test)]
use aggregate::t_975;
pub use aggregate::{OpenSetMeans, SEPARABLE_AUROC, SeedSpread, Spread, pool_gait_counts};

/// One source of images for the study.
#[derive(Clone)]
pub struct OpenSetSource {
    /// How the report names it.
    pub name: String,
    /// The run the models are trained on.
    pub train: TrainingSet,
    /// Another run of the same classes, to calibrate on (`None`: the training run calibrates).
    pub calibration: Option<TrainingSet>,
    /// A run neither saw, whose known-class images are the known test images (`None`: the
    /// training run's unused images).
    pub fresh: Option<TrainingSet>,
    /// Training options (crop, normalisation, unknown rate).
    pub opts: TrainOptions,
}

impl OpenSetSource {
    /// A lab's set whose images carry runs (a capture manifest): per class, the last run is
    /// the fresh one and the one before it calibrates, as far as the class has runs
    /// ([`TrainingSet::split_runs`]).
    pub fn from_runs(name: String, set: &TrainingSet, opts: TrainOptions) -> Self {
        let s = set.split_runs(2);
        let some = |t: crate::simdata::TrainingSet| (!t.images.is_empty()).then_some(t);
        Self {
            name,
            train: s.train,
            calibration: some(s.calibration),
            fresh: some(s.fresh),
            opts,
        }
    }
}

/// One row: a model trained without `held_out` meets it.
#[derive(Clone, Debug)]
pub struct OpenSetRow {
    /// The class the model never saw.
    pub held_out: String,
    /// Share of its images called unknown (the goal: most).
    pub unknown_held_out: f64,
    /// Share of the known test images called unknown (the goal: few).
    pub unknown_known: f64,
    /// Of those, the share of the known test images whose best class was another terrain:
    /// called unknown, they cost no accuracy (they were wrong) and spare the robot a wrong
    /// terrain's gait. `unknown_known` less this is the cost: images the model had right.
    pub unknown_known_misclassified: f64,
    /// AUROC of the novelty (less its class's threshold) separating the left-out class from
    /// the known test images: 1 perfect, 0.5 chance, whatever the threshold.
    pub auroc: f64,
    /// The same for the Parzen log density (the rule of earlier models).
    pub density_auroc: f64,
    /// The same for the plain nearest-neighbour distance in the model's PCA space.
    pub nn_auroc: f64,
    /// Known test images classified right with the rejection (unknown counts as wrong).
    pub known_accuracy: f64,
    /// Known test images classified right without it (the best class).
    pub known_accuracy_open: f64,
    /// The calibration's own check: the share of its images above their threshold.
    pub calibration_unknown: f64,
    /// Images of the left-out class.
    pub n_held_out: usize,
    /// Known test images.
    pub n_known: usize,
    /// The known test images per gait they touched down in, and those of them called unknown
    /// (images of unknown gait are not counted); in gait order. In [`OpenSetMeans`], summed
    /// over the rows.
    pub known_by_gait: Vec<node::gait_status::GaitCount>,
    /// The unknown-ground checks the model was trained with (`train --unknown-checks`' list:
    /// what `train` chose on the known classes, or the options given).
    pub checks: String,
}

/// Means for tests: a separable source's, with `unknown_known` and `known_accuracy` given.
#[cfg(test)]
pub(crate) fn mean_row(unknown_known: f64, known_accuracy: f64) -> OpenSetRow {
    OpenSetRow {
        held_out: "mean".into(),
        unknown_held_out: 0.9,
        unknown_known,
        unknown_known_misclassified: 0.0,
        auroc: 0.99,
        density_auroc: 0.5,
        nn_auroc: 0.9,
        known_accuracy,
        known_accuracy_open: 0.99,
        calibration_unknown: 0.02,
        n_held_out: 10,
        n_known: 30,
        known_by_gait: vec![],
        checks: String::new(),
    }
}

/// Leave-one-class-out on `src`: for each class, a model trained on the others (paper's split,
/// rejection calibrated as the source allows) classifies every image of the left-out class and
/// the known test images. Every image goes through the crop and contact check as in the node
/// (repair off); an image without contact counts as unknown.
pub fn leave_one_class_out(src: &OpenSetSource) -> Result<Vec<OpenSetRow>, LabError> {
    (0..src.train.classes.len())
        .map(|k| leave_class_out(src, k))
        .collect()
}

/// One row of [`leave_one_class_out`]: class `out_k` left out.
pub fn leave_class_out(src: &OpenSetSource, out_k: usize) -> Result<OpenSetRow, LabError> {
    let set = &src.train;
    let Some(out_class) = set.classes.get(out_k) else {
        return Err(LabError::NoSuchClass(out_k, set.classes.len()));
    };
    let keep: Vec<usize> = (0..set.classes.len()).filter(|&k| k != out_k).collect();
    let without = |s: &TrainingSet| -> TrainingSet {
        let idx: Vec<usize> = (0..s.labels.len())
            .filter(|&i| s.labels[i] != out_k)
            .collect();
        let mut t = s.subset(&idx);
        t.classes = keep.iter().map(|&k| s.classes[k].clone()).collect();
        for l in t.labels.iter_mut() {
            *l = keep.iter().position(|&k| k == *l).unwrap_or(0);
        }
        t
    };
    let known = without(set);
    let cal = src.calibration.as_ref().map(|c| {
        let c = without(c);
        let names = c.run_names();
        (c, names)
    });
    // The study counts decisions; their confidence is not read.
    let opts = TrainOptions {
        confidence: node::classifier::options::Confidence::Posterior,
        ..src.opts.clone()
    };
    let trained = known.train_calibrated(&opts, cal.as_ref().map(|(c, n)| (c, n.as_slice())))?;
    let checks = trained.choice.candidate.to_string();
    let (model, split) = (trained.model, trained.split);
    let calibration_unknown = model
        .unknown
        .novelty
        .as_ref()
        .map_or(f64::NAN, |n| n.calibration.called_unknown);
    let mut judge = Judge::new(model);
    // The known test images: a fresh run's, or the training run's unused ones.
    let fresh = src.fresh.as_ref().map(without);
    let known_test: Vec<(&PressureImage, usize, Option<u8>)> = match &fresh {
        Some(f) => (0..f.images.len())
            .map(|i| (&f.images[i], f.labels[i], f.gaits[i]))
            .collect(),
        None => split
            .test
            .iter()
            .map(|&i| (&known.images[i], known.labels[i], known.gaits[i]))
            .collect(),
    };
    let mut scored: Vec<Scored> = Vec::new();
    let (mut right, mut right_open, mut wrong_unknown) = (0usize, 0usize, 0usize);
    let mut known_by_gait = Vec::new();
    for &(img, truth, gait) in &known_test {
        let s = judge.score(img, false);
        if let Some(gait) = gait {
            let unknown = s.class.is_none() as usize;
            node::gait_status::add_count(&mut known_by_gait, Some(gait), 1, unknown);
        }
        right += (s.class == Some(truth)) as usize;
        right_open += (s.best == Some(truth)) as usize;
        wrong_unknown += (s.class.is_none() && s.best.is_some_and(|b| b != truth)) as usize;
        scored.push(s);
    }
    let n_known = scored.len();
    // The left-out class as the robot meets it: in the fresh run when there is one (a
    // score that only told runs apart would otherwise look good), else in the training run.
    let novel_from = match &src.fresh {
        Some(f) if f.labels.contains(&out_k) => f,
        _ => set,
    };
    for i in (0..novel_from.images.len()).filter(|&i| novel_from.labels[i] == out_k) {
        scored.push(judge.score(&novel_from.images[i], true));
    }
    let share = |novel: bool| {
        let v: Vec<_> = scored.iter().filter(|s| s.novel == novel).collect();
        v.iter().filter(|s| s.class.is_none()).count() as f64 / v.len().max(1) as f64
    };
    Ok(OpenSetRow {
        held_out: out_class.name.clone(),
        unknown_held_out: share(true),
        unknown_known: share(false),
        unknown_known_misclassified: wrong_unknown as f64 / n_known.max(1) as f64,
        auroc: auroc(&scored, |s| s.novelty),
        density_auroc: auroc(&scored, |s| s.density),
        nn_auroc: auroc(&scored, |s| s.nn),
        known_accuracy: right as f64 / n_known.max(1) as f64,
        known_accuracy_open: right_open as f64 / n_known.max(1) as f64,
        calibration_unknown,
        n_held_out: scored.len() - n_known,
        n_known,
        known_by_gait,
        checks,
    })
}

/// The single options the default (`train` choosing its checks) is compared with: the plain
/// model and each option alone on top of it.
pub const SINGLE_OPTIONS: [Candidate; 6] = {
    let p = Candidate::PLAIN;
    [
        p,
        Candidate {
            score: NoveltyScore::Knn,
            ..p
        },
        Candidate {
            normalize_load: true,
            ..p
        },
        Candidate {
            dims: Dims::Max,
            ..p
        },
        Candidate { load: true, ..p },
        Candidate { texture: true, ..p },
    ]
};

/// Leave-one-class-out on `src` with each of [`SINGLE_OPTIONS`] fixed instead of chosen (the
/// source's own pins stay on): what a user who picks one flag gets.
pub fn single_options(src: &OpenSetSource) -> Result<Vec<(Candidate, Vec<OpenSetRow>)>, LabError> {
    SINGLE_OPTIONS
        .iter()
        .map(|c| {
            let mut s = src.clone();
            s.opts.unknown_checks = UnknownChecks::Fixed(*c);
            Ok((*c, leave_one_class_out(&s)?))
        })
        .collect()
}

/// One image's scores, each larger = more novel.
struct Scored {
    /// Of the left-out class.
    novel: bool,
    /// Decided class (`None`: unknown or no contact).
    class: Option<usize>,
    /// Best class (`None`: no contact).
    best: Option<usize>,
    novelty: f64,
    density: f64,
    nn: f64,
}

/// A model's three scores for images.
struct Judge {
    cls: Classifier,
    density_thresholds: Vec<f64>,
}

impl Judge {
    fn new(model: Model) -> Self {
        let density_thresholds = model.unknown.density_thresholds.clone();
        Self {
            density_thresholds,
            cls: Classifier::new(model),
        }
    }

    fn score(&mut self, img: &PressureImage, novel: bool) -> Scored {
        let d = match self.cls.classify(&img.pixels, img.rows, img.cols, false) {
            Ok(d) if d.contact => d,
            // No contact (or an image of another size): unknown, and the most novel.
            _ => {
                return Scored {
                    novel,
                    class: None,
                    best: None,
                    novelty: f64::INFINITY,
                    density: f64::INFINITY,
                    nn: f64::INFINITY,
                };
            }
        };
        Scored {
            novel,
            class: d.class,
            best: Some(d.best),
            novelty: d.novelty - d.threshold,
            density: self.density_thresholds[d.best] - d.log_density,
            nn: self.cls.nearest_sample_distance(),
        }
    }
}

/// P(a novel image scores above a known one), ties counting half (the Mann-Whitney statistic).
fn auroc(scored: &[Scored], f: impl Fn(&Scored) -> f64) -> f64 {
    let novel: Vec<f64> = scored.iter().filter(|s| s.novel).map(&f).collect();
    let known: Vec<f64> = scored.iter().filter(|s| !s.novel).map(&f).collect();
    node::order_stats::auroc(&known, &novel)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::study::dataset_on;
    use node::classifier::image::Crop;
    use sim::dataset::Kind;

    fn s(novel: bool, v: f64) -> Scored {
        Scored {
            novel,
            class: None,
            best: None,
            novelty: v,
            density: 0.0,
            nn: 0.0,
        }
    }

    #[test]
    fn a_spread_is_the_median_and_range_and_names_the_seeds_off_target() {
        let sp = Spread::of(&[3.0, 1.0, 4.0, 2.0]);
        assert_eq!((sp.median, sp.min, sp.max), (2.5, 1.0, 4.0));
        assert!(Spread::of(&[]).median.is_nan());
        // Mean 2.5, sample sd sqrt(5/3), t(3) = 3.182: 2.5 +- 3.182 * 0.6455.
        assert_eq!(sp.mean, 2.5);
        let (lo, hi) = sp.interval();
        assert!((hi - 2.5 - 3.182 * (5.0f64 / 3.0 / 4.0).sqrt()).abs() < 1e-9);
        assert!((2.5 - lo - (hi - 2.5)).abs() < 1e-12);
        assert!(Spread::of(&[0.02]).half_width.is_nan());
        assert_eq!(t_975(9), 2.262);
        assert_eq!(t_975(100), 1.96);
        let row = |unknown_known: f64| mean_row(unknown_known, 0.97);
        let mut s = SeedSpread::default();
        for (seed, u) in [(1, 0.02), (2, 0.05), (3, 0.01)] {
            s.push(seed, row(u));
        }
        assert_eq!(s.of(|m| m.unknown_known).median, 0.02);
        assert_eq!(s.missing(|m| m.unknown_known > 0.03), vec![2]);
        assert!(s.missing(|m| m.unknown_held_out < 0.8).is_empty());
    }

    #[test]
    fn a_class_no_score_separates_is_named_and_left_out_of_the_separable_means() {
        let row = |name: &str, auroc: f64, nn_auroc: f64, unknown_held_out: f64| OpenSetRow {
            held_out: name.into(),
            auroc,
            nn_auroc,
            unknown_held_out,
            ..mean_row(0.02, 0.97)
        };
        let mut s = SeedSpread::default();
        // "b" is found by the nearest neighbour alone on average: separable, and counted
        // against our score. "c" is found by neither.
        s.push_rows(
            1,
            vec![
                row("a", 1.0, 0.5, 1.0),
                row("b", 0.6, 0.95, 0.2),
                row("c", 0.3, 0.5, 0.0),
            ],
        );
        s.push_rows(
            2,
            vec![
                row("a", 0.98, 0.5, 0.9),
                row("b", 0.7, 0.9, 0.4),
                row("c", 0.5, 0.8, 0.1),
            ],
        );
        let hard = s.inseparable();
        assert_eq!(hard.len(), 1);
        assert_eq!(hard[0].0, "c");
        assert!((hard[0].1 - 0.4).abs() < 1e-12 && (hard[0].2 - 0.65).abs() < 1e-12);
        let out = s.of_classes(&["c".to_string()], |r| r.unknown_held_out);
        // Seed 1: (1.0 + 0.2) / 2; seed 2: (0.9 + 0.4) / 2.
        assert!((out.mean - 0.625).abs() < 1e-12, "{out:?}");
        // All classes: the plain means.
        let all = s.of_classes(&[], |r| r.unknown_held_out);
        assert!(
            (all.mean - (0.4 + 1.4 / 3.0) / 2.0).abs() < 1e-12,
            "{all:?}"
        );
        // A seed added by its means alone has no classes to judge.
        let mut m = SeedSpread::default();
        m.push(1, mean_row(0.02, 0.97));
        assert!(m.classes().is_empty() && m.of_classes(&[], |r| r.auroc).mean.is_nan());
    }

    #[test]
    fn auroc_counts_pairs_and_ties() {
        let v = [s(false, 1.0), s(false, 2.0), s(true, 3.0), s(true, 2.0)];
        // Pairs (known, novel): (1,3) (1,2) (2,3) win, (2,2) ties: 3.5 of 4.
        assert_eq!(auroc(&v, |s| s.novelty), 0.875);
        assert_eq!(auroc(&v, |s| s.density), 0.5);
        assert!(auroc(&v[..2], |s| s.novelty).is_nan());
    }

    #[test]
    fn a_static_terrain_left_out_is_unknown_and_a_fresh_run_is_known() {
        let crop = Crop {
            top: 2,
            bottom: 2,
            left: 2,
            right: 2,
        };
        let g2 = controller::Gait::g2();
        let src = OpenSetSource {
            name: "static".into(),
            train: dataset_on(Kind::Static, 30, g2.clone(), 41, 1),
            calibration: Some(dataset_on(Kind::Static, 20, g2.clone(), 42, 2)),
            fresh: Some(dataset_on(Kind::Static, 20, g2, 43, 3)),
            opts: TrainOptions {
                crop: crop.into(),
                ..Default::default()
            },
        };
        let rows = leave_one_class_out(&src).unwrap();
        assert_eq!(rows.len(), 4);
        let m = OpenSetMeans::of(&rows).row;
        assert!(m.auroc >= 0.9, "{rows:?}");
        assert!(m.unknown_held_out >= 0.75, "{rows:?}");
        assert!(m.unknown_known <= 0.08, "{rows:?}");
        // Every known image called unknown was either right (the accuracy gap) or taken for
        // another terrain (the bracketed share): the two add up (all these are in contact).
        for r in &rows {
            let right_lost = r.known_accuracy_open - r.known_accuracy;
            let parts = r.unknown_known_misclassified + right_lost;
            assert!((r.unknown_known - parts).abs() < 1e-9, "{r:?}");
        }
        assert!(rows.iter().all(|r| r.n_held_out == 20 && r.n_known == 60));
    }
}
