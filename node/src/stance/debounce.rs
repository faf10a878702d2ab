//! The foot's micro-switch, debounced: an edge counts once the switch has held its new state
//! for the debounce time, judged on the foot's own timestamps (FootContact and the tactile
//! header), so that a replay debounces exactly as the live run did.

/// An accepted edge of the switch.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Edge {
    /// The foot came down at `at_us` (foot clock: when the switch first read closed).
    Touchdown {
        /// Foot time of the edge.
        at_us: u32,
    },
    /// The foot left the ground at `at_us` (foot clock: when the switch first read open).
    Liftoff {
        /// Foot time of the edge.
        at_us: u32,
    },
}

/// One foot's switch: what it last read, since when, and the debounced state.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Switch {
    /// The last reading (true: closed, the foot on the ground) and when it began.
    pub raw: bool,
    pub raw_since: u32,
    /// A reading has been heard.
    pub heard: bool,
    /// The debounced state: in stance.
    pub stance: bool,
}

impl Switch {
    /// A reading of the switch at foot time `t_us` (a FootContact: the 100 Hz report or an
    /// edge); a change starts the debounce from `t_us`.
    pub fn read(&mut self, stance: bool, t_us: u32) {
        if !self.heard || stance != self.raw {
            self.raw = stance;
            self.raw_since = t_us;
            self.heard = true;
        }
    }

    /// The edge accepted by `now_us` (foot clock): a reading that differs from the state and
    /// has held for `debounce_us`. Timestamps wrap (32-bit µs, 71 minutes).
    ///
    /// `now_us` may lie before the reading: an image carries its sample time and is received
    /// whole a few ms later, after a switch edge sent in between. Such a time has seen the
    /// reading hold not at all (a wrapping difference past half the clock is negative), not
    /// for 71 minutes: taken as held, a bouncing switch's edge settled on it, before the
    /// bounce ended and with its touchdown 2^32 µs early on the receiver's clock.
    pub fn settle(&mut self, now_us: u32, debounce_us: u32) -> Option<Edge> {
        let held = now_us.wrapping_sub(self.raw_since);
        if !self.heard || self.raw == self.stance || held > i32::MAX as u32 || held < debounce_us {
            return None;
        }
        self.stance = self.raw;
        Some(if self.stance {
            Edge::Touchdown {
                at_us: self.raw_since,
            }
        } else {
            Edge::Liftoff {
                at_us: self.raw_since,
            }
        })
    }

    /// A reading differs from the debounced state and has not been accepted yet.
    pub fn pending(&self) -> bool {
        self.heard && self.raw != self.stance
    }

    /// A frame sampled at foot time `t_us` came after a liftoff edge the debounce has not
    /// confirmed yet: outside the stance unless the edge was bounce. A frame from up to
    /// `debounce_us` before the last open reading counts too: the switch's bounce at liftoff
    /// (open, closed, open again within a few ms) leaves only its last edge in `raw_since`,
    /// and a frame from between its first and last is already in flight.
    pub fn after_open_edge(&self, t_us: u32, debounce_us: u32) -> bool {
        let since = t_us.wrapping_sub(self.raw_since) as i32;
        !self.raw && since > -(debounce_us.min(i32::MAX as u32) as i32) && since < 10_000_000
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const DEBOUNCE: u32 = 5_000;

    #[test]
    fn an_edge_counts_once_it_has_held_for_the_debounce_time() {
        let mut s = Switch::default();
        s.read(true, 100_000);
        assert_eq!(s.settle(100_000, DEBOUNCE), None);
        assert_eq!(s.settle(104_999, DEBOUNCE), None);
        // Touchdown is when the switch first closed, not when the debounce ended.
        assert_eq!(
            s.settle(105_000, DEBOUNCE),
            Some(Edge::Touchdown { at_us: 100_000 })
        );
        assert!(s.stance);
        assert_eq!(s.settle(200_000, DEBOUNCE), None, "one edge, once");
    }

    #[test]
    fn bounce_shorter_than_the_debounce_is_no_edge() {
        let mut s = Switch::default();
        s.read(true, 0);
        assert!(matches!(
            s.settle(DEBOUNCE, DEBOUNCE),
            Some(Edge::Touchdown { .. })
        ));
        // Opens for 2 ms in mid-stance, closes again: the stance goes on.
        s.read(false, 50_000);
        assert_eq!(s.settle(52_000, DEBOUNCE), None);
        s.read(true, 52_000);
        assert_eq!(s.settle(60_000, DEBOUNCE), None);
        assert!(s.stance);
        // A real liftoff.
        s.read(false, 200_000);
        assert_eq!(
            s.settle(205_000, DEBOUNCE),
            Some(Edge::Liftoff { at_us: 200_000 })
        );
    }

    #[test]
    fn repeated_reports_of_one_state_do_not_restart_the_debounce() {
        let mut s = Switch::default();
        s.read(true, 0);
        s.read(true, 3_000);
        assert!(s.settle(5_000, DEBOUNCE).is_some());
    }

    #[test]
    fn the_foot_clock_wraps_without_a_false_edge() {
        let mut s = Switch::default();
        let t = u32::MAX - 1_000;
        s.read(true, t);
        assert_eq!(s.settle(t.wrapping_add(4_000), DEBOUNCE), None);
        assert_eq!(
            s.settle(t.wrapping_add(5_000), DEBOUNCE),
            Some(Edge::Touchdown { at_us: t })
        );
    }

    #[test]
    fn a_time_from_before_the_reading_has_not_seen_it_hold() {
        // An image sampled 3 ms before the switch closed, received after the close: its
        // timestamp settles nothing, before and after the clock wraps.
        for t in [100_000, 1_500, u32::MAX - 1_000] {
            let mut s = Switch::default();
            s.read(true, t);
            assert_eq!(s.settle(t.wrapping_sub(3_000), DEBOUNCE), None, "t {t}");
            assert!(!s.stance);
            assert_eq!(
                s.settle(t.wrapping_add(DEBOUNCE), DEBOUNCE),
                Some(Edge::Touchdown { at_us: t })
            );
        }
    }

    #[test]
    fn a_frame_after_an_unconfirmed_liftoff_is_outside_the_stance() {
        let mut s = Switch::default();
        s.read(true, 0);
        s.settle(DEBOUNCE, DEBOUNCE);
        assert!(!s.after_open_edge(100_000, DEBOUNCE));
        s.read(false, 200_000);
        assert!(s.after_open_edge(201_000, DEBOUNCE));
        // Bounce: it had opened at 197 ms, closed for a ms and opened again at 200 ms; a frame
        // from between them is in flight.
        assert!(s.after_open_edge(198_000, DEBOUNCE));
        assert!(!s.after_open_edge(190_000, DEBOUNCE));
        // Timestamps 10 s or more from the edge (another stance, a wrapped clock) are not
        // judged by it.
        assert!(!s.after_open_edge(199_000 + 20_000_000, DEBOUNCE));
    }
}
