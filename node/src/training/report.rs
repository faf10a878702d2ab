//! What `presrs train` says of a model it trained: the unknown-ground choice, the calibration,
//! the bands and the split.

use crate::classifier::train::Split;

/// A model from [`TrainingSet::train_calibrated`](super::set::TrainingSet::train_calibrated).
pub struct Trained {
    /// The model.
    pub model: crate::classifier::Model,
    /// The footprint of the stances it was trained and calibrated on (`None`: none loaded).
    pub footprint: Option<super::footprint::Footprint>,
    /// The crop was given (`--crop T,B,L,R`), not measured.
    pub crop_given: bool,
    /// Whether the footprint's crop classified the held-out stances as well as none (an
    /// automatic crop of a loaded footprint).
    pub crop_check: Option<super::frame::CropCheck>,
    /// Which of the training images went where (indices into the images trained on).
    pub split: Split,
    /// Images trained on (the set less any run held out for calibration).
    pub train_images: usize,
    /// Calibration images not used: beyond `MAX_CALIBRATION_PER_CLASS` of a terrain.
    pub unused_calibration: usize,
    /// How the unknown-ground checks were chosen, and the table.
    pub choice: crate::training::choice::Choice,
    /// The images per terrain and session, as used.
    pub sessions: Vec<SessionCount>,
    /// How the deciding frame came to be.
    pub frame: super::frame::DecidingFrame,
}

/// One terrain's images of one session (a run of the capture manifest) and what they were
/// used for.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SessionCount {
    /// The terrain.
    pub terrain: String,
    /// The session (`None`: images without a manifest run).
    pub run: Option<String>,
    /// Its images.
    pub images: usize,
    /// `trained` or `calibration`.
    pub role: &'static str,
}

impl Trained {
    /// `presrs train`'s account, written to `out` in `took`: the images per terrain and
    /// session, the crop, how the unknown-ground checks were chosen (every candidate with
    /// `verbose`), how they were calibrated and what that could not measure, and the fit.
    pub fn report(
        &self,
        unknown_rate: f64,
        took: std::time::Duration,
        out: &str,
        verbose: bool,
    ) -> String {
        use std::fmt::Write;
        let (model, split) = (&self.model, &self.split);
        // Writing to a String cannot fail.
        let mut o = String::new();
        let _ = writeln!(o, "{}", self.sessions_line());
        let _ = writeln!(o, "{}", self.crop_line());
        let _ = match &self.frame {
            super::frame::DecidingFrame::Measured(f) => writeln!(o, "{f}"),
            f => writeln!(o, "{}", f.summary()),
        };
        if unknown_rate > 0.0 {
            let _ = write!(o, "{}", self.choice.report(verbose));
        }
        if self.unused_calibration > 0 {
            let _ = writeln!(
                o,
                "calibration session: {} of its images not used (its first {} per terrain calibrate)",
                self.unused_calibration,
                crate::classifier::train::MAX_CALIBRATION_PER_CLASS
            );
        }
        let _ = writeln!(o, "{}", self.calibration_line(unknown_rate));
        if let Some(bands) = &model.unknown.texture_bands {
            let each: Vec<String> = model
                .classes
                .iter()
                .zip(bands)
                .map(|(c, [lo, hi])| format!("{} {lo:.3}-{hi:.3}", c.name))
                .collect();
            let _ = writeln!(
                o,
                "texture check: an image whose roughness lies outside its terrain's band is \
                 unknown; bands over the images trained and calibrated on: {} (terrains whose \
                 bands overlap it cannot tell apart)",
                each.join(", ")
            );
        }
        if let Some(c) = model.unknown.novelty.as_ref().map(|nv| &nv.calibration)
            && c.source == crate::unknown::novelty::CalibrationSource::HeldOutRuns
            && c.training_run_images() == 0
        {
            let _ = writeln!(o, "{}", no_training_run_images_note());
        }
        let _ = writeln!(o, "{}", self.dims_line());
        let _ = writeln!(
            o,
            "trained on {} + {} images ({} classes), kernel width {:.4}, {:.1} ms; {} images \
             left for testing; wrote {out}",
            split.train.len(),
            split.validation.len(),
            model.classes.len(),
            model.kernel_width,
            took.as_secs_f64() * 1e3,
            split.test.len(),
        );
        o
    }

    /// `images per terrain and session: wood run1.log 60 trained, run2.log 60 calibration; ...`:
    /// what the capture manifest holds, as it was used.
    pub fn sessions_line(&self) -> String {
        let mut per: Vec<(&str, Vec<String>)> = Vec::new();
        for s in &self.sessions {
            let text = format!(
                "{} {} {}",
                s.run.as_deref().unwrap_or("(no manifest)"),
                s.images,
                s.role
            );
            match per.iter_mut().find(|(t, _)| *t == s.terrain) {
                Some((_, v)) => v.push(text),
                None => per.push((&s.terrain, vec![text])),
            }
        }
        let each: Vec<String> = per
            .into_iter()
            .map(|(t, v)| format!("{t}: {}", v.join(", ")))
            .collect();
        format!("images per terrain and session: {}", each.join("; "))
    }

    /// How the novelty thresholds were set, on how many images of which session, what the
    /// check calls of them; with one session, what it could not measure.
    fn calibration_line(&self, unknown_rate: f64) -> String {
        use crate::unknown::novelty::CalibrationSource;
        let Some(nv) = &self.model.unknown.novelty else {
            return if unknown_rate > 0.0 {
                "unknown terrain: no calibration image showed contact; the density rule decides"
                    .into()
            } else {
                "unknown terrain: rejection off (--unknown-rate 0)".into()
            };
        };
        let c = &nv.calibration;
        let images = match c.source {
            CalibrationSource::HeldOutRuns => {
                let held = c.held_out_images.min(c.images);
                let own = c.images.saturating_sub(held);
                let mut t = format!("{held} images of {}", c.runs.join(", "));
                if own > 0 {
                    t.push_str(&format!(" and {own} of the training session's unused ones"));
                }
                t
            }
            _ => format!("{} images", c.images),
        };
        let mut line = format!(
            "unknown terrain: thresholds from {} ({images}) at --unknown-rate {unknown_rate}: the \
             check calls {:.1}% of them unknown ({:.1}% were decided as the wrong known terrain)",
            c.source.describe(),
            100.0 * c.called_unknown,
            100.0 * c.misclassified,
        );
        if !nv.reference_classes.is_empty() {
            line.push_str(&format!(
                "; the held-out session's {} images classified right are the model's \
                 references for the next session (scored without them, the thresholds sit at \
                 its {:.3} quantile)",
                nv.reference_classes.len(),
                1.0 - c.rate
            ));
        }
        if c.source == CalibrationSource::TimeBlocks {
            line.push_str(&format!(
                ", times {:.2} (the margin `train` chose on the session's last quarter). One \
                 session measures how its stances scatter over its own time, not how far the \
                 next session (another day, another battery, a worn skin) lies from it: expect \
                 more than --unknown-rate of the next session's known ground unknown (on the \
                 project's sources, seeds 1-10, 0-9%; docs/decisions/unknown-one-session.md), \
                 and record a second session for thresholds measured on it",
                c.margin
            ));
        }
        line
    }

    /// `h = 12 PCA dimensions: ...`, with why that number.
    fn dims_line(&self) -> String {
        let m = &self.model;
        let stored = m.n_samples();
        let max_dims = self.choice.candidate.dims == crate::classifier::options::Dims::Max;
        if max_dims {
            format!(
                "h = {} PCA dimensions: the most the {stored} stored samples support (up to the \
                 paper's 52), kept because the choice found more left-out ground with them",
                m.h
            )
        } else {
            format!(
                "h = {} PCA dimensions: the number that classified the {} validation images best \
                 (the paper's section 4.2)",
                m.h,
                self.split.validation.len()
            )
        }
    }
}

impl Trained {
    /// Which crop the model has and why; a given crop that cuts loaded lines is a warning
    /// naming the share of the load it cuts.
    pub fn crop_line(&self) -> String {
        use super::footprint::LOADED_SHARE;
        let c = self.model.crop;
        let (rows, cols) = self.model.work_size().map_or((0, 0), |(r, col)| {
            (r * self.model.downsample, col * self.model.downsample)
        });
        match (&self.footprint, self.crop_given) {
            (Some(f), false) => format!(
                "crop {c} ({rows}x{cols} kept): the footprint's, the rows and columns that carry \
                 at least {:.2}% of the load over the {} stances at the deciding frame{} (give \
                 --crop T,B,L,R to set it)",
                100.0 * LOADED_SHARE,
                f.stances,
                self.crop_check
                    .map_or(String::new(), |k| format!("; {}", k.why()))
            ),
            (Some(f), true) => match f.cut_by(&c) {
                (share, loaded) if loaded > 0 => format!(
                    "warning: crop {c} as given cuts {loaded} loaded rows or columns ({:.1}% of \
                     the stances' load); the footprint's own crop is {} (drop --crop to use it)",
                    100.0 * share,
                    f.crop()
                ),
                _ => format!("crop {c} as given (it cuts no loaded row or column)"),
            },
            (None, _) => format!("crop {c}: no stance carried load to measure a footprint on"),
        }
    }
}

/// What `presrs train` adds when a calibration on held-out runs holds none of the training
/// run's images (fewer than `MIN_SAME_RUN_PER_CLASS` per terrain were left out of the model):
/// the calibration's own check then says less than the next run will do. Measured: see
/// `crate::unknown::novelty`, "How many images to store".
pub fn no_training_run_images_note() -> String {
    format!(
        "unknown terrain: the calibration holds none of the training run's images (fewer than \
         {} per terrain were left out of the model by --per-class), only the held-out run's, \
         and its check understates the next run: on the real SpeedPP2D maps (presrs lab experiment \
         open-set --per-class 30 --train 20, seeds 1-10) the next run's known images were \
         called unknown 5.9% (median; 5.1-6.4%) against 2.4% (1.9-3.6%) at the default \
         --per-class 20, which leaves 10 of each person's 30 out. Draw fewer images per terrain \
         than the training run holds, or expect more unknowns than --unknown-rate on the next \
         run.",
        crate::classifier::train::MIN_SAME_RUN_PER_CLASS
    )
}
