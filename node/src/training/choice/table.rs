//! What the choice found: each candidate's outcome, the one kept, and the table `train` prints.

use super::{CHECK_COST, Candidate, ChoiceRecord, fmt};

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
    /// The plain nearest neighbour's AUROC on the same judged images (the distance in the
    /// plain model's PCA space to the nearest stored sample): the scale the candidates' figures
    /// are read against; `None` when nothing was measured.
    pub nn_auroc: Option<f64>,
    /// Why the energy check was not weighed (`None`: it was, or nothing was measured).
    pub energy_note: Option<String>,
    /// What the energy check finds on its own, where it was weighed.
    pub energy_alone: Option<EnergyAlone>,
}

/// The energy check on its own over the folds: each stance's flights held against the map of
/// the class its texture gave it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EnergyAlone {
    /// The share of the left-out terrains' stances it calls unknown (mean over the folds).
    pub found: f64,
    /// Known stances judged, and of them called unknown.
    pub known: [usize; 2],
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
                .map(|o| {
                    let f = |v: f64| v.is_finite().then_some(v);
                    (
                        o.candidate.to_string(),
                        f(o.auroc),
                        f(o.found),
                        f(o.known_unknown),
                    )
                })
                .collect(),
        }
    }
}

impl Choice {
    /// The candidate with at most one part changed from [`Candidate::PLAIN`] (its margin
    /// aside) that scores the largest AUROC: what a user who sets one flag gets at best.
    pub fn best_single_option(&self) -> Option<usize> {
        let changed = |c: &Candidate| {
            let p = Candidate::PLAIN;
            (c.score != p.score) as usize
                + (c.normalize_load != p.normalize_load) as usize
                + (c.dims != p.dims) as usize
                + c.extra_checks()
        };
        (0..self.outcomes.len())
            .filter(|&i| {
                changed(&self.outcomes[i].candidate) <= 1 && self.outcomes[i].auroc.is_finite()
            })
            .max_by(|&a, &b| self.outcomes[a].auroc.total_cmp(&self.outcomes[b].auroc))
    }

    /// The choice as `train` prints it: how it was judged, the kept candidate, the best single
    /// option and the plain nearest neighbour; with `verbose`, every candidate's row.
    pub fn report(&self, verbose: bool) -> String {
        Report {
            choice: self,
            verbose,
        }
        .to_string()
    }
}

/// [`Choice::report`]'s text.
struct Report<'a> {
    choice: &'a Choice,
    verbose: bool,
}

/// The same as [`Choice::report`] with every row.
impl fmt::Display for Choice {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.report(true))
    }
}

impl fmt::Display for Report<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let c = self.choice;
        c.header(f)?;
        // As wide as the longest candidate's name, so the columns line up.
        let w = c
            .outcomes
            .iter()
            .map(|o| o.candidate.to_string().len())
            .fold(50, usize::max);
        let row = |f: &mut fmt::Formatter<'_>, mark: &str, o: &Outcome, note: &str| {
            writeln!(
                f,
                "{mark} {:<w$} {:>6} {:>9} {:>13}{note}",
                o.candidate.to_string(),
                num(o.auroc, 3, ""),
                num(100.0 * o.found, 1, "%"),
                num(100.0 * o.known_unknown, 1, "%"),
            )
        };
        writeln!(
            f,
            "  {:<w$} {:>6} {:>10} {:>14}",
            "candidate (--unknown-checks)", "AUROC", "left out", "known unknown"
        )?;
        writeln!(
            f,
            "  (AUROC: how well the score ranks new ground above known, 1 = always; left out: \
             the share of the left-out terrain called unknown; known unknown: the share of \
             known images called unknown)"
        )?;
        let single = c.best_single_option();
        for (i, o) in c.outcomes.iter().enumerate() {
            let kept = Some(i) == c.chosen;
            if self.verbose {
                row(f, if kept { "*" } else { " " }, o, "")?;
            } else if kept {
                row(f, "*", o, "  (kept)")?;
            } else if Some(i) == single {
                row(f, " ", o, "  (the best single option)")?;
            }
        }
        if let Some(why) = &c.energy_note {
            writeln!(f, "  energy check: not weighed: {why}")?;
        } else if let Some(e) = c.energy_alone {
            writeln!(
                f,
                "  energy check on its own: {} of the left-out ground, {}/{} known stances \
                 unknown{}",
                num(100.0 * e.found, 1, "%"),
                e.known[1],
                e.known[0],
                if c.candidate.energy {
                    ": kept beside the image checks (what it finds, they miss)"
                } else {
                    ""
                }
            )?;
        }
        if let Some(nn) = c.nn_auroc.filter(|v| v.is_finite()) {
            writeln!(
                f,
                "  {:<w$} {nn:>6.3}  (the plain nearest neighbour's distance, for scale)",
                "nearest neighbour"
            )?;
        }
        if !self.verbose && c.outcomes.len() > 2 {
            writeln!(
                f,
                "  ({} more candidates measured: `presrs train --verbose` lists them)",
                c.outcomes.len() - 1 - usize::from(single.is_some() && single != c.chosen)
            )?;
        }
        c.kept_line(f)
    }
}

/// `v` with `digits` decimals and `unit`, or `n/a` for a figure nothing measured.
fn num(v: f64, digits: usize, unit: &str) -> String {
    if v.is_finite() {
        format!("{v:.digits$}{unit}")
    } else {
        "n/a".into()
    }
}

impl Choice {
    /// How the choice was judged (or why nothing was measured), and thin terrains.
    fn header(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
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
                    "the session's last quarter, by a model of the rest (one session only: how \
                     far the next session lies from this one is not measured, nor are the load \
                     and texture bands, which stay off; record a second session and pass it \
                     with --calibrate, or capture two)"
                }
            }
        )
    }

    /// The kept candidate and why, or that nothing met the budget.
    fn kept_line(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.why.is_some() {
            return Ok(());
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
                    "kept * ({}): of those finding nearly the most left-out ground (an extra \
                     check must find {:.0} points more to be worth it), the fewest known images \
                     unknown, at most {:.1}%; per terrain left out: {}",
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
