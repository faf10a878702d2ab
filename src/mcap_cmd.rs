//! `presrs mcap`: a candump log to an MCAP file; and the `--mcap` / `--foxglove` options with
//! which `presrs node` and `presrs sim` record live. The channels and the writing are
//! [`record`]'s; this module reads arguments and says what happened.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;

use anyhow::{Context, Result};
use node::classifier::Model;
use node::{NodeService, Output};
use protocol::{IdConfig, TerrainCatalog};
use record::{LiveRecorder, McapFile, Recorder, Sink};

#[derive(clap::Args)]
pub struct McapArgs {
    /// candump log (`candump -L` format, as `candump -L any > run.log` writes it).
    pub log: PathBuf,
    /// The MCAP file to write.
    #[arg(long)]
    pub out: PathBuf,
    /// Also run the node with this model on the way: its TerrainClass per step goes on
    /// `/footN/terrain/model`, beside any TerrainClass already in the log.
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Node config (TOML): identifiers, feet, stance timing (see `examples/node.toml`).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Print the counts as JSON.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub terrains: crate::cli::TerrainsArg,
}

pub fn run(a: McapArgs) -> Result<ExitCode> {
    let mut cfg = crate::cli::load_node_config(a.config.as_deref(), &a.terrains)?;
    let catalog = cfg.catalog().context("--config terrains")?;
    let ids = cfg.ids.clone();
    let mut node = match &a.model {
        Some(m) => {
            let model = Model::load(m).context("--model")?;
            // The same decisions on every conversion, as `presrs node --replay` makes them.
            cfg.refit = cfg.refit.reproducible();
            Some(NodeService::new(cfg, model).with_context(|| format!("--model {}", m.display()))?)
        }
        None => None,
    };
    let file =
        std::fs::File::open(&a.log).with_context(|| format!("opening {}", a.log.display()))?;
    let records = protocol::candump::read_log(std::io::BufReader::new(file))
        .with_context(|| format!("reading {}", a.log.display()))?;
    let mut out = McapFile::create(&a.out).context("--out")?;
    let mut rec = Recorder::new(ids, catalog);
    let mut decided = Vec::new();
    for r in &records {
        let st = &r.stamped;
        rec.frame(st, &mut out).context("--out")?;
        if let Some(node) = node.as_mut() {
            // The node on the log's clock, one record at a time, as `presrs node --replay`.
            node.replay(std::iter::once(st), &mut |t, o| {
                if let Output::Class { foot, class } = o {
                    decided.push((t, foot, class));
                }
            });
            for (t, foot, class) in decided.drain(..) {
                rec.model_decision(t, foot, &class, &mut out)
                    .context("--out")?;
            }
        }
    }
    out.finish().context("--out")?;
    let s = rec.stats();
    if a.json {
        println!(
            "{}",
            serde_json::json!({ "frames": records.len(), "out": a.out, "stats": s })
        );
    }
    eprintln!(
        "{} frames -> {}: {} messages ({} images, {} model TerrainClass); {} undecodable and {} foreign frames not recorded",
        records.len(),
        a.out.display(),
        s.messages,
        s.images,
        s.model_decisions,
        s.undecodable,
        s.foreign
    );
    Ok(ExitCode::SUCCESS)
}

/// `--mcap FILE` and `--foxglove [ADDR]`: record while running.
#[derive(clap::Args, Clone, Debug, Default)]
pub struct LiveArgs {
    /// Record every frame seen and sent to this MCAP file, off the hot path (frames are
    /// dropped and counted, never waited for, when the disk is slower than the bus).
    #[arg(long, value_name = "FILE")]
    pub mcap: Option<PathBuf>,
    /// Serve the same channels live to the Foxglove app (Open connection -> Foxglove
    /// WebSocket, ws://HOST:PORT).
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = DEFAULT_FOXGLOVE)]
    pub foxglove: Option<String>,
}

#[cfg(feature = "foxglove")]
const DEFAULT_FOXGLOVE: &str = record::DEFAULT_ADDR;
#[cfg(not(feature = "foxglove"))]
const DEFAULT_FOXGLOVE: &str = "127.0.0.1:8765";

/// About 1.5 s of six feet's traffic (20,000 frames/s): the writer may stall that long (a
/// slow disk, a chunk being written) before frames are dropped. 88 bytes each: 2.9 MB.
const LIVE_QUEUE: usize = 32_768;

impl LiveArgs {
    /// The recorder for these options, or `None` when none is asked for or none could start.
    /// A sink that cannot start is an error in the log, naming its path or address; the
    /// caller runs on without it.
    pub fn start(&self, ids: &IdConfig, catalog: &TerrainCatalog) -> Option<LiveRecorder> {
        let mut sinks: Vec<(String, Box<dyn Sink>)> = Vec::new();
        if let Some(p) = &self.mcap {
            match McapFile::create(p) {
                Ok(f) => {
                    tracing::info!(file = %p.display(), "recording to MCAP");
                    sinks.push((p.display().to_string(), Box::new(f)));
                }
                Err(e) => tracing::error!("--mcap: {e}; running without the recording"),
            }
        }
        if let Some(addr) = &self.foxglove {
            foxglove_sink(addr, &mut sinks);
        }
        if sinks.is_empty() {
            return None;
        }
        match LiveRecorder::start(
            Recorder::new(ids.clone(), catalog.clone()),
            sinks,
            LIVE_QUEUE,
        ) {
            Ok(r) => Some(r),
            Err(e) => {
                tracing::error!("{e}; running without the recording");
                None
            }
        }
    }
}

#[cfg(feature = "foxglove")]
fn foxglove_sink(addr: &str, sinks: &mut Vec<(String, Box<dyn Sink>)>) {
    match record::FoxgloveServer::start(addr) {
        Ok(s) => {
            tracing::info!(
                "Foxglove view on ws://{}:{} (Foxglove app: Open connection -> Foxglove WebSocket)",
                addr.rsplit_once(':').map_or(addr, |(h, _)| h),
                s.port()
            );
            sinks.push((format!("ws://{addr}"), Box::new(s)));
        }
        Err(e) => tracing::error!("--foxglove: {e}; running without the live view"),
    }
}

#[cfg(not(feature = "foxglove"))]
fn foxglove_sink(addr: &str, _: &mut Vec<(String, Box<dyn Sink>)>) {
    tracing::error!(
        "--foxglove {addr}: this presrs was built without the `foxglove` feature; running without the live view"
    );
}

/// Ends a live recording and says what it holds.
pub fn finish(rec: Option<LiveRecorder>) {
    if let Some(r) = rec {
        let s = r.finish();
        tracing::info!(
            messages = s.stats.messages,
            images = s.stats.images,
            dropped = s.dropped,
            failed_sinks = s.failed.len(),
            "recording finished"
        );
    }
}

/// The tap of a live recorder as the node takes it.
pub fn tap(rec: &Option<LiveRecorder>) -> Option<Arc<dyn protocol::bus::Tap>> {
    rec.as_ref().map(|r| r.tap() as Arc<dyn protocol::bus::Tap>)
}

#[derive(clap::Args)]
pub struct ViewArgs {
    /// An MCAP recording (`presrs mcap`, or `--mcap` of node, sim or demo).
    pub recording: PathBuf,
    /// The PNG to write.
    #[arg(long)]
    pub out: PathBuf,
    /// The foot to show.
    #[arg(long, default_value_t = 0)]
    pub foot: u8,
    /// Show the image nearest this time, s from the start (default: the most loaded image of
    /// the last step decided).
    #[arg(long, value_name = "S")]
    pub at: Option<f64>,
}

/// `presrs view`: a recording's pressure image, terrain, gait and speed in one PNG.
pub fn view(a: ViewArgs) -> Result<ExitCode> {
    let msgs = record::read::read_json(&a.recording)?;
    anyhow::ensure!(
        !msgs.is_empty(),
        "{}: no JSON messages (is it a presrs recording?)",
        a.recording.display()
    );
    let name = a
        .recording
        .file_name()
        .map_or_else(String::new, |n| n.to_string_lossy().to_string());
    let s = lab::view::render(
        &msgs,
        a.foot,
        a.at,
        &format!(
            "{name}: foot {}'s pressure image, terrain, gait and speed",
            a.foot
        ),
        &a.out,
    )
    .with_context(|| format!("--out {}", a.out.display()))?;
    eprintln!(
        "{}: {:.1} s, {} images, {} TerrainClass of foot {}{}; image at {} -> {}",
        a.recording.display(),
        s.span_s,
        s.images,
        s.steps,
        a.foot,
        if s.has_truth {
            ", with the simulator's truth"
        } else {
            ""
        },
        s.image_t_s.map_or("-".into(), |t| format!("{t:.2} s")),
        a.out.display()
    );
    Ok(ExitCode::SUCCESS)
}
