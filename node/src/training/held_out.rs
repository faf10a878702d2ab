//! How well a way of preprocessing the lab's stances classifies stances a model did not see:
//! the set is cut in time blocks per terrain, a model of the other blocks classifies each
//! block's images. The deciding frame and the crop are both chosen on it.
//!
//! A share right saturates: on a foot whose terrains are far apart every candidate classifies
//! 100%, and the share cannot tell them apart. The margin does not: per held-out image, the log
//! posterior of its own terrain over the best other's (nats; negative when it is taken for
//! another). A candidate whose images sit further inside their own terrain leaves more room
//! for the next session's spread.

use crate::classifier::train::{Labelled, TIME_BLOCKS, TrainOptions, time_blocks, train};

use super::TrainingSet;

/// A margin past this many nats counts as this many: one very sure image does not outweigh
/// several unsure ones (e^8: about 3,000 to 1).
pub const MARGIN_CAP: f64 = 8.0;

/// What the held-out images said.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HeldOut {
    /// The share classified right (NaN when none was classified).
    pub accuracy: f64,
    /// Images classified.
    pub judged: usize,
    /// The mean margin, nats, each capped at ±[`MARGIN_CAP`] (NaN when none was classified).
    pub margin: f64,
    /// The margins' standard error, nats.
    pub margin_se: f64,
}

impl HeldOut {
    /// Nothing measured.
    pub const NONE: HeldOut = HeldOut {
        accuracy: f64::NAN,
        judged: 0,
        margin: f64::NAN,
        margin_se: f64::NAN,
    };

    /// Two standard deviations of a share of this many images at this accuracy (clamped off 0
    /// and 1, where the binomial spread vanishes): the counting noise two candidates' shares
    /// must differ by to be told apart.
    pub fn counting_noise(&self) -> f64 {
        let n = self.judged.max(1) as f64;
        let p = self.accuracy.clamp(1.0 / n, 1.0 - 1.0 / n);
        2.0 * (2.0 * p * (1.0 - p) / n).sqrt()
    }
}

/// `set` classified block by block (see the module docs) with `opts`' preprocessing, the
/// paper's split at its share of what the other blocks hold, no unknown-ground checks (the
/// classification is what is measured).
pub fn held_out(set: &TrainingSet, opts: &TrainOptions) -> HeldOut {
    let blocks = time_blocks(&set.labels, set.classes.len());
    let mut margins: Vec<f64> = Vec::new();
    let mut right = 0usize;
    for b in 0..TIME_BLOCKS as u8 {
        let (held, rest): (Vec<usize>, Vec<usize>) =
            (0..set.images.len()).partition(|&i| blocks[i] == b);
        let train_set: Vec<Labelled<'_>> = rest
            .iter()
            .map(|&i| Labelled::new(&set.images[i], set.labels[i]))
            .collect();
        let mut counts = vec![0usize; set.classes.len()];
        for l in &train_set {
            counts[l.class] += 1;
        }
        let least = counts.iter().copied().min().unwrap_or(0);
        if least < 2 {
            continue;
        }
        let per_class = least.min(opts.per_class);
        let o = TrainOptions {
            per_class,
            train: (per_class * opts.train / opts.per_class.max(1)).clamp(1, per_class - 1),
            unknown_rate: 0.0,
            unknown_checks: crate::classifier::options::UnknownChecks::Fixed(
                crate::classifier::options::Candidate::PLAIN,
            ),
            ..opts.clone()
        };
        let Ok((model, _)) = train(&train_set, &set.classes, &o) else {
            continue;
        };
        let mut cls = crate::classifier::Classifier::new(model);
        for &i in &held {
            let img = &set.images[i];
            let Ok(d) = cls.classify(&img.pixels, img.rows, img.cols, false) else {
                continue;
            };
            let k = set.labels[i];
            let margin = if d.contact {
                let lp = cls.log_posteriors();
                let other = (0..lp.len())
                    .filter(|&j| j != k)
                    .map(|j| lp[j])
                    .fold(f64::NEG_INFINITY, f64::max);
                (lp[k] - other).clamp(-MARGIN_CAP, MARGIN_CAP)
            } else {
                -MARGIN_CAP
            };
            right += (d.contact && d.best == k) as usize;
            margins.push(if margin.is_nan() { -MARGIN_CAP } else { margin });
        }
    }
    let n = margins.len();
    if n == 0 {
        return HeldOut::NONE;
    }
    let mean = margins.iter().sum::<f64>() / n as f64;
    let var = margins.iter().map(|m| (m - mean).powi(2)).sum::<f64>() / (n.max(2) - 1) as f64;
    HeldOut {
        accuracy: right as f64 / n as f64,
        judged: n,
        margin: mean,
        margin_se: (var / n as f64).sqrt(),
    }
}
