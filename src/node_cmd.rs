//! `presrs node`: the process on the robot, live on a CAN interface or `--replay` of a candump
//! log. The node itself is [`node::NodeService`]; this module reads the arguments, maps SIGHUP
//! to a model reload and SIGINT/SIGTERM to a stop, and prints a replay's decisions.

use std::path::Path;
use std::process::ExitCode;

use anyhow::{Context, Result};
use node::NodeService;
use node::classifier::Model;
use presrs_cli::node::NodeArgs;
use protocol::{bus::BusSource, component::Signals};

pub fn run(a: NodeArgs) -> Result<ExitCode> {
    let mut cfg =
        node::NodeConfig::load_or_default(a.config.as_deref(), &a.terrains).context("--config")?;
    // The error names the file already.
    let model = Model::load(&a.model).context("--model")?;
    let model_ids: Vec<u8> = model.classes.iter().map(|c| c.terrain_id).collect();
    match (&a.replay, &a.iface) {
        (Some(log), _) => {
            let (l, m) = (log.display(), a.model.display());
            anyhow::ensure!(
                a.live.mcap.is_none() && a.live.foxglove.is_none() && !a.ros2.any(),
                "--mcap, --foxglove, --ros2 and --ros2-bag record a live node; for a log, run `presrs mcap {l} --out FILE.mcap --model {m}` (or `presrs mcap --ros2 {l} --out DIR --model {m}`)"
            );
            // The same decisions on every replay: a refit lands at the step that asked for it.
            cfg.refit = cfg.refit.reproducible();
            let mut node = NodeService::new(cfg, model)
                .with_context(|| format!("--model {}", a.model.display()))?;
            tracing::info!("deciding frame {}", node.sample_time());
            let keep = keep_unknown(&a, &mut node, &log.display().to_string(), true)?;
            let code = replay(node, log, &a, model_ids)?;
            finish_keep(keep, &a)?;
            Ok(code)
        }
        (None, Some(iface)) => {
            let signals = Signals::install()?;
            let (feet, repair, multi_frame) = (cfg.feet, cfg.repair, cfg.multi_frame);
            let terrains = cfg.terrains.clone();
            let mut node = NodeService::new(cfg, model)
                .with_context(|| format!("--model {}", a.model.display()))?;
            tracing::info!(
                %iface,
                model = %a.model.display(),
                feet,
                repair = ?repair,
                multi_frame,
                "presrs node starting; deciding frame {}",
                node.sample_time()
            );
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
            let keep = keep_unknown(&a, &mut node, iface, false)?;
            let outputs = crate::ros2_cmd::LiveOutputs::start(
                &a.live,
                &a.ros2,
                node.ids(),
                node.catalog(),
                false,
            )?;
            let mut running = node.start_with_tap(
                BusSource::Iface(iface.clone()),
                outputs.recorder.as_ref().map(|r| r.bus_tap()),
            )?;
            running.serve(&signals, &a.model, terrains.as_deref());
            running.stop();
            outputs.finish();
            if let (Some(s), Some(path)) = (steps, &a.csv) {
                let (rows, dropped) = s.finish().context("--csv")?;
                tracing::info!(rows, dropped, path = %path.display(), "step table written");
            }
            finish_keep(keep, &a)?;
            Ok(ExitCode::SUCCESS)
        }
        (None, None) => anyhow::bail!("give --iface IFACE or --replay FILE.log"),
    }
}

/// `--keep-unknown DIR`: the keeper on the node, its writer here.
fn keep_unknown(
    a: &NodeArgs,
    node: &mut NodeService,
    source: &str,
    replay: bool,
) -> Result<Option<node::unknown::keep::KeepWriter>> {
    let Some(dir) = &a.keep_unknown else {
        return Ok(None);
    };
    let (keeper, writer) =
        node::unknown::keep::UnknownKeeper::create(dir, source, &node.catalog().clone())
            .with_context(|| format!("--keep-unknown {}", dir.display()))?;
    node.set_keep_unknown(if replay { keeper.waiting() } else { keeper });
    Ok(Some(writer))
}

/// Waits for the kept stances to be written (the node dropped) and says where they are.
fn finish_keep(keep: Option<node::unknown::keep::KeepWriter>, a: &NodeArgs) -> Result<()> {
    if let (Some(w), Some(dir)) = (keep, &a.keep_unknown) {
        let c = w
            .finish()
            .with_context(|| format!("--keep-unknown {}", dir.display()))?;
        eprintln!("kept {c} in {}", dir.display());
    }
    Ok(())
}

/// The log through the node on the log's own clock ([`node::replay`]), each decision printed,
/// and with `--truth`, the tally against the simulator's truth.
fn replay(mut node: NodeService, log: &Path, a: &NodeArgs, ids: Vec<u8>) -> Result<ExitCode> {
    let mut truth = (a.truth.as_deref())
        .map(|p| node::truth::TruthTally::from_file(p, node.catalog(), ids))
        .transpose()
        .context("--truth")?;
    let mut out = std::io::stdout().lock();
    let csv = a.csv.as_deref();
    let summary = node::replay::replay_file(&mut node, log, a.json, csv, truth.as_mut(), &mut out)
        .map_err(|e| match e {
            node::replay::ReplayFileError::Table { .. } => anyhow::Error::new(e).context("--csv"),
            e => e.into(),
        })?;
    eprintln!("{summary}");
    truth.iter().for_each(|t| eprintln!("{t}"));
    Ok(ExitCode::SUCCESS)
}
