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

use std::process::ExitCode;

use anyhow::{Context, Result};
use lab::load::{self, Beside, Feet, SIDE, WARMUP_US};
use presrs_cli::bench_node::BenchNodeArgs;
use protocol::ids::IdConfig;

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
    anyhow::ensure!(
        !(a.keep_unknown.is_some() && (a.ros2.any() || a.iface.is_some())),
        "--keep-unknown measures the in-process node with and without keeping; drop --ros2 and --iface"
    );
    let runs = Beside::plan(a.ros2.any(), a.keep_unknown.is_some());
    let mut reports = Vec::new();
    for (&n, &beside) in a.feet.iter().flat_map(|n| runs.iter().map(move |b| (n, b))) {
        let (text, json) = bench_one(&a, n, &model, beside)?;
        if !a.json {
            if a.feet.len() > 1 || runs.len() > 1 {
                println!();
            }
            if let Some(heading) = beside.heading(runs.len()) {
                println!("{heading}");
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
    beside: Beside,
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
                if beside == Beside::Bridge {
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
                a.keep_unknown.as_deref().filter(|_| beside == Beside::Keep),
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
    Ok((r.to_string(), r.to_json()))
}
