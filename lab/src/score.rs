//! Scoring, one implementation for every report: per-step accuracy, the confusion matrix,
//! steps from a terrain change to its gait, and speed per terrain and gait.

use std::collections::BTreeMap;

use node::classifier::{Classifier, Model, PressureImage};

use crate::simdata::TrainingSet;
use sim::service::StepRecord;

/// Counts `[actual][detected]` over `k` classes; column `k` counts "unknown" (no class within
/// the Parzen window), which is never right.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Confusion {
    /// `counts[actual][detected]`, `detected == k` for unknown.
    pub counts: Vec<Vec<usize>>,
}

impl Confusion {
    /// An empty matrix for `k` classes.
    pub fn new(k: usize) -> Self {
        Self {
            counts: vec![vec![0; k + 1]; k],
        }
    }

    /// Counts one decision; `detected` `None` is unknown.
    pub fn add(&mut self, actual: usize, detected: Option<usize>) {
        let k = self.counts.len();
        self.counts[actual][detected.filter(|&d| d < k).unwrap_or(k)] += 1;
    }

    /// Decisions counted.
    pub fn total(&self) -> usize {
        self.counts.iter().flatten().sum()
    }

    /// Share of decisions on the diagonal (0 when empty).
    pub fn accuracy(&self) -> f64 {
        let n = self.total();
        let ok: usize = (0..self.counts.len()).map(|i| self.counts[i][i]).sum();
        if n == 0 { 0.0 } else { ok as f64 / n as f64 }
    }

    /// Share of class `i`'s samples detected as `i` (0 when it has none).
    pub fn recall(&self, i: usize) -> f64 {
        let n: usize = self.counts[i].iter().sum();
        if n == 0 {
            0.0
        } else {
            self.counts[i][i] as f64 / n as f64
        }
    }
}

/// The confusion of `model` on the images `idx` of `set`, each changed by `alter` first (sensor
/// damage), classified with or without the paper's repair filter.
pub fn confusion(
    model: &Model,
    set: &TrainingSet,
    idx: &[usize],
    mut alter: impl FnMut(&mut PressureImage),
    repair: bool,
) -> Confusion {
    let mut c = Confusion::new(set.classes.len());
    let mut cls = Classifier::new(model.clone());
    for &i in idx {
        let mut img = set.images[i].clone();
        alter(&mut img);
        let det = cls.classify_image(&img, repair).ok().and_then(|d| d.class);
        c.add(set.labels[i], det);
    }
    c
}

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
            let to_safe: Vec<String> = u
                .steps_to_safe_gait
                .iter()
                .map(|d| d.map_or("never".into(), |d| d.to_string()))
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
                let d = rows[i..]
                    .iter()
                    .take_while(|x| x.truth == r.truth)
                    .position(|x| x.gait == safe_gait);
                u.steps_to_safe_gait.push(d);
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

/// The value at quantile `q` of `values` by the node's one rule, the nearest rank at or above
/// ([`node::stats::upper_quantile`]); `None` when empty.
pub fn percentile(values: &[f64], q: f64) -> Option<f64> {
    let mut v = values.to_vec();
    Some(node::stats::upper_quantile(&mut v, q)).filter(|x| !x.is_nan())
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
    }

    #[test]
    fn a_change_already_in_its_gait_is_zero_steps() {
        let table: BTreeMap<String, u8> = [("wood".into(), 3), ("carpet".into(), 3)].into();
        let rows = [row("wood", "wood", 3, 0.7), row("carpet", "carpet", 3, 0.6)];
        assert_eq!(Summary::of(&rows, &table).steps_to_switch, vec![0]);
        assert_eq!(Summary::of(&[], &table).accuracy, 0.0);
    }

    #[test]
    fn confusion_counts_unknown_as_wrong() {
        let mut c = Confusion::new(2);
        c.add(0, Some(0));
        c.add(0, None);
        c.add(1, Some(1));
        c.add(1, Some(0));
        assert_eq!(c.counts, vec![vec![1, 0, 1], vec![1, 1, 0]]);
        assert_eq!(c.total(), 4);
        assert_eq!(c.accuracy(), 0.5);
        assert_eq!(c.recall(0), 0.5);
        assert_eq!(Confusion::new(3).accuracy(), 0.0);
    }

    #[test]
    fn percentile_is_nearest_rank() {
        assert_eq!(percentile(&[], 0.5), None);
        assert_eq!(percentile(&[1.0, 2.0, 3.0], 0.5), Some(2.0));
        assert_eq!(percentile(&[1.0, 2.0, 3.0, 4.0], 0.99), Some(4.0));
    }
}

/// How [`evaluate`] tests a model (with the `clap` feature, `presrs eval`'s options).
#[derive(Clone, Copy, Debug)]
#[cfg_attr(feature = "clap", derive(clap::Args))]
pub struct EvalSpec {
    /// Simulated sensor damage per image, percent of sensels on dead rows and columns (eq. 6).
    #[cfg_attr(feature = "clap", arg(long = "damage", value_name = "PCT"))]
    pub damage_pct: Option<f64>,
    /// The paper's repair filter before classifying.
    #[cfg_attr(feature = "clap", arg(long))]
    pub repair: bool,
    /// Seed of the damage.
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 1))]
    pub seed: u64,
    /// Which SIMD kernels classify: `native` (the fastest this CPU has: AVX2/FMA/F16C on
    /// x86-64) or `portable` (the target's baseline SIMD only, as on an ARM computer), to
    /// compare their speed.
    #[cfg_attr(feature = "clap", arg(long, default_value = "native"))]
    pub kernels: node::classifier::Kernels,
}

/// What [`evaluate`] measured.
#[derive(Clone, Debug)]
pub struct Evaluation {
    /// Actual against detected, over the model's classes (plus unknown).
    pub confusion: Confusion,
    /// Images left out: the model was trained or validated on them.
    pub skipped: usize,
    /// Time per classification, µs, ascending.
    pub classify_us: Vec<f64>,
    /// Class folders of terrains the model was not trained on (open-set test): per folder,
    /// images and how many the model called unknown (the right answer).
    pub novel: BTreeMap<String, (usize, usize)>,
}

impl Evaluation {
    /// Share of the known classes' test images the model called unknown.
    pub fn unknown_rate(&self) -> f64 {
        let k = self.confusion.counts.len();
        let unknown: usize = self.confusion.counts.iter().map(|r| r[k]).sum();
        unknown as f64 / self.confusion.total().max(1) as f64
    }
}

impl Evaluation {
    /// `presrs eval --json`'s object: accuracy overall and per class (`names`: the model's
    /// classes), the confusion (`[actual][detected]`, the unknown column apart), open-set
    /// shares, timing, and what was asked (`spec`).
    pub fn to_json(&self, names: &[String], spec: &EvalSpec) -> serde_json::Value {
        let counts = &self.confusion;
        let k = names.len();
        let per: serde_json::Map<String, serde_json::Value> = names
            .iter()
            .enumerate()
            .map(|(i, n)| (n.clone(), counts.recall(i).into()))
            .collect();
        let confusion: Vec<&[usize]> = counts.counts.iter().map(|r| &r[..k]).collect();
        let unknown: Vec<usize> = counts.counts.iter().map(|r| r[k]).collect();
        let novel: serde_json::Map<String, serde_json::Value> = self
            .novel
            .iter()
            .map(|(t, (n, u))| {
                let share = *u as f64 / (*n).max(1) as f64;
                (
                    t.clone(),
                    serde_json::json!({"images": n, "called_unknown": u, "unknown_share": share}),
                )
            })
            .collect();
        serde_json::json!({
            "overall_accuracy": counts.accuracy(), "per_class": per, "classes": names,
            "confusion": confusion, "unknown": unknown, "unknown_rate": self.unknown_rate(),
            "novel_terrains": novel, "n_tested": counts.total(), "n_skipped": self.skipped,
            "damage_pct": spec.damage_pct, "repair": spec.repair,
            "classify_us_median": percentile(&self.classify_us, 0.5).unwrap_or(0.0),
            "classify_us_p99": percentile(&self.classify_us, 0.99).unwrap_or(0.0),
            "kernels": spec.kernels.describe(),
        })
    }

    /// `presrs eval`'s table: one row per detected class (and "unknown" when any image was),
    /// each actual class's shares in a column; then accuracy, timing and the open-set shares.
    pub fn table(&self, names: &[String], spec: &EvalSpec) -> String {
        use std::fmt::Write;
        let counts = &self.confusion;
        let k = names.len();
        let n_tested = counts.total();
        let correct: usize = (0..k).map(|i| counts.counts[i][i]).sum();
        let mut o = String::new();
        // Writing to a String cannot fail.
        let _ = writeln!(
            o,
            "left out {} images the model was trained or validated on; tested {n_tested}",
            self.skipped
        );
        let _ = write!(o, "{:>16}", "detected \\ actual");
        for n in names {
            let _ = write!(o, " {n:>12}");
        }
        let _ = writeln!(o);
        let has_unknown = counts.counts.iter().any(|r| r[k] > 0);
        for det in 0..k + usize::from(has_unknown) {
            let _ = write!(
                o,
                "{:>16}",
                names.get(det).map_or("unknown", String::as_str)
            );
            for row in &counts.counts {
                let n: usize = row.iter().sum();
                let p = if n > 0 {
                    100.0 * row[det] as f64 / n as f64
                } else {
                    0.0
                };
                let _ = write!(o, " {p:>11.1}%");
            }
            let _ = writeln!(o);
        }
        let _ = writeln!(
            o,
            "overall accuracy {:.1}% ({correct}/{n_tested}); classify median {:.1} us, p99 {:.1} us ({} kernels)",
            counts.accuracy() * 100.0,
            percentile(&self.classify_us, 0.5).unwrap_or(0.0),
            percentile(&self.classify_us, 0.99).unwrap_or(0.0),
            spec.kernels.describe()
        );
        let _ = writeln!(
            o,
            "known terrains called unknown: {:.1}%",
            100.0 * self.unknown_rate()
        );
        for (t, (n, u)) in &self.novel {
            let _ = writeln!(
                o,
                "{t} (not in the model): {u}/{n} called unknown ({:.1}%)",
                100.0 * *u as f64 / (*n).max(1) as f64
            );
        }
        o
    }
}

/// Why [`evaluate`] stopped.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    /// An image the model cannot take.
    #[error("{path}: {source}")]
    Image {
        /// The image file.
        path: String,
        /// Why.
        source: node::classifier::pwe::ImageMismatch,
    },
}

/// Classifies every image of `ds` the model was neither trained nor validated on (matched by
/// content hash), each damaged per `spec`, timing each classification. A class folder the
/// model has no class for is a terrain it does not know: its images are counted apart
/// ([`Evaluation::novel`]).
pub fn evaluate(
    model: Model,
    ds: &node::classifier::dataset::Dataset,
    spec: &EvalSpec,
) -> Result<Evaluation, EvalError> {
    use rand::SeedableRng;
    let names: Vec<String> = model.classes.iter().map(|c| c.name.clone()).collect();
    let used: std::collections::HashSet<String> = model
        .train_hashes
        .iter()
        .chain(&model.val_hashes)
        .cloned()
        .collect();
    let mut confusion = Confusion::new(names.len());
    let (mut skipped, mut times) = (0, Vec::new());
    let mut novel: BTreeMap<String, (usize, usize)> = BTreeMap::new();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(spec.seed);
    let mut c = Classifier::with_kernels(model, spec.kernels);
    for s in &ds.samples {
        let actual = names.iter().position(|n| *n == ds.classes[s.class]);
        if used.contains(&s.image.content_hash()) {
            skipped += 1;
            continue;
        }
        let mut img = s.image.clone();
        if let Some(p) = spec.damage_pct {
            node::classifier::repair::damage(&mut img, p, &mut rng);
        }
        let t0 = std::time::Instant::now();
        let d = c
            .classify_image(&img, spec.repair)
            .map_err(|source| EvalError::Image {
                path: s.path.display().to_string(),
                source,
            })?;
        times.push(t0.elapsed().as_secs_f64() * 1e6);
        match actual {
            Some(a) => confusion.add(a, d.class),
            None => {
                let e = novel.entry(ds.classes[s.class].clone()).or_default();
                e.0 += 1;
                e.1 += d.class.is_none() as usize;
            }
        }
    }
    times.sort_by(f64::total_cmp);
    Ok(Evaluation {
        confusion,
        skipped,
        classify_us: times,
        novel,
    })
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
