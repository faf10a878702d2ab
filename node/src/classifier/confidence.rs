//! A decision's confidence as the measured chance that it is right.
//!
//! The Parzen posterior is no such chance: the stored samples of one terrain lie so far from
//! another's that nearly every image's posterior is 1.0, right or wrong (298 of 300 demo steps
//! at 100.0%; new ground taken for sand at 100.0%), and the controller's `min_confidence_pct`
//! never acted. What does tell a sure decision from a guess is how far the image lies inside
//! its terrain: its margin (the log posterior of the chosen terrain over the next, nats) and its
//! room under the novelty threshold (1 - novelty / threshold: 0 at the threshold, where new
//! ground that looks nearly known is accepted).
//!
//! `train` measures the chance on decisions it can judge: each known terrain left out in turn,
//! a model of the others calibrated as the model is, classifies the calibration run; a known
//! image is right or wrong, a left-out image is wrong (new ground taken for a known terrain),
//! rejected or not (`crate::training` says why). A logistic curve in the two figures is fitted to them (a small ridge
//! and one pseudo-decision each way keep it finite when every accepted image was right),
//! stored with the model
//! ([`ConfidenceMap`]) with its reliability table, and the classifier reports its chance as the
//! decision's confidence. No allocation at decision time: two features and an exponential.

use serde::{Deserialize, Serialize};

/// Margins past this many nats count as this many (a sure decision is sure).
pub const MARGIN_CAP: f64 = 20.0;

/// The measured chance that a decision is right; see the module docs.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ConfidenceMap {
    /// The logistic curve's weights: bias, margin (per [`MARGIN_CAP`]), room.
    pub weights: [f64; 3],
    /// Decisions it was fitted on, and of them right.
    pub judged: usize,
    /// Of `judged`, right.
    pub right: usize,
    /// The reliability table on those decisions: per band of confidence, the decisions and
    /// how many were right.
    pub reliability: Vec<ReliabilityBin>,
}

/// One band of the reliability table.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReliabilityBin {
    /// The band's confidence, from `lo` to `hi` (0..=1).
    pub lo: f64,
    /// See `lo`.
    pub hi: f64,
    /// Decisions whose confidence fell in it.
    pub n: usize,
    /// Of them, right.
    pub right: usize,
    /// Their mean confidence.
    pub mean: f64,
}

/// The bands of the reliability table.
pub const BANDS: [(f64, f64); 5] = [(0.0, 0.5), (0.5, 0.7), (0.7, 0.9), (0.9, 0.99), (0.99, 1.0)];

/// The two figures of a decision: margin (log posterior of the chosen class over the next,
/// capped, per cap) and room under the novelty threshold (1 - novelty / threshold, from -1 to
/// 1: an accepted decision's is at least 0).
#[inline]
pub fn features(margin_nats: f64, novelty: f64, threshold: f64) -> [f64; 2] {
    let m = if margin_nats.is_nan() {
        0.0
    } else {
        margin_nats.clamp(0.0, MARGIN_CAP) / MARGIN_CAP
    };
    // Negative past the threshold (rejected images, in fitting), down to -1.
    let room = if threshold.is_finite() && threshold > 0.0 && novelty.is_finite() {
        (1.0 - novelty / threshold).clamp(-1.0, 1.0)
    } else {
        1.0
    };
    [m, room]
}

impl ConfidenceMap {
    /// The chance that a decision with these figures is right.
    #[inline]
    pub fn chance(&self, f: [f64; 2]) -> f64 {
        let [b, wm, wr] = self.weights;
        let z = b + wm * f[0] + wr * f[1];
        1.0 / (1.0 + (-z).exp())
    }

    /// Fits the curve to `samples` (each decision's figures, whether it was right, and its
    /// weight); its reliability table on `judged`. `None` with fewer than 10 samples.
    pub fn fit_weighted(
        samples: &[([f64; 2], bool, f64)],
        judged: &[([f64; 2], bool)],
    ) -> Option<Self> {
        if samples.len() < 10 {
            return None;
        }
        let mut m = Self {
            weights: logistic(samples),
            judged: judged.len(),
            right: judged.iter().filter(|s| s.1).count(),
            reliability: Vec::new(),
        };
        m.reliability = m.table(judged);
        Some(m)
    }

    /// [`Self::fit_weighted`] with every decision's weight 1, its table on them all.
    pub fn fit(samples: &[([f64; 2], bool)]) -> Option<Self> {
        let w: Vec<([f64; 2], bool, f64)> = samples.iter().map(|&(f, r)| (f, r, 1.0)).collect();
        Self::fit_weighted(&w, samples)
    }

    /// The reliability table of this map on `samples`.
    pub fn table(&self, samples: &[([f64; 2], bool)]) -> Vec<ReliabilityBin> {
        BANDS
            .iter()
            .map(|&(lo, hi)| {
                let inside: Vec<(f64, bool)> = samples
                    .iter()
                    .map(|&(f, r)| (self.chance(f), r))
                    .filter(|&(c, _)| c >= lo && (c < hi || (hi >= 1.0 && c <= 1.0)))
                    .collect();
                let n = inside.len();
                ReliabilityBin {
                    lo,
                    hi,
                    n,
                    right: inside.iter().filter(|x| x.1).count(),
                    mean: inside.iter().map(|x| x.0).sum::<f64>() / n.max(1) as f64,
                }
            })
            .collect()
    }

    /// Expected calibration error of a table: the decisions' weighted gap between the mean
    /// confidence and the share right, per band.
    pub fn calibration_error(table: &[ReliabilityBin]) -> f64 {
        let total: usize = table.iter().map(|b| b.n).sum();
        table
            .iter()
            .filter(|b| b.n > 0)
            .map(|b| b.n as f64 * (b.mean - b.right as f64 / b.n as f64).abs())
            .sum::<f64>()
            / total.max(1) as f64
    }

    /// Finite weights (a model file's check).
    pub fn is_valid(&self) -> bool {
        self.weights.iter().all(|w| w.is_finite())
    }
}

/// Logistic regression by Newton's method with a small ridge (so that a set where every
/// decision was right still gives finite weights: the chance then rises towards the share
/// right, not to 1 at any cost).
fn logistic(samples: &[([f64; 2], bool, f64)]) -> [f64; 3] {
    const RIDGE: f64 = 0.1;
    // One right and one wrong decision at the mean figures (Laplace's rule: with every
    // decision right, the chance is about (n + 1) / (n + 2), not 1).
    let n = samples.len().max(1) as f64;
    let mean = [0, 1].map(|i| samples.iter().map(|s| s.0[i]).sum::<f64>() / n);
    let pseudo = [(mean, true, 1.0), (mean, false, 1.0)];
    let mut w = [0.0f64; 3];
    for _ in 0..50 {
        let mut g = [0.0f64; 3];
        let mut h = [[0.0f64; 3]; 3];
        for &(f, r, wt) in samples.iter().chain(&pseudo) {
            let x = [1.0, f[0], f[1]];
            let z: f64 = (0..3).map(|i| w[i] * x[i]).sum();
            let p = 1.0 / (1.0 + (-z).exp());
            let y = if r { 1.0 } else { 0.0 };
            for i in 0..3 {
                g[i] += wt * (p - y) * x[i];
                for j in 0..3 {
                    h[i][j] += wt * p * (1.0 - p) * x[i] * x[j];
                }
            }
        }
        // The ridge on the two slopes only: the bias is the base rate's.
        for i in 1..3 {
            g[i] += RIDGE * w[i];
            h[i][i] += RIDGE;
        }
        let Some(step) = solve3(h, g) else { break };
        let mut moved = 0.0f64;
        for i in 0..3 {
            w[i] -= step[i];
            moved = moved.max(step[i].abs());
        }
        if !w.iter().all(|v| v.is_finite()) {
            return [0.0; 3];
        }
        if moved < 1e-9 {
            break;
        }
    }
    w
}

/// `h x = g` for a symmetric 3x3 `h` (Cramer's rule); `None` when singular.
fn solve3(h: [[f64; 3]; 3], g: [f64; 3]) -> Option<[f64; 3]> {
    let det = |m: [[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det(h);
    if !d.is_finite() || d.abs() < 1e-12 {
        return None;
    }
    let mut out = [0.0; 3];
    for (c, o) in out.iter_mut().enumerate() {
        let mut m = h;
        for r in 0..3 {
            m[r][c] = g[r];
        }
        *o = det(m) / d;
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_chance_follows_how_often_such_decisions_were_right() {
        // Sure decisions (large margin, room) always right; those at the threshold right half
        // the time.
        let mut s = Vec::new();
        for i in 0..200 {
            s.push((features(15.0, 0.2, 1.0), true));
            s.push((features(0.5, 0.98, 1.0), i % 2 == 0));
        }
        let m = ConfidenceMap::fit(&s).unwrap();
        let sure = m.chance(features(15.0, 0.2, 1.0));
        let edge = m.chance(features(0.5, 0.98, 1.0));
        assert!(sure > 0.95, "{sure}");
        assert!((0.3..0.7).contains(&edge), "{edge}");
        assert!(ConfidenceMap::calibration_error(&m.reliability) < 0.05);
        // Every decision right: finite weights, a high chance, never exactly 1.
        let all: Vec<_> = (0..30)
            .map(|i| (features(i as f64, 0.5, 1.0), true))
            .collect();
        let m = ConfidenceMap::fit(&all).unwrap();
        assert!(m.is_valid());
        let c = m.chance(features(20.0, 0.0, 1.0));
        assert!(c > 0.9 && c < 1.0, "{c}");
        assert!(ConfidenceMap::fit(&all[..5]).is_none());
    }
}
