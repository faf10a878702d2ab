//! The foot's own deciding frame: which time after touchdown classifies the lab's stances best.
//!
//! The paper's hopper reached its stance's full load about 70 ms after touchdown, and the
//! node samples there by default. Another foot, gait or robot loads differently: a frame taken
//! before the load has built up shows less of the ground's texture. When the captured set keeps
//! each stance's frames (`presrs capture` writes them to `DIR/.stance`, one per
//! [`FRAME_OFFSETS_MS`]), `train` measures every offset that nearly every stance reaches: the
//! session is cut in time blocks, a model of the other blocks classifies each block's frames at
//! that offset, and the offset that classifies the most right is kept; offsets within two
//! standard deviations of it (the counting noise of that many stances) tie, and a tie goes to
//! the one nearest the node's configured sample time. The model stores it (`sample_ms`), and the node
//! samples each stance's frame nearest it.

use crate::classifier::train::{Labelled, TIME_BLOCKS, TrainOptions, time_blocks, train};
use crate::stance::FRAME_OFFSETS_MS;

use super::TrainingSet;

/// An offset counts only when at least this share of the stances have a frame there: at a
/// later one, a short stance would end without a sample on the robot.
pub const MIN_COVERAGE: f64 = 0.95;

/// What one offset measured.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameScore {
    /// Time after touchdown, ms.
    pub offset_ms: u32,
    /// The share of the stances with a frame there.
    pub coverage: f64,
    /// The share of the held-out frames classified right (NaN when not measured).
    pub accuracy: f64,
    /// Frames classified.
    pub judged: usize,
}

/// The offsets measured and the one kept.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameChoice {
    /// Each offset of [`FRAME_OFFSETS_MS`].
    pub scores: Vec<FrameScore>,
    /// The kept offset's index.
    pub chosen: usize,
}

impl FrameChoice {
    /// The kept offset, ms.
    pub fn offset_ms(&self) -> u32 {
        self.scores[self.chosen].offset_ms
    }
}

/// `train`'s line: the offset kept and the table it was chosen from.
impl std::fmt::Display for FrameChoice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let c = &self.scores[self.chosen];
        let each: Vec<String> = self
            .scores
            .iter()
            .map(|s| {
                if s.accuracy.is_finite() {
                    format!("{} ms {:.1}%", s.offset_ms, 100.0 * s.accuracy)
                } else {
                    format!(
                        "{} ms n/a ({:.0}% of stances reach it)",
                        s.offset_ms,
                        100.0 * s.coverage
                    )
                }
            })
            .collect();
        write!(
            f,
            "deciding frame: {} ms after touchdown: of the frames within counting noise of the \
             one that classified the most held-out stances right, the nearest the node's sample \
             time ({:.1}% of {}; each session's time blocks judged by a model of the others); \
             per offset: {}",
            c.offset_ms,
            100.0 * c.accuracy,
            c.judged,
            each.join(", ")
        )
    }
}

/// Measures the deciding frame on `set`'s stance frames (see the module docs), with `opts`'
/// preprocessing; `default_ms` (the node's configured sample time) wins a tie. `None` when the
/// set keeps no frames, or no offset could be measured.
pub fn choose_frame(
    set: &TrainingSet,
    opts: &TrainOptions,
    default_ms: u32,
) -> Option<FrameChoice> {
    let n = set.images.len();
    let scores: Vec<FrameScore> = FRAME_OFFSETS_MS
        .iter()
        .enumerate()
        .map(|(j, &offset_ms)| {
            let at = set.at_frame(j);
            let coverage = at
                .as_ref()
                .map_or(0.0, |s| s.images.len() as f64 / n.max(1) as f64);
            let (accuracy, judged) = match at {
                Some(s) if coverage >= MIN_COVERAGE => held_out_accuracy(&s, opts),
                _ => (f64::NAN, 0),
            };
            FrameScore {
                offset_ms,
                coverage,
                accuracy,
                judged,
            }
        })
        .collect();
    let best = scores
        .iter()
        .map(|s| s.accuracy)
        .filter(|a| a.is_finite())
        .fold(f64::NEG_INFINITY, f64::max);
    if !best.is_finite() {
        return None;
    }
    // Offsets within two standard deviations of the best one's accuracy (of the difference of
    // two shares of that many stances) tie: then the nearest the node's own sample time, whose
    // frame a lab has been running with, unless another is clearly better.
    let judged = scores.iter().map(|s| s.judged).max().unwrap_or(1).max(1) as f64;
    let p = best.clamp(1.0 / judged, 1.0 - 1.0 / judged);
    let noise = 2.0 * (2.0 * p * (1.0 - p) / judged).sqrt();
    let chosen = (0..scores.len())
        .filter(|&j| scores[j].accuracy.is_finite() && scores[j].accuracy >= best - noise)
        .min_by_key(|&j| scores[j].offset_ms.abs_diff(default_ms))?;
    Some(FrameChoice { scores, chosen })
}

/// The share of `set`'s images classified right by models of the other time blocks, and how
/// many were classified.
fn held_out_accuracy(set: &TrainingSet, opts: &TrainOptions) -> (f64, usize) {
    let blocks = time_blocks(&set.labels, set.classes.len());
    let (mut right, mut judged) = (0usize, 0usize);
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
        // The paper's split at its share, on what the other blocks hold; no rejection (the
        // classification is what is measured, and calibrating would cost the time).
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
            if let Ok(d) = cls.classify(&img.pixels, img.rows, img.cols, false) {
                judged += 1;
                right += (d.contact && d.best == set.labels[i]) as usize;
            }
        }
    }
    if judged == 0 {
        return (f64::NAN, 0);
    }
    (right as f64 / judged as f64, judged)
}
