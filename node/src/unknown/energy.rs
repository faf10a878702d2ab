//! The stance's energy balance: what a stance did to the hop, read from the flights on either
//! side of it, held against what stances on its terrain do ([`super::Reason::Energy`]).
//!
//! A hopper's flight is ballistic, so its length says how fast the foot left the ground; the
//! flight before a stance says how fast it came down. On one terrain (and the stance law the
//! robot runs) the flight after a stance follows from the flight before it, a return map
//! `after = intercept + slope * before`, learned per class from the robot's own closed-loop
//! runs on known ground (`presrs lab energy`). Ground that looks like a known terrain to the
//! texture but takes more energy out of a hop (or gives more back) shows as a flight after its
//! stance that the class's map does not predict.
//!
//! The verdict on a stance comes at the next touchdown, when its flight after has ended. The
//! node uses it for the stance after: a stance the texture gives the class whose last stance
//! took energy its map does not allow is unknown (TerrainClass flag ENERGY). On new ground the
//! first stance is the texture's; the robot's controller confirms unknown on the second.
//!
//! Why this and not the image's load: docs/decisions/unknown-energy-check.md.

use serde::{Deserialize, Serialize};

/// Flights outside this range (µs) are not hops: a robot standing, a lost edge, bounce.
pub const PLAUSIBLE_FLIGHT_US: std::ops::RangeInclusive<u32> = 20_000..=1_000_000;

/// Fewer stances than this in a class: no map for it (a line and its tails need them).
pub const MIN_STANCES: usize = 20;

/// One class's return map: the flight after a stance from the flight before it, seconds.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReturnMap {
    /// Flight after for a flight before of 0, s.
    pub intercept_s: f64,
    /// d(flight after) / d(flight before).
    pub slope: f64,
    /// The residuals (flight after less the map's) that pass: low and high, s.
    pub residual_s: [f64; 2],
    /// Stances it was fitted on.
    pub stances: usize,
}

impl ReturnMap {
    /// The map's flight after for `before_s`.
    pub fn predict(&self, before_s: f64) -> f64 {
        self.intercept_s + self.slope * before_s
    }

    /// The flight after (`after_s`) lies within the map's band for the flight before.
    pub fn passes(&self, before_s: f64, after_s: f64) -> bool {
        let r = after_s - self.predict(before_s);
        (self.residual_s[0]..=self.residual_s[1]).contains(&r)
    }

    /// Values a loaded file may hold.
    pub fn is_valid(&self) -> bool {
        let [lo, hi] = self.residual_s;
        self.intercept_s.is_finite()
            && self.slope.is_finite()
            && lo.is_finite()
            && hi.is_finite()
            && lo <= hi
    }
}

/// What one stance did to the hop: its flights before and after (µs, foot clock) and the
/// class the texture gave it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct EnergyObservation {
    /// The foot.
    pub foot: u8,
    /// The stance's step number.
    pub step: u16,
    /// The class index the texture gave the stance (`None`: unknown, no contact, no sample).
    pub class: Option<usize>,
    /// From the liftoff before the stance to its touchdown, µs.
    pub flight_before_us: Option<u32>,
    /// From its liftoff to the next touchdown, µs.
    pub flight_after_us: Option<u32>,
    /// Receive times (the bus's clock, a log's timestamps) of the stance's touchdown and its
    /// liftoff (the next touchdown's when its liftoff was not heard): the stance, for a labels
    /// file in the log's time.
    pub span_rx_us: (u64, u64),
}

impl EnergyObservation {
    /// Both flights, seconds, when both are plausible hops.
    pub fn flights_s(&self) -> Option<(f64, f64)> {
        plausible_flights_s([self.flight_before_us, self.flight_after_us])
    }
}

/// A stance's flights before and after it (µs), seconds, when both are plausible hops.
pub fn plausible_flights_s(flights_us: [Option<u32>; 2]) -> Option<(f64, f64)> {
    let ok = |v: Option<u32>| v.filter(|v| PLAUSIBLE_FLIGHT_US.contains(v));
    Some((
        ok(flights_us[0])? as f64 * 1e-6,
        ok(flights_us[1])? as f64 * 1e-6,
    ))
}

/// Fits one return map per class from `(class, flight before s, flight after s)` stances of
/// known ground; a class with fewer than [`MIN_STANCES`] gets none. `rate` is the share of
/// the fitting stances let outside the band (half each side, the model's `unknown_rate`);
/// the band is then widened by a quarter of its width each side, as the load ranges are:
/// the next run is not the one the band was drawn on.
pub fn fit(stances: &[(usize, f64, f64)], n_classes: usize, rate: f64) -> Vec<Option<ReturnMap>> {
    (0..n_classes)
        .map(|k| {
            let (x, y): (Vec<f64>, Vec<f64>) = stances
                .iter()
                .filter(|s| s.0 == k && s.1.is_finite() && s.2.is_finite())
                .map(|s| (s.1, s.2))
                .unzip();
            let n = x.len();
            if n < MIN_STANCES {
                return None;
            }
            let mx = x.iter().sum::<f64>() / n as f64;
            let my = y.iter().sum::<f64>() / n as f64;
            let sxx: f64 = x.iter().map(|v| (v - mx) * (v - mx)).sum();
            let sxy: f64 = x.iter().zip(&y).map(|(a, b)| (a - mx) * (b - my)).sum();
            // Flights that hardly vary (steady hopping only) say nothing of the slope: then
            // the map is the mean flight after, and the band its spread.
            let slope = if sxx > n as f64 * 1e-8 {
                sxy / sxx
            } else {
                0.0
            };
            let intercept = my - slope * mx;
            let mut r: Vec<f64> = x
                .iter()
                .zip(&y)
                .map(|(a, b)| b - intercept - slope * a)
                .collect();
            r.sort_by(f64::total_cmp);
            Some(ReturnMap {
                intercept_s: intercept,
                slope,
                residual_s: crate::order_stats::widened_band(&r, rate),
                stances: n,
            })
        })
        .collect()
}

/// One foot's energy balance as the stances go by (no allocation: runs per step).
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Balance {
    /// The last liftoff, foot clock, and when it was received.
    liftoff_us: Option<u32>,
    liftoff_rx_us: u64,
    /// A stance has begun (the first touchdown has nothing before it to judge).
    started: bool,
    /// The stance in progress: its touchdown's receive time, the flight before it, and the
    /// class the texture gave it.
    touchdown_rx_us: u64,
    flight_before_us: Option<u32>,
    pub class: Option<usize>,
    /// The class whose last stance the map did not allow: its next stance is unknown.
    pub suspect: Option<usize>,
    /// The latest stance judged (at the touchdown after it).
    pub last: Option<EnergyObservation>,
}

impl Balance {
    pub fn liftoff(&mut self, at_us: u32, rx_us: u64) {
        self.liftoff_us = Some(at_us);
        self.liftoff_rx_us = rx_us;
    }

    /// A touchdown at `at_us` (foot clock), received at `rx_us`: the stance before it (step
    /// `step`) is judged against `maps`, and a new stance begins. Returns the judgement, when
    /// there was one: the stance's class and whether it lay outside that class's map.
    pub fn touchdown(
        &mut self,
        foot: u8,
        step: u16,
        at_us: u32,
        rx_us: u64,
        maps: Option<&[Option<ReturnMap>]>,
    ) -> Option<(usize, bool)> {
        let after = self.liftoff_us.map(|l| at_us.wrapping_sub(l));
        let mut judged = None;
        if self.started {
            let o = EnergyObservation {
                foot,
                step,
                class: self.class,
                flight_before_us: self.flight_before_us,
                flight_after_us: after,
                span_rx_us: (
                    self.touchdown_rx_us,
                    if after.is_some() {
                        self.liftoff_rx_us
                    } else {
                        rx_us
                    },
                ),
            };
            judged = match (o.class, o.flights_s()) {
                (Some(k), Some((b, a))) => maps
                    .and_then(|m| m.get(k).copied().flatten())
                    .map(|m| (k, !m.passes(b, a))),
                _ => None,
            };
            self.suspect = judged.filter(|&(_, outside)| outside).map(|(k, _)| k);
            self.last = Some(o);
        }
        self.started = true;
        self.touchdown_rx_us = rx_us;
        self.flight_before_us = after;
        self.liftoff_us = None;
        self.class = None;
        judged
    }

    /// Another model was installed: its class indices are not the ones held here.
    pub fn forget_classes(&mut self) {
        self.class = None;
        self.suspect = None;
    }

    /// The texture's class `k` for the stance in progress is unknown by the energy balance.
    pub fn rejects(&self, k: usize) -> bool {
        self.suspect == Some(k)
    }
}

/// One terrain's stances against its return map over a replay.
///
/// On a run over ground known to be the model's terrains, a terrain with more stances outside
/// than the model's unknown rate has a map that no longer fits the robot: fit the maps again
/// (`presrs lab energy`). What moved them on the simulator: a payload put clay's stances outside
/// and left the others' in (docs/real-robot.md), as sand does; so a run over unknown ground
/// cannot tell the two apart.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct EnergyTally {
    /// The terrain's name.
    pub terrain: String,
    /// Stances the texture gave this terrain with both flights hops (judged against the map).
    pub judged: u32,
    /// Of them, those whose flight after lay outside the map's band.
    pub outside: u32,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_fitted_map_recovers_the_line_and_bands_its_spread() {
        // after = 0.05 + 0.6 before, residuals +-2 ms alternating.
        let s: Vec<(usize, f64, f64)> = (0..100)
            .map(|i| {
                let b = 0.10 + 0.0005 * i as f64;
                let noise = if i % 2 == 0 { 0.002 } else { -0.002 };
                (1, b, 0.05 + 0.6 * b + noise)
            })
            .collect();
        let maps = fit(&s, 3, 0.02);
        assert!(maps[0].is_none() && maps[2].is_none(), "no stances, no map");
        let m = maps[1].expect("100 stances");
        assert!((m.slope - 0.6).abs() < 0.01, "{m:?}");
        assert!((m.intercept_s - 0.05).abs() < 0.002, "{m:?}");
        assert!(m.passes(0.12, 0.05 + 0.6 * 0.12));
        assert!(
            m.passes(0.12, 0.05 + 0.6 * 0.12 + 0.0025),
            "inside the widened band"
        );
        assert!(
            !m.passes(0.12, 0.05 + 0.6 * 0.12 - 0.01),
            "a stance that took 10 ms of flight"
        );
        assert_eq!(m.stances, 100);
        assert!(m.is_valid());
    }

    #[test]
    fn too_few_stances_or_steady_flights() {
        let few: Vec<_> = (0..MIN_STANCES - 1)
            .map(|i| (0, 0.1 + i as f64 * 1e-3, 0.1))
            .collect();
        assert!(fit(&few, 1, 0.02)[0].is_none());
        // Steady hopping: no slope to learn, the mean flight after and its spread.
        let steady: Vec<_> = (0..40)
            .map(|i| (0, 0.12, 0.12 + if i % 2 == 0 { 0.001 } else { -0.001 }))
            .collect();
        let m = fit(&steady, 1, 0.02)[0].expect("40 stances");
        assert_eq!(m.slope, 0.0);
        assert!(m.passes(0.12, 0.12) && !m.passes(0.12, 0.11));
    }

    #[test]
    fn a_stance_outside_its_map_makes_the_next_of_its_class_unknown() {
        let map = ReturnMap {
            intercept_s: 0.0,
            slope: 1.0,
            residual_s: [-0.005, 0.005],
            stances: 50,
        };
        let maps = [None, Some(map)];
        let mut b = Balance::default();
        // Stance 1 (class 1) after a 120 ms flight, lifts off, flies 120 ms: as the map says.
        b.touchdown(0, 1, 0, 1, Some(&maps));
        b.liftoff(200_000, 0);
        b.touchdown(0, 1, 320_000, 2, Some(&maps));
        assert_eq!(
            b.last.map(|o| o.flights_s()),
            Some(None),
            "no flight before the first"
        );
        b.class = Some(1);
        b.liftoff(500_000, 0);
        b.touchdown(0, 2, 620_000, 3, Some(&maps));
        assert!(!b.rejects(1), "120 ms after 120 ms passes");
        b.class = Some(1);
        b.liftoff(800_000, 0);
        // Flew 100 ms after 120 ms before: the ground took energy class 1 does not.
        b.touchdown(0, 3, 900_000, 4, Some(&maps));
        assert!(b.rejects(1) && !b.rejects(0));
        assert_eq!(b.last.map(|o| o.step), Some(3));
        // The texture says class 0 now: no map for it, nothing held against it.
        b.class = Some(0);
        b.liftoff(1_100_000, 0);
        b.touchdown(0, 4, 1_200_000, 5, Some(&maps));
        assert!(!b.rejects(1) && !b.rejects(0));
        // A lost liftoff edge (no liftoff heard): no flight after, no verdict.
        b.class = Some(1);
        b.touchdown(0, 5, 1_500_000, 6, Some(&maps));
        assert_eq!(b.suspect, None);
        assert_eq!(b.last.and_then(|o| o.flight_after_us), None);
    }
}
