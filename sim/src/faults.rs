//! Sensor faults: fatigue damage (whole dead rows and columns, growing with steps), stuck and
//! noisy sensels, and slow drift.

use rand::Rng;
use rand::seq::SliceRandom;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

/// How the sensor degrades. All zero: a perfect sensor.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FaultParams {
    /// Expected new dead lines (rows or columns) per 1000 steps: the fatigue damage rate. The
    /// paper's foot lost 1 row and 2 columns in 961 steps (section 8): about 3.1.
    pub dead_lines_per_1000_steps: f64,
    /// Damage present from the start, percent of sensels (eq. (6)).
    pub initial_damage_pct: f64,
    /// Sensels stuck at a random value.
    pub stuck_pixels: usize,
    /// Sensels with extra noise (standard deviation `noisy_sd` counts).
    pub noisy_pixels: usize,
    /// Standard deviation of the noisy sensels' extra noise, counts.
    pub noisy_sd: f64,
    /// Gain drift, fraction per hour of sensor time (piezoresistive creep).
    pub drift_per_hour: f64,
}

/// The sensor's faults at one moment.
#[derive(Clone, Debug)]
pub struct Faults {
    /// What the faults grow from.
    pub params: FaultParams,
    /// Rows of sensels.
    pub rows: usize,
    /// Columns of sensels.
    pub cols: usize,
    /// Dead rows.
    pub dead_rows: Vec<bool>,
    /// Dead columns.
    pub dead_cols: Vec<bool>,
    /// Stuck sensels: index and the value they read.
    pub stuck: Vec<(usize, u16)>,
    /// Noisy sensels.
    pub noisy: Vec<usize>,
    /// Multiplicative gain from drift.
    pub drift_gain: f64,
}

impl Faults {
    /// The faults of a new `rows` x `cols` sensor: stuck and noisy sensels drawn, the initial damage applied.
    pub fn new(params: FaultParams, rows: usize, cols: usize, rng: &mut impl Rng) -> Self {
        let mut f = Self {
            rows,
            cols,
            dead_rows: vec![false; rows],
            dead_cols: vec![false; cols],
            stuck: Vec::new(),
            noisy: Vec::new(),
            drift_gain: 1.0,
            params,
        };
        let n = rows * cols;
        for _ in 0..f.params.stuck_pixels {
            f.stuck
                .push((rng.random_range(0..n), rng.random_range(0..=255)));
        }
        for _ in 0..f.params.noisy_pixels {
            f.noisy.push(rng.random_range(0..n));
        }
        let pct = f.params.initial_damage_pct;
        f.damage_to(pct, rng);
        f
    }

    /// Eq. (6): percent of sensels on a dead row or column.
    pub fn damage_pct(&self) -> f64 {
        let dr = self.dead_rows.iter().filter(|&&d| d).count();
        let dc = self.dead_cols.iter().filter(|&&d| d).count();
        let dead = dr * self.cols + dc * self.rows - dr * dc;
        100.0 * dead as f64 / (self.rows * self.cols) as f64
    }

    /// Kills random live lines until the damage reaches `pct`.
    pub fn damage_to(&mut self, pct: f64, rng: &mut impl Rng) {
        let mut live: Vec<(bool, usize)> = (0..self.rows)
            .filter(|&r| !self.dead_rows[r])
            .map(|r| (true, r))
            .chain(
                (0..self.cols)
                    .filter(|&c| !self.dead_cols[c])
                    .map(|c| (false, c)),
            )
            .collect();
        live.shuffle(rng);
        for (is_row, i) in live {
            if self.damage_pct() >= pct {
                break;
            }
            self.kill(is_row, i);
        }
    }

    fn kill(&mut self, is_row: bool, i: usize) {
        if is_row {
            self.dead_rows[i] = true;
        } else {
            self.dead_cols[i] = true;
        }
    }

    /// One step of wear: a new dead line with probability rate/1000.
    pub fn on_step(&mut self, rng: &mut impl Rng) {
        let p = (self.params.dead_lines_per_1000_steps / 1000.0).clamp(0.0, 1.0);
        if p > 0.0 && rng.random_bool(p) {
            let is_row = rng.random_bool(0.5);
            let i = rng.random_range(0..if is_row { self.rows } else { self.cols });
            self.kill(is_row, i);
        }
    }

    /// Advances the drift by `dt_s` seconds of sensor time.
    pub fn on_time(&mut self, dt_s: f64) {
        self.drift_gain *= 1.0 + self.params.drift_per_hour * dt_s / 3600.0;
    }

    /// Applies the faults to an image of counts.
    pub fn apply(&self, pixels: &mut [u16], max: u16, rng: &mut impl Rng) {
        for &i in &self.noisy {
            let n: f64 = StandardNormal.sample(rng);
            let v = pixels[i] as f64 + n * self.params.noisy_sd;
            pixels[i] = v.round().clamp(0.0, max as f64) as u16;
        }
        for &(i, v) in &self.stuck {
            pixels[i] = v.min(max);
        }
        for (r, _) in self.dead_rows.iter().enumerate().filter(|(_, d)| **d) {
            pixels[r * self.cols..(r + 1) * self.cols].fill(0);
        }
        for (c, _) in self.dead_cols.iter().enumerate().filter(|(_, d)| **d) {
            for r in 0..self.rows {
                pixels[r * self.cols + c] = 0;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn rng() -> rand_chacha::ChaCha8Rng {
        rand_chacha::ChaCha8Rng::seed_from_u64(5)
    }

    #[test]
    fn damage_is_eq_6_the_share_of_sensels_on_dead_lines() {
        // The paper's foot after 961 steps: 1 row and 2 columns of the 41x38 crop.
        let mut f = Faults::new(FaultParams::default(), 41, 38, &mut rng());
        assert_eq!(f.damage_pct(), 0.0);
        f.kill(true, 3);
        f.kill(false, 0);
        f.kill(false, 7);
        let want = 100.0 * (38 + 2 * 41 - 2) as f64 / (41 * 38) as f64;
        assert!((f.damage_pct() - want).abs() < 1e-12, "{}", f.damage_pct());
        assert!((7.0..8.0).contains(&f.damage_pct()));
    }

    #[test]
    fn initial_damage_reaches_the_level_and_zeroes_exactly_the_dead_lines() {
        let p = FaultParams {
            initial_damage_pct: 30.0,
            ..Default::default()
        };
        let f = Faults::new(p, 44, 44, &mut rng());
        // Lines are whole: the level is reached, overshooting by at most one line (44 of 1936).
        assert!((30.0..30.0 + 100.0 * 44.0 / 1936.0).contains(&f.damage_pct()));
        let mut px = vec![100u16; 44 * 44];
        f.apply(&mut px, 255, &mut rng());
        for r in 0..44 {
            for c in 0..44 {
                let dead = f.dead_rows[r] || f.dead_cols[c];
                assert_eq!(px[r * 44 + c] == 0, dead, "({r}, {c})");
            }
        }
    }

    #[test]
    fn stuck_sensels_read_their_value_and_drift_grows_the_gain() {
        let p = FaultParams {
            stuck_pixels: 3,
            drift_per_hour: 0.02,
            ..Default::default()
        };
        let mut f = Faults::new(p, 44, 44, &mut rng());
        let mut px = vec![0u16; 44 * 44];
        f.apply(&mut px, 255, &mut rng());
        for &(i, v) in &f.stuck {
            assert_eq!(px[i], v);
        }
        f.on_time(3600.0);
        assert!((f.drift_gain - 1.02).abs() < 1e-12);
    }

    #[test]
    fn wear_adds_dead_lines_at_its_rate_and_none_without_one() {
        let mut none = Faults::new(FaultParams::default(), 44, 44, &mut rng());
        let mut r = rng();
        for _ in 0..5000 {
            none.on_step(&mut r);
        }
        assert_eq!(none.damage_pct(), 0.0);
        let p = FaultParams {
            dead_lines_per_1000_steps: 1000.0,
            ..Default::default()
        };
        let mut always = Faults::new(p, 44, 44, &mut rng());
        always.on_step(&mut r);
        assert!(always.damage_pct() > 0.0);
    }
}
