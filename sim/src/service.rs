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
    /// Forward speed over the step, m/s.
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
        let truth = robot.step_at(foot, t_us).map_or("?", |s| s.terrain.name());
        let (speed, _) = robot.speed_and_position(foot).unwrap_or((0.0, 0.0));
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
}

/// What one run of the simulator saw (`presrs sim --report`'s file).
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
        Self {
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
        self.ids.filters(&[
            MessageKind::LegCommand,
            MessageKind::GaitStatus,
            MessageKind::TerrainClass,
        ])
    }

    fn on_frame(&mut self, st: &Stamped, _: u64, _: &mut Outbox) {
        self.robot.on_frame(&st.frame);
        if let Ok(Some((foot, Message::TerrainClass(tc)))) = messages::decode(&st.frame, &self.ids)
        {
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
        self.robot.advance_to(self.t_us, &mut |f| out.push(f));
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
    tracing::info!(iface = %source.label(), feet = cfg.feet, speed = opts.speed, gait = cfg.gait, "presrs sim running");
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
        steps: sim.records,
    }
}
