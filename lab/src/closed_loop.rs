//! The closed loop in lock-step simulated time: the simulated hopper, the node and the
//! controller on one in-process bus, advanced one millisecond at a time, as fast as the machine
//! runs. Each step the node decides becomes a [`StepRecord`] with the ground truth beside it,
//! the same record `presrs lab sim` keeps on a real bus.
//!
//! The three parties talk only through CAN frames on the bus, as they do as processes on
//! vcan; lock-step only fixes the order within a millisecond (robot, node, controller, robot),
//! so a run is the same on every machine for a seed.

use std::sync::Arc;
use std::time::Duration;

use controller::ControllerConfig;
use controller::service::ControllerService;
use node::NodeConfig;
use node::NodeService;
use node::classifier::Model;
use protocol::bus::InProcBus;
use protocol::component::{Component, LockStep};
use sim::runner::{SimConfig, SimRobot, Track};
use sim::service::{SimService, StepRecord};

use crate::LabError;

/// What runs in the loop besides the simulator.
#[derive(Clone, Debug)]
pub struct LoopParams<'a> {
    /// The node's config (its catalog must know the model's terrains).
    pub node: NodeConfig,
    /// `None`: no controller, the hopper holds `fixed_gait`.
    pub controller: Option<&'a ControllerConfig>,
    /// The gait without a controller (default G2).
    pub fixed_gait: Option<u8>,
    /// Sensor damage from the start, percent of sensels (eq. 6).
    pub damage_pct: f64,
    /// Steps to run (the loop also ends after `steps + 20` simulated seconds).
    pub steps: usize,
    /// The simulator's seed.
    pub seed: u64,
    /// The controller is killed at `.0` (simulated µs) and a new one started `.1` µs later, as
    /// a process crash and restart on a robot would: the new one knows only what the bus says.
    pub controller_restart: Option<(u64, u64)>,
    /// The node likewise: killed at `.0` (simulated µs), a new one with the same model and
    /// config started `.1` µs later.
    pub node_restart: Option<(u64, u64)>,
    /// The bus carries nothing from `.0` (simulated µs) for `.1` µs: every frame sent is lost,
    /// as on an interface that is down.
    pub link_down: Option<(u64, u64)>,
    /// The leg through motors: the simulator's leg `foot` answers as this config's drivers and
    /// a leg bridge ([`leg::LegService`]) between the controller and them (`presrs demo --leg`).
    pub leg: Option<leg::LegConfig>,
    /// With a leg of motors: its bridge's process does not run from `.0` (simulated µs) for
    /// `.1` µs, as on a machine that cannot keep up with it (the vcan tests' emulated kernel
    /// stalls a process for 100 ms and more); the frames that come meanwhile wait in its
    /// socket and are read when it runs again.
    pub leg_stall: Option<(u64, u64)>,
    /// Mass the simulated hopper carries, kg (`presrs demo --payload`): a load the model and
    /// its energy maps were not made with.
    pub payload_kg: f64,
}

impl<'a> LoopParams<'a> {
    /// The default node, `controller` choosing the gait, no damage.
    pub fn with_controller(controller: &'a ControllerConfig, steps: usize, seed: u64) -> Self {
        Self {
            node: NodeConfig::default(),
            controller: Some(controller),
            fixed_gait: None,
            damage_pct: 0.0,
            steps,
            seed,
            controller_restart: None,
            node_restart: None,
            link_down: None,
            leg: None,
            leg_stall: None,
            payload_kg: 0.0,
        }
    }
}

/// A finished run.
#[derive(Clone, Debug)]
pub struct LoopRun {
    /// One row per step the node decided, in order.
    pub rows: Vec<StepRecord>,
    /// When the hopper fell, simulated µs.
    pub fall_times_us: Vec<u64>,
    /// With a leg of motors: its bridge's LegState against the truth.
    pub leg_state: Option<sim::service::LegStateCheck>,
    /// With a leg of motors: the bridge's counters.
    pub leg_counters: Option<leg::LegCounters>,
    /// Every touchdown's truth, on the recording's clock (its `epoch_us` added; simulated time
    /// without a recording). Empty from the real-time loop.
    pub truth: Vec<sim::runner::StepTruth>,
}

impl LoopRun {
    /// Times the hopper fell.
    pub fn falls(&self) -> u64 {
        self.fall_times_us.len() as u64
    }
}

/// True while `t_us` lies in a fault's window (start, length), µs.
fn during(window: Option<(u64, u64)>, t_us: u64) -> bool {
    window.is_some_and(|(at, len)| (at..at + len).contains(&t_us))
}

/// A part whose process does not run during `window` ([`LoopParams::leg_stall`]): what comes
/// meanwhile is `held`, as in its socket, and read with the time it runs again.
struct Stalled<'p> {
    inner: &'p mut dyn Component,
    window: Option<(u64, u64)>,
    held: &'p mut Vec<protocol::Stamped>,
}

impl Stalled<'_> {
    fn catch_up(&mut self, now_us: u64, out: &mut protocol::component::Outbox) {
        for st in self.held.drain(..) {
            self.inner.on_frame(&st, now_us, out);
        }
    }
}

impl Component for Stalled<'_> {
    fn name(&self) -> &'static str {
        self.inner.name()
    }
    fn filters(&self) -> Vec<(u32, u32)> {
        self.inner.filters()
    }
    fn on_frame(
        &mut self,
        frame: &protocol::Stamped,
        now_us: u64,
        out: &mut protocol::component::Outbox,
    ) {
        if during(self.window, now_us) {
            self.held.push(*frame);
        } else {
            self.catch_up(now_us, out);
            self.inner.on_frame(frame, now_us, out);
        }
    }
    fn tick(&mut self, now_us: u64, out: &mut protocol::component::Outbox) {
        if !during(self.window, now_us) {
            self.catch_up(now_us, out);
            self.inner.tick(now_us, out);
        }
    }
}

/// A recording of a [`run`]: every frame on the bus and the simulator's truth.
pub struct LoopRecording<'a> {
    /// Gets every frame any part sends, stamped `epoch_us` + simulated time (a live
    /// recorder's tap: MCAP, Foxglove).
    pub tap: Option<&'a dyn protocol::bus::Tap>,
    /// Every frame any part sends, as a candump log (interface [`LOG_IFACE`]), written as it
    /// is sent. Synchronous, unlike the tap: the lock-step loop has no real time to keep, so
    /// the log is whole (a tap drops frames when its writer falls behind). A write error ends
    /// the run with [`LabError::Log`].
    pub log: Option<&'a mut dyn std::io::Write>,
    /// Added to simulated time (from 0) in the stamps: the wall clock at the start, so that
    /// tools show the run at the time it was made.
    pub epoch_us: u64,
    /// Called every 10 ms of simulated time with the stamp and the robot.
    pub truth: &'a mut dyn FnMut(u64, &SimRobot),
    /// Simulated time per wall time; `None` runs as fast as the machine can (for a live
    /// view, 1.0: the robot at its own speed).
    pub pace: Option<f64>,
    /// Ends the run early when set (SIGINT on a paced run).
    pub stop: &'a std::sync::atomic::AtomicBool,
}

/// The interface name in a [`LoopRecording::log`], as in `presrs lab sim --log`'s: the robot's
/// bus (`canplayer vcan0=can0 -I FILE` replays it onto vcan0).
pub const LOG_IFACE: &str = "can0";

/// Runs the loop on `track` with `model` until `p.steps` steps are decided; `on_step` sees each
/// row as it comes (to print a live log).
pub fn run(
    track: &Track,
    model: Model,
    p: &LoopParams,
    on_step: impl FnMut(&StepRecord),
) -> Result<LoopRun, LabError> {
    run_recorded(track, model, p, on_step, None)
}

/// Where `presrs demo` records a lock-step run: a live recorder (MCAP, Foxglove), a candump
/// log, or both.
pub struct DemoOutputs<'a> {
    /// Gets every frame and foot 0's truth, stamped on the wall clock.
    pub live: Option<&'a record::LiveRecorder>,
    /// Every frame as a candump log ([`LoopRecording::log`]). Without `live` it is stamped as
    /// `presrs lab sim --log` stamps its own: simulated time from [`sim::runner::LOG_EPOCH_US`].
    pub log: Option<&'a mut dyn std::io::Write>,
    /// Paced to real time, so that a live view has something to watch.
    pub paced: bool,
    /// Ends the run early when set (SIGINT).
    pub stop: &'a std::sync::atomic::AtomicBool,
}

/// [`run`] recorded to `out`.
pub fn run_to(
    track: &Track,
    model: Model,
    p: &LoopParams,
    on_step: impl FnMut(&StepRecord),
    out: DemoOutputs,
) -> Result<LoopRun, LabError> {
    let tap = out.live.map(|l| l.tap());
    let mut truth = |t_us: u64, robot: &SimRobot| {
        if let (Some(tap), Some(t)) = (&tap, sim_truth(robot, track, 0)) {
            tap.offer_truth(t_us, 0, t);
        }
    };
    let rec = LoopRecording {
        tap: tap.as_deref().map(|t| t as &dyn protocol::bus::Tap),
        log: out.log.map(|w| &mut *w as &mut dyn std::io::Write),
        epoch_us: match out.live {
            Some(_) => protocol::clock::epoch_us(),
            None => sim::runner::LOG_EPOCH_US,
        },
        truth: &mut truth,
        pace: out.paced.then_some(1.0),
        stop: out.stop,
    };
    run_recorded(track, model, p, on_step, Some(rec))
}

/// [`run`], recorded (see [`LoopRecording`]).
pub fn run_recorded(
    track: &Track,
    model: Model,
    p: &LoopParams,
    mut on_step: impl FnMut(&StepRecord),
    rec: Option<LoopRecording>,
) -> Result<LoopRun, LabError> {
    let wall = std::time::Instant::now();
    let sim_cfg = sim_config(track, p);
    let mut bridge = p.leg.clone().map(|l| leg::LegService::new(l, false));
    let mut node_cfg = p.node.clone();
    // Lock-step simulated time: a refit lands at the step that asked for it, as in a replay.
    node_cfg.refit = node_cfg.refit.reproducible();
    let restart_with = p.node_restart.map(|_| (node_cfg.clone(), model.clone()));
    let first = NodeService::new(node_cfg, model)?;
    let catalog = first.catalog().clone();
    let mut node = Some(first);
    let mut ctrl = new_controller(p)?;
    let (tap, log, epoch_us, pace, stop, mut truth) = match rec {
        Some(r) => (
            r.tap,
            r.log,
            r.epoch_us,
            r.pace,
            Some(r.stop),
            Some(r.truth),
        ),
        None => (None, None, 0, None, None, None),
    };
    // The robot's truth every 10 ms of simulated time, for a recording.
    let mut observe = |t_us: u64, robot: &SimRobot| {
        if let Some(f) = truth.as_mut() {
            f(epoch_us + t_us, robot);
        }
    };
    let mut sim = SimService::new(sim_cfg, p.seed, None, &catalog, &mut observe);
    let mut sent = Sent::new(tap, log, epoch_us);
    // Parts in turn within a millisecond: the robot (it hears the controller's last
    // commands, then moves), the node, the controller; with a leg of motors, its bridge last
    // (it hears the motors' replies and the controller's command of this millisecond).
    let mut bus = LockStep::new(4, 1 << 16);
    bus.start_all(
        &mut parts_of(&mut sim, &mut node, &mut ctrl, bridge.as_mut()),
        &mut sent,
    )?;
    let mut t_us = 0u64;
    let limit_us = (p.steps as u64 + 20) * 1_000_000;
    let mut reported = 0;
    let mut held = Vec::new();
    while sim.records().len() < p.steps && t_us < limit_us {
        t_us += 1000;
        if stop.is_some_and(|s| s.load(std::sync::atomic::Ordering::Relaxed)) {
            break;
        }
        keep_pace(pace, tap, t_us, wall);
        bus.set_link(!during(p.link_down, t_us));
        restarts(
            p,
            t_us,
            &mut node,
            &restart_with,
            &mut ctrl,
            &mut bus,
            &mut sent,
        )?;
        let mut stalled = bridge.as_mut().map(|b| Stalled {
            inner: b,
            window: p.leg_stall,
            held: &mut held,
        });
        let mut parts: [Option<&mut dyn Component>; 4] = [
            Some(&mut sim),
            node.as_mut().map(|n| n as &mut dyn Component),
            ctrl.as_mut().map(|c| c as &mut dyn Component),
            stalled.as_mut().map(|s| s as &mut dyn Component),
        ];
        bus.step(t_us, &mut parts, &mut sent)?;
        if let Some(e) = sent.error.take() {
            return Err(LabError::Log(e));
        }
        for row in &sim.records()[reported..] {
            on_step(row);
        }
        reported = sim.records().len();
    }
    // The same lifecycle as the other runners: each part stops, the leg bridge's motors first
    // (their stop frames go on the bus and into the log, as `presrs leg` sends them).
    bus.stop_all(
        &mut parts_of(&mut sim, &mut node, &mut ctrl, bridge.as_mut()),
        &mut sent,
    )?;
    if let Some(e) = sent.error.take() {
        return Err(LabError::Log(e));
    }
    Ok(finish(sim, bridge, epoch_us))
}

/// Where the loop's frames go: stamped `epoch_us` on, to the tap and the candump log; the first
/// write error is kept for the loop to end the run with (the bus holds this while it steps).
struct Sent<'a> {
    tap: Option<&'a dyn protocol::bus::Tap>,
    log: Option<&'a mut dyn std::io::Write>,
    epoch_us: u64,
    error: Option<std::io::Error>,
}

impl<'a> Sent<'a> {
    fn new(
        tap: Option<&'a dyn protocol::bus::Tap>,
        log: Option<&'a mut dyn std::io::Write>,
        epoch_us: u64,
    ) -> Self {
        Self {
            tap,
            log,
            epoch_us,
            error: None,
        }
    }
}

impl protocol::emit::Emit<protocol::Stamped> for Sent<'_> {
    fn emit(&mut self, st: protocol::Stamped) {
        let st = protocol::Stamped {
            t_us: self.epoch_us + st.t_us,
            ..st
        };
        if let Some(tap) = self.tap {
            tap.offer(&st);
        }
        if let Some(w) = self.log.as_mut()
            && let Err(e) = protocol::candump::write_record(w, LOG_IFACE, &st)
        {
            self.error.get_or_insert(e);
        }
    }
}

/// The loop's controller, as `p` asks for one.
fn new_controller(p: &LoopParams) -> Result<Option<ControllerService>, LabError> {
    Ok(p.controller
        .map(|c| ControllerService::new(c.clone()))
        .transpose()?)
}

/// Killed processes, and new ones started after their windows (`p.node_restart`,
/// `p.controller_restart`): a new one knows only what the bus says from then on.
fn restarts(
    p: &LoopParams,
    t_us: u64,
    node: &mut Option<NodeService>,
    restart_with: &Option<(NodeConfig, Model)>,
    ctrl: &mut Option<ControllerService>,
    bus: &mut LockStep,
    sent: &mut dyn protocol::emit::Emit<protocol::Stamped>,
) -> Result<(), LabError> {
    if during(p.node_restart, t_us) {
        *node = None;
    } else if node.is_none()
        && let Some((cfg, model)) = restart_with
    {
        let mut n = NodeService::new(cfg.clone(), model.clone())?;
        bus.start(1, &mut n, sent)?;
        *node = Some(n);
    }
    if during(p.controller_restart, t_us) {
        *ctrl = None;
    } else if ctrl.is_none() {
        *ctrl = new_controller(p)?;
        if let Some(c) = ctrl.as_mut() {
            bus.start(2, c, sent)?;
        }
    }
    Ok(())
}

/// The loop's parts in their bus order: the robot, the node, the controller, the leg bridge.
fn parts_of<'a>(
    sim: &'a mut SimService<'_>,
    node: &'a mut Option<NodeService>,
    ctrl: &'a mut Option<ControllerService>,
    bridge: Option<&'a mut leg::LegService>,
) -> [Option<&'a mut dyn Component>; 4] {
    [
        Some(sim),
        node.as_mut().map(|n| n as &mut dyn Component),
        ctrl.as_mut().map(|c| c as &mut dyn Component),
        bridge.map(|b| b as &mut dyn Component),
    ]
}

/// The simulated robot of a loop run: the track, and what the parameters change of it.
fn sim_config(track: &Track, p: &LoopParams) -> SimConfig {
    let mut cfg = SimConfig {
        track: track.clone(),
        ..Default::default()
    };
    if let Some(g) = p.fixed_gait {
        cfg.gait = g;
    }
    cfg.faults.initial_damage_pct = p.damage_pct;
    cfg.payload_kg = p.payload_kg;
    cfg.leg = p.leg.clone();
    cfg
}

/// Waits, before simulated millisecond `t_us`, for the wall clock (a paced run) or for the
/// recorder's tap to catch up.
fn keep_pace(
    pace: Option<f64>,
    tap: Option<&dyn protocol::bus::Tap>,
    t_us: u64,
    wall: std::time::Instant,
) {
    if let Some(pace) = pace.filter(|p| *p > 0.0) {
        let due = Duration::from_secs_f64(t_us as f64 * 1e-6 / pace);
        if let Some(wait) = due.checked_sub(wall.elapsed()) {
            std::thread::sleep(wait);
        }
    } else if let Some(tap) = tap {
        // Simulated time has no real time to keep: the loop waits for its recorder (a
        // slower disk or network) rather than have it drop frames.
        while tap.backlog() > 0.5 {
            std::thread::sleep(Duration::from_millis(1));
        }
    }
}

/// The run's result: its steps, the robot's truth on the recording's clock, its falls and the
/// leg's figures.
fn finish(sim: SimService<'_>, bridge: Option<leg::LegService>, epoch_us: u64) -> LoopRun {
    let truth = sim
        .robot()
        .steps
        .iter()
        .map(|s| sim::runner::StepTruth {
            touchdown_us: epoch_us + s.touchdown_us,
            ..*s
        })
        .collect();
    LoopRun {
        truth,
        fall_times_us: sim.robot().falls.clone(),
        leg_state: sim.leg_state_check(),
        leg_counters: bridge.map(|b| b.counters()),
        rows: sim.into_records(),
    }
}

/// What the simulator knows of leg `foot` and the robot does not, for a recording's
/// `/sim/leg<foot>` channel.
pub fn sim_truth(robot: &SimRobot, track: &Track, foot: u8) -> Option<record::SimTruth> {
    let (speed, x) = robot.speed_and_position(foot)?;
    Some(record::SimTruth {
        speed_m_s: speed,
        position_m: x,
        terrain: track.terrain_at(x).id(),
        gait: robot.gait_in_effect(foot).unwrap_or(0),
        falls: robot.falls.len() as u32,
    })
}

/// How long [`run_realtime`] runs for `steps` steps, s: 0.4 s per step plus 1 s to start.
pub fn realtime_seconds(steps: usize) -> f64 {
    steps as f64 * 0.4 + 1.0
}

/// [`run`] in real time, as the processes run on a robot: the node's threads
/// ([`NodeService::start`]), the controller's bus loop ([`controller::service::run`]) on a
/// thread of its own and the simulator's ([`sim::service::run`]) on this one, all on one
/// in-process bus with the wall clock. Runs [`realtime_seconds`] and returns the first
/// `p.steps` steps and the controller's gait switches. `p.controller` is required (`None`
/// means the default config).
pub fn run_realtime(
    track: &Track,
    model: Model,
    p: &LoopParams,
) -> Result<(LoopRun, u64), LabError> {
    use protocol::bus::BusSource;
    use std::sync::atomic::{AtomicBool, Ordering};
    let bus = InProcBus::new();
    let stop = Arc::new(AtomicBool::new(false));
    let node = NodeService::new(p.node.clone(), model)?.start(BusSource::InProc(bus.clone()))?;
    let controller = {
        let cfg = p.controller.cloned().unwrap_or_default();
        let (src, stop) = (BusSource::InProc(bus.clone()), stop.clone());
        std::thread::Builder::new()
            .name("controller".into())
            .spawn(move || controller::service::run(cfg, src, 1.0, &stop))
            .map_err(LabError::Thread)?
    };
    let opts = sim::service::RunOptions {
        speed: 1.0,
        duration_s: Some(realtime_seconds(p.steps)),
        seed: p.seed,
    };
    let mut sim_cfg = SimConfig {
        track: track.clone(),
        ..Default::default()
    };
    sim_cfg.faults.initial_damage_pct = p.damage_pct;
    sim_cfg.payload_kg = p.payload_kg;
    let catalog = node.catalog().clone();
    let report = sim::service::run(
        sim_cfg,
        &opts,
        BusSource::InProc(bus),
        &catalog,
        &stop,
        &mut |_, _| {},
    );
    stop.store(true, Ordering::Relaxed);
    let switches = controller
        .join()
        .map_err(|_| LabError::Panicked("controller"))??;
    node.stop();
    let rows = report.steps.into_iter().take(p.steps).collect();
    Ok((
        LoopRun {
            rows,
            fall_times_us: report
                .fall_times_s
                .iter()
                .map(|t| (t * 1e6) as u64)
                .collect(),
            leg_state: None,
            leg_counters: None,
            truth: Vec::new(),
        },
        switches,
    ))
}
