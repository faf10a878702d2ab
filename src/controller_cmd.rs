//! `presrs controller`: the gait controller as a process on a CAN interface. It follows the foot
//! switch and leg angle, sends LegCommand at `command_hz` (eq. (4) in stance, the eq. (5) angle in
//! flight), switches gait per the terrain the node reports, falls back to the safe gait when the
//! node's heartbeat stops, and sends GaitStatus at every switch and at `status_hz`
//! ([`controller::service::run`]).

use std::process::ExitCode;

use anyhow::{Context, Result};
use controller::ControllerConfig;
use presrs_cli::controller::ControllerArgs;

use protocol::bus::BusSource;
use protocol::component::Signals;

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
    }
    if let Some(n) = a.sweep {
        cfg.sweep_steps = n;
    }
    if a.terrains.terrains.is_some() || a.sweep.is_some() {
        let catalog = cfg.catalog()?;
        cfg.validate(&catalog)?;
    }
    if cfg.sweep_steps > 0 {
        tracing::info!(
            steps = cfg.sweep_steps,
            "sweeping: every gait for {} steps on each terrain met, the safe gait first",
            cfg.sweep_steps
        );
    }
    let signals = Signals::install()?;
    controller::service::run(
        cfg,
        BusSource::Iface(a.iface.clone()),
        a.time_scale,
        &signals.stop,
    )?;
    Ok(ExitCode::SUCCESS)
}
