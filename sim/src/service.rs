//! The simulator as a process runs it: on a bus, with simulated time following the wall clock
//! (times `speed`), publishing FootContact, LegState and the tactile frames and obeying
//! LegCommand.
//!
//! Because the simulator knows the truth, it also scores what others put on the bus: every
//! TerrainClass it hears is matched to the stance in progress on that foot, with the gait the
//! leg ran, as a [`StepRecord`]; [`run`] returns them in a [`SimReport`].

use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use protocol::bus::BusSource;
use protocol::component::{self, Component, Outbox};
use protocol::ids::MessageKind;
use protocol::messages::{self, Message};
use protocol::{IdConfig, Stamped, TerrainCatalog};

use crate::runner::{SimConfig, SimRobot};

/// One step as the simulator saw it: the truth, and what the node said about it.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct StepRecord {
    /// Robot time when the TerrainClass arrived, s.
    pub t_s: f64,
    /// The foot.
    pub foot: u8,
    /// The node's step counter from its TerrainClass.
    pub step: u16,
    /// The terrain under the foot.
    pub truth: String,
    /// The terrain the node reported (its catalog name, or "unknown").
    pub classified: String,
    /// The node's confidence, percent.
    pub confidence_pct: f64,
    /// The sensor damage the node reported, percent.
    pub damage_pct: f64,
    /// The gait the leg ran when the TerrainClass arrived.
    pub gait: u8,
    /// Forward speed over the stride that ended at this step's touchdown, m/s.
    pub speed_m_s: f64,
}

impl StepRecord {
    /// The record of `tc` from `foot` at `t_us`, with what `robot` knows.
    pub fn of(
        robot: &SimRobot,
        foot: u8,
        tc: &messages::TerrainClass,
        t_us: u64,
        catalog: &TerrainCatalog,
    ) -> Self {
        let step = robot.step_at(foot, t_us);
        let truth = step.map_or("?", |s| s.terrain.name());
        // The stride's speed (touchdown to touchdown), not the body's at this moment: the
        // TerrainClass comes at mid-stance, where the body is slowest (about 25% below).
        let speed = step.map_or(0.0, |s| s.speed_m_s);
        Self {
            t_s: t_us as f64 * 1e-6,
            foot,
            step: tc.step,
            truth: truth.to_string(),
            classified: catalog.describe(tc.terrain),
            confidence_pct: tc.confidence_pct,
            damage_pct: tc.damage_pct,
            gait: robot.gait_in_effect(foot).unwrap_or(0),
            speed_m_s: speed,
        }
    }

    /// The node named the terrain under the foot (every score of a run counts these).
    pub fn is_correct(&self) -> bool {
        self.truth == self.classified
    }
}

/// One step's line of a run's live log (`presrs demo`).
impl std::fmt::Display for StepRecord {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // An unknown step has no confidence: the frame's is the rejected class's.
        let confidence = if self.classified == protocol::Terrain::UNKNOWN.name() {
            "-".to_string()
        } else {
            format!("{:.1}%", self.confidence_pct)
        };
        write!(
            f,
            "t {:7.2} s  step {:4}  true {:<8} classified {:<8} {confidence:>6}  gait G{}  {:.2} m/s",
            self.t_s, self.step, self.truth, self.classified, self.gait, self.speed_m_s
        )
    }
}

/// A leg of motors: how the LegState its bridge sends agrees with the simulator's truth,
/// while the bridge drives the leg. Each is compared with the nearest truth of the 3 ms before
/// its stamp where that stamp is on the simulator's clock (one process: the lock-step demo),
/// else (processes on a bus each keep their own clock) of the last 50 ms, so that the delay of
/// the bridge and the bus (at touchdown and liftoff the massless simulated leg jumps to its new
/// set point) is not counted as the encoders' error.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct LegStateCheck {
    /// LegState frames heard.
    pub frames: u64,
    /// Of them, compared with the truth just before their own timestamp (the same clock).
    pub at_timestamp: u64,
    /// Angle error, rad: median, 95th percentile, largest.
    pub angle_err_rad: [f64; 3],
    /// Length error, m: median, 95th percentile, largest.
    pub length_err_m: [f64; 3],
    #[serde(skip)]
    errors: Vec<(f64, f64)>,
}

impl LegStateCheck {
    fn add(&mut self, angle_err: f64, length_err: f64, at_timestamp: bool) {
        self.frames += 1;
        self.at_timestamp += at_timestamp as u64;
        self.errors.push((angle_err, length_err));
    }

    fn summarize(&mut self) {
        let pct = |mut v: Vec<f64>| {
            v.sort_by(f64::total_cmp);
            let at = |q: f64| {
                v.get(((v.len() as f64 - 1.0) * q).round() as usize)
                    .copied()
                    .unwrap_or(0.0)
            };
            [at(0.5), at(0.95), at(1.0)]
        };
        self.angle_err_rad = pct(self.errors.iter().map(|e| e.0).collect());
        self.length_err_m = pct(self.errors.iter().map(|e| e.1).collect());
    }
}

/// What one run of the simulator saw (`presrs lab sim --report`'s file).
#[derive(Debug, serde::Serialize)]
pub struct SimReport {
    /// Robot time run, s.
    pub simulated_s: f64,
    /// Wall time taken, s.
    pub wall_s: f64,
    /// Touchdowns over all feet.
    pub touchdowns: usize,
    /// Times a simulated hopper fell (and was set back on its feet).
    pub falls: u64,
    /// When, robot time (s).
    pub fall_times_s: Vec<f64>,
    /// Frames the bus refused.
    pub send_errors: u64,
    /// Every TerrainClass heard.
    pub steps: Vec<StepRecord>,
    /// A leg of motors (`--leg`): its bridge's LegState against the truth.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub leg_state: Option<LegStateCheck>,
}

impl std::fmt::Display for SimReport {
    /// One line: time simulated against wall time, touchdowns, falls, the TerrainClass heard
    /// and how many named the terrain under the foot, send errors.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let n = self.steps.len();
        let correct = self.steps.iter().filter(|s| s.is_correct()).count();
        write!(
            f,
            "{:.1} s simulated in {:.1} s wall; {} touchdowns, {} falls; {n} TerrainClass \
             heard, {correct} correct",
            self.simulated_s, self.wall_s, self.touchdowns, self.falls
        )?;
        if n > 0 {
            write!(f, " ({:.1}%)", 100.0 * correct as f64 / n as f64)?;
        }
        write!(f, "; {} send errors", self.send_errors)
    }
}

/// How a run goes besides the robot's config.
#[derive(Clone, Debug)]
pub struct RunOptions {
    /// Robot time per wall time (1 = real time).
    pub speed: f64,
    /// Stop after this much robot time, s (`None`: until `stop`).
    pub duration_s: Option<f64>,
    /// The simulator's seed.
    pub seed: u64,
}

/// Milliseconds of a leg of motors' truth kept to judge its bridge's LegState.
const LEG_HISTORY: usize = 64;

/// The most robot time one pass of the simulator covers, µs: commands are read between passes.
const MAX_LAG_US: u64 = 2_000;

/// The simulated robot as a part on the bus ([`Component`]): its robot time follows the
/// runner's clock in steps of at least 1 ms, it sends what its feet and legs send, obeys
/// LegCommand, and scores every TerrainClass it hears.
pub struct SimService<'a> {
    robot: SimRobot,
    ids: IdConfig,
    catalog: &'a TerrainCatalog,
    observe: &'a mut dyn FnMut(u64, &SimRobot),
    records: Vec<StepRecord>,
    end_us: Option<u64>,
    t_us: u64,
    /// Robot time given up because the machine could not keep up (see `tick`).
    stretched_us: u64,
    /// The foot whose leg is motors, and its LegState check.
    motor_leg: Option<(u8, LegStateCheck)>,
    /// That leg's truth over the last [`LEG_HISTORY`] ms of robot time: (µs, angle, length).
    leg_history: std::collections::VecDeque<(u64, f64, f64)>,
}

impl<'a> SimService<'a> {
    /// The robot `cfg` describes, run for `duration_s` of robot time (`None`: until stopped);
    /// `observe` sees it every 10 ms of robot time (a recording's ground truth).
    pub fn new(
        cfg: SimConfig,
        seed: u64,
        duration_s: Option<f64>,
        catalog: &'a TerrainCatalog,
        observe: &'a mut dyn FnMut(u64, &SimRobot),
    ) -> Self {
        let ids = cfg.ids.clone();
        let motor_leg = cfg.leg.as_ref().map(|l| (l.foot, LegStateCheck::default()));
        Self {
            motor_leg,
            leg_history: std::collections::VecDeque::with_capacity(LEG_HISTORY),
            robot: SimRobot::new(cfg, seed),
            ids,
            catalog,
            observe,
            records: Vec::new(),
            end_us: duration_s.map(|d| (d * 1e6) as u64),
            t_us: 0,
            stretched_us: 0,
        }
    }

    /// The robot.
    pub fn robot(&self) -> &SimRobot {
        &self.robot
    }

    /// Robot time so far, µs.
    pub fn t_us(&self) -> u64 {
        self.t_us
    }

    /// Every TerrainClass heard so far, scored.
    pub fn records(&self) -> &[StepRecord] {
        &self.records
    }

    /// A leg of motors: its bridge's LegState against the truth so far.
    pub fn leg_state_check(&self) -> Option<LegStateCheck> {
        self.motor_leg.clone().map(|(_, mut c)| {
            c.summarize();
            c
        })
    }

    /// The robot, to inject driver faults in tests.
    pub fn robot_mut(&mut self) -> &mut SimRobot {
        &mut self.robot
    }

    /// The records, the service done with.
    pub fn into_records(self) -> Vec<StepRecord> {
        self.records
    }
}

impl Component for SimService<'_> {
    fn name(&self) -> &'static str {
        "sim"
    }

    /// What the simulator reads: the controller's LegCommand and GaitStatus (the leg's own
    /// laws follow the controller's gait between commands; the process filtered GaitStatus
    /// out until the lock-step loop ran on this same component and its speeds moved) and the
    /// node's TerrainClass (to score it).
    fn filters(&self) -> Vec<(u32, u32)> {
        // A leg of motors hears its drivers' frames and its bridge's LegState: everything.
        if self.motor_leg.is_some() {
            return Vec::new();
        }
        self.ids.filters(&[
            MessageKind::LegCommand,
            MessageKind::GaitStatus,
            MessageKind::TerrainClass,
        ])
    }

    fn on_frame(&mut self, st: &Stamped, _: u64, _: &mut Outbox) {
        self.robot.on_frame(&st.frame);
        let msg = messages::decode(&st.frame, &self.ids);
        if let (Some((leg, check)), Ok(Some((foot, Message::LegState(ls))))) =
            (self.motor_leg.as_mut(), &msg)
            && *foot == *leg
            && let Some(now) = self.robot.leg_truth(*foot)
            // While the bridge drives the leg: in the damped stop the hopper falls and is set
            // back on its feet (a jump of the truth no encoder follows).
            && self.robot.motors_driven(*foot) == Some(true)
        {
            // The readings behind a LegState are older than its stamp (the bridge's period,
            // the bus): it is compared with the nearest truth of the few ms before its stamp
            // where that stamp is on our clock (one process: the lock-step demo), else (each
            // process keeps its own clock) of the last 50 ms: a bus of processes under
            // emulation delayed LegState by more than 20 ms of the simulator's time. Nearest in
            // units of the bounds, 0.01 rad and 2 mm.
            let on_our_clock = self
                .leg_history
                .iter()
                .any(|h| h.0 as u32 == ls.timestamp_us);
            let (end, span) = if on_our_clock {
                (ls.timestamp_us as u64, 3_000)
            } else {
                (self.t_us as u32 as u64, 50_000)
            };
            let recent = self
                .leg_history
                .iter()
                .filter(|h| {
                    let t = h.0 as u32 as u64;
                    t <= end && end - t <= span
                })
                .map(|h| (h.1, h.2))
                .min_by(|a, b| {
                    let e = |t: &(f64, f64)| {
                        (ls.leg_angle_rad - t.0).abs() / 0.01
                            + (ls.leg_length_m - t.1).abs() / 0.002
                    };
                    e(a).total_cmp(&e(b))
                });
            let stamped = recent.filter(|_| on_our_clock);
            let (angle, length) = stamped.or(recent).unwrap_or(now);
            check.add(
                (ls.leg_angle_rad - angle).abs(),
                (ls.leg_length_m - length).abs(),
                stamped.is_some(),
            );
        }
        if let Ok(Some((foot, Message::TerrainClass(tc)))) = msg {
            self.records.push(StepRecord::of(
                &self.robot,
                foot,
                &tc,
                self.t_us,
                self.catalog,
            ));
        }
    }

    fn tick(&mut self, now_us: u64, out: &mut Outbox) {
        // Simulated time follows the runner's clock in steps of at least 1 ms.
        let target = now_us.saturating_sub(self.stretched_us);
        if target < self.t_us + 1000 || self.done() {
            return;
        }
        // A machine too slow for `speed` (a debug build, emulation, a loaded CI runner):
        // robot time slows down rather than jumping ahead to catch up. A jump would run the
        // leg for tens of ms on one stale command and deliver the foot's frames in bursts; a
        // real leg never pauses, and neither does its controller's view of it.
        if target > self.t_us + MAX_LAG_US {
            self.stretched_us += target - (self.t_us + MAX_LAG_US);
        }
        let before = self.t_us;
        self.t_us = target.min(self.t_us + MAX_LAG_US);
        self.robot.advance_to(self.t_us, out);
        if let Some((foot, _)) = self.motor_leg
            && let Some((a, l)) = self.robot.leg_truth(foot)
        {
            if self.leg_history.len() == LEG_HISTORY {
                self.leg_history.pop_front();
            }
            self.leg_history.push_back((self.t_us, a, l));
        }
        if self.t_us / 10_000 != before / 10_000 {
            (self.observe)(self.t_us, &self.robot);
        }
    }

    fn done(&self) -> bool {
        self.end_us.is_some_and(|e| self.t_us >= e)
    }
}

/// Runs the simulated robot on `source` until `opts.duration_s` or `stop`; names terrains the
/// node reports from `catalog`. `observe` sees the robot every 10 ms of robot time (a
/// recording's ground truth), with that time.
pub fn run(
    cfg: SimConfig,
    opts: &RunOptions,
    source: BusSource,
    catalog: &TerrainCatalog,
    stop: &AtomicBool,
    observe: &mut dyn FnMut(u64, &SimRobot),
) -> SimReport {
    let start = Instant::now();
    tracing::info!(iface = %source.label(), feet = cfg.feet, speed = opts.speed, gait = cfg.gait, "presrs lab sim running");
    let mut sim = SimService::new(cfg, opts.seed, opts.duration_s, catalog, observe);
    let run_opts = component::RunOptions {
        time_scale: opts.speed,
        // The simulator is the robot: it ticks often, so each pass covers about 1 ms.
        tick: Duration::from_micros(300),
        ..component::RunOptions::default()
    };
    let stats = component::run(&mut sim, &source, &run_opts, stop);
    let robot = &sim.robot;
    SimReport {
        simulated_s: sim.t_us as f64 * 1e-6,
        wall_s: start.elapsed().as_secs_f64(),
        touchdowns: robot.steps.len(),
        falls: robot.falls.len() as u64,
        fall_times_s: robot.falls.iter().map(|&t| t as f64 * 1e-6).collect(),
        send_errors: stats.send_errors,
        leg_state: sim.leg_state_check(),
        steps: sim.records,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The step's speed is its stride's (the truth's touchdown to touchdown), not the body's at
    /// the moment its TerrainClass came (mid-stance, the slowest).
    #[test]
    fn a_step_record_carries_the_stride_speed() {
        let mut robot = SimRobot::new(SimConfig::default(), 1);
        let mut sink = Vec::new();
        let mut t = 0u64;
        while robot.steps.len() < 12 {
            t += 1_000;
            robot.advance_to(t, &mut sink);
            sink.clear();
        }
        // 70 ms after the last touchdown: mid-stance, where a TerrainClass comes.
        let last = robot.steps[robot.steps.len() - 1];
        robot.advance_to(last.touchdown_us + 70_000, &mut sink);
        let tc = messages::TerrainClass::default();
        let catalog = TerrainCatalog::paper();
        let r = StepRecord::of(&robot, 0, &tc, last.touchdown_us + 70_000, &catalog);
        assert_eq!(r.speed_m_s, last.speed_m_s);
        let (now, _) = robot.speed_and_position(0).unwrap();
        assert!(now < 0.9 * r.speed_m_s, "{now} against {}", r.speed_m_s);
    }

    #[test]
    fn the_report_line_scores_what_was_heard() {
        let step = |truth: &str, classified: &str| StepRecord {
            t_s: 1.0,
            foot: 0,
            step: 1,
            truth: truth.into(),
            classified: classified.into(),
            confidence_pct: 90.0,
            damage_pct: 0.0,
            gait: 2,
            speed_m_s: 0.5,
        };
        let mut r = SimReport {
            simulated_s: 12.0,
            wall_s: 3.04,
            touchdowns: 40,
            falls: 1,
            fall_times_s: vec![5.0],
            send_errors: 0,
            steps: vec![],
            leg_state: None,
        };
        assert_eq!(
            r.to_string(),
            "12.0 s simulated in 3.0 s wall; 40 touchdowns, 1 falls; 0 TerrainClass heard, 0 \
             correct; 0 send errors"
        );
        r.steps = vec![
            step("wood", "wood"),
            step("wood", "carpet"),
            step("clay", "clay"),
        ];
        assert!(
            r.to_string()
                .contains("3 TerrainClass heard, 2 correct (66.7%);"),
            "{r}"
        );
    }
}
