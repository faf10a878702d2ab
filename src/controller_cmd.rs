//! `presrs controller`: the gait controller as a process on a CAN interface. It follows the foot
//! switch and leg angle, sends LegCommand at `command_hz` (eq. (4) in stance, the eq. (5) angle in
//! flight), switches gait per the terrain the node reports, falls back to the safe gait when the
//! node's heartbeat stops, and sends GaitStatus at every switch and at `status_hz`.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use controller::{Controller, ControllerConfig};
use protocol::bus::CanBus;
use protocol::ids::MessageKind;
use protocol::messages::{self, Message};

use crate::runtime::Signals;
use protocol::bus::{Backoff, BusSource, after_bus_error, open_with_retry};

#[derive(clap::Args)]
pub struct ControllerArgs {
    /// CAN interface (can0, vcan0).
    #[arg(long)]
    pub iface: String,
    /// Gaits and policy (TOML or JSON by extension); see `examples/controller.toml`.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// The controller's clock rate relative to the wall clock; match `presrs sim --speed` when
    /// the simulator runs slower or faster than real time (on a robot: 1).
    #[arg(long, default_value_t = 1.0)]
    pub time_scale: f64,
    /// Overrides the config's `terrains` key.
    #[command(flatten)]
    pub terrains: crate::cli::TerrainsArg,
}

pub fn load_config(path: Option<&std::path::Path>) -> Result<ControllerConfig> {
    match path {
        None => Ok(ControllerConfig::default()),
        Some(p) => ControllerConfig::load(p).context("--config"),
    }
}

pub fn run(a: ControllerArgs) -> Result<ExitCode> {
    anyhow::ensure!(
        a.time_scale > 0.0 && a.time_scale.is_finite(),
        "--time-scale {}: expected a positive factor (1 = real time)",
        a.time_scale
    );
    let mut cfg = load_config(a.config.as_deref())?;
    if a.terrains.terrains.is_some() {
        cfg.terrains = a.terrains.terrains.clone();
        let catalog = cfg.catalog()?;
        cfg.validate(&catalog)?;
    }
    let signals = Signals::install()?;
    run_on(
        cfg,
        BusSource::Iface(a.iface.clone()),
        a.time_scale,
        &signals,
    )?;
    Ok(ExitCode::SUCCESS)
}

/// The controller on any bus until `signals` stop it; returns the number of gait switches.
pub fn run_on(
    cfg: ControllerConfig,
    source: BusSource,
    time_scale: f64,
    signals: &Signals,
) -> Result<u64> {
    let ids = cfg.ids.clone();
    let foot = cfg.foot;
    let catalog = cfg.catalog()?;
    let mut ctrl = Controller::new(cfg, &catalog);
    let start = Instant::now();
    let now_us = || (start.elapsed().as_secs_f64() * time_scale * 1e6) as u64;
    let mut out: Vec<Message> = Vec::with_capacity(8);
    let mut backoff = Backoff::default();
    let mut switches_logged = 0;
    'open: while !signals.stopping() {
        let Some(mut bus) = open_with_retry(&source, &signals.stop, "controller", &mut || {})
        else {
            break;
        };
        // Only what the controller reads: in the kernel, so that the tactile stream (about 2,600
        // frames/s per foot) never reaches this process. Without the filter a controller that
        // fell behind the tactile stream heard touchdowns late, and the hopper fell every step.
        if let Err(e) = bus.set_filters(&ids.filters(&[
            MessageKind::FootContact,
            MessageKind::LegState,
            MessageKind::TerrainClass,
            MessageKind::NodeStatus,
        ])) {
            after_bus_error("controller filters", &e, &mut backoff, &signals.stop);
            continue 'open;
        }
        backoff.reset();
        tracing::info!(iface = %source.label(), foot, gait = ctrl.gait().id, "presrs controller running");
        while !signals.stopping() {
            // Everything queued, then the laws: a burst never waits one loop per frame.
            let mut wait = Duration::from_millis(1);
            loop {
                match bus.recv(wait) {
                    Ok(Some(st)) => {
                        // Undecodable frames (other traffic, garbage) are not ours: ignored.
                        if let Ok(Some((f, m))) = messages::decode(&st.frame, &ids) {
                            ctrl.on_message(f, &m, now_us(), &mut |o| out.push(o));
                        }
                        wait = Duration::ZERO;
                    }
                    Ok(None) => break,
                    Err(e) => {
                        after_bus_error("controller receive", &e, &mut backoff, &signals.stop);
                        continue 'open;
                    }
                }
            }
            ctrl.tick(now_us(), &mut |o| out.push(o));
            for m in out.drain(..) {
                if let Message::GaitStatus(g) = &m
                    && ctrl.switches != switches_logged
                {
                    switches_logged = ctrl.switches;
                    tracing::info!(gait = g.gait, terrain = g.terrain, reason = ?g.reason, "gait switch");
                }
                let Some(f) = m.to_frame(&ids, foot) else {
                    continue;
                };
                if let Err(e) = bus.send(&f) {
                    after_bus_error("controller send", &e, &mut backoff, &signals.stop);
                    continue 'open;
                }
            }
        }
    }
    tracing::info!(switches = ctrl.switches, "presrs controller stopped");
    Ok(ctrl.switches)
}
