//! `presrs sim`: the simulated hopper and foot on a CAN interface, in real time (or `--speed`
//! times faster), as a separate process: it publishes FootContact, LegState and the tactile
//! frames, obeys LegCommand, and holds its configured gait when no controller is on the bus.
//!
//! Because the simulator knows the truth, it also scores what others put on the bus: every
//! TerrainClass it hears is matched to the stance in progress on that foot, and the gait the
//! leg runs is recorded per step. `--report FILE.json` writes that record at exit; the system
//! tests read it.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use protocol::bus::CanBus;
use protocol::ids::MessageKind;
use protocol::messages::{self, Message};
use sim::faults::FaultParams;
use sim::runner::{SimConfig, SimRobot, Track};

use crate::runtime::Signals;
use protocol::bus::{Backoff, BusSource, after_bus_error, open_with_retry};

#[derive(clap::Args)]
pub struct SimArgs {
    /// CAN interface (vcan0, can0). Must carry CAN FD (MTU 72): the tactile frames are FD.
    #[arg(long)]
    pub iface: String,
    /// Track file (TOML: diameter_m, [[segments]] terrain, length_m); default: a quarter each of
    /// wood, grass, clay and carpet on the paper's 2.8 m circle.
    #[arg(long)]
    pub track: Option<PathBuf>,
    /// Legs, each with its foot sensor (foot ids 0..N).
    #[arg(long, default_value_t = 1)]
    pub feet: u8,
    /// Simulated time per wall-clock time: 1 is real time, 2 twice as fast.
    #[arg(long, default_value_t = 1.0)]
    pub speed: f64,
    /// Gait held without a controller: G1, G2 or G3.
    #[arg(long, default_value = "G2")]
    pub gait: String,
    /// Sensor damage from the start, percent of sensels on dead lines (eq. 6).
    #[arg(long, default_value_t = 0.0)]
    pub damage: f64,
    /// Serial number of foot 0's sensor (foot i wears serial + i): the same default as
    /// `presrs dataset --sensor`, so a model trained on that data fits this foot.
    #[arg(long, default_value_t = sim::DEFAULT_SENSOR)]
    pub sensor: u64,
    /// Stop after this much simulated time, s (default: run until SIGINT/SIGTERM).
    #[arg(long)]
    pub duration: Option<f64>,
    /// Write the per-step record (truth, what the node said, the gait run) as JSON at exit.
    #[arg(long)]
    pub report: Option<PathBuf>,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Track terrains and reported names come from this catalog.
    #[command(flatten)]
    pub terrains: crate::cli::TerrainsArg,
}

#[derive(Clone, Debug, serde::Serialize)]
pub struct StepRecord {
    pub t_s: f64,
    pub foot: u8,
    /// The node's step counter from its TerrainClass.
    pub step: u16,
    pub truth: String,
    pub classified: String,
    pub confidence_pct: f64,
    pub damage_pct: f64,
    /// The gait the leg ran when the TerrainClass arrived.
    pub gait: u8,
    pub speed_m_s: f64,
}

/// The `--track` file (its terrains named in `catalog`), or the default track (wood, grass,
/// clay, carpet quarters).
pub fn load_track(
    path: Option<&std::path::Path>,
    catalog: &protocol::TerrainCatalog,
) -> Result<Track> {
    match path {
        Some(p) => {
            let text = std::fs::read_to_string(p)
                .with_context(|| format!("reading --track {}", p.display()))?;
            Ok(Track::from_toml(&text, &p.display().to_string(), catalog)?)
        }
        None => Ok(Track::default()),
    }
}

/// The most robot time one pass of the simulator covers, µs: commands are read between passes.
const MAX_LAG_US: u64 = 2_000;

/// What one run of the simulator saw: the `--report` file's content.
#[derive(Debug, serde::Serialize)]
pub struct SimReport {
    pub simulated_s: f64,
    pub wall_s: f64,
    pub touchdowns: usize,
    /// Times a simulated hopper fell (and was set back on its feet).
    pub falls: u64,
    /// When, robot time (s).
    pub fall_times_s: Vec<f64>,
    pub send_errors: u64,
    pub steps: Vec<StepRecord>,
}

pub fn run(a: SimArgs) -> Result<ExitCode> {
    let signals = Signals::install()?;
    let track = load_track(a.track.as_deref(), &a.terrains.catalog()?)?;
    let r = run_on(&a, track, BusSource::Iface(a.iface.clone()), &signals)?;
    let n = r.steps.len();
    let correct = r.steps.iter().filter(|s| s.truth == s.classified).count();
    eprintln!(
        "presrs sim: {:.1} s simulated in {:.1} s wall; {} touchdowns, {} falls; {n} TerrainClass heard, {correct} correct{}; {} send errors",
        r.simulated_s,
        r.wall_s,
        r.touchdowns,
        r.falls,
        if n > 0 {
            format!(" ({:.1}%)", 100.0 * correct as f64 / n as f64)
        } else {
            String::new()
        },
        r.send_errors
    );
    if let Some(p) = &a.report {
        std::fs::write(p, serde_json::to_string_pretty(&r)?)
            .with_context(|| format!("writing --report {}", p.display()))?;
    }
    Ok(ExitCode::SUCCESS)
}

/// The simulator on any bus until `--duration` or `signals` stop it.
pub fn run_on(
    a: &SimArgs,
    track: Track,
    source: BusSource,
    signals: &Signals,
) -> Result<SimReport> {
    anyhow::ensure!(
        a.speed > 0.0 && a.speed.is_finite(),
        "--speed {}: expected a positive factor (1 = real time)",
        a.speed
    );
    anyhow::ensure!(
        (0.0..=100.0).contains(&a.damage),
        "--damage {}: expected a percentage in 0..=100",
        a.damage
    );
    let gait = controller::Gait::by_name(&a.gait)
        .with_context(|| format!("--gait {}: expected G1, G2 or G3", a.gait))?;
    let cfg = SimConfig {
        track,
        gait: gait.id,
        feet: a.feet.max(1),
        faults: FaultParams {
            initial_damage_pct: a.damage,
            ..Default::default()
        },
        sensor: a.sensor,
        ..Default::default()
    };
    let ids = cfg.ids.clone();
    let catalog = a.terrains.catalog()?;
    let mut robot = SimRobot::new(cfg, a.seed);
    let start = Instant::now();
    let mut records: Vec<StepRecord> = Vec::new();
    let report =
        |robot: &SimRobot, records: Vec<StepRecord>, t_us: u64, send_errors: u64| SimReport {
            simulated_s: t_us as f64 * 1e-6,
            wall_s: start.elapsed().as_secs_f64(),
            touchdowns: robot.steps.len(),
            falls: robot.falls.len() as u64,
            fall_times_s: robot.falls.iter().map(|&t| t as f64 * 1e-6).collect(),
            send_errors,
            steps: records,
        };
    let Some(mut bus) = open_sim_bus(&source, signals, &ids) else {
        return Ok(report(&robot, records, 0, 0));
    };
    tracing::info!(iface = %source.label(), feet = a.feet, speed = a.speed, gait = %a.gait, "presrs sim running");
    let end_us = a.duration.map(|d| (d * 1e6) as u64);
    // Robot time given up because the machine could not keep up (see below).
    let mut stretched_us = 0u64;
    let mut out = Vec::with_capacity(128);
    let mut backoff = Backoff::default();
    let mut send_errors = 0u64;
    let mut t_us = 0u64;
    loop {
        if signals.stopping() || end_us.is_some_and(|e| t_us >= e) {
            break;
        }
        // Simulated time follows the wall clock; 1 ms steps, sleeping when ahead.
        let target =
            ((start.elapsed().as_secs_f64() * a.speed * 1e6) as u64).saturating_sub(stretched_us);
        if target < t_us + 1000 {
            std::thread::sleep(Duration::from_micros(300));
            continue;
        }
        // A machine too slow for `--speed` (a debug build, emulation, a loaded CI runner):
        // robot time slows down rather than jumping ahead to catch up. A jump would run the
        // leg for tens of ms on one stale command and deliver the foot's frames in bursts; a
        // real leg never pauses, and neither does its controller's view of it.
        if target > t_us + MAX_LAG_US {
            stretched_us += target - (t_us + MAX_LAG_US);
        }
        t_us = target.min(t_us + MAX_LAG_US);
        robot.advance_to(t_us, &mut |f| out.push(f));
        for f in out.drain(..) {
            if let Err(e) = bus.send(&f) {
                send_errors += 1;
                // A lost frame is what a real foot would cause too; a dead bus is reopened.
                if send_errors.is_power_of_two() {
                    tracing::warn!("sim send: {e} ({send_errors} send errors so far)");
                }
                if matches!(e, protocol::BusError::Down { .. }) {
                    after_bus_error("sim", &e, &mut backoff, &signals.stop);
                    if let Some(b) = open_sim_bus(&source, signals, &ids) {
                        bus = b;
                    }
                    break;
                }
            }
        }
        while let Ok(Some(st)) = bus.recv(Duration::ZERO) {
            robot.on_frame(&st.frame);
            if let Ok(Some((foot, Message::TerrainClass(tc)))) = messages::decode(&st.frame, &ids) {
                let truth = robot.step_at(foot, t_us).map_or("?", |s| s.terrain.name());
                let (speed, _) = robot.speed_and_position(foot).unwrap_or((0.0, 0.0));
                records.push(StepRecord {
                    t_s: t_us as f64 * 1e-6,
                    foot,
                    step: tc.step,
                    truth: truth.to_string(),
                    classified: catalog.describe(tc.terrain),
                    confidence_pct: tc.confidence_pct,
                    damage_pct: tc.damage_pct,
                    gait: robot.gait_in_effect(foot).unwrap_or(0),
                    speed_m_s: speed,
                });
            }
        }
    }
    Ok(report(&robot, records, t_us, send_errors))
}

/// Opens the simulator's bus, passing it only what the simulator reads: the controller's
/// LegCommand and the node's TerrainClass (to score it).
fn open_sim_bus(
    source: &BusSource,
    signals: &Signals,
    ids: &protocol::IdConfig,
) -> Option<Box<dyn CanBus>> {
    let mut bus = open_with_retry(source, &signals.stop, "sim", &mut || {})?;
    let kinds = [MessageKind::LegCommand, MessageKind::TerrainClass];
    if let Err(e) = bus.set_filters(&ids.filters(&kinds)) {
        // Unfiltered still works; it only costs the simulator time.
        tracing::warn!("sim: receive filters not set ({e}); reading every frame");
    }
    Some(bus)
}
