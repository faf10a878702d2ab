//! `presrs node`: the process on the robot, live on a CAN interface or `--replay` of a candump
//! log. The node itself is [`node::NodeService`]; this module reads the arguments, maps SIGHUP
//! to a model reload and SIGINT/SIGTERM to a stop, and prints a replay's decisions.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Duration;

use anyhow::{Context, Result};
use node::NodeService;
use node::classifier::Model;
use protocol::bus::BusSource;

use protocol::component::Signals;

#[derive(clap::Args)]
pub struct NodeArgs {
    /// CAN interface (can0, vcan0).
    #[arg(long, required_unless_present = "replay", conflicts_with = "replay")]
    pub iface: Option<String>,
    /// Run the pipeline on a candump log (`candump -L` format) instead of a bus, with the log's
    /// timestamps, and print the TerrainClass stream.
    #[arg(long)]
    pub replay: Option<PathBuf>,
    /// Model file from `presrs train`.
    #[arg(long)]
    pub model: PathBuf,
    /// Node config (TOML); see `examples/node.toml`.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Replay: print each TerrainClass as a JSON line (`t_us`: when the node decided the step,
    /// on the log's clock, µs; `step`: the foot's step counter, as on the bus).
    #[arg(long)]
    pub json: bool,
    /// One CSV row per step and foot, live or on a replay: foot, step (the bus's counter,
    /// numbered as `capture`'s manifest), touchdown_s (the debounced touchdown) and
    /// decision_s (when the node decided), both on the log's clock (its timestamps; live, the
    /// bus's receive clock), terrain, unknown_reason, confidence_pct (empty for unknown
    /// ground: no terrain was chosen) and gait (the controller's, empty before its first
    /// GaitStatus).
    #[arg(long, value_name = "FILE")]
    pub csv: Option<PathBuf>,
    /// Overrides the config's `terrains` key.
    #[command(flatten)]
    pub terrains: protocol::TerrainsArg,
    #[command(flatten)]
    pub live: record::LiveOptions,
    /// `--ros2`: the node's bus as ROS 2 topics on Zenoh; `--ros2-bag DIR`: as a rosbag2.
    #[command(flatten)]
    pub ros2: ros2::Ros2Options,
}

pub fn run(a: NodeArgs) -> Result<ExitCode> {
    let mut cfg =
        node::NodeConfig::load_or_default(a.config.as_deref(), &a.terrains).context("--config")?;
    // The error names the file already.
    let model = Model::load(&a.model).context("--model")?;
    match (&a.replay, &a.iface) {
        (Some(log), _) => {
            anyhow::ensure!(
                a.live.mcap.is_none() && a.live.foxglove.is_none() && !a.ros2.any(),
                "--mcap, --foxglove, --ros2 and --ros2-bag record a live node; for a log, run `presrs mcap {} --out FILE.mcap --model {}` (or `presrs mcap --ros2 {} --out DIR --model {}`)",
                log.display(),
                a.model.display(),
                log.display(),
                a.model.display()
            );
            // The same decisions on every replay: a refit lands at the step that asked for it.
            cfg.refit = cfg.refit.reproducible();
            let node = NodeService::new(cfg, model)
                .with_context(|| format!("--model {}", a.model.display()))?;
            replay(node, log, a.json, a.csv.as_deref())
        }
        (None, Some(iface)) => {
            let signals = Signals::install()?;
            tracing::info!(
                %iface,
                model = %a.model.display(),
                feet = cfg.feet,
                sample_ms = cfg.sample_ms,
                repair = ?cfg.repair,
                multi_frame = cfg.multi_frame,
                "presrs node starting"
            );
            let mut node = NodeService::new(cfg, model)
                .with_context(|| format!("--model {}", a.model.display()))?;
            // After the checks above: a bad model or config is an error before any file exists.
            let steps = a
                .csv
                .as_deref()
                .map(|p| node::step_table::StepLog::create(p, node.catalog().clone()))
                .transpose()
                .context("--csv")?;
            if let Some(s) = steps.as_ref().and_then(|s| s.sender()) {
                node.set_step_log(s);
            }
            let outputs = crate::ros2_cmd::LiveOutputs::start(
                &a.live,
                &a.ros2,
                node.ids(),
                node.catalog(),
                false,
            )?;
            let running = node.start_with_tap(
                BusSource::Iface(iface.clone()),
                outputs.recorder.as_ref().map(|r| r.bus_tap()),
            )?;
            while !signals.stopping() && running.is_running() {
                if signals.take_reload() {
                    match running.reload_model(&a.model) {
                        Ok(id) => {
                            tracing::info!(model = %a.model.display(), model_id = id, "SIGHUP: model reloaded")
                        }
                        Err(e) => tracing::error!("SIGHUP: {e}; keeping the model already loaded"),
                    }
                }
                std::thread::sleep(Duration::from_millis(50));
            }
            running.stop();
            outputs.finish();
            if let (Some(s), Some(path)) = (steps, &a.csv) {
                let (rows, dropped) = s.finish().context("--csv")?;
                tracing::info!(rows, dropped, path = %path.display(), "step table written");
            }
            Ok(ExitCode::SUCCESS)
        }
        (None, None) => anyhow::bail!("give --iface IFACE or --replay FILE.log"),
    }
}

/// The log through the node on the log's own clock ([`node::replay`]), each decision printed.
fn replay(mut node: NodeService, log: &Path, json: bool, csv: Option<&Path>) -> Result<ExitCode> {
    use std::io::Write;
    // Checked to its end before the first decision is printed, then streamed.
    let file = protocol::candump::LogFile::check(log)?;
    let mut records = file.records()?;
    let catalog = node.catalog().clone();
    let mut table = match csv {
        Some(p) => {
            let f = std::fs::File::create(p).with_context(|| format!("--csv {}", p.display()))?;
            let mut w = std::io::BufWriter::new(f);
            writeln!(w, "{}", node::step_table::HEADER)?;
            Some(w)
        }
        None => None,
    };
    let mut write_err = None;
    let summary = node::replay::replay_log(&mut node, &mut records, &mut |(t_us, o)| {
        if let (Some(w), Some(row)) = (table.as_mut(), node::step_table::StepRow::of(t_us, &o))
            && write_err.is_none()
            && let Err(e) = writeln!(w, "{}", row.to_csv(&catalog))
        {
            write_err = Some(e);
        }
        let node::service::Output::Class {
            foot, class, gait, ..
        } = o
        else {
            return;
        };
        if json {
            let line = node::replay::class_json(t_us, foot, &class, gait, &catalog);
            println!("{line}");
        } else {
            println!("{}", node::replay::class_line(t_us, foot, &class, &catalog));
        }
    });
    records.finish()?;
    if let (Some(p), Some(e)) = (csv, write_err) {
        return Err(e).with_context(|| format!("--csv {}", p.display()));
    }
    if let (Some(p), Some(mut w)) = (csv, table) {
        w.flush()
            .with_context(|| format!("--csv {}", p.display()))?;
    }
    eprintln!("{summary}");
    Ok(ExitCode::SUCCESS)
}
