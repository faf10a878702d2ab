//! How `train` chooses a model's unknown-ground checks: by measurement on the lab's own runs,
//! not by flags the lab would have to know to set.
//!
//! Each known terrain is left out in turn and plays the unknown ground. A model of the others
//! is trained on the training run for every combination of the options that change the
//! features (load normalisation, PCA dimensions) and calibrated on half of the calibration run
//! (the next run of known ground) for each novelty score; the other half is judged as known
//! ground, the left-out terrain's images of both runs as new ground, with and without the load
//! and texture checks. Of the candidates that call at most [`BUDGET_FACTOR`] times
//! `--unknown-rate` of the judged known images unknown and find nearly the most left-out ground
//! (an extra check counted [`CHECK_COST`] less), the one that calls the fewest known images
//! unknown is kept (the rule and its constants: `pick.rs`).
//!
//! With one run only, the training run's images the model does not store are the known ground
//! judged, the load and texture bands stay off (one run cannot test them), and [`Choice`] says
//! so. The table is printed by `train` and kept in the model ([`crate::unknown::ChoiceRecord`]),
//! so that the lab sees what its ground needed and why. Why this rule:
//! docs/decisions/unknown-choice.md.

use std::fmt;

use crate::classifier::options::TrainOptions;
use crate::classifier::options::{Candidate, Dims, Margin, UnknownChecks};
use crate::classifier::texture::roughness;
use crate::classifier::train::{
    CalibrateError, Labelled, TrainError, add_load_check_on, add_texture_check, calibrate_on_runs,
    preprocess, rescore, train_with_max_dims,
};
use crate::classifier::{ClassInfo, Classifier, Model, PressureImage};
use crate::order_stats::auroc;
use crate::unknown::novelty::NoveltyScore;
use crate::unknown::{self, Bands, ChoiceRecord, Measured};

mod fold;
mod pick;
mod table;

use fold::*;

use pick::pick;
pub use pick::{BUDGET_FACTOR, CHECK_COST, FALLBACK_SLACK, NEAR, tie};
pub use table::{Choice, EnergyAlone, JudgedOn, MIN_CALIBRATION_IMAGES, Outcome};

/// Why the choice could not be measured.
#[derive(Debug, thiserror::Error)]
pub enum ChoiceError {
    /// Training a candidate failed.
    #[error(transparent)]
    Train(#[from] TrainError),
    /// Calibrating a candidate failed.
    #[error(transparent)]
    Calibrate(#[from] CalibrateError),
}

/// One judged image: known ground or the left-out terrain.
struct Judged {
    novel: bool,
    /// The stance's flights before and after, s, where known (the energy check's input).
    flights: Option<(f64, f64)>,
    /// `None`: no contact (unknown under every candidate).
    measured: Option<Measured>,
    roughness: f64,
}

/// The grid `opts` leaves open: a part a flag pins is not searched. With `one_run`, the load
/// and texture bands stay off unless pinned: a band drawn on one run cannot be held against
/// the next one here (docs/decisions/figures-behind-comments.md, one-run-bands).
fn grid(opts: &TrainOptions, one_run: bool, energy_ok: bool) -> Vec<Candidate> {
    let both = [false, true];
    let pinned = |on: bool| if on { &both[1..] } else { &both[..] };
    let band = |on: bool| {
        if on || !one_run {
            pinned(on)
        } else {
            &both[..1]
        }
    };
    let dims: &[Dims] = if opts.h.is_some() {
        &[Dims::Accuracy]
    } else {
        &[Dims::Accuracy, Dims::Max]
    };
    // With one session, how far past its own time blocks' thresholds the next session may lie
    // is weighed too; another session measures it.
    let margins: &[Margin] = if one_run {
        &Margin::ONE_SESSION_GRID
    } else {
        &[Margin::ONE_SESSION]
    };
    let energies: &[bool] = if energy_ok { &both } else { &both[..1] };
    let mut out = Vec::new();
    for &normalize_load in pinned(opts.normalize_load) {
        for &d in dims {
            for score in [NoveltyScore::KnnResidual, NoveltyScore::Knn] {
                for &load in band(opts.check_load) {
                    for &texture in band(opts.check_texture) {
                        for &energy in energies {
                            for &margin in margins {
                                out.push(Candidate {
                                    score,
                                    normalize_load,
                                    dims: d,
                                    load,
                                    texture,
                                    energy,
                                    margin,
                                });
                            }
                        }
                    }
                }
            }
        }
    }
    out
}

/// Chooses the unknown-ground checks for a model of `classes` trained on `training` (class
/// indices into `classes`), with `calibration` the next run of the same terrains (empty: one
/// run only). `opts.unknown_checks` `Fixed` is kept as given (with the flags' pins); `Auto`
/// is measured as the module docs say.
pub fn choose(
    training: &[Labelled<'_>],
    calibration: &[Labelled<'_>],
    classes: &[ClassInfo],
    opts: &TrainOptions,
) -> Result<Choice, ChoiceError> {
    let budget = (BUDGET_FACTOR * opts.unknown_rate).min(crate::unknown::MAX_UNKNOWN_RATE);
    let judged_on = if calibration.is_empty() {
        JudgedOn::TrainingRun
    } else {
        JudgedOn::CalibrationRun
    };
    let names: Vec<String> = classes.iter().map(|c| c.name.clone()).collect();
    let thin: Vec<(String, usize)> = if calibration.is_empty() {
        Vec::new()
    } else {
        (0..classes.len())
            .map(|k| (k, calibration.iter().filter(|l| l.class == k).count()))
            .filter(|&(_, n)| n < MIN_CALIBRATION_IMAGES)
            .map(|(k, n)| (names[k].clone(), n))
            .collect()
    };
    let unmeasured = |candidate: Candidate, why: &str| Choice {
        outcomes: Vec::new(),
        chosen: None,
        candidate,
        budget,
        judged_on,
        why: Some(why.to_string()),
        classes: names.clone(),
        thin: thin.clone(),
        nn_auroc: None,
        energy_note: None,
        energy_alone: None,
    };
    let pins = Candidate {
        normalize_load: opts.normalize_load,
        load: opts.check_load,
        texture: opts.check_texture,
        ..Candidate::PLAIN
    };
    if let UnknownChecks::Fixed(c) = opts.unknown_checks {
        return Ok(unmeasured(c, "as --unknown-checks gives it"));
    }
    if opts.unknown_rate <= 0.0 {
        return Ok(unmeasured(pins, "--unknown-rate 0: no rejection"));
    }
    if classes.len() < 3 {
        return Ok(unmeasured(
            pins,
            "two terrains: leaving one out leaves a model of one, so nothing was measured; the \
             flags' checks as given",
        ));
    }
    let energy = energy_support(training, calibration, classes);
    let grid = grid(opts, calibration.is_empty(), energy.is_ok());
    let n_classes = classes.len();
    // One session: its last time block is the known ground judged (a model fitted on the
    // earlier blocks meets it as it would the next session), the rest trains.
    let (training, later) = if calibration.is_empty() {
        split_in_time(training, n_classes)
    } else {
        (training.to_vec(), Vec::new())
    };
    let (training, later) = (training.as_slice(), later.as_slice());
    let folds = Folds {
        training,
        calibration,
        later,
        classes,
        opts,
        grid: &grid,
    };
    let tallies = run_folds(&folds);
    let (outcomes, nn, alone) = pool(tallies, &grid, n_classes)?;
    let chosen = with_energy(pick(&outcomes, budget), &outcomes, &alone, opts, budget);
    Ok(Choice {
        candidate: chosen.map_or(pins, |i| outcomes[i].candidate),
        chosen,
        outcomes,
        budget,
        judged_on,
        why: None,
        classes: names,
        thin,
        nn_auroc: Some(nn).filter(|v| v.is_finite()),
        energy_note: energy.err(),
        energy_alone: Some(alone),
    })
}

/// What every fold is cut from: the sessions, the terrains, the options and the candidates.
/// `later`, with no calibration run: the session's later images, judged as known ground.
struct Folds<'s, 'a> {
    training: &'s [Labelled<'a>],
    calibration: &'s [Labelled<'a>],
    later: &'s [Labelled<'a>],
    classes: &'s [ClassInfo],
    opts: &'s TrainOptions,
    grid: &'s [Candidate],
}

/// Every fold (each known terrain left out in turn), on the machine's cores; the folds are
/// independent and merged in their order, so the figures do not depend on how many cores
/// there are.
fn run_folds(folds: &Folds<'_, '_>) -> Vec<Option<Result<FoldTally, ChoiceError>>> {
    let n_classes = folds.classes.len();
    let threads = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .min(n_classes);
    let mut tallies: Vec<Option<Result<FoldTally, ChoiceError>>> = Vec::new();
    tallies.resize_with(n_classes, || None);
    std::thread::scope(|scope| {
        let handles: Vec<_> = (0..threads)
            .map(|t| {
                scope.spawn(move || {
                    (t..n_classes)
                        .step_by(threads)
                        .map(|k| (k, fold(k, folds)))
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        for h in handles {
            // A fold that panicked is a bug; it ends `train` as a panic would have.
            for (k, r) in h.join().unwrap_or_else(|e| std::panic::resume_unwind(e)) {
                tallies[k] = Some(r);
            }
        }
    });
    tallies
}

/// The mean of the finite values of `v` (NaN when none is).
fn finite_mean(v: &[f64]) -> f64 {
    let f: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    if f.is_empty() {
        f64::NAN
    } else {
        f.iter().sum::<f64>() / f.len() as f64
    }
}

/// The folds' tallies pooled per candidate: per left-out terrain its share found, the known
/// counts summed, the AUROC averaged; with the plain nearest neighbour's AUROC and the energy
/// check's on its own.
fn pool(
    tallies: Vec<Option<Result<FoldTally, ChoiceError>>>,
    grid: &[Candidate],
    n_classes: usize,
) -> Result<(Vec<Outcome>, f64, EnergyAlone), ChoiceError> {
    let mut found = vec![vec![f64::NAN; n_classes]; grid.len()];
    let mut known = vec![[0usize; 2]; grid.len()];
    let mut aurocs = vec![Vec::new(); grid.len()];
    let mut nn = Vec::new();
    let (mut alone_found, mut alone_known) = (Vec::new(), [0usize; 2]);
    for (out_k, t) in tallies.into_iter().enumerate() {
        let Some(t) = t else { continue };
        let (t, fold_nn, alone) = t?;
        nn.extend(fold_nn);
        alone_found.extend(alone.found);
        alone_known[0] += alone.known[0];
        alone_known[1] += alone.known[1];
        for (ci, t) in t.into_iter().enumerate() {
            if let Some(f) = t.found {
                found[ci][out_k] = f;
            }
            known[ci][0] += t.known[0];
            known[ci][1] += t.known[1];
            aurocs[ci].extend(t.auroc);
        }
    }
    let outcomes = grid
        .iter()
        .enumerate()
        .map(|(i, c)| Outcome {
            candidate: *c,
            auroc: finite_mean(&aurocs[i]),
            found: finite_mean(&found[i]),
            found_per_class: found[i].clone(),
            known_unknown: known[i][1] as f64 / known[i][0].max(1) as f64,
            known_judged: known[i][0],
        })
        .collect();
    let alone = EnergyAlone {
        found: finite_mean(&alone_found),
        known: alone_known,
    };
    Ok((outcomes, finite_mean(&nn), alone))
}

/// The kept candidate with the energy check beside it, when the check finds left-out ground
/// at next to no cost on known ground (`pick::energy_pays`: what it finds, the image checks
/// missed) and the pair stays within the budget; else `chosen` as it is.
fn with_energy(
    chosen: Option<usize>,
    outcomes: &[Outcome],
    alone: &EnergyAlone,
    opts: &TrainOptions,
    budget: f64,
) -> Option<usize> {
    let i = chosen?;
    if outcomes[i].candidate.energy || !pick::energy_pays(alone, opts.unknown_rate) {
        return chosen;
    }
    let paired = Candidate {
        energy: true,
        ..outcomes[i].candidate
    };
    outcomes
        .iter()
        .position(|o| o.candidate == paired)
        .filter(|&j| outcomes[j].known_unknown <= budget + 1e-12)
        .or(chosen)
}

/// What one fold measured of one candidate.
#[derive(Clone, Copy, Default)]
struct Tally {
    /// The share of the left-out terrain's images called unknown.
    found: Option<f64>,
    /// Known images judged, and of them called unknown.
    known: [usize; 2],
    /// The novelty's AUROC.
    auroc: Option<f64>,
}

/// Whether the sessions' flights can carry the energy check, or why not in words: every
/// terrain needs [`crate::unknown::energy::MIN_STANCES`] stances with both flights heard, and
/// the flights after them must vary (a hop's flight that never changes, as a robot standing or a
/// generated stream's, says nothing of the ground).
pub fn energy_support(
    training: &[Labelled<'_>],
    calibration: &[Labelled<'_>],
    classes: &[ClassInfo],
) -> Result<(), String> {
    use crate::unknown::energy::MIN_STANCES;
    let mut per = vec![Vec::new(); classes.len()];
    for l in training.iter().chain(calibration) {
        if let (Some(v), Some((_, after))) = (per.get_mut(l.class), flights_s(l)) {
            v.push(after);
        }
    }
    let total: usize = per.iter().map(Vec::len).sum();
    if total == 0 {
        return Err(
            "no stance with both flights in the sessions' manifests (captured before the \
             flights were kept, or from a bus whose foot switch was not heard): capture again \
             with this build"
                .into(),
        );
    }
    if let Some(k) = per.iter().position(|v| v.len() < MIN_STANCES) {
        return Err(format!(
            "{} has {} stances with both flights, fewer than the {MIN_STANCES} a return map \
             needs: capture more steps of it",
            classes[k].name,
            per[k].len()
        ));
    }
    let all: Vec<f64> = per.into_iter().flatten().collect();
    let (lo, hi) = all
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    // The foot switch reports at 100 Hz: flights within one report of each other are one.
    if hi - lo < 0.01 {
        return Err(format!(
            "every flight after a stance lasts {:.0}-{:.0} ms: flights that do not vary say \
             nothing of the ground",
            lo * 1e3,
            hi * 1e3
        ));
    }
    Ok(())
}

/// One session's images cut in time: per class, all but its last time block
/// (`classifier::train::time_blocks`), and the last block.
fn split_in_time<'a>(
    training: &[Labelled<'a>],
    n_classes: usize,
) -> (Vec<Labelled<'a>>, Vec<Labelled<'a>>) {
    let classes: Vec<usize> = training.iter().map(|l| l.class).collect();
    let blocks = crate::classifier::train::time_blocks(&classes, n_classes);
    let last = (crate::classifier::train::TIME_BLOCKS - 1) as u8;
    let (early, late): (Vec<_>, Vec<_>) =
        training.iter().zip(&blocks).partition(|(_, b)| **b < last);
    (
        early.into_iter().map(|(l, _)| *l).collect(),
        late.into_iter().map(|(l, _)| *l).collect(),
    )
}

/// `opts` for a fold's training images of `counts` per class: the paper's split at the same
/// share where a class has fewer images than `--per-class` (one session, cut in time).
fn fold_options(opts: &TrainOptions, counts: &[usize]) -> TrainOptions {
    let mut o = opts.clone();
    let least = counts.iter().copied().min().unwrap_or(0);
    if least < o.per_class && least >= 2 {
        let train = (least * o.train / o.per_class.max(1)).clamp(1, least - 1);
        (o.per_class, o.train) = (least, train);
    }
    o
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::classifier::Crop;
    use rand::{Rng, SeedableRng};

    /// A 24x24 texture of period `period`: the terrain, with random offset, load and noise.
    fn texture(rng: &mut impl Rng, period: usize) -> PressureImage {
        let (dy, dx) = (rng.random_range(0..period), rng.random_range(0..period));
        let load = rng.random_range(0.8..1.2);
        let px = (0..24 * 24)
            .map(|i| {
                let (r, c) = (i / 24 + dy, i % 24 + dx);
                let on = r % period < period / 2 && c % period < period / 2;
                let v: f64 =
                    if on { 150.0 * load } else { 10.0 * load } + rng.random_range(-8.0..8.0);
                v.clamp(0.0, 255.0) as u16
            })
            .collect();
        PressureImage::new(24, 24, 8, px)
    }

    fn run(seed: u64, per_class: usize) -> Vec<(PressureImage, usize)> {
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        (0..3)
            .flat_map(|k| (0..per_class).map(move |_| k))
            .map(|k| (texture(&mut rng, [4, 7, 11][k]), k))
            .collect()
    }

    fn labelled(v: &[(PressureImage, usize)]) -> Vec<Labelled<'_>> {
        v.iter()
            .map(|(image, class)| Labelled::new(image, *class))
            .collect()
    }

    fn classes() -> Vec<ClassInfo> {
        ["wood", "carpet", "grass"]
            .iter()
            .enumerate()
            .map(|(i, n)| ClassInfo {
                name: n.to_string(),
                terrain_id: i as u8,
            })
            .collect()
    }

    fn opts() -> TrainOptions {
        TrainOptions {
            crop: "1,1,1,1".parse::<Crop>().unwrap().into(),
            ..TrainOptions::default()
        }
    }

    #[test]
    fn with_a_second_run_every_candidate_is_measured_and_the_kept_one_finds_new_ground() {
        let (t, c) = (run(1, 30), run(2, 40));
        let choice = choose(&labelled(&t), &labelled(&c), &classes(), &opts()).unwrap();
        assert_eq!(choice.judged_on, JudgedOn::CalibrationRun);
        // Two scores x two normalisations x two dimension choices x four band combinations.
        assert_eq!(choice.outcomes.len(), 32);
        let kept = &choice.outcomes[choice.chosen.unwrap()];
        assert_eq!(kept.candidate, choice.candidate);
        // Within the budget where any candidate is, else the fewest known called unknown.
        let least = choice
            .outcomes
            .iter()
            .map(|o| o.known_unknown)
            .fold(f64::INFINITY, f64::min);
        assert!(
            kept.known_unknown <= choice.budget.max(least) + 1e-12,
            "{choice}"
        );
        // Three textures of different periods: each left out is found.
        assert!(kept.found >= 0.9, "{choice}");
        assert!(kept.found_per_class.iter().all(|f| f.is_finite()));
        let table = choice.to_string();
        assert!(table.contains("* ") && table.contains("kept *"), "{table}");
        let rec = choice.record();
        assert_eq!(rec.chosen, choice.candidate.to_string());
        assert_eq!(rec.table.len(), 32);
        // The same data give the same choice, whatever the threads did.
        let again = choose(&labelled(&t), &labelled(&c), &classes(), &opts()).unwrap();
        assert_eq!(again.outcomes, choice.outcomes);
    }

    #[test]
    fn a_terrain_too_thin_in_the_calibration_run_is_named() {
        let t = run(1, 30);
        // Wood has 2 images in the calibration run, the others 20.
        let c: Vec<(PressureImage, usize)> = run(2, 20)
            .into_iter()
            .filter({
                let mut wood = 0;
                move |(_, k)| {
                    *k != 0 || {
                        wood += 1;
                        wood <= 2
                    }
                }
            })
            .collect();
        let choice = choose(&labelled(&t), &labelled(&c), &classes(), &opts()).unwrap();
        assert_eq!(choice.thin, vec![("wood".to_string(), 2)]);
        assert!(
            choice.to_string().contains("too few images of wood (2)"),
            "{choice}"
        );
    }

    #[test]
    fn one_run_keeps_the_bands_off_and_says_so() {
        let t = run(1, 40);
        let choice = choose(&labelled(&t), &[], &classes(), &opts()).unwrap();
        assert_eq!(choice.judged_on, JudgedOn::TrainingRun);
        assert!(
            choice
                .outcomes
                .iter()
                .all(|o| o.candidate.extra_checks() == 0)
        );
        // The 8 candidates without a band, each at the 4 margins one session chooses among.
        assert_eq!(choice.outcomes.len(), 8 * Margin::ONE_SESSION_GRID.len());
        assert!(choice.to_string().contains("one session only"), "{choice}");
        // A pinned band is kept even so: the flag is the lab's word.
        let pinned = TrainOptions {
            check_texture: true,
            ..opts()
        };
        let c = choose(&labelled(&t), &[], &classes(), &pinned).unwrap();
        assert!(c.outcomes.iter().all(|o| o.candidate.texture));
    }

    #[test]
    fn a_fixed_list_two_terrains_or_no_rejection_measure_nothing() {
        let t = run(1, 30);
        let fixed = TrainOptions {
            unknown_checks: "knn,texture".parse().unwrap(),
            ..opts()
        };
        let c = choose(&labelled(&t), &[], &classes(), &fixed).unwrap();
        assert!(c.outcomes.is_empty() && c.chosen.is_none());
        assert_eq!(c.candidate.to_string(), "knn,texture");
        let two: Vec<(PressureImage, usize)> = t.into_iter().filter(|(_, k)| *k < 2).collect();
        let c = choose(&labelled(&two), &[], &classes()[..2], &opts()).unwrap();
        assert!(c.why.as_deref().is_some_and(|w| w.contains("two terrains")));
        let off = TrainOptions {
            unknown_rate: 0.0,
            ..opts()
        };
        let c = choose(&labelled(&two), &[], &classes()[..2], &off).unwrap();
        assert!(c.outcomes.is_empty());
    }
}
