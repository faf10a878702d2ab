//! Feet that are not the paper's: a rule fitted to the paper's hopper foot (full load at about
//! 70 ms, the footprint filling the array but for three rows and six columns, a crisp switch)
//! failed on every foot built by others. These are the ways they differ, for the simulated
//! hopper to wear: a foot that rolls on heel first, one that loads slowly, a footprint off the
//! array's centre or smaller than it, a weaker sensor, dead lines from the start, a switch that
//! bounces more, and a foot clock that starts near its 32-bit wrap and stamps each image at its
//! sample time, some milliseconds before it is sent.
//!
//! [`FootModel::PRESETS`] names the feet `presrs lab feet` walks the README's path on;
//! [`FootModel::paper`] is the simulator's own foot, and leaves every run as it was.

use serde::{Deserialize, Serialize};

use crate::skin::Footprint;

/// How a simulated foot presses its array and reports its switch.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FootModel {
    /// Its name in tables.
    pub name: String,
    /// The foot base on the array: rows `r0..r0+h`, columns `c0..c0+w` (the paper's: 0, 6, 41,
    /// 38).
    pub footprint: [usize; 4],
    /// Seconds from touchdown until the hopper's load is all on the array (0: at once, as the
    /// paper's stiff foot); the load grows in proportion meanwhile.
    pub ramp_s: f64,
    /// During the ramp the footprint grows row by row from the heel (row 0), each loaded row
    /// at its full pressure: a foot that rolls on.
    pub roll: bool,
    /// The sensor's counts per unit pressure against the paper's (0.5: half as many counts, the
    /// same electronic noise).
    pub gain: f64,
    /// Sensels on dead rows and columns from the start, percent (eq. 6).
    pub dead_pct: f64,
    /// Switch bounce: the most reversals at each edge (the paper's foot: 3, within 2 ms).
    pub bounce_max: u8,
    /// The foot's clock at simulated time 0, µs (near 2^32: it wraps within the run).
    pub clock_base_us: u32,
    /// Each image is stamped this long before it is sent (its sample time; the array's
    /// read-out and the transfer take the rest), µs.
    pub sample_lead_us: u32,
}

impl Default for FootModel {
    fn default() -> Self {
        Self::paper()
    }
}

impl FootModel {
    /// The simulator's own foot, as the paper's hopper had it.
    pub fn paper() -> Self {
        Self {
            name: "paper".into(),
            footprint: [0, 6, 41, 38],
            ramp_s: 0.0,
            roll: false,
            gain: 1.0,
            dead_pct: 0.0,
            bounce_max: 3,
            clock_base_us: 0,
            sample_lead_us: 0,
        }
    }

    /// The feet `presrs lab feet` walks (besides the paper's): each differs from the paper's in
    /// one way, the rolling one in two (it also bounces and wraps its clock).
    pub fn presets() -> Vec<FootModel> {
        let p = Self::paper();
        vec![
            p.clone(),
            Self {
                name: "rolls on (full at 120 ms)".into(),
                ramp_s: 0.12,
                roll: true,
                bounce_max: 5,
                clock_base_us: u32::MAX - 3_000_000,
                sample_lead_us: 4_000,
                ..p.clone()
            },
            Self {
                name: "loads slowly (full at 150 ms)".into(),
                ramp_s: 0.15,
                ..p.clone()
            },
            Self {
                name: "off-centre (rows 10-43, columns 8-37)".into(),
                footprint: [10, 8, 34, 30],
                ramp_s: 0.08,
                ..p.clone()
            },
            Self {
                name: "small (24x24 in the middle)".into(),
                footprint: [10, 10, 24, 24],
                ..p.clone()
            },
            Self {
                name: "weak (half the gain)".into(),
                gain: 0.5,
                ..p.clone()
            },
            Self {
                name: "dead lines (5%)".into(),
                dead_pct: 5.0,
                ..p
            },
        ]
    }

    /// The foot base as the skin takes it.
    pub fn base(&self) -> Footprint {
        let [r0, c0, h, w] = self.footprint;
        Footprint::Ellipse { r0, c0, h, w }
    }

    /// The share of the hopper's load on the array `tau_s` after touchdown.
    pub fn load_share(&self, tau_s: f64) -> f64 {
        if self.roll || self.ramp_s <= 0.0 {
            return 1.0;
        }
        (tau_s / self.ramp_s).clamp(0.0, 1.0)
    }

    /// Rolling on, `tau_s` after touchdown: the rows from this one on carry nothing yet
    /// (`None`: every row is down).
    pub fn rolled_from_row(&self, tau_s: f64) -> Option<usize> {
        if !self.roll || self.ramp_s <= 0.0 || tau_s >= self.ramp_s {
            return None;
        }
        let [r0, _, h, _] = self.footprint;
        Some(r0 + ((tau_s / self.ramp_s) * h as f64).ceil() as usize)
    }

    /// The foot clock at simulated time `t_us`.
    pub fn clock(&self, t_us: u64) -> u32 {
        self.clock_base_us.wrapping_add(t_us as u32)
    }

    /// A foot that cannot be simulated, named by its field.
    pub fn validate(&self) -> Result<(), String> {
        let [r0, c0, h, w] = self.footprint;
        let bad = if h < 4 || w < 4 || r0 + h > 44 || c0 + w > 44 {
            Some("footprint: rows r0..r0+h and columns c0..c0+w inside 44x44, h and w >= 4")
        } else if !(0.0..=1.0).contains(&self.ramp_s) {
            Some("ramp_s: 0..=1")
        } else if !(0.05..=4.0).contains(&self.gain) {
            Some("gain: 0.05..=4")
        } else if !(0.0..=100.0).contains(&self.dead_pct) {
            Some("dead_pct: 0..=100")
        } else if self.sample_lead_us > 9_000 {
            Some("sample_lead_us: 0..=9000 (an image is sent within its 10 ms frame)")
        } else {
            None
        };
        bad.map_or(Ok(()), |b| Err(format!("foot `{}`: {b}", self.name)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_paper_foot_changes_nothing_and_the_others_differ_as_named() {
        let p = FootModel::paper();
        assert_eq!(p.load_share(0.0), 1.0);
        assert_eq!(p.rolled_from_row(0.01), None);
        assert_eq!(p.clock(1234), 1234);
        assert_eq!(p.base(), Footprint::FOOT);
        let feet = FootModel::presets();
        for f in &feet {
            f.validate().unwrap();
        }
        let roll = &feet[1];
        assert_eq!(roll.rolled_from_row(0.0), Some(0));
        assert_eq!(roll.rolled_from_row(0.06), Some(21));
        assert_eq!(roll.rolled_from_row(0.12), None);
        assert_eq!(roll.clock(3_000_001), 0, "wraps 3 s into the run");
        let slow = &feet[2];
        assert!((slow.load_share(0.075) - 0.5).abs() < 1e-12);
        let mut bad = FootModel::paper();
        bad.footprint = [20, 0, 30, 10];
        assert!(bad.validate().unwrap_err().contains("footprint"));
    }
}
