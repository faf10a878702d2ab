//! `presrs leg`: the leg bridge as a process ([`leg::bridge::run`]): LegCommand to the motor
//! drivers of `leg.toml` (moteus, ODrive, MIT protocol), LegState and LegStatus from their
//! encoders, the damped stop on a stale command or a driver fault, every motor stopped at exit.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result};
use protocol::bus::BusSource;

use crate::runtime::Signals;

#[derive(clap::Args)]
pub struct LegArgs {
    /// CAN interface LegCommand comes on (can0, vcan0).
    #[arg(long)]
    pub iface: String,
    /// The leg: geometry, joints and drivers, impedance, timeouts (docs/real-robot.md, "The leg").
    #[arg(long)]
    pub config: PathBuf,
    /// Read every joint and send LegState, move nothing (bring-up).
    #[arg(long)]
    pub check: bool,
    /// The robot's clock rate relative to the wall clock (match `presrs sim --speed`; 1 on a robot).
    #[arg(long, default_value_t = 1.0)]
    pub time_scale: f64,
}

pub fn run(a: LegArgs) -> Result<ExitCode> {
    anyhow::ensure!(
        a.time_scale > 0.0 && a.time_scale.is_finite(),
        "--time-scale {}: expected a positive factor (1 = real time)",
        a.time_scale
    );
    let cfg = leg::LegConfig::from_file(&a.config).context("--config")?;
    if let Some(m) = &cfg.motor_iface {
        anyhow::ensure!(
            m == &a.iface,
            "{}: motor_iface = {m:?}: a second bus for the motors is not supported yet; \
             put the motors on --iface {} (the config check refuses ids that collide with ours)",
            a.config.display(),
            a.iface
        );
    }
    let signals = Signals::install()?;
    let c = leg::bridge::run(
        cfg,
        a.check,
        &BusSource::Iface(a.iface),
        a.time_scale,
        &signals.stop,
    );
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
