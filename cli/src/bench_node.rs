//! `presrs` argument types: BenchNodeArgs.

use std::path::PathBuf;

#[derive(clap::Args)]
pub struct BenchNodeArgs {
    /// Run `presrs node` as a child process on this CAN interface (vcan0). Default: the node's
    /// threads on an in-process bus in this process.
    #[arg(long)]
    pub iface: Option<String>,
    /// Model file; default: the demo's model (trained on first run, then cached).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Feet served, each at 100 Hz; a list (`1,4,8`) measures each count in turn (`--json`:
    /// an array of reports).
    #[arg(long, value_delimiter = ',', default_value = "6")]
    pub feet: Vec<u8>,
    /// Measured seconds, after 1 s of warm-up.
    #[arg(long, default_value_t = 10.0)]
    pub seconds: f64,
    /// A label carried into the report (say "emulated" for a VM).
    #[arg(long)]
    pub label: Option<String>,
    /// Print the report as one JSON object.
    #[arg(long)]
    pub json: bool,
    /// Record the node's traffic to this MCAP file while measuring (`presrs node --mcap`):
    /// the report adds the recorder's CPU, what it wrote and what it dropped.
    #[arg(long, value_name = "FILE")]
    pub mcap: Option<PathBuf>,
    /// The in-process node's threads: 1 (the default, as `presrs node` runs) or 3 (receive,
    /// pipeline and send), to measure one against the other (docs/decisions/node-threads.md).
    #[arg(long, default_value = "1")]
    pub node_threads: node::NodeThreads,
    /// Measure each feet count twice in one run, without and then with the node keeping its
    /// unknown stances in DIR (`presrs node --keep-unknown`); the report adds what it wrote and
    /// dropped. With the demo's model little of the load is unknown: give `--model` one that
    /// lacks a terrain of the load to keep many.
    #[arg(long, value_name = "DIR")]
    pub keep_unknown: Option<std::path::PathBuf>,
    /// `--ros2`: measure each feet count twice in one run, without and then with the ROS 2
    /// bridge beside the node on the same bus (publishing on Zenoh, as `presrs bridge` does);
    /// the report adds the bridge's CPU and drops.
    #[command(flatten, next_help_heading = "ROS 2 (Zenoh, rmw_zenoh)")]
    pub ros2: ros2::Ros2Options,
}
