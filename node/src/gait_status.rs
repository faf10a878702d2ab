//! The gait the robot is running, as the controller announces it on the bus (GaitStatus, at
//! every switch and at 10 Hz): what `presrs capture` records per step and `presrs node
//! --replay` counts unknowns by. A terrain met in a gait the model was not trained in can look
//! new (docs/real-robot.md, "A gait the model never saw"); knowing the gait tells that apart
//! from new ground.

use protocol::Stamped;
use protocol::ids::{IdConfig, MessageKind};
use protocol::messages::{Message, decode};

/// `G1`.. for a gait the controller announced, `no GaitStatus` for a step without one.
pub fn gait_name(gait: Option<u8>) -> String {
    gait.map_or_else(|| "no GaitStatus".to_string(), |g| format!("G{g}"))
}

/// Steps decided in one gait, and those of them called unknown: where a run's unknowns fall.
/// Unknowns that gather in a gait the model was not trained in are the gait's, not the
/// ground's: capture that gait (docs/real-robot.md, "Record the whole bus").
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct GaitCount {
    /// The gait (`None`: not known, before the first GaitStatus).
    pub gait: Option<u8>,
    /// Steps (or images) in it.
    pub steps: usize,
    /// Of them, called unknown.
    pub unknown: usize,
}

/// Adds `steps` steps of `gait`, `unknown` of them unknown, to `counts`, which stays in gait
/// order with the steps of no known gait last.
pub fn add_count(counts: &mut Vec<GaitCount>, gait: Option<u8>, steps: usize, unknown: usize) {
    let key = |g: Option<u8>| g.map_or(256, u16::from);
    match counts.binary_search_by_key(&key(gait), |c| key(c.gait)) {
        Ok(i) => {
            counts[i].steps += steps;
            counts[i].unknown += unknown;
        }
        Err(i) => counts.insert(
            i,
            GaitCount {
                gait,
                steps,
                unknown,
            },
        ),
    }
}

/// Steps and unknowns per gait as a node decides them: counted on the hot path (a decision
/// in, a count up) without allocating, then read as [`GaitCount`]s for a report. The gait a
/// step is counted in is the one in force when it is decided, as `presrs node --replay` and the
/// live node's log both count.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct GaitTally {
    /// [steps, unknown] per gait id; index 0 holds the steps before any GaitStatus (gait 0 is
    /// the protocol's "none").
    counts: Box<[[u64; 2]; 256]>,
}

impl Default for GaitTally {
    fn default() -> Self {
        Self {
            counts: Box::new([[0; 2]; 256]),
        }
    }
}

impl GaitTally {
    /// One step decided in `gait` (`None`: before any GaitStatus), `unknown` or not.
    pub fn add(&mut self, gait: Option<u8>, unknown: bool) {
        let c = &mut self.counts[gait.map_or(0, usize::from)];
        c[0] += 1;
        c[1] += unknown as u64;
    }

    /// What was counted after `earlier` (a copy of this tally taken before).
    pub fn since(&self, earlier: &GaitTally) -> GaitTally {
        let mut d = self.clone();
        for (c, e) in d.counts.iter_mut().zip(earlier.counts.iter()) {
            c[0] = c[0].saturating_sub(e[0]);
            c[1] = c[1].saturating_sub(e[1]);
        }
        d
    }

    /// Steps called unknown, over all gaits.
    pub fn unknown(&self) -> u64 {
        self.counts.iter().map(|c| c[1]).sum()
    }

    /// The gaits with steps, in gait order, the steps of no known gait last; empty when no
    /// step had a gait (a bus without GaitStatus has nothing to say per gait).
    pub fn counts(&self) -> Vec<GaitCount> {
        let mut v = Vec::new();
        for (g, c) in self.counts.iter().enumerate().filter(|(_, c)| c[0] > 0) {
            let gait = (g > 0).then_some(g as u8);
            add_count(&mut v, gait, c[0] as usize, c[1] as usize);
        }
        if v.iter().all(|c| c.gait.is_none()) {
            v.clear();
        }
        v
    }
}

/// `G1 3/103, G2 0/67 (the model was not trained in it)`: unknown steps of all steps per gait,
/// naming the gaits `model_gaits` (the model's, when it says) lacks.
pub fn describe_counts(counts: &[GaitCount], model_gaits: Option<&[u8]>) -> String {
    let mut s = String::new();
    for (i, g) in counts.iter().enumerate() {
        if i > 0 {
            s.push_str(", ");
        }
        s.push_str(&format!("{} {}/{}", gait_name(g.gait), g.unknown, g.steps));
        if let (Some(gait), Some(trained)) = (g.gait, model_gaits)
            && !trained.contains(&gait)
        {
            s.push_str(" (the model was not trained in it)");
        }
    }
    s
}

/// The gaits the controller announced (GaitStatus, at every switch and at 10 Hz), kept as
/// their last switches so that a step decided after a switch still gets the gait it touched
/// down in.
#[derive(Clone, Debug)]
pub struct GaitTrack {
    /// (receive time µs, gait), oldest first; at most [`GaitTrack::KEPT`], allocated once so
    /// that following the bus never allocates.
    switches: Vec<(u64, u8)>,
}

impl Default for GaitTrack {
    fn default() -> Self {
        Self {
            switches: Vec::with_capacity(Self::KEPT),
        }
    }
}

impl GaitTrack {
    /// Switches kept. A step is decided within a stance of its touchdown (well under a second);
    /// at most a switch per stance, eight reach back further than any step waits.
    pub const KEPT: usize = 8;

    /// Takes the gait from a GaitStatus frame (any other frame is not looked at beyond its
    /// identifier). A malformed GaitStatus says nothing about the gait: the last one stands.
    pub fn on_frame(&mut self, st: &Stamped, ids: &IdConfig) {
        if let Some((MessageKind::GaitStatus, _)) =
            ids.lookup(st.frame.raw_id(), st.frame.is_extended())
            && let Ok(Some((_, Message::GaitStatus(g)))) = decode(&st.frame, ids)
            && g.gait != 0
        {
            self.observe(st.t_us, g.gait);
        }
    }

    /// The latest gait, if any GaitStatus came.
    pub fn current(&self) -> Option<u8> {
        self.switches.last().map(|&(_, g)| g)
    }

    /// The controller said `gait` is in force at `t_us`.
    pub fn observe(&mut self, t_us: u64, gait: u8) {
        if self.switches.last().is_some_and(|&(_, g)| g == gait) {
            return;
        }
        if self.switches.len() == Self::KEPT {
            self.switches.remove(0);
        }
        self.switches.push((t_us, gait));
    }

    /// The gait in force at `t_us`; `None` before the first GaitStatus, or earlier than the
    /// switches kept reach.
    pub fn at(&self, t_us: u64) -> Option<u8> {
        self.switches
            .iter()
            .rev()
            .find(|&&(t, _)| t <= t_us)
            .map(|&(_, g)| g)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_step_gets_the_gait_in_force_at_its_touchdown() {
        let mut g = GaitTrack::default();
        assert_eq!(g.at(5), None, "no GaitStatus yet");
        g.observe(10, 2);
        g.observe(20, 2); // the 10 Hz repeat: no switch
        g.observe(30, 3);
        assert_eq!(
            (g.at(9), g.at(10), g.at(29), g.at(30)),
            (None, Some(2), Some(2), Some(3))
        );
        // A step decided after later switches still gets its own touchdown's gait.
        for (i, gait) in [1, 2, 1, 2, 1, 2, 1].into_iter().enumerate() {
            g.observe(100 + i as u64, gait);
        }
        assert_eq!(g.switches.len(), GaitTrack::KEPT);
        assert_eq!(g.at(100), Some(1));
        // Older than every switch kept: not known, rather than a wrong gait.
        assert_eq!(g.at(15), None);
    }

    #[test]
    fn counts_stay_in_gait_order_with_the_unknown_gait_last() {
        let mut v = Vec::new();
        add_count(&mut v, None, 1, 0);
        add_count(&mut v, Some(3), 2, 1);
        add_count(&mut v, Some(1), 4, 0);
        add_count(&mut v, Some(3), 1, 1);
        let got: Vec<(Option<u8>, usize, usize)> =
            v.iter().map(|c| (c.gait, c.steps, c.unknown)).collect();
        assert_eq!(got, [(Some(1), 4, 0), (Some(3), 3, 2), (None, 1, 0)]);
    }

    #[test]
    fn a_tally_counts_per_gait_and_says_nothing_without_gait_status() {
        let mut t = GaitTally::default();
        t.add(None, false);
        assert!(t.counts().is_empty(), "no GaitStatus: nothing per gait");
        t.add(Some(3), true);
        t.add(Some(1), false);
        t.add(Some(3), false);
        assert_eq!(t.unknown(), 1);
        let got: Vec<(Option<u8>, usize, usize)> = t
            .counts()
            .iter()
            .map(|c| (c.gait, c.steps, c.unknown))
            .collect();
        assert_eq!(got, [(Some(1), 1, 0), (Some(3), 2, 1), (None, 1, 0)]);
        assert_eq!(
            describe_counts(&t.counts(), Some(&[1, 2])),
            "G1 0/1, G3 1/2 (the model was not trained in it), no GaitStatus 0/1"
        );
        assert_eq!(
            describe_counts(&t.counts(), None),
            "G1 0/1, G3 1/2, no GaitStatus 0/1"
        );
    }

    #[test]
    fn the_gait_comes_from_gait_status_frames_only() {
        use protocol::messages::{GaitReason, GaitStatus};
        let ids = IdConfig::default();
        let status = GaitStatus {
            gait: 3,
            terrain: 1,
            omega_rad_s: 20.0,
            beta_des_rad: 0.3,
            reason: GaitReason::Terrain,
            foot: 0,
        };
        let mut g = GaitTrack::default();
        let frame = Message::GaitStatus(status);
        let st = Stamped {
            t_us: 50,
            frame: frame.to_frame(&ids, 0).unwrap(),
        };
        g.on_frame(&st, &ids);
        assert_eq!((g.current(), g.at(50)), (Some(3), Some(3)));
        // Gait 0 ("none") and a malformed frame leave the last gait standing.
        let none = Message::GaitStatus(GaitStatus { gait: 0, ..status });
        g.on_frame(
            &Stamped {
                t_us: 60,
                frame: none.to_frame(&ids, 0).unwrap(),
            },
            &ids,
        );
        let id = st.frame.id();
        let short = protocol::frame::CanFrame::classic(id, &[9, 9]).unwrap();
        g.on_frame(
            &Stamped {
                t_us: 70,
                frame: short,
            },
            &ids,
        );
        assert_eq!(g.at(80), Some(3));
    }
}
