//! What the choice found: each candidate's outcome, the one kept, and the table `train` prints.

use super::*;

/// What one candidate measured, over every terrain left out.
#[derive(Clone, Debug, PartialEq)]
pub struct Outcome {
    /// The candidate.
    pub candidate: Candidate,
    /// The novelty score's AUROC, new ground against known, mean over the left-out terrains.
    pub auroc: f64,
    /// The share of the left-out terrain's images called unknown, mean over the terrains.
    pub found: f64,
    /// Per left-out terrain (in the model's class order), its share.
    pub found_per_class: Vec<f64>,
    /// The share of the judged known images called unknown, pooled.
    pub known_unknown: f64,
    /// The judged known images, pooled over the left-out terrains (the share's count).
    pub known_judged: usize,
}

/// Which images were judged as known ground.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum JudgedOn {
    /// Half of the calibration run (the other half calibrated).
    CalibrationRun,
    /// The training run's images the models do not store: the same recording, so its figure
    /// says less of the robot's next run.
    TrainingRun,
}

/// `train`'s choice and the table it chose from.
#[derive(Clone, Debug)]
pub struct Choice {
    /// Every candidate measured, in the grid's order.
    pub outcomes: Vec<Outcome>,
    /// Index of the kept one in `outcomes`; `None` when nothing could be measured (see `why`).
    pub chosen: Option<usize>,
    /// The candidate the model is trained with.
    pub candidate: Candidate,
    /// The known-image budget the choice was held to.
    pub budget: f64,
    /// Which images were judged as known ground.
    pub judged_on: JudgedOn,
    /// Why no candidate was measured, when none was.
    pub why: Option<String>,
    /// The terrains, in `found_per_class`'s order.
    pub classes: Vec<String>,
    /// Terrains of the model with fewer than [`MIN_CALIBRATION_IMAGES`] images in the
    /// calibration run (with their count): too few to judge them as known ground, said by name.
    pub thin: Vec<(String, usize)>,
}

/// Fewest images of a terrain in the calibration run for the choice to judge it as known ground
/// (half of them calibrate, half are judged).
pub const MIN_CALIBRATION_IMAGES: usize = 6;

impl Choice {
    /// The record a model keeps.
    pub fn record(&self) -> ChoiceRecord {
        ChoiceRecord {
            chosen: self.candidate.to_string(),
            how: match (&self.why, self.judged_on) {
                (Some(w), _) => w.clone(),
                (None, JudgedOn::CalibrationRun) => {
                    "measured: each terrain left out, judged on half the calibration run".into()
                }
                (None, JudgedOn::TrainingRun) => {
                    "measured: each terrain left out, judged on the training run's unused images"
                        .into()
                }
            },
            budget: self.budget,
            table: self
                .outcomes
                .iter()
                .map(|o| (o.candidate.to_string(), o.auroc, o.found, o.known_unknown))
                .collect(),
        }
    }
}

/// The table `train` prints: each candidate's figures, the kept one marked, and how it was
/// judged.
impl fmt::Display for Choice {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if let Some(why) = &self.why {
            return writeln!(f, "unknown-ground checks: {} ({why})", self.candidate);
        }
        if !self.thin.is_empty() {
            let each: Vec<String> = self
                .thin
                .iter()
                .map(|(name, n)| format!("{name} ({n})"))
                .collect();
            writeln!(
                f,
                "calibration run: too few images of {} to judge as known ground (at least {} \
                 each): the known figures below rest on a handful of them; capture more",
                each.join(", "),
                MIN_CALIBRATION_IMAGES
            )?;
        }
        writeln!(
            f,
            "unknown-ground checks, each of {} terrains left out in turn as new ground; known \
             ground judged on {}:",
            self.classes.len(),
            match self.judged_on {
                JudgedOn::CalibrationRun =>
                    "half of the calibration run (the other half calibrated)",
                JudgedOn::TrainingRun => {
                    "the training run's unused images (one run only: the next run will scatter \
                     more, and the load and texture bands, which one run cannot test, stay off; \
                     record a second run and pass it with --calibrate, or capture two runs)"
                }
            }
        )?;
        writeln!(
            f,
            "  {:<50} {:>6} {:>10} {:>14}",
            "candidate (--unknown-checks)", "AUROC", "left out", "known unknown"
        )?;
        for (i, o) in self.outcomes.iter().enumerate() {
            let mark = if Some(i) == self.chosen { "*" } else { " " };
            writeln!(
                f,
                "{mark} {:<50} {:>6.3} {:>9.1}% {:>13.1}%",
                o.candidate.to_string(),
                o.auroc,
                100.0 * o.found,
                100.0 * o.known_unknown
            )?;
        }
        if let Some(o) = self.chosen.map(|i| &self.outcomes[i]) {
            let per: Vec<String> = self
                .classes
                .iter()
                .zip(&o.found_per_class)
                .map(|(c, v)| format!("{c} {:.0}%", 100.0 * v))
                .collect();
            if o.known_unknown <= self.budget + 1e-12 {
                writeln!(
                    f,
                    "kept * ({}): of those finding nearly the most left-out ground (each check \
                     counted {:.0} points less), the fewest known images unknown, at most \
                     {:.1}%; per terrain left out: {}",
                    self.candidate,
                    100.0 * CHECK_COST,
                    100.0 * self.budget,
                    per.join(", ")
                )?;
            } else {
                // Said plainly: the lab's next run will send the robot to the safe gait often.
                writeln!(
                    f,
                    "kept * ({}): no candidate calls at most {:.1}% of the known images unknown; \
                     of the cheapest this one weighs best ({:.1}%). Expect that share of known \
                     steps in the \
                     safe gait: capture a longer calibration run (more stances per terrain, in \
                     every gait), or raise --unknown-rate; per terrain left out: {}",
                    self.candidate,
                    100.0 * self.budget,
                    100.0 * o.known_unknown,
                    per.join(", ")
                )?;
            }
        }
        Ok(())
    }
}
