//! Scoring of closed-loop runs, one implementation for every report: per-step accuracy, steps
//! from a terrain change to its gait, and speed per terrain and gait. The confusion matrix and
//! a model judged on a dataset are `tools::eval`'s, which needs no simulator.

use std::collections::BTreeMap;

use sim::service::StepRecord;

/// A closed-loop run in the numbers the paper reports.
#[derive(Clone, Debug, PartialEq)]
pub struct Summary {
    /// Steps decided.
    pub steps: usize,
    /// Steps whose reported terrain was the true one.
    pub correct: usize,
    /// `correct / steps` (0 for no steps).
    pub accuracy: f64,
    /// Steps whose gait differs from the step before.
    pub switches: usize,
    /// For each terrain change whose terrain's gait was reached before the next change: steps
    /// from the change to the first step in that gait. Terrains without a gait in the table,
    /// and changes the run ended before resolving, are not counted.
    pub steps_to_switch: Vec<usize>,
    /// Mean speed (m/s) and steps, per (terrain, gait).
    pub speeds: BTreeMap<(String, u8), (f64, usize)>,
    /// Terrains on the track the model was not trained on (see [`Summary::with_unknown`]).
    pub unknown_terrains: BTreeMap<String, UnknownTerrain>,
}

/// What `presrs demo` reports of one closed-loop run: its [`Summary`] with the falls, the
/// track, and the leg through motors when there was one.
#[derive(Clone, Debug)]
pub struct DemoReport {
    /// The steps scored.
    pub summary: Summary,
    /// Falls in the run.
    pub falls: u64,
    /// The simulator, node and controller ran on the wall clock (`--realtime`).
    pub realtime: bool,
    /// The track's length, m.
    pub track_m: f64,
    /// The controller's safe gait (for unknown terrain).
    pub safe_gait: u8,
    /// The step log written (`--csv`), if one was asked for.
    pub csv: Option<String>,
    /// The leg through motors (`--leg`): its protocol, the bridge's LegState against the truth
    /// and the bridge's counters.
    pub leg: Option<(String, sim::service::LegStateCheck, leg::LegCounters)>,
}

impl DemoReport {
    /// `presrs demo --json`'s object.
    pub fn to_json(&self) -> serde_json::Value {
        let sum = &self.summary;
        let table: Vec<serde_json::Value> = sum
            .speeds
            .iter()
            .map(|((t, g), (v, k))| serde_json::json!({"terrain": t, "gait": g, "mean_speed_m_s": v, "steps": k}))
            .collect();
        serde_json::json!({
            "steps": sum.steps,
            "accuracy": sum.accuracy,
            "switches": sum.switches,
            "steps_to_switch": sum.steps_to_switch,
            "steps_to_switch_max": sum.max_steps_to_switch(),
            "falls": self.falls,
            "realtime": self.realtime,
            "speed_per_terrain_and_gait": table,
            "track_m": self.track_m,
            "unknown_terrains": sum.unknown_terrains.iter().map(|(t, u)| serde_json::json!({
                "terrain": t, "steps": u.steps, "called_unknown": u.called_unknown,
                "steps_to_safe_gait": u.steps_to_safe_gait,
            })).collect::<Vec<_>>(),
            "csv": self.csv,
            "leg": self.leg.as_ref().map(|(protocol, state, counters)| serde_json::json!({
                "protocol": protocol,
                "leg_state": state,
                "bridge": counters,
            })),
        })
    }
}

impl std::fmt::Display for DemoReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let sum = &self.summary;
        let n = sum.steps;
        writeln!(
            f,
            "\nsummary: {n} steps, per-step accuracy {:.1}% ({}/{n}), {} gait switches",
            sum.accuracy * 100.0,
            sum.correct,
            sum.switches
        )?;
        writeln!(
            f,
            "steps from a terrain change to its gait: {:?} (max {})",
            sum.steps_to_switch,
            sum.max_steps_to_switch()
        )?;
        writeln!(f, "falls: {}", self.falls)?;
        if let Some((protocol, st, c)) = &self.leg {
            writeln!(
                f,
                "leg through {protocol} motors: {} LegState from the encoders ({} at their own timestamp); error against the truth, median / 95th percentile / largest: angle {:.4} / {:.4} / {:.4} rad, length {:.2} / {:.2} / {:.2} mm; {} LegCommands, {} clamped, {} malformed replies",
                st.frames,
                st.at_timestamp,
                st.angle_err_rad[0],
                st.angle_err_rad[1],
                st.angle_err_rad[2],
                st.length_err_m[0] * 1e3,
                st.length_err_m[1] * 1e3,
                st.length_err_m[2] * 1e3,
                c.commands,
                c.clamped,
                c.malformed_replies
            )?;
        }
        for (t, u) in &sum.unknown_terrains {
            // An entry the run ended on may have been too short to switch: said so, not
            // "never".
            let to_safe: Vec<String> = (u.steps_to_safe_gait.iter().zip(&u.entries))
                .map(|(d, &(len, ended))| match (d, ended) {
                    (Some(d), _) => d.to_string(),
                    (None, true) => format!("not yet: the run ended {len} steps on"),
                    (None, false) => format!("never: left after {len} steps"),
                })
                .collect();
            writeln!(
                f,
                "terrain the model does not know: {t}: {}/{} steps called unknown; safe gait G{} reached after [{}] steps on each entry",
                u.called_unknown,
                u.steps,
                self.safe_gait,
                to_safe.join(", ")
            )?;
        }
        writeln!(f, "mean speed (m/s) per terrain and gait:")?;
        for ((t, g), (v, k)) in &sum.speeds {
            writeln!(f, "  {t:<8} G{g}: {v:.2} ({k} steps)")?;
        }
        match &self.csv {
            Some(c) => writeln!(f, "step log: {c}"),
            None => Ok(()),
        }
    }
}

/// How the loop met a terrain its model does not know.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct UnknownTerrain {
    /// Steps on it.
    pub steps: usize,
    /// Of those, steps the node called unknown (the right answer).
    pub called_unknown: usize,
    /// For each time the hopper came onto it: steps until the first step in the safe gait
    /// (`None`: not reached before it left).
    pub steps_to_safe_gait: Vec<Option<usize>>,
    /// For each time the hopper came onto it: its steps there, and whether the run ended on it.
    pub entries: Vec<(usize, bool)>,
}

impl Summary {
    /// Scores `rows` against `terrain_gaits` (the controller's table: terrain name -> gait).
    pub fn of(rows: &[StepRecord], terrain_gaits: &BTreeMap<String, u8>) -> Self {
        let n = rows.len();
        let correct = rows.iter().filter(|r| r.is_correct()).count();
        let switches = rows.windows(2).filter(|w| w[0].gait != w[1].gait).count();
        let mut steps_to_switch = Vec::new();
        for i in 1..n {
            if rows[i].truth == rows[i - 1].truth {
                continue;
            }
            let Some(&want) = terrain_gaits.get(&rows[i].truth) else {
                continue;
            };
            let reached = rows[i..]
                .iter()
                .take_while(|r| r.truth == rows[i].truth)
                .position(|r| r.gait == want);
            if let Some(d) = reached {
                steps_to_switch.push(d);
            }
        }
        let mut sums: BTreeMap<(String, u8), (f64, usize)> = BTreeMap::new();
        for r in rows {
            let e = sums.entry((r.truth.clone(), r.gait)).or_insert((0.0, 0));
            e.0 += r.speed_m_s;
            e.1 += 1;
        }
        let speeds = sums
            .into_iter()
            .map(|(key, (s, k))| (key, (s / k as f64, k)))
            .collect();
        Self {
            steps: n,
            correct,
            accuracy: if n > 0 {
                correct as f64 / n as f64
            } else {
                0.0
            },
            switches,
            steps_to_switch,
            speeds,
            unknown_terrains: BTreeMap::new(),
        }
    }

    /// Scores the steps on terrains outside `known` (the model's classes): "unknown" is the
    /// right answer there (counted in `correct` and `accuracy`), and the loop should reach
    /// `safe_gait` on them.
    pub fn with_unknown(mut self, rows: &[StepRecord], known: &[String], safe_gait: u8) -> Self {
        for (i, r) in rows.iter().enumerate() {
            if known.contains(&r.truth) {
                continue;
            }
            let u = self.unknown_terrains.entry(r.truth.clone()).or_default();
            u.steps += 1;
            if r.classified == "unknown" {
                u.called_unknown += 1;
                self.correct += 1;
            }
            if i == 0 || rows[i - 1].truth != r.truth {
                let on = || rows[i..].iter().take_while(|x| x.truth == r.truth);
                u.steps_to_safe_gait
                    .push(on().position(|x| x.gait == safe_gait));
                let len = on().count();
                u.entries.push((len, i + len == rows.len()));
            }
        }
        if self.steps > 0 {
            self.accuracy = self.correct as f64 / self.steps as f64;
        }
        self
    }

    /// The largest of [`Summary::steps_to_switch`] (0 when none).
    pub fn max_steps_to_switch(&self) -> usize {
        self.steps_to_switch.iter().copied().max().unwrap_or(0)
    }
}

/// The CSV header of [`write_steps`]: one row per step the node decided.
pub const STEPS_CSV_HEADER: &str = "t_s,step,true_terrain,classified,confidence_pct,gait,speed_m_s";

/// Writes `rows` as CSV (`presrs demo --csv`): time (s), the node's step counter, the true
/// terrain, the one the node said, its confidence (%), the gait the leg ran and its speed (m/s).
pub fn write_steps(mut w: impl std::io::Write, rows: &[StepRecord]) -> std::io::Result<()> {
    writeln!(w, "{STEPS_CSV_HEADER}")?;
    for r in rows {
        // An unknown step has no confidence: the frame's is the rejected class's.
        let confidence = if r.classified == protocol::Terrain::UNKNOWN.name() {
            String::new()
        } else {
            format!("{:.1}", r.confidence_pct)
        };
        writeln!(
            w,
            "{:.3},{},{},{},{confidence},{},{:.3}",
            r.t_s, r.step, r.truth, r.classified, r.gait, r.speed_m_s
        )?;
    }
    w.flush()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(truth: &str, classified: &str, gait: u8, speed: f64) -> StepRecord {
        StepRecord {
            t_s: 0.0,
            foot: 0,
            step: 0,
            damage_pct: 0.0,
            truth: truth.into(),
            classified: classified.into(),
            confidence_pct: 100.0,
            gait,
            speed_m_s: speed,
        }
    }

    #[test]
    fn steps_to_switch_counts_from_the_change_to_the_terrains_gait() {
        let table: BTreeMap<String, u8> =
            [("wood".into(), 3), ("clay".into(), 1), ("grass".into(), 2)].into();
        let rows = [
            row("wood", "wood", 3, 0.7),
            row("clay", "wood", 3, 0.4),
            row("clay", "clay", 3, 0.4),
            row("clay", "clay", 1, 0.3),
            row("grass", "grass", 1, 0.5),
            row("grass", "grass", 1, 0.5),
            // Ends before grass reached G2: not counted.
            row("sand", "unknown", 1, 0.2),
        ];
        let s = Summary::of(&rows, &table);
        assert_eq!(s.steps_to_switch, vec![2]);
        assert_eq!(s.max_steps_to_switch(), 2);
        assert_eq!((s.steps, s.correct, s.switches), (7, 5, 1));
        assert!((s.accuracy - 5.0 / 7.0).abs() < 1e-12);
        assert_eq!(s.speeds[&("clay".to_string(), 3)], (0.4, 2));
        assert_eq!(s.speeds[&("grass".to_string(), 1)], (0.5, 2));
    }

    #[test]
    fn unknown_is_the_right_answer_on_a_terrain_the_model_does_not_know() {
        let table: BTreeMap<String, u8> = [("wood".into(), 3)].into();
        let rows = [
            row("wood", "wood", 3, 0.7),
            row("sand", "wood", 3, 0.6),
            row("sand", "unknown", 3, 0.5),
            row("sand", "unknown", 1, 0.4),
            row("wood", "wood", 1, 0.4),
            row("sand", "wood", 3, 0.6),
        ];
        let s = Summary::of(&rows, &table).with_unknown(&rows, &["wood".into()], 1);
        assert_eq!((s.steps, s.correct), (6, 4));
        let u = &s.unknown_terrains["sand"];
        assert_eq!((u.steps, u.called_unknown), (4, 2));
        assert_eq!(u.steps_to_safe_gait, vec![Some(2), None]);
        assert_eq!(u.entries, vec![(3, false), (1, true)]);
    }

    #[test]
    fn a_change_already_in_its_gait_is_zero_steps() {
        let table: BTreeMap<String, u8> = [("wood".into(), 3), ("carpet".into(), 3)].into();
        let rows = [row("wood", "wood", 3, 0.7), row("carpet", "carpet", 3, 0.6)];
        assert_eq!(Summary::of(&rows, &table).steps_to_switch, vec![0]);
        assert_eq!(Summary::of(&[], &table).accuracy, 0.0);
    }
}
