//! Order statistics shared by training and the unknown-ground checks: a leaf module (it
//! imports nothing of the crate), so that neither has to import the other for them.

/// The `q` quantile of `v` (sorted in place), by the nearest rank at or above: with `n` values,
/// at most `floor((1 - q) n)` lie above it. NaN when empty.
pub fn upper_quantile(v: &mut [f64], q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let i = ((q * v.len() as f64).ceil() as usize).clamp(1, v.len()) - 1;
    v[i]
}

/// The median of `v` (sorted in place); NaN when empty.
pub fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// The band of sorted, non-empty `v` that lets `rate` of it out (half each side), widened by
/// a quarter of its width each side: the next run is not the one the band was drawn on.
pub fn widened_band(v: &[f64], rate: f64) -> [f64; 2] {
    let tail = ((rate / 2.0 * v.len() as f64).floor() as usize).min(v.len() - 1);
    let (lo, hi) = (v[tail], v[v.len() - 1 - tail]);
    let margin = 0.25 * (hi - lo);
    [lo - margin, hi + margin]
}

/// Per class, [`widened_band`] of its values (non-finite ones left out), its lower end at 0 at
/// the least (loads and roughness are never negative); a class without values accepts all.
pub fn class_bands(per_class: Vec<Vec<f64>>, rate: f64) -> Vec<[f64; 2]> {
    per_class
        .into_iter()
        .map(|mut v| {
            v.retain(|x| x.is_finite());
            if v.is_empty() {
                return [f64::NEG_INFINITY, f64::INFINITY];
            }
            v.sort_by(f64::total_cmp);
            let [lo, hi] = widened_band(&v, rate);
            [lo.max(0.0), hi]
        })
        .collect()
}

/// The area under the ROC curve of a score that should be larger for `positive` than for
/// `negative` values: the share of (negative, positive) pairs it orders right, ties half. NaN
/// when either side is empty.
pub fn auroc(negative: &[f64], positive: &[f64]) -> f64 {
    if negative.is_empty() || positive.is_empty() {
        return f64::NAN;
    }
    let mut pos = positive.to_vec();
    pos.sort_by(f64::total_cmp);
    // For each negative, the positives above it and tied with it, by binary search.
    let mut wins = 0.0;
    for &k in negative {
        let below = pos.partition_point(|&v| v < k);
        let not_above = pos.partition_point(|&v| v <= k);
        wins += (pos.len() - not_above) as f64 + 0.5 * (not_above - below) as f64;
    }
    wins / (pos.len() * negative.len()) as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_count_from_the_top() {
        let mut v: Vec<f64> = (1..=50).map(f64::from).collect();
        // 2% of 50 = 1 value may lie above: the 49th.
        assert_eq!(upper_quantile(&mut v, 0.98), 49.0);
        assert_eq!(upper_quantile(&mut v, 1.0), 50.0);
        assert_eq!(upper_quantile(&mut [3.0], 0.98), 3.0);
        assert!(upper_quantile(&mut [], 0.5).is_nan());
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&mut [4.0, 1.0, 2.0, 3.0]), 2.5);
    }

    #[test]
    fn quantiles_and_bands() {
        let mut v: Vec<f64> = (1..=100).map(f64::from).collect();
        assert_eq!(upper_quantile(&mut v, 0.98), 98.0);
        assert_eq!(median(&mut [3.0, 1.0, 2.0, 4.0]), 2.5);
        assert!(median(&mut []).is_nan());
        // A band of a non-negative quantity never starts below zero (it printed
        // `-0.953-11.849` for a roughness before).
        let b = class_bands(vec![vec![0.1, 0.2, 10.0], vec![], vec![f64::NAN]], 0.0);
        assert_eq!(b[0][0], 0.0);
        assert!(b[0][1] > 10.0);
        assert_eq!(b[1], [f64::NEG_INFINITY, f64::INFINITY]);
        assert_eq!(b[2], [f64::NEG_INFINITY, f64::INFINITY]);
    }

    #[test]
    fn bands_let_the_rate_out_widened() {
        let r = class_bands(vec![(0..100).map(|i| i as f64).collect()], 0.02);
        // 1 of 100 out each side: 1..=98, widened by 97 / 4, and not below zero.
        assert_eq!(r[0], [0.0, 98.0 + 24.25]);
        assert_eq!(widened_band(&[10.0, 20.0], 0.0), [7.5, 22.5]);
    }

    #[test]
    fn auroc_counts_pairs_and_ties() {
        // Pairs (negative, positive): (1,3) (1,2) (2,3) win, (2,2) ties: 3.5 of 4.
        assert_eq!(auroc(&[1.0, 2.0], &[3.0, 2.0]), 0.875);
        assert_eq!(auroc(&[3.0], &[1.0]), 0.0);
        assert!(auroc(&[], &[1.0]).is_nan());
    }
}
