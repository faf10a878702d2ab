//! A model judged on a dataset, as `presrs eval` prints it: the confusion matrix (detected
//! against actual, unknown apart), accuracy, the shares of terrains the model does not know,
//! and the time per classification. It needs a model and images only, never the simulator:
//! a lab runs it on its own captured sessions. The paper's experiments score with the same
//! [`Confusion`], so a number means the same thing wherever it is printed.

use std::collections::BTreeMap;

use node::classifier::{Classifier, Model, PressureImage};
use node::training::TrainingSet;

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

/// The value at quantile `q` of `values` by the node's one rule, the nearest rank at or above
/// ([`node::order_stats::upper_quantile`]); `None` when empty.
pub fn percentile(values: &[f64], q: f64) -> Option<f64> {
    let mut v = values.to_vec();
    Some(node::order_stats::upper_quantile(&mut v, q)).filter(|x| !x.is_nan())
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
    /// Which image of each stance was judged.
    pub frame: FrameUse,
}

/// Which image of each stance [`evaluate`] judged: the frame the model decides at, where the
/// set keeps its stances' frames (`capture` does, in `.stance/`), else the image the set holds.
///
/// Why: `train` measures the foot's deciding frame (30 to 190 ms after touchdown) and trains
/// there, while a capture's images are at the node's sample time of the capture; judged on
/// those, a model of another frame calls known ground unknown.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FrameUse {
    /// The model's deciding frame, ms after touchdown (`None`: a model without one).
    pub ms: Option<u32>,
    /// Images replaced by their stance's frame at `ms`.
    pub at_frame: usize,
    /// Images judged as the set holds them: no stance frames beside them.
    pub as_held: usize,
    /// Stances that ended before `ms`: left out (the node sends them as no sample).
    pub ended: usize,
}

impl std::fmt::Display for FrameUse {
    /// One line (with its newline): the frame judged, or why the images were taken as held.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let Some(ms) = self.ms else {
            return writeln!(
                f,
                "images as the set holds them (the model names no deciding frame)"
            );
        };
        if self.at_frame > 0 {
            write!(
                f,
                "judged at the model's deciding frame, {ms} ms after touchdown: {} stances' \
                 frames from the set's .stance/",
                self.at_frame
            )?;
            if self.ended > 0 {
                write!(
                    f,
                    "; {} ended before it, left out (the node: no sample)",
                    self.ended
                )?;
            }
            if self.as_held > 0 {
                write!(f, "; {} without frames, as held", self.as_held)?;
            }
            return writeln!(f);
        }
        writeln!(
            f,
            "images as the set holds them: it keeps no stance frames (a set `presrs capture` \
             wrote does); the model decides {ms} ms after touchdown, so a set sampled at \
             another time judges it at the wrong frame"
        )
    }
}

/// Sample `s`'s stance frame `j` from `root`'s `.stance/` folder: `Some(None)` when the stance
/// had ended by then, `None` when the set keeps no frames for it.
fn stance_frame(
    root: &std::path::Path,
    s: &node::classifier::dataset::Sample,
    j: usize,
) -> Option<Option<PressureImage>> {
    let frames = node::capture::stance_frames(root, &s.path)?;
    if frames.len() != node::stance::FRAME_OFFSETS_MS.len() {
        return None;
    }
    let f = frames.into_iter().nth(j)?;
    Some(f.pixels.iter().any(|&p| p > 0).then_some(f))
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
            "frame_ms": self.frame.ms, "images_at_frame": self.frame.at_frame,
            "images_as_held": self.frame.as_held, "stances_ended_before_frame": self.frame.ended,
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
        o.push_str(&self.frame.to_string());
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
    let mut frame = FrameUse {
        ms: model.sample_ms,
        ..FrameUse::default()
    };
    let j = (model.sample_ms)
        .and_then(|ms| node::stance::FRAME_OFFSETS_MS.iter().position(|&o| o == ms));
    let mut c = Classifier::with_kernels(model, spec.kernels);
    for s in &ds.samples {
        let actual = names.iter().position(|n| *n == ds.classes[s.class]);
        let mut img = match j.and_then(|j| stance_frame(&ds.root, s, j)) {
            Some(Some(f)) => {
                frame.at_frame += 1;
                f
            }
            Some(None) => {
                frame.ended += 1;
                continue;
            }
            None => {
                frame.as_held += 1;
                s.image.clone()
            }
        };
        // The model's hashes are of the images it trained on: the frame's, where it had them.
        if used.contains(&img.content_hash()) {
            skipped += 1;
            continue;
        }
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
        frame,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

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
