//! `presrs` argument types: LegArgs.

use std::path::PathBuf;

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
