//! One fold of the choice: a known terrain left out, the sessions cut around it, the fold's
//! models fitted and every candidate tallied on them.

use super::{
    Bands, Candidate, ChoiceError, ClassInfo, Classifier, Dims, Folds, Judged, Labelled, Margin,
    Measured, Model, NoveltyScore, PressureImage, Tally, TrainOptions, UnknownChecks,
    add_load_check_on, add_texture_check, auroc, calibrate_on_runs, fold_options, preprocess,
    rescore, roughness, train_with_max_dims, unknown,
};

/// What one fold measured: per candidate its tally, the plain nearest neighbour's AUROC, and
/// the energy check's on its own (each stance's flights against its texture class's map).
pub(super) type FoldTally = (Vec<Tally>, Option<f64>, Tally);

/// A judged image with its stance's flights (seconds, both plausible hops), where known.
pub(super) type WithFlights<'a> = (&'a PressureImage, Option<(f64, f64)>);

/// One labelled image's flights, as the energy check judges them: both plausible hops.
pub(super) fn flights_s(l: &Labelled<'_>) -> Option<(f64, f64)> {
    crate::unknown::energy::plausible_flights_s(l.flights)
}

/// The images one fold sees, terrain `out_k` left out (classes renumbered without it).
pub(super) struct FoldSets<'a> {
    classes: Vec<ClassInfo>,
    /// The fold model's training images.
    train: Vec<Labelled<'a>>,
    /// The calibration run's known images: `cal_a` calibrates, `cal_b` is judged.
    cal_a: Vec<(&'a PressureImage, usize)>,
    cal_b: Vec<WithFlights<'a>>,
    /// With one session: its later known images, judged.
    later: Vec<WithFlights<'a>>,
    /// The left-out terrain's images, from every run.
    novel: Vec<WithFlights<'a>>,
    /// Known stances (class, flight before, flight after) the energy maps are fitted on.
    stances: Vec<(usize, f64, f64)>,
}

impl<'a> FoldSets<'a> {
    fn new(
        out_k: usize,
        training: &[Labelled<'a>],
        calibration: &[Labelled<'a>],
        later: &[Labelled<'a>],
        classes: &[ClassInfo],
    ) -> Self {
        let keep: Vec<usize> = (0..classes.len()).filter(|&k| k != out_k).collect();
        let relabel = |k: usize| keep.iter().position(|&c| c == k);
        let train: Vec<Labelled<'a>> = training
            .iter()
            .filter_map(|l| relabel(l.class).map(|class| Labelled { class, ..*l }))
            .collect();
        // The calibration run's known images alternate per terrain: A calibrates, B is judged.
        let (mut cal_a, mut cal_b) = (Vec::new(), Vec::new());
        let mut seen = vec![0usize; classes.len()];
        let mut stances: Vec<(usize, f64, f64)> = train
            .iter()
            .filter_map(|l| flights_s(l).map(|(b, a)| (l.class, b, a)))
            .collect();
        for l in calibration {
            if let Some(k) = relabel(l.class) {
                seen[l.class] += 1;
                if seen[l.class] % 2 == 1 {
                    cal_a.push((l.image, k));
                    stances.extend(flights_s(l).map(|(b, a)| (k, b, a)));
                } else {
                    cal_b.push((l.image, flights_s(l)));
                }
            }
        }
        let novel = training
            .iter()
            .chain(calibration)
            .chain(later)
            .filter(|l| l.class == out_k)
            .map(|l| (l.image, flights_s(l)))
            .collect();
        let later = later
            .iter()
            .filter(|l| l.class != out_k)
            .map(|l| (l.image, flights_s(l)))
            .collect();
        Self {
            classes: keep.iter().map(|&k| classes[k].clone()).collect(),
            train,
            cal_a,
            cal_b,
            later,
            novel,
            stances,
        }
    }

    /// The known images judged: half the calibration run; else the session's later images;
    /// else the training images the model does not store (`test`).
    fn judged_known(&self, test: &[usize]) -> Vec<WithFlights<'a>> {
        if !self.cal_a.is_empty() {
            self.cal_b.clone()
        } else if !self.later.is_empty() {
            self.later.clone()
        } else {
            test.iter()
                .map(|&i| (self.train[i].image, flights_s(&self.train[i])))
                .collect()
        }
    }
}

/// One fold: terrain `out_k` left out; per candidate of the grid, its tally.
pub(super) fn fold(out_k: usize, folds: &Folds<'_, '_>) -> Result<FoldTally, ChoiceError> {
    let Folds {
        training,
        calibration,
        later,
        classes,
        opts,
        grid,
    } = *folds;
    let sets = FoldSets::new(out_k, training, calibration, later, classes);
    let fits = fold_models(&sets, opts, grid)?;
    let maps = crate::unknown::energy::fit(&sets.stances, sets.classes.len(), opts.unknown_rate);
    let mut tally = vec![Tally::default(); grid.len()];
    let mut nn_auroc = None;
    let mut energy_alone = Tally::default();
    let one_session = !sets.later.is_empty();
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
            // The nearest neighbour and the energy check alone, once per fold: on the first
            // (plain) model's classes.
            let first = nn_auroc.is_none();
            if first {
                nn_auroc = Some(nearest_neighbour_auroc(
                    m.clone(),
                    judged_known,
                    &sets.novel,
                ));
            }
            // The bands are held here, per candidate; the classifier judges the novelty.
            let (load_bands, texture_bands) =
                (m.unknown.load_bands.take(), m.unknown.texture_bands.take());
            let judged = judge(m, judged_known, &sets.novel);
            let ratio = |j: &Judged| {
                j.measured
                    .map_or(f64::INFINITY, |x| x.novelty / x.threshold.abs().max(1e-12))
            };
            let neg: Vec<f64> = judged.iter().filter(|j| !j.novel).map(ratio).collect();
            let pos: Vec<f64> = judged.iter().filter(|j| j.novel).map(ratio).collect();
            let a = auroc(&neg, &pos);
            if first {
                energy_alone = tally_of(&judged, Bands::default(), f64::INFINITY, Some(&maps));
            }
            for (ci, c) in grid.iter().enumerate().filter(|(_, c)| of_this(c)) {
                let bands = Bands {
                    load: load_bands.as_deref().filter(|_| c.load),
                    texture: texture_bands.as_deref().filter(|_| c.texture),
                };
                // One session: the candidate's factor on its own thresholds.
                let margin = if one_session { c.margin.factor() } else { 1.0 };
                let energy = c.energy.then_some(maps.as_slice());
                tally[ci] = tally_of(&judged, bands, margin, energy);
                if a.is_finite() {
                    tally[ci].auroc = Some(a);
                }
            }
        }
    }
    Ok((tally, nn_auroc.filter(|v| v.is_finite()), energy_alone))
}

/// The fold's models, one per load normalisation and dimension choice of `grid` (calibrated
/// on half the calibration run when there is one; with the load and texture bands, held apart
/// per candidate), each with the known images it is judged on.
pub(super) type FoldModel<'a> = ((bool, Dims), Model, Vec<WithFlights<'a>>);

pub(super) fn fold_models<'a>(
    sets: &FoldSets<'a>,
    opts: &TrainOptions,
    grid: &[Candidate],
) -> Result<Vec<FoldModel<'a>>, ChoiceError> {
    let mut counts = vec![0usize; sets.classes.len()];
    for l in &sets.train {
        counts[l.class] += 1;
    }
    let opts = &fold_options(opts, &counts);
    // The load and texture bands over the images the fold's model may meet as known.
    let band_images: Vec<(&PressureImage, usize)> = sets
        .train
        .iter()
        .map(|l| (l.image, l.class))
        .chain(sets.cal_a.iter().copied())
        .collect();
    let mut fits = Vec::new();
    let mut norms: Vec<bool> = grid.iter().map(|c| c.normalize_load).collect();
    norms.dedup();
    let want_max = grid.iter().any(|c| c.dims == Dims::Max);
    for normalize_load in norms {
        let mut o = opts.clone();
        o.normalize_load = normalize_load;
        o.check_load = false;
        o.check_texture = false;
        // Thresholds as the time blocks set them: each candidate's margin is applied later.
        o.unknown_checks = UnknownChecks::Fixed(Candidate {
            margin: Margin::MEASURED,
            ..Candidate::PLAIN
        });
        // Both dimension choices from one PCA.
        let (by_accuracy, most, split) = train_with_max_dims(&sets.train, &sets.classes, &o)?;
        let judged_known = sets.judged_known(&split.test);
        for (dims, m) in [(Dims::Accuracy, Some(by_accuracy)), (Dims::Max, most)] {
            let Some(mut m) = m.filter(|_| dims == Dims::Accuracy || want_max) else {
                continue;
            };
            if !sets.cal_a.is_empty() {
                let imgs: Vec<(&PressureImage, &str)> = sets
                    .cal_a
                    .iter()
                    .map(|&(img, k)| (img, sets.classes[k].name.as_str()))
                    .collect();
                calibrate_on_runs(&mut m, &imgs, &["calibration run, half".to_string()])?;
            }
            add_load_check_on(&mut m, band_images.iter().copied());
            add_texture_check(&mut m, band_images.iter().copied());
            fits.push(((normalize_load, dims), m, judged_known.clone()));
        }
    }
    Ok(fits)
}

/// One candidate's tally over `judged`: the share of the left-out terrain called unknown and
/// the known images called unknown, by the image's checks at `margin` on the novelty's
/// thresholds, and by the energy check with `maps` (each stance's own flights against its best
/// class's map).
pub(super) fn tally_of(
    judged: &[Judged],
    bands: Bands<'_>,
    margin: f64,
    maps: Option<&[Option<crate::unknown::energy::ReturnMap>]>,
) -> Tally {
    let mut t = Tally::default();
    let (mut n_novel, mut novel_unknown) = (0usize, 0usize);
    for j in judged {
        let is_unknown = j.measured.is_none_or(|mut x| {
            x.threshold *= margin;
            let energy = maps.is_some_and(|maps| {
                j.flights.is_some_and(|(b, a)| {
                    maps.get(x.best)
                        .copied()
                        .flatten()
                        .is_some_and(|m| !m.passes(b, a))
                })
            });
            let image = unknown::image_verdict(x, bands, || j.roughness);
            unknown::step_verdict(image, energy).is_some()
        });
        if j.novel {
            n_novel += 1;
            novel_unknown += is_unknown as usize;
        } else {
            t.known[0] += 1;
            t.known[1] += is_unknown as usize;
        }
    }
    if n_novel > 0 {
        t.found = Some(novel_unknown as f64 / n_novel as f64);
    }
    t
}

/// The AUROC of the plain nearest-neighbour distance in `model`'s PCA space, `novel` against
/// `known` (an image without contact the most novel).
pub(super) fn nearest_neighbour_auroc(
    model: Model,
    known: &[WithFlights<'_>],
    novel: &[WithFlights<'_>],
) -> f64 {
    let mut cls = Classifier::new(model);
    let mut dist = |img: &PressureImage| match cls.classify(&img.pixels, img.rows, img.cols, false)
    {
        Ok(d) if d.contact => cls.nearest_sample_distance(),
        _ => f64::INFINITY,
    };
    let neg: Vec<f64> = known.iter().map(|(i, _)| dist(i)).collect();
    let pos: Vec<f64> = novel.iter().map(|(i, _)| dist(i)).collect();
    auroc(&neg, &pos)
}

/// Classifies `known` and `novel` with `model` and keeps what the verdict needs.
pub(super) fn judge(
    model: Model,
    known: &[WithFlights<'_>],
    novel: &[WithFlights<'_>],
) -> Vec<Judged> {
    let (crop, down) = (model.crop, model.downsample);
    let mut cls = Classifier::new(model);
    let mut out = Vec::with_capacity(known.len() + novel.len());
    for (&(img, flights), is_novel) in known
        .iter()
        .map(|i| (i, false))
        .chain(novel.iter().map(|i| (i, true)))
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
            flights,
        });
    }
    out
}
