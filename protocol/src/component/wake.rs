//! When [`run`](super::run) sleeps, warms a component up and polls for the frame the component
//! must answer at once ([`Component::expected_frame_us`](super::Component::expected_frame_us)):
//! one plan per pass through the runner's loop, from the expected time and the runner's clock.
//! Why each constant has its value: docs/decisions/node-wake.md.

use crate::quantile::StepQuantile;

/// How long before a component's expected frame the runner wakes to warm it up, µs: more than
/// a wake from sleep, a cold warm-up and the poll's lead take.
pub const PRE_WAKE_US: u64 = 500;

/// How long before the expected time the runner polls the bus, µs: the expected time is when
/// the component expects the frame, not the earliest it can come. The sleep before it ends
/// early by the thread's measured oversleep, so the poll starts here.
pub const POLL_LEAD_US: u64 = 50;

/// How long past the expected time the runner polls before it sleeps again, µs: a frame that
/// comes later than that (a late sender, a busy bus) wakes the thread as before.
pub const POLL_AFTER_US: u64 = 300;

/// While the expected frame is further than [`PRE_WAKE_US`] away, the runner sleeps this long
/// at a time without watching the bus, then takes every frame queued, µs: the frames before it
/// need no instant answer, and a wake-up per burst cost more CPU than the frames' work.
pub const COALESCE_US: u64 = 4_000;

/// The thread's timer slack while it waits for expected frames, ns (Linux's default: 50 µs).
const TIMER_SLACK_NS: u64 = 1_000;

/// The thread's oversleep, µs: its running 7/8 quantile (start, step down, step up), at most
/// `MAX_OVERSLEEP_US` so that the poll starts after the warm-up.
const OVERSLEEP: (i64, i64, i64) = (100, 2, 14);
const MAX_OVERSLEEP_US: i64 = 300;

/// What the runner does before it takes frames, given the expected time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Plan {
    /// Far from it: sleep in batches, for at most this long (µs), without watching the bus.
    Batch { for_us: u64 },
    /// Warmed up: sleep (woken by a frame) for at most this long (µs), to the poll's start.
    Sleep { for_us: u64, until_us: u64 },
    /// Poll the bus for this long (µs) or until a frame comes.
    Poll { for_us: u64 },
    /// Past the poll: wait for frames as without an expected time.
    AsUsual,
}

/// The runner's wake state: the expected time it last warmed up for and its oversleep.
#[derive(Debug)]
pub(super) struct Wake {
    oversleep: StepQuantile,
    warmed_for: Option<u64>,
}

impl Default for Wake {
    fn default() -> Self {
        Self {
            oversleep: StepQuantile::new(OVERSLEEP.0, OVERSLEEP.1, OVERSLEEP.2),
            warmed_for: None,
        }
    }
}

impl Wake {
    /// True once per expected time `at`, from [`PRE_WAKE_US`] before it to the poll's end: the
    /// component warms up now. The first also sets the thread's timer slack.
    pub(super) fn warm_up_due(&mut self, at: u64, now: u64) -> bool {
        let near = now + PRE_WAKE_US >= at && now <= at.saturating_add(POLL_AFTER_US);
        if !near || self.warmed_for == Some(at) {
            return false;
        }
        if self.warmed_for.is_none() {
            set_timer_slack();
        }
        self.warmed_for = Some(at);
        true
    }

    /// What to do at `now` for a frame expected at `at` (both on the runner's clock, µs).
    pub(super) fn plan(&self, at: u64, now: u64) -> Plan {
        if now + PRE_WAKE_US < at {
            return Plan::Batch {
                for_us: at - PRE_WAKE_US - now,
            };
        }
        let early = self.oversleep.get().clamp(0, MAX_OVERSLEEP_US) as u64;
        let wake = at.saturating_sub(POLL_LEAD_US + early);
        let end = at.saturating_add(POLL_AFTER_US);
        if now < wake {
            Plan::Sleep {
                for_us: wake - now,
                until_us: wake,
            }
        } else if now < end {
            Plan::Poll { for_us: end - now }
        } else {
            Plan::AsUsual
        }
    }

    /// A sleep planned to end at `until_us` ran out at `now`.
    pub(super) fn slept(&mut self, until_us: u64, now: u64) {
        let late = (now as i64 - until_us as i64).clamp(0, MAX_OVERSLEEP_US);
        self.oversleep.observe(late);
    }
}

/// Sets the calling thread's timer slack to [`TIMER_SLACK_NS`] (Linux; elsewhere nothing).
fn set_timer_slack() {
    #[cfg(target_os = "linux")]
    // SAFETY: PR_SET_TIMERSLACK reads one integer and sets the calling thread's slack only.
    unsafe {
        libc::prctl(
            libc::PR_SET_TIMERSLACK,
            TIMER_SLACK_NS as libc::c_ulong,
            0 as libc::c_ulong,
            0 as libc::c_ulong,
            0 as libc::c_ulong,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn far_batches_near_warms_up_once_then_sleeps_polls_and_gives_up() {
        let mut w = Wake::default();
        let at = 1_000_000;
        assert_eq!(w.plan(at, at - 2_000), Plan::Batch { for_us: 1_500 });
        assert!(!w.warm_up_due(at, at - 2_000));
        assert!(w.warm_up_due(at, at - 400));
        assert!(!w.warm_up_due(at, at - 300), "once per expected time");
        // The poll starts POLL_LEAD_US before the time, less the oversleep (100 us at first).
        let start = at - POLL_LEAD_US - 100;
        assert_eq!(
            w.plan(at, at - 400),
            Plan::Sleep {
                for_us: start - (at - 400),
                until_us: start
            }
        );
        assert_eq!(w.plan(at, start), Plan::Poll { for_us: 450 });
        assert_eq!(w.plan(at, at + POLL_AFTER_US), Plan::AsUsual);
        assert!(!w.warm_up_due(at + 10_000, at), "too early for the next");
    }

    #[test]
    fn the_poll_starts_earlier_by_the_oversleep_measured() {
        let mut w = Wake::default();
        for _ in 0..200 {
            w.slept(0, 40);
        }
        let at = 1_000_000;
        let Plan::Sleep { until_us, .. } = w.plan(at, at - 400) else {
            panic!("{:?}", w.plan(at, at - 400));
        };
        assert!((at - POLL_LEAD_US - 54..=at - POLL_LEAD_US - 26).contains(&until_us));
    }
}
