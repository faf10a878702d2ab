//! The unknown thresholds' densities and the kNN ratio's unit: each stored sample's
//! leave-one-out density and each class's spread.

use super::{Model, sq_dist, widen};
use crate::order_stats::median;

/// `v` when it is a positive number, else `fallback` (else 1).
pub(crate) fn positive(v: f64, fallback: f64) -> f64 {
    if v.is_finite() && v > 0.0 {
        v
    } else if fallback.is_finite() && fallback > 0.0 {
        fallback
    } else {
        1.0
    }
}

/// Per class, the median over its stored samples of the mean distance to the `k` nearest other
/// stored samples of the class (the kNN ratio's unit).
pub(crate) fn class_spreads(m: &Model, k: usize) -> Vec<f64> {
    let h = m.h;
    let n = m.n_samples();
    let mut per: Vec<Vec<f64>> = vec![Vec::new(); m.classes.len()];
    let mut d = Vec::with_capacity(n);
    for i in 0..n {
        let c = m.sample_classes[i];
        d.clear();
        d.extend(
            (0..n)
                .filter(|&j| j != i && m.sample_classes[j] == c)
                .map(|j| {
                    sq_dist(
                        &m.samples[i * h..(i + 1) * h],
                        &m.samples[j * h..(j + 1) * h],
                    )
                    .sqrt()
                }),
        );
        if d.is_empty() {
            continue;
        }
        d.sort_by(f64::total_cmp);
        let kk = k.min(d.len());
        per[c].push(d[..kk].iter().sum::<f64>() / kk as f64);
    }
    let mut all: Vec<f64> = per.iter().flatten().copied().collect();
    let pooled = median(&mut all);
    per.iter_mut()
        .map(|v| {
            let md = median(v);
            positive(md, pooled)
        })
        .collect()
}

/// The unknown thresholds, one per class, calibrated on held-out images: each stored sample's
/// log density under its own class without it (leave-one-out: held out from the kernel sum, as
/// a new image of its terrain would be). A class's threshold is the `unknown_rate` quantile of
/// its samples' densities, so about that share of its images falls below it.
///
/// Per class, because the classes' spreads differ: a tight class's unusual image is as dense
/// as a loose class's typical one (docs/decisions/unknown-calibration.md).
///
/// Without a rate (0, or an older model): for every class the lowest density of any sample
/// less 10 nats (22,000 times less dense than the least typical training image), which rejects
/// almost nothing: the paper's classifier, which had no rejection. A class alone with one
/// sample has no density to calibrate on: its threshold is the least finite number (nothing
/// is below it, and a model file holds it: JSON has no infinity).
pub(crate) fn unknown_thresholds(m: &Model) -> Vec<f64> {
    let lo = loo_log_densities(m);
    let mut per: Vec<Vec<f64>> = vec![Vec::new(); m.classes.len()];
    for (d, &k) in lo.iter().zip(&m.sample_classes) {
        if d.is_finite() {
            per[k].push(*d);
        }
    }
    let lowest = lo
        .iter()
        .copied()
        .filter(|d| d.is_finite())
        .fold(f64::INFINITY, f64::min);
    let t: Vec<f64> = per
        .iter_mut()
        .enumerate()
        .map(|(k, v)| {
            if v.is_empty() {
                return f64::MIN;
            }
            v.sort_by(f64::total_cmp);
            match m.unknown.rate {
                r if r > 0.0 => {
                    // Images strictly below v[k] are unknown: k of n, at most the rate.
                    let q = v[((r * v.len() as f64).floor() as usize).min(v.len() - 1)];
                    widen(m, k, q)
                }
                _ => lowest - 10.0,
            }
        })
        .map(|t: f64| if t.is_finite() { t } else { f64::MIN })
        .collect();
    t
}

/// Each stored sample's leave-one-out log density under its own class, in the samples' order
/// (`-inf` for a sample alone in its class).
pub fn loo_log_densities(m: &Model) -> Vec<f64> {
    let h = m.h;
    let s2 = 2.0 * m.kernel_width * m.kernel_width;
    let mut out = Vec::with_capacity(m.n_samples());
    for i in 0..m.n_samples() {
        let k = m.sample_classes[i];
        let others: Vec<f64> = (0..m.n_samples())
            .filter(|&j| j != i && m.sample_classes[j] == k)
            .map(|j| {
                -sq_dist(
                    &m.samples[i * h..(i + 1) * h],
                    &m.samples[j * h..(j + 1) * h],
                ) / s2
            })
            .collect();
        if others.is_empty() {
            out.push(f64::NEG_INFINITY);
            continue;
        }
        let mx = others.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
        let ld = mx + others.iter().map(|e| (e - mx).exp()).sum::<f64>().ln()
            - (others.len() as f64).ln()
            - 0.5 * h as f64 * (std::f64::consts::PI * s2).ln();
        out.push(ld);
    }
    out
}
