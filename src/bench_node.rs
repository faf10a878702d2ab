//! `presrs bench-node`: issue 5's speed targets measured on the node as it runs.
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
use std::process::{Command, ExitCode, Stdio};
use std::time::Duration;

use anyhow::{Context, Result};
use lab::load::{self, Feet, NodeProcess, SIDE, Tally, WARMUP_US, memory_mb, task_cpu_ns};
use node::NodeConfig;
use protocol::bus::{BusSource, CanBus, InProcBus};
use protocol::ids::{IdConfig, MessageKind};

#[derive(clap::Args)]
pub struct BenchNodeArgs {
    /// Run `presrs node` as a child process on this CAN interface (vcan0). Default: the node's
    /// threads on an in-process bus in this process.
    #[arg(long)]
    pub iface: Option<String>,
    /// Model file; default: the demo's model (trained on first run, then cached).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Feet served, each at 100 Hz.
    #[arg(long, default_value_t = 6)]
    pub feet: u8,
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
}

pub fn run(a: BenchNodeArgs) -> Result<ExitCode> {
    anyhow::ensure!(
        a.seconds > 0.0 && a.seconds <= 3600.0,
        "--seconds {}: allowed (0, 3600]",
        a.seconds
    );
    let model = crate::cli::load_or_train(a.model.as_deref())?;
    anyhow::ensure!(
        model.input_rows == SIDE && model.input_cols == SIDE,
        "the model takes {}x{} images; the benchmark plays the PreSRS's 44x44",
        model.input_rows,
        model.input_cols
    );
    let ids = IdConfig::default();
    let feet = Feet::new(a.feet, load::image_pool(), ids.clone()).context("--feet")?;
    let cfg = NodeConfig {
        feet: a.feet,
        ..NodeConfig::default()
    };
    let total_us = WARMUP_US + (a.seconds * 1e6) as u64;

    match &a.iface {
        None => {
            let bus = InProcBus::new();
            let live = record::LiveOptions {
                mcap: a.mcap.clone(),
                foxglove: None,
            };
            let recording = live.start(&ids, &protocol::TerrainCatalog::paper());
            anyhow::ensure!(
                a.mcap.is_none() || recording.is_some(),
                "--mcap: the recording could not start (the log says why)"
            );
            let node = node::NodeService::new(cfg.clone(), model)?.start_with_tap(
                BusSource::InProc(bus.clone()),
                recording.as_ref().map(|r| r.bus_tap()),
            )?;
            let rec_cpu_start = task_cpu_ns("self", Some(&["record"]));
            let cpu = || task_cpu_ns("self", Some(&["receive", "pipeline", "send"]));
            let result = load::measure(
                &mut bus.endpoint(),
                &mut bus.endpoint(),
                &ids,
                feet,
                total_us,
                &cpu,
            );
            let rec_cpu_end = task_cpu_ns("self", Some(&["record"]));
            let stats = node.stop();
            let mem = memory_mb("self");
            let m = result?;
            let recorded = recording.map(|r| {
                let s = r.finish();
                serde_json::json!({
                    "file": a.mcap,
                    "messages": s.stats.messages,
                    "images": s.stats.images,
                    "dropped": s.dropped,
                    "failed": s.failed,
                    "recorder_cpu_pct_of_one_core": rec_cpu_start.zip(rec_cpu_end)
                        .map(|(a0, a1)| a1.saturating_sub(a0) as f64 * 1e-9 / (total_us as f64 * 1e-6) * 100.0),
                })
            });
            let extra = serde_json::json!({
                "node_rx_frames": stats.rx_frames,
                "node_rx_dropped": stats.rx_dropped,
                "bus_overruns": bus.overruns(),
                "mcap": recorded,
            });
            report(
                &a,
                "inproc",
                "whole process: node threads and load generator",
                &m,
                mem,
                extra,
            )
        }
        Some(iface) => {
            let dir = std::env::temp_dir().join(format!("presrs-bench-{}", std::process::id()));
            std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
            let model_path = dir.join("model.json");
            model
                .save(&model_path)
                .with_context(|| format!("writing {}", model_path.display()))?;
            let cfg_path = dir.join("node.toml");
            std::fs::write(&cfg_path, format!("feet = {}\n", a.feet))
                .with_context(|| format!("writing {}", cfg_path.display()))?;
            let mut tx = protocol::bus::SocketCanBus::open(iface)
                .with_context(|| format!("--iface {iface}"))?;
            let mut rx = protocol::bus::SocketCanBus::open(iface)
                .with_context(|| format!("--iface {iface}"))?;
            rx.set_filters(&ids.filters(&[MessageKind::TerrainClass, MessageKind::NodeStatus]))?;
            let mut cmd = Command::new(std::env::current_exe()?);
            cmd.args(["node", "--iface", iface, "--model"])
                .arg(&model_path)
                .arg("--config")
                .arg(&cfg_path);
            if let Some(p) = &a.mcap {
                cmd.arg("--mcap").arg(p);
            }
            let mut node = NodeProcess(
                cmd.stdout(Stdio::null())
                    .spawn()
                    .context("starting presrs node")?,
            );
            let result = node
                .wait_for_heartbeat(&mut rx, &ids, Duration::from_secs(20))
                .and_then(|()| {
                    let pid = node.pid();
                    let cpu = || task_cpu_ns(&pid, None);
                    load::measure(&mut tx, &mut rx, &ids, feet, total_us, &cpu)
                });
            let mem = memory_mb(&node.pid());
            node.stop();
            let _ = std::fs::remove_dir_all(&dir);
            let m = result?;
            report(
                &a,
                iface,
                "the presrs node process",
                &m,
                mem,
                serde_json::json!({}),
            )
        }
    }
}

fn report(
    a: &BenchNodeArgs,
    bus: &str,
    memory_scope: &str,
    tally: &Tally,
    memory_mb: (Option<f64>, Option<f64>),
    extra: serde_json::Value,
) -> Result<ExitCode> {
    let r = load::BenchReport {
        bus,
        label: a.label.as_deref(),
        feet: a.feet,
        seconds: a.seconds,
        memory_scope,
        tally,
        memory_mb,
        extra,
    };
    if a.json {
        println!("{}", r.to_json());
    } else {
        print!("{r}");
    }
    Ok(ExitCode::SUCCESS)
}
