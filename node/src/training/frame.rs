//! The foot's own deciding frame: which time after touchdown tells the lab's terrains apart.
//!
//! The paper's hopper reached its stance's full load about 70 ms after touchdown. Another foot
//! rolls on, loads slowly or sits elsewhere: a frame taken before the load has built up shows
//! less of the ground. When the captured set keeps each stance's frames (`presrs capture`
//! writes them to `DIR/.stance`, one per [`FRAME_OFFSETS_MS`]), `train` measures every offset
//! that nearly every stance reaches ([`super::held_out`]: time blocks, each judged by a model
//! of the others), with the whole stance's footprint as the crop, so that no offset is judged
//! on a crop that cuts the load it carries.
//!
//! The choice goes down a chain, each step only among the offsets the step before could not
//! tell apart: the share classified right (within its counting noise), the held-out margin
//! (within two standard errors), the share of the stance's peak load the frame holds (within
//! [`LOAD_TIE`]), and last the earliest that has a tied offset before it (the decision soon,
//! with a frame period of slack for a session that loads slower). On a foot whose terrains are
//! far apart every offset classifies 100%, and the margin or the load decides; `train` prints
//! which step decided, never the node's default as if it had been measured.
//!
//! The lab's word wins: `train --sample-ms` (or a capture made with the config's `sample_ms`
//! set) pins the frame ([`super::set`]).

use crate::classifier::train::TrainOptions;
use crate::classifier::{Crop, PressureImage};
use crate::stance::FRAME_OFFSETS_MS;

use super::TrainingSet;
use super::held_out::{HeldOut, held_out};

/// An offset counts only when at least this share of the stances have a frame there: at a
/// later one, a short stance would end without a sample on the robot.
pub const MIN_COVERAGE: f64 = 0.95;

/// Two offsets whose frames hold shares of the stance's peak load this close tie on load.
pub const LOAD_TIE: f64 = 0.02;

/// What one offset measured.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameScore {
    /// Time after touchdown, ms.
    pub offset_ms: u32,
    /// The share of the stances with a frame there.
    pub coverage: f64,
    /// The held-out images' account (nothing where too few stances reach it).
    pub held_out: HeldOut,
    /// The median share of its stance's peak load the frame holds (the peak over the stance's
    /// frames at every offset).
    pub load: f64,
}

/// Which step of the chain chose the frame (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameBasis {
    /// It classified more held-out stances right than any other offset by more than counting
    /// noise.
    Accuracy,
    /// Offsets tied on accuracy; it had the widest held-out margin.
    Margin,
    /// Offsets tied on accuracy and margin; its frame holds the most of the stance's load.
    Load,
    /// Nothing measured told the tied offsets apart: the earliest of them with a tied offset
    /// before it (a session that loads slower still decides on a frame like them).
    Earliest,
}

/// The offsets measured and the one kept.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameChoice {
    /// Each offset of [`FRAME_OFFSETS_MS`].
    pub scores: Vec<FrameScore>,
    /// The kept offset's index.
    pub chosen: usize,
    /// What chose it.
    pub basis: FrameBasis,
    /// The offsets (indices) still tied at the step that chose: those it was chosen among.
    pub tied: Vec<usize>,
}

impl FrameChoice {
    /// The kept offset, ms.
    pub fn offset_ms(&self) -> u32 {
        self.scores[self.chosen].offset_ms
    }

    /// Why this offset, in a few words, with the figure that made it (`train`'s summary).
    pub fn why(&self) -> String {
        let c = &self.scores[self.chosen];
        let span = || {
            let ms: Vec<u32> = self
                .tied
                .iter()
                .map(|&j| self.scores[j].offset_ms)
                .collect();
            match (ms.first(), ms.last()) {
                (Some(a), Some(b)) if a != b => format!("{a}-{b} ms"),
                _ => String::new(),
            }
        };
        let acc = 100.0 * c.held_out.accuracy;
        match self.basis {
            FrameBasis::Accuracy => format!("the most held-out stances right, {acc:.1}%"),
            FrameBasis::Margin => format!(
                "{} tie at {acc:.1}% right; the widest held-out margin, {:.1} nats",
                span(),
                c.held_out.margin
            ),
            FrameBasis::Load => format!(
                "{} tie at {acc:.1}% right and on margin; the most of the stance's load, {:.0}%",
                span(),
                100.0 * c.load
            ),
            FrameBasis::Earliest => format!(
                "{} classify alike ({acc:.1}% right, margin {:.1} nats, {:.0}% of the load): \
                 the earliest with one of them before it, for a session that loads slower",
                span(),
                c.held_out.margin,
                100.0 * c.load
            ),
        }
    }
}

/// `train --verbose`'s line: the offset kept, why, and the table it was chosen from.
impl std::fmt::Display for FrameChoice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let each: Vec<String> = self
            .scores
            .iter()
            .map(|s| {
                if s.held_out.accuracy.is_finite() {
                    format!(
                        "{} ms {:.1}% {:+.2} nats {:.0}% load",
                        s.offset_ms,
                        100.0 * s.held_out.accuracy,
                        s.held_out.margin,
                        100.0 * s.load
                    )
                } else {
                    format!(
                        "{} ms n/a ({:.0}% of stances reach it)",
                        s.offset_ms,
                        100.0 * s.coverage
                    )
                }
            })
            .collect();
        let judged = self.scores[self.chosen].held_out.judged;
        write!(
            f,
            "deciding frame: {} ms after touchdown ({}; {judged} stances, each session's time \
             blocks judged by a model of the others; each offset: held-out right, margin, share \
             of the stance's peak load); per offset: {}",
            self.offset_ms(),
            self.why(),
            each.join(", ")
        )
    }
}

/// Measures the deciding frame on `set`'s stance frames (see the module docs), with `opts`'
/// preprocessing (an automatic crop is the whole stance's footprint). `None` when the set
/// keeps no frames, or no offset could be measured.
pub fn choose_frame(set: &TrainingSet, opts: &TrainOptions) -> Option<FrameChoice> {
    let n = set.images.len();
    let at: Vec<Option<TrainingSet>> = (0..FRAME_OFFSETS_MS.len())
        .map(|j| set.at_frame(j))
        .collect();
    at.first()?.as_ref()?;
    let opts = TrainOptions {
        crop: crate::classifier::train::resolve_crop(
            opts.crop,
            at.iter().flatten().flat_map(|s| &s.images),
        )
        .into(),
        ..opts.clone()
    };
    let loads = peak_load_shares(set);
    let scores: Vec<FrameScore> = FRAME_OFFSETS_MS
        .iter()
        .zip(&at)
        .enumerate()
        .map(|(j, (&offset_ms, at))| {
            let coverage = at
                .as_ref()
                .map_or(0.0, |s| s.images.len() as f64 / n.max(1) as f64);
            let held_out = match at {
                Some(s) if coverage >= MIN_COVERAGE => held_out(s, &opts),
                _ => HeldOut::NONE,
            };
            FrameScore {
                offset_ms,
                coverage,
                held_out,
                load: loads[j],
            }
        })
        .collect();
    choose(scores)
}

/// The chain of the module docs over measured `scores`.
fn choose(scores: Vec<FrameScore>) -> Option<FrameChoice> {
    let measured: Vec<usize> = (0..scores.len())
        .filter(|&j| scores[j].held_out.accuracy.is_finite())
        .collect();
    let best_by = |idx: &[usize], key: &dyn Fn(&FrameScore) -> f64| {
        idx.iter()
            .copied()
            .max_by(|&a, &b| key(&scores[a]).total_cmp(&key(&scores[b])))
    };
    let top = best_by(&measured, &|s| s.held_out.accuracy)?;
    let noise = scores[top].held_out.counting_noise();
    let best = scores[top].held_out.accuracy;
    let tied: Vec<usize> = measured
        .iter()
        .copied()
        .filter(|&j| scores[j].held_out.accuracy >= best - noise)
        .collect();
    let pick = |basis, chosen, tied| {
        Some(FrameChoice {
            scores: scores.clone(),
            chosen,
            basis,
            tied,
        })
    };
    if tied.len() == 1 {
        return pick(FrameBasis::Accuracy, top, tied);
    }
    let top = best_by(&tied, &|s| s.held_out.margin)?;
    let (m, se) = (scores[top].held_out.margin, scores[top].held_out.margin_se);
    let near: Vec<usize> = tied
        .iter()
        .copied()
        .filter(|&j| scores[j].held_out.margin >= m - 2.0 * se.max(scores[j].held_out.margin_se))
        .collect();
    if near.len() == 1 {
        return pick(FrameBasis::Margin, top, tied);
    }
    let top = best_by(&near, &|s| s.load)?;
    let full: Vec<usize> = near
        .iter()
        .copied()
        .filter(|&j| scores[j].load >= scores[top].load - LOAD_TIE)
        .collect();
    if full.len() == 1 {
        return pick(FrameBasis::Load, top, near);
    }
    // The earliest with a tied offset before it: a next session that loads a frame period
    // slower still decides on a frame like the ones measured.
    let first = *full.first()?;
    let slack = full
        .iter()
        .copied()
        .find(|&j| j > 0 && full.contains(&(j - 1)))
        .unwrap_or(first);
    pick(FrameBasis::Earliest, slack, full)
}

/// Per offset, the median over the stances of the share of the stance's peak load its frame
/// there holds (0 where no stance has a frame there).
fn peak_load_shares(set: &TrainingSet) -> Vec<f64> {
    let load = |img: &PressureImage| img.pixels.iter().map(|&p| f64::from(p)).sum::<f64>();
    let per_offset: Vec<Vec<f64>> = (0..FRAME_OFFSETS_MS.len())
        .map(|j| {
            set.frames
                .iter()
                .filter_map(|frames| {
                    let peak = frames.iter().map(load).fold(0.0, f64::max);
                    let f = frames.get(j)?;
                    (peak > 0.0).then(|| load(f) / peak)
                })
                .collect()
        })
        .collect();
    per_offset
        .into_iter()
        .map(|mut v| {
            v.sort_by(|a, b| a.total_cmp(b));
            v.get(v.len() / 2).copied().unwrap_or(0.0)
        })
        .collect()
}

/// The crop `train` keeps of the footprint's own `crop` (measured on the images at the chosen
/// frame): it when it classifies `set`'s held-out stances at least as well as no crop (more
/// right, or as many and a margin not two standard errors below), else none. A crop that cuts
/// nothing is kept unmeasured.
pub fn check_crop(set: &TrainingSet, opts: &TrainOptions, crop: Crop) -> CropCheck {
    let with = |c: Crop| {
        held_out(
            set,
            &TrainOptions {
                crop: c.into(),
                ..opts.clone()
            },
        )
    };
    if crop == Crop::default() {
        return CropCheck {
            footprint: crop,
            cut: HeldOut::NONE,
            none: HeldOut::NONE,
            kept: true,
        };
    }
    let (cut, none) = (with(crop), with(Crop::default()));
    let kept = !none.accuracy.is_finite()
        || cut.accuracy > none.accuracy
        || (cut.accuracy == none.accuracy
            && cut.margin >= none.margin - 2.0 * cut.margin_se.max(none.margin_se));
    CropCheck {
        footprint: crop,
        cut,
        none,
        kept,
    }
}

/// Whether the footprint's crop paid for itself ([`check_crop`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CropCheck {
    /// The footprint's own crop.
    pub footprint: Crop,
    /// The held-out stances with it, and with no crop (nothing measured for a crop that cuts
    /// nothing).
    pub cut: HeldOut,
    /// See `cut`.
    pub none: HeldOut,
    /// It classified at least as well as no crop, and the model has it.
    pub kept: bool,
}

impl CropCheck {
    /// The crop the model gets.
    pub fn crop(&self) -> Crop {
        if self.kept {
            self.footprint
        } else {
            Crop::default()
        }
    }

    /// `train`'s words for it: the two held-out accounts.
    pub fn why(&self) -> String {
        let acc = |h: &HeldOut| {
            format!(
                "{:.1}% right, margin {:.1} nats",
                100.0 * h.accuracy,
                h.margin
            )
        };
        if !self.cut.accuracy.is_finite() {
            return "it cuts no loaded line".into();
        }
        if self.kept {
            format!(
                "held-out stances: {} with it, {} without",
                acc(&self.cut),
                acc(&self.none)
            )
        } else {
            format!(
                "not kept: the footprint's crop {} classified the held-out stances worse than \
                 none ({} against {})",
                self.footprint,
                acc(&self.cut),
                acc(&self.none)
            )
        }
    }
}

/// How the model's deciding frame came to be.
#[derive(Clone, Debug, PartialEq)]
pub enum DecidingFrame {
    /// Measured on the stances' frames.
    Measured(FrameChoice),
    /// The lab's: `--sample-ms`, or the time the set was captured at.
    Pinned {
        /// Ms after touchdown.
        ms: u32,
        /// Who set it.
        by: Pin,
    },
    /// The sessions keep no stance frames: the node's sample time (its config's, or 70 ms).
    NotMeasured,
}

/// Who pinned the deciding frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pin {
    /// `train --sample-ms`.
    Option,
    /// The capture was made at this time (its config's `sample_ms`).
    Capture,
}

impl DecidingFrame {
    /// The frame the model stores, ms (`None`: the node's own).
    pub fn ms(&self) -> Option<u32> {
        match self {
            DecidingFrame::Measured(c) => Some(c.offset_ms()),
            DecidingFrame::Pinned { ms, .. } => Some(*ms),
            DecidingFrame::NotMeasured => None,
        }
    }

    /// `deciding frame 130 ms after touchdown (why)`: `train`'s summary.
    pub fn summary(&self) -> String {
        match self {
            DecidingFrame::Measured(c) => {
                format!(
                    "deciding frame {} ms after touchdown ({})",
                    c.offset_ms(),
                    c.why()
                )
            }
            DecidingFrame::Pinned {
                ms,
                by: Pin::Option,
            } => {
                format!("deciding frame {ms} ms after touchdown (--sample-ms)")
            }
            DecidingFrame::Pinned {
                ms,
                by: Pin::Capture,
            } => format!(
                "deciding frame {ms} ms after touchdown (the set was captured at it: the capture \
                 config's sample_ms; --sample-ms to choose another)"
            ),
            DecidingFrame::NotMeasured => "deciding frame: the node's sample time (the sessions \
                 keep no stance frames to measure one on: capture them with this build)"
                .into(),
        }
    }
}

/// The frame the lab pinned, if it did, and where `set`'s images for it are: a stance frame's
/// index, or `None` for the set's own images. `--sample-ms` pins one of the stance frames'
/// offsets, or the time the set was captured at (or any time, for a set without a manifest
/// or frames: the lab knows what its images are); a set captured at another time than the
/// node's default pins that one.
pub fn pinned(
    set: &TrainingSet,
    opts: &TrainOptions,
) -> Result<Option<(u32, Pin, Option<usize>)>, String> {
    let frames = set.at_frame(0).is_some();
    let captured_near = |ms: u32| set.captured_ms.is_some_and(|c| c.abs_diff(ms) <= NEAR_MS);
    if let Some(ms) = opts.sample_ms {
        if let Some(j) = FRAME_OFFSETS_MS
            .iter()
            .position(|&o| o == ms)
            .filter(|_| frames)
        {
            return Ok(Some((ms, Pin::Option, Some(j))));
        }
        if captured_near(ms) || (!frames && set.captured_ms.is_none()) {
            return Ok(Some((ms, Pin::Option, None)));
        }
        return Err(format!(
            "--sample-ms {ms}: the set holds its stances at {} ms after touchdown{}; give one of \
             those, or capture again with `sample_ms = {ms}` in the capture's config",
            set.captured_ms
                .map_or("an unknown time".into(), |c| c.to_string()),
            if frames {
                format!(
                    " and their frames at {}",
                    FRAME_OFFSETS_MS.map(|o| o.to_string()).join(", ")
                )
            } else {
                String::new()
            }
        ));
    }
    let default = crate::config::DEFAULT_SAMPLE_MS;
    Ok(set
        .captured_ms
        .filter(|&c| c.abs_diff(default) > NEAR_MS)
        .map(|c| (c, Pin::Capture, None)))
}

/// A capture's images lie within half a frame period of its sample time.
const NEAR_MS: u32 = 5;

#[cfg(test)]
mod tests {
    use super::*;

    fn score(offset_ms: u32, accuracy: f64, margin: f64, load: f64) -> FrameScore {
        FrameScore {
            offset_ms,
            coverage: 1.0,
            held_out: HeldOut {
                accuracy,
                judged: 75,
                margin,
                margin_se: 0.1,
            },
            load,
        }
    }

    #[test]
    fn each_step_of_the_chain_decides_only_what_the_one_before_could_not() {
        // One offset clearly best.
        let c = choose(vec![score(30, 0.80, 2.0, 0.5), score(70, 0.99, 3.0, 1.0)]).unwrap();
        assert_eq!((c.offset_ms(), c.basis), (70, FrameBasis::Accuracy));
        // All at 100%: the margin.
        let c = choose(vec![
            score(50, 1.0, 5.0, 1.0),
            score(70, 1.0, 7.5, 1.0),
            score(90, 1.0, 6.0, 1.0),
        ])
        .unwrap();
        assert_eq!((c.offset_ms(), c.basis), (70, FrameBasis::Margin));
        assert!(c.why().contains("50-90 ms tie"), "{}", c.why());
        // Margins alike: the load.
        let c = choose(vec![
            score(50, 1.0, 8.0, 0.7),
            score(70, 1.0, 8.0, 0.9),
            score(90, 1.0, 8.0, 1.0),
        ])
        .unwrap();
        assert_eq!((c.offset_ms(), c.basis), (90, FrameBasis::Load));
        // Nothing tells them apart: the earliest, and it says so.
        let c = choose(vec![
            score(30, 0.9, 1.0, 0.4),
            score(50, 1.0, 8.0, 1.0),
            score(70, 1.0, 8.0, 1.0),
        ])
        .unwrap();
        assert_eq!((c.offset_ms(), c.basis), (70, FrameBasis::Earliest));
        assert!(c.why().contains("classify alike"), "{}", c.why());
        assert!(!c.to_string().contains("measured"));
        // Nothing measured: no choice.
        let mut s = score(70, 1.0, 8.0, 1.0);
        s.held_out = HeldOut::NONE;
        assert!(choose(vec![s]).is_none());
    }
}
