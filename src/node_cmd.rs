//! `presrs node`: the process on the robot. Live on a CAN interface, or `--replay` of a candump
//! log through the same pipeline.
//!
//! Live, three threads joined by bounded crossbeam channels:
//! - receive: reads the bus and forwards every frame; it never blocks on the others (a full queue
//!   drops the frame and counts it);
//! - pipeline: reassembly, stance tracking and classification ([`StancePipeline`]); SIGHUP
//!   reloads the model here, keeping the old one if the new file is bad;
//! - send: TerrainClass frames as they come, NodeStatus at `status_hz`.
//!
//! Each of receive and send owns its own socket, opened with retry and backoff: a missing
//! interface, or one that goes down, is reported in the log and in NodeStatus, never fatal.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicU8, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use crossbeam_channel::{Receiver, RecvTimeoutError, Sender, TrySendError, bounded};
use node::classifier::Model;
use node::{NodeConfig, StancePipeline};
use protocol::frame::{CanFrame, Stamped};
use protocol::messages::{Message, NodeState, NodeStatus, TerrainClass};

use crate::runtime::{Backoff, BusSource, Signals, after_bus_error, open_source_with_retry};

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
    /// Replay: print each TerrainClass as a JSON line.
    #[arg(long)]
    pub json: bool,
    /// Overrides the config's `terrains` key.
    #[command(flatten)]
    pub terrains: crate::cli::TerrainsArg,
}

pub fn load_config(path: Option<&Path>) -> Result<NodeConfig> {
    let Some(p) = path else {
        return Ok(NodeConfig::default());
    };
    NodeConfig::load(p).context("--config")
}

pub fn run(a: NodeArgs) -> Result<ExitCode> {
    let mut cfg = load_config(a.config.as_deref())?;
    if a.terrains.terrains.is_some() {
        cfg.terrains = a.terrains.terrains.clone();
    }
    let catalog = cfg.catalog()?;
    let model = Model::load(&a.model).with_context(|| format!("--model {}", a.model.display()))?;
    model
        .check_catalog(&catalog)
        .with_context(|| format!("--model {}", a.model.display()))?;
    match (&a.replay, &a.iface) {
        (Some(log), _) => replay(cfg, model, log, a.json, &catalog),
        (None, Some(iface)) => {
            let signals = Signals::install()?;
            live(
                cfg,
                model,
                &a.model,
                BusSource::Iface(iface.clone()),
                signals,
            )?;
            Ok(ExitCode::SUCCESS)
        }
        (None, None) => anyhow::bail!("give --iface IFACE or --replay FILE.log"),
    }
}

fn replay(
    mut cfg: NodeConfig,
    model: Model,
    log: &Path,
    json: bool,
    catalog: &protocol::TerrainCatalog,
) -> Result<ExitCode> {
    // The same decisions on every replay: a refit lands at the step that asked for it.
    cfg.refit = cfg.refit.reproducible();
    let file = std::fs::File::open(log).with_context(|| format!("opening {}", log.display()))?;
    let records = protocol::candump::read_log(std::io::BufReader::new(file))
        .with_context(|| format!("reading {}", log.display()))?;
    let mut pipeline = StancePipeline::new(cfg, Some(model));
    let mut out = Vec::new();
    let mut t_us = 0;
    for r in &records {
        t_us = r.stamped.t_us;
        pipeline.on_frame(&r.stamped, &mut |foot, tc| out.push((foot, tc)));
        for (foot, tc) in out.drain(..) {
            print_class(t_us, foot, &tc, json, catalog);
        }
    }
    let c = pipeline.counters;
    let r = pipeline.reassembly_stats();
    eprintln!(
        "replayed {} frames ({:.1} s): {} steps, {} classified, {} without a sample; {} images, {} CRC failures, {} incomplete, {} undecodable frames",
        records.len(),
        records
            .first()
            .map_or(0.0, |f| t_us.saturating_sub(f.stamped.t_us) as f64 * 1e-6),
        c.steps,
        c.classified,
        c.no_sample,
        r.delivered,
        r.crc_failures,
        r.incomplete,
        c.decode_errors
    );
    Ok(ExitCode::SUCCESS)
}

fn print_class(
    t_us: u64,
    foot: u8,
    tc: &TerrainClass,
    json: bool,
    catalog: &protocol::TerrainCatalog,
) {
    let name = catalog.describe(tc.terrain);
    if json {
        println!(
            "{}",
            serde_json::json!({
                "t_us": t_us, "foot": foot, "step": tc.step, "terrain": name,
                "terrain_id": tc.terrain, "confidence_pct": tc.confidence_pct,
                "damage_pct": tc.damage_pct, "flags": tc.flags, "latency_us": tc.latency_us,
            })
        );
    } else {
        println!(
            "{:.6} foot {foot} step {:5} {:<13} {:5.1}%  damage {:4.1}%  flags 0x{:02X}",
            t_us as f64 * 1e-6,
            tc.step,
            name,
            tc.confidence_pct,
            tc.damage_pct,
            tc.flags
        );
    }
}

/// What the send thread reports in NodeStatus, written by the other threads.
#[derive(Default)]
pub struct Shared {
    state: AtomicU8,
    model_id: AtomicU64,
    damage_bits: AtomicU64,
    crc_failures: AtomicU64,
    incomplete: AtomicU64,
    pub bus_errors: AtomicU64,
    pub rx_frames: AtomicU64,
    pub rx_dropped: AtomicU64,
    pub tx_frames: AtomicU64,
    pub tx_dropped: AtomicU64,
}

fn state_from(v: u8) -> NodeState {
    match v {
        1 => NodeState::Running,
        2 => NodeState::Degraded,
        3 => NodeState::NoModel,
        4 => NodeState::Stopping,
        _ => NodeState::Starting,
    }
}

/// The live node on `source` until `signals` says stop; returns its counters.
pub fn live(
    cfg: NodeConfig,
    model: Model,
    model_path: &Path,
    source: BusSource,
    signals: Signals,
) -> Result<Arc<Shared>> {
    let catalog = cfg.catalog()?;
    model.check_catalog(&catalog)?;
    let shared = Arc::new(Shared::default());
    shared.model_id.store(model.id(), Ordering::Relaxed);
    // About 0.4 s of one foot's FD tactile stream: room for the pipeline to fall briefly behind.
    let (rx_tx, rx_rx) = bounded::<Stamped>(16_384);
    let (out_tx, out_rx) = bounded::<CanFrame>(256);
    let iface = source.label().to_string();
    tracing::info!(
        %iface,
        model = %model_path.display(),
        feet = cfg.feet,
        sample_ms = cfg.sample_ms,
        repair = ?cfg.repair,
        multi_frame = cfg.multi_frame,
        "presrs node starting"
    );
    let status_period = Duration::from_secs_f64(1.0 / cfg.status_hz.max(0.1));
    let ids = cfg.ids.clone();

    let receive = {
        let (src, sig, sh) = (source.clone(), signals.clone(), shared.clone());
        std::thread::Builder::new()
            .name("receive".into())
            .spawn(move || receive_loop(&src, &sig, &sh, rx_tx))?
    };
    let pipeline = {
        let (sig, sh, path) = (signals.clone(), shared.clone(), model_path.to_path_buf());
        std::thread::Builder::new()
            .name("pipeline".into())
            .spawn(move || pipeline_loop(cfg, (model, &catalog), &path, &sig, &sh, rx_rx, out_tx))?
    };
    let send = {
        let (src, sig, sh) = (source, signals.clone(), shared.clone());
        std::thread::Builder::new()
            .name("send".into())
            .spawn(move || send_loop(&src, &sig, &sh, out_rx, &ids, status_period))?
    };
    for (name, h) in [("receive", receive), ("pipeline", pipeline), ("send", send)] {
        if h.join().is_err() {
            tracing::error!("the {name} thread panicked");
        }
    }
    tracing::info!(
        rx_frames = shared.rx_frames.load(Ordering::Relaxed),
        rx_dropped = shared.rx_dropped.load(Ordering::Relaxed),
        tx_frames = shared.tx_frames.load(Ordering::Relaxed),
        tx_dropped = shared.tx_dropped.load(Ordering::Relaxed),
        bus_errors = shared.bus_errors.load(Ordering::Relaxed),
        "presrs node stopped"
    );
    Ok(shared)
}

fn receive_loop(source: &BusSource, sig: &Signals, sh: &Shared, to_pipeline: Sender<Stamped>) {
    let mut backoff = Backoff::default();
    let degrade = &mut || sh.state.store(NodeState::Degraded as u8, Ordering::Relaxed);
    while !sig.stopping() {
        let Some(mut bus) = open_source_with_retry(source, &sig.stop, "receive", degrade) else {
            break;
        };
        backoff.reset();
        sh.state.store(NodeState::Running as u8, Ordering::Relaxed);
        while !sig.stopping() {
            match bus.recv(Duration::from_millis(20)) {
                Ok(Some(st)) => {
                    sh.rx_frames.fetch_add(1, Ordering::Relaxed);
                    match to_pipeline.try_send(st) {
                        Ok(()) => {}
                        Err(TrySendError::Full(_)) => {
                            sh.rx_dropped.fetch_add(1, Ordering::Relaxed);
                        }
                        Err(TrySendError::Disconnected(_)) => return,
                    }
                }
                Ok(None) => {}
                Err(e) => {
                    sh.bus_errors.fetch_add(1, Ordering::Relaxed);
                    sh.state.store(NodeState::Degraded as u8, Ordering::Relaxed);
                    if !after_bus_error("receive", &e, &mut backoff, &sig.stop) {
                        return;
                    }
                    break;
                }
            }
        }
    }
}

fn pipeline_loop(
    cfg: NodeConfig,
    (model, catalog): (Model, &protocol::TerrainCatalog),
    model_path: &Path,
    sig: &Signals,
    sh: &Shared,
    from_receive: Receiver<Stamped>,
    to_send: Sender<CanFrame>,
) {
    let mut pipeline = StancePipeline::new(cfg, Some(model));
    let mut decided: Vec<(u8, TerrainClass)> = Vec::with_capacity(8);
    let mut last_log = Instant::now();
    let mut last_publish = Instant::now();
    let mut last_counters = pipeline.counters;
    loop {
        if sig.take_reload() {
            let loaded = Model::load(model_path)
                .map_err(anyhow::Error::from)
                .and_then(|m| {
                    m.check_catalog(catalog)?;
                    Ok(m)
                });
            match loaded {
                Ok(m) => {
                    let id = m.id();
                    pipeline.set_model(Some(m));
                    sh.model_id.store(id, Ordering::Relaxed);
                    tracing::info!(model = %model_path.display(), "SIGHUP: model reloaded");
                }
                Err(e) => tracing::error!("SIGHUP: {e}; keeping the model already loaded"),
            }
        }
        match from_receive.recv_timeout(Duration::from_millis(50)) {
            Ok(st) => {
                pipeline.on_frame(&st, &mut |foot, tc| decided.push((foot, tc)));
                for (foot, tc) in decided.drain(..) {
                    if let Some(f) = pipeline.to_frame(foot, &tc)
                        && to_send.try_send(f).is_err()
                    {
                        sh.tx_dropped.fetch_add(1, Ordering::Relaxed);
                    }
                }
            }
            Err(RecvTimeoutError::Timeout) => {
                if sig.stopping() {
                    break;
                }
            }
            Err(RecvTimeoutError::Disconnected) => break,
        }
        // Counters for NodeStatus every 50 ms (twice per status at 10 Hz), a log line every
        // 10 s: never per frame.
        if last_publish.elapsed() < Duration::from_millis(50) {
            continue;
        }
        last_publish = Instant::now();
        let r = pipeline.reassembly_stats();
        sh.crc_failures.store(r.crc_failures, Ordering::Relaxed);
        sh.incomplete.store(r.incomplete, Ordering::Relaxed);
        sh.damage_bits
            .store(pipeline.damage_pct().to_bits(), Ordering::Relaxed);
        if last_log.elapsed() >= Duration::from_secs(10) {
            let c = pipeline.counters;
            tracing::info!(
                frames = c.frames - last_counters.frames,
                steps = c.steps - last_counters.steps,
                classified = c.classified - last_counters.classified,
                no_sample = c.no_sample - last_counters.no_sample,
                decode_errors = c.decode_errors - last_counters.decode_errors,
                images = r.delivered,
                crc_failures = r.crc_failures,
                incomplete = r.incomplete,
                rx_dropped = sh.rx_dropped.load(Ordering::Relaxed),
                damage_pct = pipeline.damage_pct(),
                "last 10 s"
            );
            last_counters = c;
            last_log = Instant::now();
        }
    }
}

fn send_loop(
    source: &BusSource,
    sig: &Signals,
    sh: &Shared,
    from_pipeline: Receiver<CanFrame>,
    ids: &protocol::ids::IdConfig,
    status_period: Duration,
) {
    let mut heartbeat = 0u8;
    let mut backoff = Backoff::default();
    let degrade = &mut || sh.state.store(NodeState::Degraded as u8, Ordering::Relaxed);
    'open: while !sig.stopping() {
        let Some(mut bus) = open_source_with_retry(source, &sig.stop, "send", degrade) else {
            break;
        };
        backoff.reset();
        let mut next_status = Instant::now();
        loop {
            let stopping = sig.stopping();
            let wait = next_status.saturating_duration_since(Instant::now());
            // Nothing (timeout, or the pipeline has stopped) still sends the status when due.
            let mut to_send = [from_pipeline.recv_timeout(wait).ok(), None];
            if Instant::now() >= next_status || stopping {
                next_status += status_period;
                heartbeat = heartbeat.wrapping_add(1);
                let clamp = |v: u64| v.min(255) as u8;
                let st = NodeStatus {
                    heartbeat,
                    state: if stopping {
                        NodeState::Stopping
                    } else {
                        state_from(sh.state.load(Ordering::Relaxed))
                    },
                    model_id: sh.model_id.load(Ordering::Relaxed) as u16,
                    crc_failures: clamp(sh.crc_failures.load(Ordering::Relaxed)),
                    incomplete_frames: clamp(sh.incomplete.load(Ordering::Relaxed)),
                    bus_errors: clamp(sh.bus_errors.load(Ordering::Relaxed)),
                    damage_pct: f64::from_bits(sh.damage_bits.load(Ordering::Relaxed)),
                };
                to_send[1] = Message::NodeStatus(st).to_frame(ids, 0);
            }
            for f in to_send.iter().flatten() {
                match bus.send(f) {
                    Ok(()) => {
                        sh.tx_frames.fetch_add(1, Ordering::Relaxed);
                    }
                    Err(e) => {
                        sh.bus_errors.fetch_add(1, Ordering::Relaxed);
                        sh.tx_dropped.fetch_add(1, Ordering::Relaxed);
                        sh.state.store(NodeState::Degraded as u8, Ordering::Relaxed);
                        if !after_bus_error("send", &e, &mut backoff, &sig.stop) {
                            break 'open;
                        }
                        continue 'open;
                    }
                }
            }
            if stopping {
                break 'open;
            }
        }
    }
}
