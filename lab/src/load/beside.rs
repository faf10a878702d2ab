//! What runs beside the node in one measurement of `presrs lab bench-node`: each feet count
//! is measured alone, then with the part whose cost is asked for, in one run (machines are
//! noisy: a ratio means something only between runs of the same minute).

/// What runs beside the node in one measurement.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Beside {
    /// The node alone.
    Nothing,
    /// The ROS 2 bridge (`--ros2`).
    Bridge,
    /// The unknown stances kept (`--keep-unknown`).
    Keep,
}

impl Beside {
    /// The measurements of one feet count: alone, then beside the bridge or the keeper.
    pub fn plan(bridge: bool, keep: bool) -> &'static [Beside] {
        match (bridge, keep) {
            (true, _) => &[Beside::Nothing, Beside::Bridge],
            (_, true) => &[Beside::Nothing, Beside::Keep],
            _ => &[Beside::Nothing],
        }
    }

    /// The heading of its report among `runs` measurements (none when it is the only one).
    pub fn heading(self, runs: usize) -> Option<&'static str> {
        match (self, runs) {
            (_, 1) => None,
            (Beside::Bridge, _) => Some("with the ROS 2 bridge:"),
            (Beside::Keep, _) => Some("keeping unknown stances:"),
            (Beside::Nothing, _) => Some("alone:"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_part_asked_for_is_measured_after_the_node_alone() {
        assert_eq!(Beside::plan(false, false), &[Beside::Nothing]);
        assert_eq!(
            Beside::plan(true, false),
            &[Beside::Nothing, Beside::Bridge]
        );
        assert_eq!(Beside::plan(false, true), &[Beside::Nothing, Beside::Keep]);
        assert_eq!(Beside::Nothing.heading(1), None);
        assert_eq!(Beside::Keep.heading(2), Some("keeping unknown stances:"));
    }
}
