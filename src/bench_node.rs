//! `presrs lab bench-node`: the speed targets measured on the node as it runs.
//!
//! A load generator plays `--feet` feet at 100 Hz (PreSRS frame rate, CAN FD segments) with a
//! step every 300 ms (150 ms stance), using simulated G2 images of the four dynamic terrains.
//! It measures, per step, the wall time from sending the **last segment of the sampled frame**
//! (the frame nearest 70 ms after touchdown) to receiving that step's TerrainClass; and the
//! node's CPU time and resident memory over the measured window.
//!
//! - No `--iface`: the node's own receive/pipeline/send threads ([`node::NodeService::start`]) on an
//!   in-process bus in this process. CPU counts only those three threads; memory is the whole
//!   process (node plus load generator), an upper bound for the node.
//! - `--iface vcan0`: `presrs node` as a child process on that interface; CPU and memory are the
//!   child's alone.
//!
//! The figures go to a report (`--json`), not to a timed test: the machines are noisy.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result};
use lab::load::{self, Feet, SIDE, WARMUP_US};
use protocol::ids::IdConfig;

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
    /// `--ros2`: measure each feet count twice in one run, without and then with the ROS 2
    /// bridge beside the node on the same bus (publishing on Zenoh, as `presrs bridge` does);
    /// the report adds the bridge's CPU and drops.
    #[command(flatten)]
    pub ros2: ros2::Ros2Options,
}

pub fn run(a: BenchNodeArgs) -> Result<ExitCode> {
    anyhow::ensure!(
        a.seconds > 0.0 && a.seconds <= 3600.0,
        "--seconds {}: allowed (0, 3600]",
        a.seconds
    );
    let model = lab::model::load_or_train_logged(a.model.as_deref()).context("--model")?;
    anyhow::ensure!(
        model.input_rows == SIDE && model.input_cols == SIDE,
        "the model takes {}x{} images; the benchmark plays the PreSRS's 44x44",
        model.input_rows,
        model.input_cols
    );
    anyhow::ensure!(
        !(a.ros2.any() && (a.mcap.is_some() || a.iface.is_some())),
        "--ros2 measures the in-process node with and without the bridge; drop --mcap and --iface"
    );
    let runs: &[bool] = if a.ros2.any() {
        &[false, true]
    } else {
        &[false]
    };
    let mut reports = Vec::new();
    for (&n, &bridge) in a.feet.iter().flat_map(|n| runs.iter().map(move |b| (n, b))) {
        let (text, json) = bench_one(&a, n, &model, bridge)?;
        if !a.json {
            if a.feet.len() > 1 || bridge {
                println!();
            }
            if a.ros2.any() {
                println!(
                    "{}",
                    if bridge {
                        "with the ROS 2 bridge:"
                    } else {
                        "without the ROS 2 bridge:"
                    }
                );
            }
            print!("{text}");
        }
        reports.push(json);
    }
    if a.json {
        match reports.as_slice() {
            [one] => println!("{one}"),
            _ => println!("{}", serde_json::Value::Array(reports)),
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// One measurement with `feet_n` feet (the node in this process, or as a process on
/// `--iface`): its report as text and as JSON.
fn bench_one(
    a: &BenchNodeArgs,
    feet_n: u8,
    model: &node::classifier::Model,
    bridge: bool,
) -> Result<(String, serde_json::Value)> {
    let feet = Feet::new(feet_n, load::image_pool(), IdConfig::default()).context("--feet")?;
    let total_us = WARMUP_US + (a.seconds * 1e6) as u64;
    let (bus, run) = match &a.iface {
        None => (
            "inproc",
            load::bench_inproc(
                model.clone(),
                feet,
                total_us,
                a.mcap.as_deref(),
                a.node_threads,
                if bridge {
                    let out = a
                        .ros2
                        .start(
                            &IdConfig::default(),
                            &protocol::TerrainCatalog::paper(),
                            false,
                        )
                        .context("--ros2")?;
                    out.map(|o| Box::new(o) as Box<dyn record::FrameConsumer>)
                } else {
                    None
                },
            )?,
        ),
        Some(iface) => (
            iface.as_str(),
            load::bench_process(
                &std::env::current_exe()?,
                iface,
                model,
                feet,
                total_us,
                a.mcap.as_deref(),
            )
            .with_context(|| format!("--iface {iface}"))?,
        ),
    };
    let r = load::BenchReport {
        bus,
        label: a.label.as_deref(),
        feet: feet_n,
        seconds: a.seconds,
        memory_scope: run.memory_scope,
        tally: &run.tally,
        memory_mb: run.memory_mb,
        extra: run.extra,
    };
    let mut text = r.to_string();
    if let Some(b) = r.extra.get("beside").filter(|b| !b.is_null()) {
        text.push_str(&format!(
            "ROS 2 bridge beside it: CPU {:.1}% of one core, {} frames dropped\n",
            b["cpu_pct_of_one_core"].as_f64().unwrap_or(f64::NAN),
            b["dropped"]
        ));
    }
    Ok((text, r.to_json()))
}
