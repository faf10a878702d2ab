//! Rows of leave-one-class-out runs summed up: per-gait counts pooled, a source's means, one
//! figure's spread over seeds (median, range, the mean's 95% interval) and the classes no
//! score separates.

use super::OpenSetRow;

/// The per-gait counts of several rows, summed gait by gait.
pub fn pool_gait_counts<'a>(
    rows: impl IntoIterator<Item = &'a Vec<node::gait_status::GaitCount>>,
) -> Vec<node::gait_status::GaitCount> {
    let mut v = Vec::new();
    for c in rows.into_iter().flatten() {
        node::gait_status::add_count(&mut v, c.gait, c.steps, c.unknown);
    }
    v
}

/// Means over a source's rows.
#[derive(Clone, Debug)]
pub struct OpenSetMeans {
    /// Mean of each field, in [`OpenSetRow`]'s order (held_out is "mean").
    pub row: OpenSetRow,
    /// Lowest and highest AUROC of the rows.
    pub auroc_range: (f64, f64),
}

impl OpenSetMeans {
    /// The means of `rows`.
    pub fn of(rows: &[OpenSetRow]) -> Self {
        let n = rows.len().max(1) as f64;
        let m = |f: fn(&OpenSetRow) -> f64| rows.iter().map(f).sum::<f64>() / n;
        let lo = rows.iter().map(|r| r.auroc).fold(f64::INFINITY, f64::min);
        let hi = rows
            .iter()
            .map(|r| r.auroc)
            .fold(f64::NEG_INFINITY, f64::max);
        Self {
            row: OpenSetRow {
                held_out: "mean".into(),
                unknown_held_out: m(|r| r.unknown_held_out),
                unknown_known: m(|r| r.unknown_known),
                unknown_known_misclassified: m(|r| r.unknown_known_misclassified),
                auroc: m(|r| r.auroc),
                density_auroc: m(|r| r.density_auroc),
                nn_auroc: m(|r| r.nn_auroc),
                known_accuracy: m(|r| r.known_accuracy),
                known_accuracy_open: m(|r| r.known_accuracy_open),
                calibration_unknown: m(|r| r.calibration_unknown),
                n_held_out: rows.iter().map(|r| r.n_held_out).sum(),
                n_known: rows.iter().map(|r| r.n_known).sum(),
                known_by_gait: pool_gait_counts(rows.iter().map(|r| &r.known_by_gait)),
                checks: String::new(),
            },
            auroc_range: (lo, hi),
        }
    }
}

/// One figure over several seeds: its median, lowest and highest value, and its mean with a
/// 95% interval.
///
/// The range says how far one run can land from the rest; the mean's interval says what rate
/// a lab can expect over its runs. A per-run bound and an expected rate are different targets
/// (docs/decisions/figures-behind-comments.md, spread-binomial).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Spread {
    /// The median (of an even count, the mean of the middle two).
    pub median: f64,
    /// The lowest value.
    pub min: f64,
    /// The highest value.
    pub max: f64,
    /// The mean.
    pub mean: f64,
    /// Half the width of the mean's 95% interval (Student's t over the seeds, which are
    /// independent draws; the left-out classes of one seed share its runs and are not): NaN
    /// with fewer than two seeds.
    pub half_width: f64,
}

/// Student's t at 97.5% for `df` degrees of freedom (df 1-30, then the normal's 1.96): a table
/// rather than a statistics crate for one column of one table.
pub(super) fn t_975(df: usize) -> f64 {
    const T: [f64; 30] = [
        12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160,
        2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064, 2.060, 2.056,
        2.052, 2.048, 2.045, 2.042,
    ];
    match df {
        0 => f64::NAN,
        1..=30 => T[df - 1],
        _ => 1.96,
    }
}

impl Spread {
    /// The spread of `v` (NaN everywhere when it is empty).
    pub fn of(v: &[f64]) -> Self {
        let mut v = v.to_vec();
        let median = node::order_stats::median(&mut v);
        let n = v.len();
        let mean = v.iter().sum::<f64>() / n as f64;
        let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n.saturating_sub(1) as f64;
        Self {
            median,
            min: v.first().copied().unwrap_or(f64::NAN),
            max: v.last().copied().unwrap_or(f64::NAN),
            mean,
            half_width: t_975(n.saturating_sub(1)) * (var / n as f64).sqrt(),
        }
    }

    /// The mean's 95% interval, lowest and highest.
    pub fn interval(&self) -> (f64, f64) {
        (self.mean - self.half_width, self.mean + self.half_width)
    }
}

/// One source's means ([`OpenSetMeans`]) over several seeds: each seed draws another split
/// and, for the simulated sources, other runs. A single seed can be a kind one: this is the
/// spread to report.
#[derive(Clone, Debug, Default)]
pub struct SeedSpread {
    /// The seeds, in the order of `means`.
    pub seeds: Vec<u64>,
    /// The source's means on each seed.
    pub means: Vec<OpenSetRow>,
    /// Each seed's rows, one per left-out class (empty for a seed added by its means alone).
    pub rows: Vec<Vec<OpenSetRow>>,
}

/// The mean of `f` over `rows` (NaN for none).
pub(super) fn mean_of(rows: &[&OpenSetRow], f: fn(&OpenSetRow) -> f64) -> f64 {
    rows.iter().map(|r| f(r)).sum::<f64>() / rows.len() as f64
}

/// The AUROC at which a left-out class counts as separable from the known ones: the issue's
/// own bar for a score that works.
pub const SEPARABLE_AUROC: f64 = 0.9;

impl SeedSpread {
    /// Adds one seed's means.
    pub fn push(&mut self, seed: u64, means: OpenSetRow) {
        self.seeds.push(seed);
        self.means.push(means);
        self.rows.push(Vec::new());
    }

    /// Adds one seed's rows (and their means).
    pub fn push_rows(&mut self, seed: u64, rows: Vec<OpenSetRow>) {
        self.push(seed, OpenSetMeans::of(&rows).row);
        if let Some(last) = self.rows.last_mut() {
            *last = rows;
        }
    }

    /// The left-out classes, each with the mean over the seeds of its AUROC by our score and
    /// by the plain nearest neighbour, in the rows' order.
    pub fn classes(&self) -> Vec<(String, f64, f64)> {
        let mut v: Vec<(String, Vec<f64>, Vec<f64>)> = Vec::new();
        for r in self.rows.iter().flatten() {
            let i = match v.iter().position(|(n, _, _)| *n == r.held_out) {
                Some(i) => i,
                None => {
                    v.push((r.held_out.clone(), Vec::new(), Vec::new()));
                    v.len() - 1
                }
            };
            v[i].1.push(r.auroc);
            v[i].2.push(r.nn_auroc);
        }
        let mean = |x: &[f64]| x.iter().sum::<f64>() / x.len().max(1) as f64;
        v.into_iter()
            .map(|(n, a, b)| (n, mean(&a), mean(&b)))
            .collect()
    }

    /// The classes that no score measured separates from the known images: over the seeds,
    /// neither our score's mean AUROC nor the nearest neighbour's reaches [`SEPARABLE_AUROC`].
    /// The targets hold "where the classes are separable at all"; these are where they
    /// are not, named in the report so that a better score can take them back.
    pub fn inseparable(&self) -> Vec<(String, f64, f64)> {
        self.classes()
            .into_iter()
            .filter(|&(_, ours, nn)| ours.max(nn) < SEPARABLE_AUROC)
            .collect()
    }

    /// Whether any seed's rows (one per left-out class) were kept.
    pub fn has_rows(&self) -> bool {
        self.rows.iter().any(|r| !r.is_empty())
    }

    /// Each seed with its rows of the classes not in `except` (seeds with none left out).
    fn kept_rows<'a, 'e>(
        &'a self,
        except: &'e [String],
    ) -> impl Iterator<Item = (u64, Vec<&'a OpenSetRow>)> + use<'a, 'e> {
        self.seeds
            .iter()
            .zip(&self.rows)
            .filter_map(move |(&seed, rows)| {
                let kept: Vec<&OpenSetRow> = rows
                    .iter()
                    .filter(|r| !except.contains(&r.held_out))
                    .collect();
                (!kept.is_empty()).then_some((seed, kept))
            })
    }

    /// The spread over the seeds of `f`'s mean over each seed's rows of the classes not in
    /// `except`.
    pub fn of_classes(&self, except: &[String], f: fn(&OpenSetRow) -> f64) -> Spread {
        let per_seed: Vec<f64> = self
            .kept_rows(except)
            .map(|(_, rows)| mean_of(&rows, f))
            .filter(|x| !x.is_nan())
            .collect();
        Spread::of(&per_seed)
    }

    /// The seed whose separable classes (those not in `except`) were found least, and its
    /// least-found class: where the spread over seeds comes from.
    pub fn least_found(&self, except: &[String]) -> Option<(u64, &OpenSetRow)> {
        let found = |r: &OpenSetRow| r.unknown_held_out;
        let (seed, rows) = self
            .kept_rows(except)
            .min_by(|a, b| mean_of(&a.1, found).total_cmp(&mean_of(&b.1, found)))?;
        let least = rows
            .into_iter()
            .min_by(|a, b| a.unknown_held_out.total_cmp(&b.unknown_held_out))?;
        Some((seed, least))
    }

    /// The spread of one figure of the means.
    pub fn of(&self, f: fn(&OpenSetRow) -> f64) -> Spread {
        Spread::of(&self.means.iter().map(f).collect::<Vec<_>>())
    }

    /// The seeds whose means `miss` says miss a target.
    pub fn missing(&self, miss: impl Fn(&OpenSetRow) -> bool) -> Vec<u64> {
        self.seeds
            .iter()
            .zip(&self.means)
            .filter(|(_, m)| miss(m))
            .map(|(&s, _)| s)
            .collect()
    }
}
