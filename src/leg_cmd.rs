//! `presrs leg`: the leg bridge as a process ([`leg::bridge::run`]): LegCommand to the motor
//! drivers of `leg.toml` (moteus, ODrive, MIT protocol), LegState and LegStatus from their
//! encoders, the damped stop on a stale command or a driver fault, every motor stopped at exit.

use std::process::ExitCode;

use anyhow::{Context, Result};
use presrs_cli::leg::LegArgs;
use protocol::bus::BusSource;

use protocol::component::Signals;

pub fn run(a: LegArgs) -> Result<ExitCode> {
    anyhow::ensure!(
        a.time_scale > 0.0 && a.time_scale.is_finite(),
        "--time-scale {}: expected a positive factor (1 = real time)",
        a.time_scale
    );
    if let Some(kind) = a.example {
        print!("{}", leg::LegConfig::example(kind).to_toml()?);
        return Ok(ExitCode::SUCCESS);
    }
    let (Some(iface), Some(path)) = (a.iface, a.config) else {
        anyhow::bail!("--iface and --config are required (or --example PROTOCOL)");
    };
    let cfg = leg::LegConfig::from_file(&path).context("--config")?;
    let signals = Signals::install()?;
    let main = BusSource::Iface(iface);
    let c = match cfg.motor_iface.clone() {
        Some(m) if m != main.label() => leg::bridge::run_two_buses(
            cfg,
            a.check,
            &main,
            &BusSource::Iface(m),
            a.time_scale,
            &signals.stop,
        ),
        _ => leg::bridge::run(cfg, a.check, &main, a.time_scale, &signals.stop),
    };
    tracing::info!(
        commands = c.commands,
        joint_commands = c.joint_commands,
        clamped = c.clamped,
        malformed_replies = c.malformed_replies,
        stopped_periods = c.stopped_periods,
        "leg bridge ended"
    );
    Ok(ExitCode::SUCCESS)
}
