//! The simulator as a process runs it: on a bus, with simulated time following the wall clock
//! (times `speed`), publishing FootContact, LegState and the tactile frames and obeying
//! LegCommand.
//!
//! Because the simulator knows the truth, it also scores what others put on the bus: every
//! TerrainClass it hears is matched to the stance in progress on that foot, with the gait the
//! leg ran, as a [`StepRecord`]; [`run`] returns them in a [`SimReport`].

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use protocol::bus::{Backoff, BusSource, CanBus, open_with_retry, reopen_after_error};
use protocol::ids::MessageKind;
use protocol::messages::{self, Message};
use protocol::{IdConfig, TerrainCatalog};

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
    let ids = cfg.ids.clone();
    let (feet, gait) = (cfg.feet, cfg.gait);
    let mut robot = SimRobot::new(cfg, opts.seed);
    let start = Instant::now();
    let mut records: Vec<StepRecord> = Vec::new();
    let report =
        |robot: &SimRobot, records: Vec<StepRecord>, t_us: u64, send_errors: u64| SimReport {
            simulated_s: t_us as f64 * 1e-6,
            wall_s: start.elapsed().as_secs_f64(),
            touchdowns: robot.steps.len(),
            falls: robot.falls.len() as u64,
            fall_times_s: robot.falls.iter().map(|&t| t as f64 * 1e-6).collect(),
            send_errors,
            steps: records,
        };
    let Some(mut bus) = open_sim_bus(&source, stop, &ids) else {
        return report(&robot, records, 0, 0);
    };
    tracing::info!(iface = %source.label(), feet, speed = opts.speed, gait, "presrs sim running");
    let end_us = opts.duration_s.map(|d| (d * 1e6) as u64);
    // Robot time given up because the machine could not keep up (see below).
    let mut stretched_us = 0u64;
    let mut out = Vec::with_capacity(128);
    let mut backoff = Backoff::default();
    let mut send_errors = 0u64;
    let mut t_us = 0u64;
    loop {
        if stop.load(Ordering::Relaxed) || end_us.is_some_and(|e| t_us >= e) {
            break;
        }
        // Simulated time follows the wall clock; 1 ms steps, sleeping when ahead.
        let target = ((start.elapsed().as_secs_f64() * opts.speed * 1e6) as u64)
            .saturating_sub(stretched_us);
        if target < t_us + 1000 {
            std::thread::sleep(Duration::from_micros(300));
            continue;
        }
        // A machine too slow for `speed` (a debug build, emulation, a loaded CI runner):
        // robot time slows down rather than jumping ahead to catch up. A jump would run the
        // leg for tens of ms on one stale command and deliver the foot's frames in bursts; a
        // real leg never pauses, and neither does its controller's view of it.
        if target > t_us + MAX_LAG_US {
            stretched_us += target - (t_us + MAX_LAG_US);
        }
        let before = t_us;
        t_us = target.min(t_us + MAX_LAG_US);
        robot.advance_to(t_us, &mut |f| out.push(f));
        if t_us / 10_000 != before / 10_000 {
            observe(t_us, &robot);
        }
        for f in out.drain(..) {
            if let Err(e) = bus.send(&f) {
                send_errors += 1;
                // A lost frame is what a real foot would cause too; a dead bus is reopened.
                if send_errors.is_power_of_two() {
                    tracing::warn!("sim send: {e} ({send_errors} send errors so far)");
                }
                if matches!(e, protocol::BusError::Down { .. }) {
                    if let Some(b) =
                        reopen_after_error(&source, "sim", &e, &mut backoff, stop, &mut || {})
                    {
                        bus = filtered(b, &ids);
                    }
                    break;
                }
            }
        }
        while let Ok(Some(st)) = bus.recv(Duration::ZERO) {
            robot.on_frame(&st.frame);
            if let Ok(Some((foot, Message::TerrainClass(tc)))) = messages::decode(&st.frame, &ids) {
                records.push(StepRecord::of(&robot, foot, &tc, t_us, catalog));
            }
        }
    }
    report(&robot, records, t_us, send_errors)
}

/// Opens the simulator's bus, passing it only what the simulator reads: the controller's
/// LegCommand and the node's TerrainClass (to score it).
fn open_sim_bus(source: &BusSource, stop: &AtomicBool, ids: &IdConfig) -> Option<Box<dyn CanBus>> {
    Some(filtered(
        open_with_retry(source, stop, "sim", &mut || {})?,
        ids,
    ))
}

fn filtered(mut bus: Box<dyn CanBus>, ids: &IdConfig) -> Box<dyn CanBus> {
    let kinds = [MessageKind::LegCommand, MessageKind::TerrainClass];
    if let Err(e) = bus.set_filters(&ids.filters(&kinds)) {
        // Unfiltered still works; it only costs the simulator time.
        tracing::warn!("sim: receive filters not set ({e}); reading every frame");
    }
    bus
}
