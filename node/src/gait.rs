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

/// The gaits the controller announced (GaitStatus, at every switch and at 10 Hz), kept as
/// their last switches so that a step decided after a switch still gets the gait it touched
/// down in.
#[derive(Clone, Debug, Default)]
pub struct GaitTrack {
    /// (receive time µs, gait), oldest first; at most [`GaitTrack::KEPT`].
    switches: Vec<(u64, u8)>,
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
