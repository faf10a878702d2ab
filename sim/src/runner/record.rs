//! A simulated run written as a candump log, with the terrain each step stood on (its truth).

use super::{SimConfig, SimRobot, StepTruth};
use protocol::emit::Emit;

/// The log's clock at simulated time 0 for [`record`]: 2023-11-14, a plausible candump time.
pub const LOG_EPOCH_US: u64 = 1_700_000_000_000_000;

/// Runs the robot alone (no controller: each leg holds its gait) for `duration_us` of simulated
/// time and hands every frame it sends to `emit`, stamped on a log clock starting at
/// [`LOG_EPOCH_US`], as `candump -L` would have recorded it. Returns the ground truth of every
/// step, touchdown times on the same log clock. `observe` sees the robot every 10 ms, with
/// the log clock's time.
pub fn record(
    cfg: SimConfig,
    seed: u64,
    duration_us: u64,
    observe: &mut dyn FnMut(u64, &SimRobot),
    emit: &mut dyn Emit<protocol::Stamped>,
) -> Vec<StepTruth> {
    let mut robot = SimRobot::new(cfg, seed);
    let mut t = 0;
    while t < duration_us {
        t = (t + 1000).min(duration_us);
        if t.is_multiple_of(10_000) {
            observe(LOG_EPOCH_US + t, &robot);
        }
        robot.advance_to(t, &mut |frame| {
            emit.emit(protocol::Stamped {
                t_us: LOG_EPOCH_US + t,
                frame,
            })
        });
    }
    robot
        .steps
        .iter()
        .map(|s| StepTruth {
            touchdown_us: LOG_EPOCH_US + s.touchdown_us,
            ..*s
        })
        .collect()
}

/// [`record`] until the robot has made `steps` steps and the last one is over (the next
/// touchdown, or a second after the last; at most `steps` seconds and 20 more of simulated
/// time): a session of a given number of stances. Returns the truth of those `steps` (fewer
/// when the robot fell short of them in time).
pub fn record_steps(
    cfg: SimConfig,
    seed: u64,
    steps: usize,
    emit: &mut dyn Emit<protocol::Stamped>,
) -> Vec<StepTruth> {
    let mut robot = SimRobot::new(cfg, seed);
    let limit = (steps as u64 + 20) * 1_000_000;
    let (mut t, mut ended) = (0, None);
    while t < limit && ended.is_none_or(|end| t < end) {
        t += 1000;
        robot.advance_to(t, &mut |frame| {
            emit.emit(protocol::Stamped {
                t_us: LOG_EPOCH_US + t,
                frame,
            })
        });
        if ended.is_none() && robot.steps.len() >= steps {
            ended = Some(t + 1_000_000);
        }
        if robot.steps.len() > steps {
            break;
        }
    }
    robot
        .steps
        .iter()
        .take(steps)
        .map(|s| StepTruth {
            touchdown_us: LOG_EPOCH_US + s.touchdown_us,
            ..*s
        })
        .collect()
}

/// [`record`] as a candump log (`candump -L` lines, interface `can0`) written to `w`, every
/// frame also handed to `tap` (a live recording). Returns the frames written and the steps'
/// truth; the first write error stops the writing and is returned.
pub fn record_candump(
    cfg: SimConfig,
    seed: u64,
    duration_us: u64,
    observe: &mut dyn FnMut(u64, &SimRobot),
    tap: &mut dyn FnMut(&protocol::Stamped),
    mut w: &mut dyn std::io::Write,
) -> std::io::Result<(u64, Vec<StepTruth>)> {
    let mut err = None;
    let mut frames = 0u64;
    let steps = record(cfg, seed, duration_us, observe, &mut |st| {
        tap(&st);
        if err.is_none() {
            match protocol::candump::write_record(&mut w, "can0", &st) {
                Ok(()) => frames += 1,
                Err(e) => err = Some(e),
            }
        }
    });
    match err {
        Some(e) => Err(e),
        None => w.flush().map(|()| (frames, steps)),
    }
}

/// Labels (`start_s,end_s,terrain,foot` lines, the format `presrs capture --labels` reads) for
/// the steps of a [`record`]: one range per run of steps on one terrain, from the first
/// touchdown to the next terrain's first touchdown (the last to `end_us`).
pub fn truth_labels(steps: &[StepTruth], end_us: u64) -> String {
    let mut out = String::from("start_s,end_s,terrain,foot\n");
    let feet = steps.iter().map(|s| s.foot).max().map_or(0, |m| m + 1);
    for foot in 0..feet {
        let mine: Vec<&StepTruth> = steps.iter().filter(|s| s.foot == foot).collect();
        let mut i = 0;
        while i < mine.len() {
            let mut j = i;
            while j + 1 < mine.len() && mine[j + 1].terrain == mine[i].terrain {
                j += 1;
            }
            let end = mine.get(j + 1).map_or(end_us, |s| s.touchdown_us);
            out += &format!(
                "{},{},{},{foot}\n",
                protocol::candump::format_seconds(mine[i].touchdown_us),
                protocol::candump::format_seconds(end),
                mine[i].terrain.name()
            );
            i = j + 1;
        }
    }
    out
}
