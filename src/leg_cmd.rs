//! `presrs leg`: the leg bridge as a process ([`leg::bridge::run`]): LegCommand to the motor
//! drivers of `leg.toml` (moteus, ODrive, MIT protocol), LegState and LegStatus from their
//! encoders, the damped stop on a stale command or a driver fault, every motor stopped at exit.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result};
use protocol::bus::BusSource;

use protocol::component::Signals;

#[derive(clap::Args)]
pub struct LegArgs {
    /// CAN interface LegCommand comes on (can0, vcan0).
    #[arg(long, required_unless_present = "example")]
    pub iface: Option<String>,
    /// The leg: geometry, joints and drivers, impedance, timeouts (docs/real-robot.md, "The leg").
    #[arg(long, required_unless_present = "example")]
    pub config: Option<PathBuf>,
    /// Print the built-in prismatic leg on this protocol's motors (moteus, odrive, mit) as a
    /// config file to start from, and exit.
    #[arg(long, value_name = "PROTOCOL", conflicts_with_all = ["iface", "config"])]
    pub example: Option<leg::DriverKind>,
    /// Read every joint and send LegState, move nothing (bring-up).
    #[arg(long)]
    pub check: bool,
    /// The robot's clock rate relative to the wall clock (match `presrs lab sim --speed`; 1 on a robot).
    #[arg(long, default_value_t = 1.0)]
    pub time_scale: f64,
}

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
