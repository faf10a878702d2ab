//! `presrs` argument types: ControllerArgs.

use std::path::PathBuf;

#[derive(clap::Args)]
pub struct ControllerArgs {
    /// CAN interface (can0, vcan0).
    #[arg(long)]
    pub iface: String,
    /// Gaits and policy (TOML or JSON by extension); see `examples/controller.toml`.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// The controller's clock rate relative to the wall clock; match `presrs lab sim --speed` when
    /// the simulator runs slower or faster than real time (on a robot: 1).
    #[arg(long, default_value_t = 1.0)]
    pub time_scale: f64,
    /// Overrides the config's `sweep_steps`: every gait for STEPS steps on each terrain it
    /// meets, the safe gait first, then the terrain's own (`presrs lab adaptation` tables the
    /// run's log).
    #[arg(long, value_name = "STEPS")]
    pub sweep: Option<u32>,
    /// Overrides the config's `terrains` key.
    #[command(flatten)]
    pub terrains: protocol::TerrainsArg,
}
