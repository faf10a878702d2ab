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
use crate::classifier::options::{Candidate, Dims, UnknownChecks};
use crate::classifier::texture::roughness;
use crate::classifier::train::{
    CalibrateError, Labelled, TrainError, add_load_check_on, add_texture_check, calibrate_on_runs,
    preprocess, rescore, train_with_max_dims,
};
use crate::classifier::{ClassInfo, Classifier, Model, PressureImage};
use crate::stats::auroc;
use crate::unknown::novelty::NoveltyScore;
use crate::unknown::{self, Bands, ChoiceRecord, Measured};

mod pick;
mod table;

use pick::pick;
pub use pick::{BUDGET_FACTOR, CHECK_COST, FALLBACK_SLACK, NEAR, tie};
pub use table::{Choice, JudgedOn, MIN_CALIBRATION_IMAGES, Outcome};

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
    /// `None`: no contact (unknown under every candidate).
    measured: Option<Measured>,
    roughness: f64,
}

/// The grid `opts` leaves open: a part a flag pins is not searched. With `one_run`, the load
/// and texture bands stay off unless pinned: a band drawn on one run cannot be held against
/// the next one here (measured: the texture band of one run on the simulator's hopping
/// stances, kept by a choice judged on that run, called 10.4% of the next run on another sensor
/// unknown, against 2.1% without it).
fn grid(opts: &TrainOptions, one_run: bool) -> Vec<Candidate> {
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
    let mut out = Vec::new();
    for &normalize_load in pinned(opts.normalize_load) {
        for &d in dims {
            for score in [NoveltyScore::KnnResidual, NoveltyScore::Knn] {
                for &load in band(opts.check_load) {
                    for &texture in band(opts.check_texture) {
                        out.push(Candidate {
                            score,
                            normalize_load,
                            dims: d,
                            load,
                            texture,
                        });
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
    let grid = grid(opts, calibration.is_empty());
    let n_classes = classes.len();
    // The folds are independent: on the machine's cores, merged in their order, so that the
    // figures do not depend on how many cores there are.
    let threads = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .min(n_classes);
    let mut tallies: Vec<Option<Result<Vec<Tally>, ChoiceError>>> = Vec::new();
    tallies.resize_with(n_classes, || None);
    std::thread::scope(|scope| {
        let handles: Vec<_> = (0..threads)
            .map(|t| {
                let grid = &grid;
                scope.spawn(move || {
                    (t..n_classes)
                        .step_by(threads)
                        .map(|k| (k, fold(k, training, calibration, classes, opts, grid)))
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
    // Per candidate: per left-out terrain its share found; pooled known counts; per-fold AUROC.
    let mut found = vec![vec![f64::NAN; n_classes]; grid.len()];
    let mut known = vec![[0usize; 2]; grid.len()];
    let mut aurocs = vec![Vec::new(); grid.len()];
    for (out_k, t) in tallies.into_iter().enumerate() {
        let Some(t) = t else { continue };
        for (ci, t) in t?.into_iter().enumerate() {
            if let Some(f) = t.found {
                found[ci][out_k] = f;
            }
            known[ci][0] += t.known[0];
            known[ci][1] += t.known[1];
            aurocs[ci].extend(t.auroc);
        }
    }
    let mean = |v: &[f64]| {
        let f: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
        if f.is_empty() {
            f64::NAN
        } else {
            f.iter().sum::<f64>() / f.len() as f64
        }
    };
    let outcomes: Vec<Outcome> = grid
        .iter()
        .enumerate()
        .map(|(i, c)| Outcome {
            candidate: *c,
            auroc: mean(&aurocs[i]),
            found: mean(&found[i]),
            found_per_class: found[i].clone(),
            known_unknown: known[i][1] as f64 / known[i][0].max(1) as f64,
            known_judged: known[i][0],
        })
        .collect();
    let chosen = pick(&outcomes, budget);
    Ok(Choice {
        candidate: chosen.map_or(pins, |i| outcomes[i].candidate),
        chosen,
        outcomes,
        budget,
        judged_on,
        why: None,
        classes: names,
        thin,
    })
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

/// One fold: terrain `out_k` left out; per candidate of `grid`, its tally.
fn fold(
    out_k: usize,
    training: &[Labelled<'_>],
    calibration: &[Labelled<'_>],
    classes: &[ClassInfo],
    opts: &TrainOptions,
    grid: &[Candidate],
) -> Result<Vec<Tally>, ChoiceError> {
    let n_classes = classes.len();
    let mut tally = vec![Tally::default(); grid.len()];
    let keep: Vec<usize> = (0..n_classes).filter(|&k| k != out_k).collect();
    let relabel = |k: usize| keep.iter().position(|&c| c == k);
    let fold_classes: Vec<ClassInfo> = keep.iter().map(|&k| classes[k].clone()).collect();
    let train_k: Vec<Labelled<'_>> = training
        .iter()
        .filter_map(|l| {
            relabel(l.class).map(|class| Labelled {
                image: l.image,
                class,
            })
        })
        .collect();
    // The calibration run's known images alternate per terrain: A calibrates, B is judged.
    let (mut cal_a, mut cal_b) = (Vec::new(), Vec::new());
    let mut seen = vec![0usize; n_classes];
    for l in calibration {
        if let Some(k) = relabel(l.class) {
            seen[l.class] += 1;
            let side = if seen[l.class] % 2 == 1 {
                &mut cal_a
            } else {
                &mut cal_b
            };
            side.push((l.image, fold_classes[k].name.as_str(), k));
        }
    }
    let novel: Vec<&PressureImage> = training
        .iter()
        .chain(calibration)
        .filter(|l| l.class == out_k)
        .map(|l| l.image)
        .collect();
    // The load and texture bands over the images the fold's model may meet as known.
    let band_images: Vec<(&PressureImage, usize)> = train_k
        .iter()
        .map(|l| (l.image, l.class))
        .chain(cal_a.iter().map(|&(img, _, k)| (img, k)))
        .collect();
    let mut fits: Vec<((bool, Dims), Model, Vec<&PressureImage>)> = Vec::new();
    let mut norms: Vec<bool> = grid.iter().map(|c| c.normalize_load).collect();
    norms.dedup();
    let want_max = grid.iter().any(|c| c.dims == Dims::Max);
    for normalize_load in norms {
        let mut o = opts.clone();
        o.normalize_load = normalize_load;
        o.check_load = false;
        o.check_texture = false;
        o.unknown_checks = UnknownChecks::Fixed(Candidate::PLAIN);
        // Both dimension choices from one PCA.
        let (by_accuracy, most, split) = train_with_max_dims(&train_k, &fold_classes, &o)?;
        let judged_known: Vec<&PressureImage> = if cal_a.is_empty() {
            split.test.iter().map(|&i| train_k[i].image).collect()
        } else {
            cal_b.iter().map(|&(img, _, _)| img).collect()
        };
        let variants = [(Dims::Accuracy, Some(by_accuracy)), (Dims::Max, most)];
        for (dims, m) in variants {
            let Some(mut m) = m.filter(|_| dims == Dims::Accuracy || want_max) else {
                continue;
            };
            if !cal_a.is_empty() {
                let imgs: Vec<(&PressureImage, &str)> =
                    cal_a.iter().map(|&(img, n, _)| (img, n)).collect();
                calibrate_on_runs(&mut m, &imgs, &["calibration run, half".to_string()])?;
            }
            add_load_check_on(&mut m, band_images.iter().copied());
            add_texture_check(&mut m, band_images.iter().copied());
            fits.push(((normalize_load, dims), m, judged_known.clone()));
        }
    }
    for (key, base, judged_known) in &fits {
        for score in [NoveltyScore::KnnResidual, NoveltyScore::Knn] {
            let of_this = |c: &Candidate| (c.normalize_load, c.dims) == *key && c.score == score;
            if !grid.iter().any(of_this) {
                continue;
            }
            let mut m = base.clone();
            if score != NoveltyScore::KnnResidual {
                rescore(&mut m, score);
            }
            // The bands are held here, per candidate; the classifier judges the novelty.
            let (load_bands, texture_bands) = (m.load_ranges.take(), m.texture_ranges.take());
            let judged = judge(m, judged_known, &novel);
            let ratio = |j: &Judged| {
                j.measured
                    .map_or(f64::INFINITY, |x| x.novelty / x.threshold.abs().max(1e-12))
            };
            let neg: Vec<f64> = judged.iter().filter(|j| !j.novel).map(ratio).collect();
            let pos: Vec<f64> = judged.iter().filter(|j| j.novel).map(ratio).collect();
            let a = auroc(&neg, &pos);
            for (ci, c) in grid.iter().enumerate().filter(|(_, c)| of_this(c)) {
                let bands = Bands {
                    load: load_bands.as_deref().filter(|_| c.load),
                    texture: texture_bands.as_deref().filter(|_| c.texture),
                };
                let (mut n_novel, mut novel_unknown) = (0usize, 0usize);
                for j in &judged {
                    let is_unknown = j
                        .measured
                        .is_none_or(|x| unknown::image_verdict(x, bands, || j.roughness).is_some());
                    if j.novel {
                        n_novel += 1;
                        novel_unknown += is_unknown as usize;
                    } else {
                        tally[ci].known[0] += 1;
                        tally[ci].known[1] += is_unknown as usize;
                    }
                }
                if n_novel > 0 {
                    tally[ci].found = Some(novel_unknown as f64 / n_novel as f64);
                }
                if a.is_finite() {
                    tally[ci].auroc = Some(a);
                }
            }
        }
    }
    Ok(tally)
}

/// Classifies `known` and `novel` with `model` and keeps what the verdict needs.
fn judge(model: Model, known: &[&PressureImage], novel: &[&PressureImage]) -> Vec<Judged> {
    let (crop, down) = (model.crop, model.downsample);
    let mut cls = Classifier::new(model);
    let mut out = Vec::with_capacity(known.len() + novel.len());
    for (img, is_novel) in known
        .iter()
        .map(|i| (*i, false))
        .chain(novel.iter().map(|i| (*i, true)))
    {
        let d = cls.classify(&img.pixels, img.rows, img.cols, false);
        let work = preprocess(img, &crop, down);
        let (load, rough) = work.as_ref().map_or((0.0, f64::NAN), |w| {
            (
                w.pixels.iter().map(|&p| p as f64).sum(),
                roughness(&w.pixels, w.rows, w.cols),
            )
        });
        out.push(Judged {
            novel: is_novel,
            measured: d.ok().filter(|d| d.contact).map(|d| Measured {
                best: d.best,
                novelty: d.novelty,
                threshold: d.threshold,
                load,
            }),
            roughness: rough,
        });
    }
    out
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
            .map(|(image, class)| Labelled {
                image,
                class: *class,
            })
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
            crop: "1,1,1,1".parse::<Crop>().unwrap(),
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
        assert_eq!(choice.outcomes.len(), 8);
        assert!(choice.to_string().contains("one run only"), "{choice}");
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
