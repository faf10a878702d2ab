//! `presrs train`'s short account: what was written, what was chosen for this foot and its
//! data, and every warning, in a few lines. The whole account, every candidate and every
//! reason, is [`Trained::report`] (`train --verbose`).
//!
//! A line here is either a choice (crop, PCA dimensions, deciding frame, unknown-ground
//! checks, calibration) with the one number it was chosen by, or a warning the lab must act
//! on (a crop that cuts load, a check that calls too much known ground unknown, one session
//! only, thin calibration terrains). Nothing is said here that the long account does not say.

use std::fmt::Write;

use super::report::Trained;
use crate::unknown::novelty::CalibrationSource;

/// A left-out terrain the kept checks find less than this share of is named in the summary:
/// new ground like it will mostly be taken for known ground.
const WEAK_FOUND: f64 = 0.5;

/// A calibration run taken for another known terrain more often than this is warned about:
/// on the robot most of those steps come out unknown or wrong, beyond what the checks count.
const WRONG_TERRAIN_WARN: f64 = 0.10;

impl Trained {
    /// The short account of a model written to `out` in `took`; see the module docs.
    pub fn summary(&self, unknown_rate: f64, took: std::time::Duration, out: &str) -> String {
        // Writing to a String cannot fail.
        let mut o = String::new();
        let (m, split) = (&self.model, &self.split);
        let names: Vec<&str> = m.classes.iter().map(|c| c.name.as_str()).collect();
        let (fit, width, k) = (
            split.train.len(),
            split.validation.len(),
            names.len().max(1),
        );
        // Per terrain when the draw was even (the paper's 13 + 7), else the totals alone.
        let each = match fit % k == 0 && width % k == 0 {
            true => {
                let (f, w) = (fit / k, width / k);
                format!(
                    " ({f} + {w} per terrain: `--per-class {}`, `--train {f}`)",
                    f + w
                )
            }
            false => String::new(),
        };
        let _ = writeln!(
            o,
            "wrote {out}: {} terrains ({}), fitted on {fit} images and its kernel width chosen \
             on {width}{each} of the training run's {}, in {:.1} s",
            names.len(),
            names.join(", "),
            self.train_images,
            took.as_secs_f64()
        );
        let _ = writeln!(o, "{}", self.settings_line());
        if unknown_rate > 0.0 {
            let _ = writeln!(o, "{}", self.unknown_line());
        }
        let _ = writeln!(o, "{}", self.calibration_short(unknown_rate));
        let _ = writeln!(o, "{}", self.confidence_line());
        for w in self.warnings() {
            let _ = writeln!(o, "{w}");
        }
        let _ = writeln!(
            o,
            "next: `presrs eval --model {out} --data DIR` on a capture it was not trained on, \
             `presrs node --replay LOG --model {out}` on a run; `train --verbose`: every \
             candidate measured and why each was chosen"
        );
        o
    }

    /// What a decision's confidence means: the reliability table it was measured on.
    pub fn confidence_line(&self) -> String {
        let Some(c) = &self.model.confidence else {
            return "confidence: the Parzen posterior (no calibration run to measure the chance \
                    of being right on: capture a second session)"
                .into();
        };
        let bands: Vec<String> = c
            .reliability
            .iter()
            .filter(|b| b.n > 0)
            .map(|b| {
                format!(
                    "{:.0}-{:.0}%: {} of {} right",
                    100.0 * b.lo,
                    100.0 * b.hi,
                    b.right,
                    b.n
                )
            })
            .collect();
        format!(
            "confidence: the measured chance of being right, from {} decisions of models that \
             left each terrain out in turn ({} right; new ground taken for known counted \
             wrong); reliability: {}",
            c.judged,
            c.right,
            bands.join(", ")
        )
    }

    /// `crop 0,3,6,0 (measured) · h = 12 PCA dimensions · deciding frame 120 ms (measured)`.
    fn settings_line(&self) -> String {
        let m = &self.model;
        let crop = match (&self.footprint, self.crop_given, &self.crop_check) {
            (_, true, _) => format!("crop {} (as given)", m.crop),
            (Some(_), false, Some(k)) if !k.kept => format!(
                "no crop (the footprint's {} classified held-out stances worse: {:.1}% against \
                 {:.1}% right)",
                k.footprint,
                100.0 * k.cut.accuracy,
                100.0 * k.none.accuracy
            ),
            (Some(_), false, _) => format!(
                "crop {} (the footprint's at the deciding frame; held-out stances no worse than \
                 with none)",
                m.crop
            ),
            (None, false, _) => format!("crop {} (no stance carried load to measure)", m.crop),
        };
        let frame = self.frame.summary();
        format!("{crop}; h = {} PCA dimensions; {frame}", m.h)
    }

    /// The kept unknown-ground checks and what they found on the left-out terrains.
    fn unknown_line(&self) -> String {
        let c = &self.choice;
        let Some(o) = c.chosen.map(|i| &c.outcomes[i]) else {
            return format!(
                "unknown ground: {} ({})",
                c.candidate,
                c.why.as_deref().unwrap_or("not measured")
            );
        };
        let weak: Vec<String> = c
            .classes
            .iter()
            .zip(&o.found_per_class)
            .filter(|(_, v)| **v < WEAK_FOUND)
            .map(|(t, v)| format!("{t} {:.0}%", 100.0 * v))
            .collect();
        let weak = match weak.is_empty() {
            true => String::new(),
            false => format!(" (least: {})", weak.join(", ")),
        };
        format!(
            "unknown ground: {}; with each terrain left out in turn, it finds {:.0}% of it{weak} \
             and calls {:.1}% of the calibration run's known ground unknown (a next session \
             calls more: `node --replay LOG --truth CSV` measures it)",
            c.candidate,
            100.0 * o.found,
            100.0 * o.known_unknown
        )
    }

    /// Where the thresholds come from, in one clause; with one session, what to do about it.
    fn calibration_short(&self, unknown_rate: f64) -> String {
        let Some(nv) = &self.model.unknown.novelty else {
            return match unknown_rate > 0.0 {
                true => "unknown ground: no calibration image showed contact".into(),
                false => "unknown ground: rejection off (--unknown-rate 0)".into(),
            };
        };
        let c = &nv.calibration;
        let n = c.images;
        let from = match c.source {
            CalibrationSource::HeldOutRuns => {
                let held = c.held_out_images.min(n);
                format!(
                    "held-out runs ({}: {held} images; and {} of the training run's unused)",
                    c.runs.join(", "),
                    n - held
                )
            }
            CalibrationSource::SameRun => format!("the training run's unused images, {n}"),
            CalibrationSource::LeaveOneOut => format!("the stored samples, leave-one-out, {n}"),
            CalibrationSource::TimeBlocks => {
                format!("this one session, in time blocks, {n} images")
            }
        };
        let mut line = format!("thresholds at --unknown-rate {unknown_rate} from {from}");
        if c.margin != 1.0 || c.source == CalibrationSource::TimeBlocks {
            line.push_str(&format!(", margin {:.2}", c.margin));
        }
        if c.source == CalibrationSource::TimeBlocks {
            line.push_str(
                ": one session cannot measure the next; expect more of the next session's known \
                 ground unknown, and record a second session (--calibrate DIR, or capture two)",
            );
        }
        line
    }

    /// What the lab must act on, one line each.
    fn warnings(&self) -> Vec<String> {
        let mut w = Vec::new();
        if let (Some(f), true) = (&self.footprint, self.crop_given)
            && f.cut_by(&self.model.crop).1 > 0
        {
            w.push(self.crop_line());
        }
        let c = &self.choice;
        // The calibration on a held-out run, which the checks below judge.
        let held_out = (self.model.unknown.novelty.as_ref())
            .map(|nv| &nv.calibration)
            .filter(|cal| cal.source == CalibrationSource::HeldOutRuns);
        if let Some(o) = c.chosen.map(|i| &c.outcomes[i])
            && o.known_unknown > c.budget + 1e-12
        {
            w.push(format!(
                "warning: the kept checks call {:.1}% of known ground unknown (at most {:.1}% \
                 wanted): expect that share of known steps in the safe gait; capture a longer \
                 calibration run, or raise --unknown-rate",
                100.0 * o.known_unknown,
                100.0 * c.budget
            ));
        }
        if let Some(cal) = held_out
            && cal.misclassified > WRONG_TERRAIN_WARN
        {
            w.push(format!(
                "warning: the model took {:.0}% of its calibration images ({} and the training \
                 run's unused) for another known terrain (h = {} PCA dimensions, chosen on {} \
                 validation images): on the robot most of those steps come out unknown (the safe \
                 gait) or wrong, beyond the share above. `presrs node --replay LOG --model MODEL --truth CSV` on the next run \
                 counts them; a larger draw (`--per-class 40` where a session holds 60 stances \
                 of each terrain) chooses both on more images: docs/decisions/train-draw.md",
                100.0 * cal.misclassified,
                cal.runs.join(", "),
                self.model.h,
                self.split.validation.len()
            ));
        }
        if !c.thin.is_empty() {
            let each: Vec<String> = c.thin.iter().map(|(t, n)| format!("{t} ({n})")).collect();
            w.push(format!(
                "warning: too few calibration images of {} to judge them as known ground; \
                 capture more",
                each.join(", ")
            ));
        }
        if let Some(cal) = held_out
            && cal.training_run_images() == 0
        {
            w.push(
                "warning: the calibration holds none of the training run's images: expect more \
                 unknowns than --unknown-rate on the next run (draw fewer --per-class)"
                    .into(),
            );
        }
        w
    }
}
