//! The closed loop in lock-step simulated time: the simulated hopper, the node and the
//! controller on one in-process bus, advanced one millisecond at a time, as fast as the machine
//! runs. Each step the node decides becomes a [`StepRecord`] with the ground truth beside it,
//! the same record `presrs sim` keeps on a real bus.
//!
//! The three parties talk only through CAN frames on the bus, as they do as processes on
//! vcan; lock-step only fixes the order within a millisecond (robot, node, controller, robot),
//! so a run is the same on every machine for a seed.

use std::sync::Arc;
use std::time::Duration;

use controller::{Controller, ControllerConfig};
use node::classifier::Model;
use node::{NodeConfig, NodeService, Output};
use protocol::bus::{CanBus, InProcBus};
use protocol::clock::ManualClock;
use protocol::messages;
use sim::runner::{SimConfig, SimRobot, Track};
use sim::service::StepRecord;

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

/// A recording of a [`run`]: every frame on the bus and the simulator's truth.
pub struct LoopRecording<'a> {
    /// Gets every frame any of the three sends, stamped `epoch_us` + simulated time.
    pub tap: &'a dyn protocol::bus::Tap,
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

/// [`run`], recorded (see [`LoopRecording`]).
pub fn run_recorded(
    track: &Track,
    model: Model,
    p: &LoopParams,
    mut on_step: impl FnMut(&StepRecord),
    mut rec: Option<LoopRecording>,
) -> Result<LoopRun, LabError> {
    let wall = std::time::Instant::now();
    let clock = ManualClock::new(0);
    let bus = InProcBus::with_clock(Arc::new(clock.clone()), 1 << 16);
    let (mut sim_ep, mut node_ep, mut ctrl_ep) = (bus.endpoint(), bus.endpoint(), bus.endpoint());
    let mut sim_cfg = SimConfig {
        track: track.clone(),
        ..Default::default()
    };
    if let Some(g) = p.fixed_gait {
        sim_cfg.gait = g;
    }
    sim_cfg.faults.initial_damage_pct = p.damage_pct;
    let ids = sim_cfg.ids.clone();
    let mut robot = SimRobot::new(sim_cfg, p.seed);
    let mut node_cfg = p.node.clone();
    // Lock-step simulated time: a refit lands at the step that asked for it, as in a replay.
    node_cfg.refit = node_cfg.refit.reproducible();
    let restart_with = p.node_restart.map(|_| (node_cfg.clone(), model.clone()));
    let mut node = NodeService::new(node_cfg, model)?;
    let mut node_dead = false;
    let catalog = node.catalog().clone();
    let mut ctrl = match p.controller {
        Some(c) => Some(Controller::new(c.clone(), &c.catalog()?)),
        None => None,
    };
    let mut rows: Vec<StepRecord> = Vec::new();
    let mut t_us = 0u64;
    let zero = Duration::ZERO;
    let limit_us = (p.steps as u64 + 20) * 1_000_000;
    // Reused every millisecond: the loop allocates only when a step is logged.
    let mut sent = Vec::new();
    let mut said = Vec::new();
    let mut out = Vec::new();
    let offer = |rec: &Option<LoopRecording>, t_us: u64, frame: &protocol::CanFrame| {
        if let Some(r) = rec {
            r.tap.offer(&protocol::Stamped {
                t_us: r.epoch_us + t_us,
                frame: *frame,
            });
        }
    };
    while rows.len() < p.steps && t_us < limit_us {
        t_us += 1000;
        clock.set_us(t_us);
        let down = during(p.link_down, t_us);
        if let Some(r) = rec.as_mut() {
            if r.stop.load(std::sync::atomic::Ordering::Relaxed) {
                break;
            }
            if let Some(pace) = r.pace.filter(|p| *p > 0.0) {
                let due = Duration::from_secs_f64(t_us as f64 * 1e-6 / pace);
                if let Some(wait) = due.checked_sub(wall.elapsed()) {
                    std::thread::sleep(wait);
                }
            }
            if t_us.is_multiple_of(10_000) {
                (r.truth)(r.epoch_us + t_us, &robot);
            }
        }
        robot.advance_to(t_us, &mut |f| sent.push(f));
        for f in sent.drain(..) {
            offer(&rec, t_us, &f);
            if !down {
                sim_ep.send(&f)?;
            }
        }
        // The node: frames, then what is due by now (deadlines, the heartbeat); none while
        // killed.
        if during(p.node_restart, t_us) {
            node_dead = true;
            while node_ep.recv(zero)?.is_some() {}
        } else if node_dead && let Some((cfg, model)) = &restart_with {
            node = NodeService::new(cfg.clone(), model.clone())?;
            node_dead = false;
        }
        while !node_dead && let Some(st) = node_ep.recv(zero)? {
            node.process(&st, &mut |o| said.push(o));
        }
        if !node_dead {
            node.tick(t_us, &mut |o| said.push(o));
        }
        for o in said.drain(..) {
            if let Some(f) = node.frame(&o) {
                offer(&rec, t_us, &f);
                if !down {
                    node_ep.send(&f)?;
                }
            }
            let Output::Class { foot, class: tc } = o else {
                continue;
            };
            let row = StepRecord::of(&robot, foot, &tc, t_us, &catalog);
            on_step(&row);
            rows.push(row);
        }
        // The controller (none while killed: its frames are lost, as a dead process's are).
        if let Some(c) = p.controller {
            if during(p.controller_restart, t_us) {
                ctrl = None;
                while ctrl_ep.recv(zero)?.is_some() {}
            } else if ctrl.is_none() {
                ctrl = Some(Controller::new(c.clone(), &c.catalog()?));
            }
        }
        while let Some(st) = ctrl_ep.recv(zero)? {
            if let (Some(ctrl), Ok(Some((foot, m)))) =
                (ctrl.as_mut(), messages::decode(&st.frame, &ids))
            {
                ctrl.on_message(foot, &m, t_us, &mut |o| out.push(o));
            }
        }
        if let Some(ctrl) = ctrl.as_mut() {
            ctrl.tick(t_us, &mut |o| out.push(o));
        }
        for m in out.drain(..) {
            if let Some(f) = m.to_frame(&ids, 0) {
                offer(&rec, t_us, &f);
                if !down {
                    ctrl_ep.send(&f)?;
                }
            }
        }
        // The robot hears the controller.
        while let Some(st) = sim_ep.recv(zero)? {
            robot.on_frame(&st.frame);
        }
    }
    Ok(LoopRun {
        rows,
        fall_times_us: robot.falls.clone(),
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
        },
        switches,
    ))
}
