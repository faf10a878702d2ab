//! What `presrs train` says of a model it trained: the unknown-ground choice, the calibration,
//! the bands and the split.

use crate::classifier::train::Split;

/// A model from [`TrainingSet::train_calibrated`](super::set::TrainingSet::train_calibrated).
pub struct Trained {
    /// The model.
    pub model: crate::classifier::Model,
    /// Which of the training images went where (indices into the images trained on).
    pub split: Split,
    /// Images trained on (the set less any run held out for calibration).
    pub train_images: usize,
    /// Calibration images not used: beyond `MAX_CALIBRATION_PER_CLASS` of a terrain.
    pub unused_calibration: usize,
    /// How the unknown-ground checks were chosen, and the table.
    pub choice: crate::training::choice::Choice,
}

impl Trained {
    /// `presrs train`'s account: unused calibration images, how the unknown-terrain check was
    /// calibrated (or why there is none: `unknown_rate` as asked), and what was trained, in
    /// `took`, written to `out`.
    pub fn report(&self, unknown_rate: f64, took: std::time::Duration, out: &str) -> String {
        use std::fmt::Write;
        let (model, split) = (&self.model, &self.split);
        let mut o = String::new();
        // Writing to a String cannot fail.
        if unknown_rate > 0.0 {
            let _ = write!(o, "{}", self.choice);
        }
        if self.unused_calibration > 0 {
            let _ = writeln!(
                o,
                "calibration run: {} images not used (at most {} per terrain, the first ones)",
                self.unused_calibration,
                crate::classifier::train::MAX_CALIBRATION_PER_CLASS
            );
        }
        let _ = match &model.novelty {
            Some(nv) => {
                let c = &nv.calibration;
                writeln!(
                    o,
                    "unknown terrain: calibrated on {} ({} images{}) to --unknown-rate {}{}: \
                     the check calls {:.1}% of them unknown ({:.1}% were taken for another \
                     terrain){}",
                    c.source.describe(),
                    c.images,
                    if c.runs.is_empty() {
                        String::new()
                    } else {
                        format!(" of {}", c.runs.join(", "))
                    },
                    unknown_rate,
                    if nv.reference_classes.is_empty() {
                        String::new()
                    } else {
                        format!(
                            " (the held-out run's {} images classified right are now the \
                             model's references for the next run; scored without them, the \
                             calibration set its thresholds at {:.3})",
                            nv.reference_classes.len(),
                            c.rate
                        )
                    },
                    100.0 * c.called_unknown,
                    100.0 * c.misclassified,
                    if c.margin > 1.0 {
                        format!(
                            " before the margin (x{}); with one run only, calibrate on a second \
                             one (--calibrate DIR) for thresholds that fit the robot's next run",
                            c.margin
                        )
                    } else {
                        String::new()
                    }
                )
            }
            None if unknown_rate > 0.0 => writeln!(
                o,
                "unknown terrain: no calibration image showed contact; the density rule decides"
            ),
            None => writeln!(o, "unknown terrain: rejection off (--unknown-rate 0)"),
        };
        if let Some(bands) = &model.texture_ranges {
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
        if let Some(c) = model.novelty.as_ref().map(|nv| &nv.calibration)
            && c.source == crate::unknown::novelty::CalibrationSource::HeldOutRuns
            && c.training_run_images() == 0
        {
            let _ = writeln!(o, "{}", no_training_run_images_note());
        }
        let _ = writeln!(
            o,
            "trained on {} + {} images ({} classes), h = {}, kernel width {:.4}, {:.1} ms; {} \
             images left for testing; wrote {out}",
            split.train.len(),
            split.validation.len(),
            model.classes.len(),
            model.h,
            model.kernel_width,
            took.as_secs_f64() * 1e3,
            split.test.len(),
        );
        o
    }
}

/// What `presrs train` adds when a calibration on held-out runs holds none of the training
/// run's images (fewer than `MIN_SAME_RUN_PER_CLASS` per terrain were left out of the model):
/// the calibration's own check then says less than the next run will do. Measured: see
/// `crate::classifier::novelty`, "How many images to store".
pub fn no_training_run_images_note() -> String {
    format!(
        "unknown terrain: the calibration holds none of the training run's images (fewer than \
         {} per terrain were left out of the model by --per-class), only the held-out run's, \
         and its check understates the next run: on the real SpeedPP2D maps (presrs experiment \
         open-set --per-class 30 --train 20, seeds 1-10) the next run's known images were \
         called unknown 5.9% (median; 5.1-6.4%) against 2.4% (1.9-3.6%) at the default \
         --per-class 20, which leaves 10 of each person's 30 out. Draw fewer images per terrain \
         than the training run holds, or expect more unknowns than --unknown-rate on the next \
         run.",
        crate::classifier::train::MIN_SAME_RUN_PER_CLASS
    )
}
