//! `presrs lab sim`: the simulated hopper and foot on a CAN interface, in real time (or `--speed`
//! times faster), as a separate process: it publishes FootContact, LegState and the tactile
//! frames, obeys LegCommand, and holds its configured gait when no controller is on the bus.
//!
//! Because the simulator knows the truth, it also scores what others put on the bus: every
//! TerrainClass it hears is matched to the stance in progress on that foot, and the gait the
//! leg runs is recorded per step. `--report FILE.json` writes that record at exit; the system
//! tests read it.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result};
use sim::faults::FaultParams;
use sim::runner::SimConfig;
use sim::service::RunOptions;

use std::sync::atomic::Ordering;

use protocol::bus::{BusSource, Tap};
use protocol::component::Signals;
use sim::runner::SimRobot;

#[derive(clap::Args)]
pub struct SimArgs {
    /// CAN interface (vcan0, can0). Must carry CAN FD (MTU 72): the tactile frames are FD.
    #[arg(long, required_unless_present = "log", conflicts_with = "log")]
    pub iface: Option<String>,
    /// No bus: write what the robot sends to this candump log (`candump -L` format), in
    /// simulated time, as fast as it computes; needs --duration. The robot holds its gait.
    #[arg(long, requires = "duration")]
    pub log: Option<PathBuf>,
    /// With --log: write the true terrain of every step as a labels CSV for `presrs capture
    /// --labels` (start_s,end_s,terrain,foot in the log's timestamps).
    #[arg(long, requires = "log")]
    pub truth: Option<PathBuf>,
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
    #[command(flatten)]
    pub foot: sim::FootOptions,
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
    pub terrains: protocol::TerrainsArg,
    /// The leg as two motors of this protocol (moteus, odrive, mit): the simulator takes their
    /// commands from a leg bridge (`presrs leg`) instead of LegCommand and answers as the
    /// drivers do; LegState is then the bridge's.
    #[arg(long, value_name = "PROTOCOL", conflicts_with = "log")]
    pub leg: Option<leg::DriverKind>,
    /// The leg's config for `--leg` (the same file `presrs leg` runs with); default: the
    /// built-in prismatic leg on that protocol's motors.
    #[arg(long, value_name = "FILE", requires = "leg")]
    pub leg_config: Option<PathBuf>,
    /// Mass the hopper carries, kg (0 to 2; its body is 2 kg): the robot's run with a load its
    /// model and energy maps were not made with.
    #[arg(long, value_name = "KG", default_value_t = 0.0)]
    pub payload: f64,
    /// Fault drill for `--leg`: the length joint's driver goes silent at this robot time (s).
    #[arg(long, value_name = "SECONDS", requires = "leg")]
    pub leg_silent_at: Option<f64>,
    /// `--mcap FILE`: every frame on the bus (or, with --log, every frame the robot sends) and
    /// the simulator's truth per leg (`/sim/legN`: speed, position, true terrain) as MCAP;
    /// `--foxglove`: the same live.
    #[command(flatten)]
    pub live: record::LiveOptions,
    /// `--ros2`: the bus as ROS 2 topics on Zenoh; `--ros2-bag DIR`: as a rosbag2.
    #[command(flatten)]
    pub ros2: ros2::Ros2Options,
}

pub fn run(a: SimArgs) -> Result<ExitCode> {
    let signals = Signals::install()?;
    let catalog = a.terrains.catalog()?;
    let track =
        sim::runner::Track::load_or_default(a.track.as_deref(), &catalog).context("--track")?;
    anyhow::ensure!(
        a.speed > 0.0 && a.speed.is_finite(),
        "--speed {}: expected a positive factor (1 = real time)",
        a.speed
    );
    let (gait, damage) = a.foot.checked()?;
    let feet = a.feet.max(1);
    let cfg = SimConfig {
        track,
        gait: gait.id,
        feet,
        faults: FaultParams {
            initial_damage_pct: damage,
            ..Default::default()
        },
        sensor: a.foot.sensor,
        leg: a
            .leg
            .map(|k| leg::LegConfig::for_driver(k, a.leg_config.as_deref()))
            .transpose()
            .context("--leg-config")?,
        leg_silent_at_s: a.leg_silent_at,
        payload_kg: sim::check_payload(a.payload)?,
        ..Default::default()
    };
    let ids = cfg.ids.clone();
    let outputs = crate::ros2_cmd::LiveOutputs::start(&a.live, &a.ros2, &ids, &catalog, false)?;
    let tap = outputs.recorder.as_ref().map(|r| r.tap());
    let track = cfg.track.clone();
    let mut observe = |t_us: u64, robot: &SimRobot| {
        if let Some(tap) = &tap {
            for f in 0..feet {
                if let Some(t) = lab::closed_loop::sim_truth(robot, &track, f) {
                    tap.offer_truth(t_us, f, t);
                }
            }
        }
    };
    if let Some(log) = &a.log {
        let r = write_log(cfg, &a, log, tap.as_deref(), &mut observe);
        outputs.finish();
        return r;
    }
    let opts = RunOptions {
        speed: a.speed,
        duration_s: a.duration,
        seed: a.seed,
    };
    let source = BusSource::Iface(
        a.iface
            .clone()
            .context("give --iface IFACE or --log FILE")?,
    );
    let listener = match &tap {
        Some(tap) => Some(record::listen(
            source.clone(),
            tap.clone(),
            signals.stop.clone(),
        )?),
        None => None,
    };
    // Robot time is the simulator's own; the recording's clock is the bus's (the wall clock).
    let r = sim::service::run(
        cfg,
        &opts,
        source,
        &catalog,
        &signals.stop,
        &mut |_, robot| observe(protocol::clock::epoch_us(), robot),
    );
    if let Some(l) = listener {
        signals.stop.store(true, Ordering::Relaxed);
        let _ = l.join();
    }
    outputs.finish();
    eprintln!("presrs lab sim: {r}");
    if let Some(p) = &a.report {
        std::fs::write(p, serde_json::to_string_pretty(&r)?)
            .with_context(|| format!("writing --report {}", p.display()))?;
    }
    Ok(ExitCode::SUCCESS)
}

/// `presrs lab sim --log`: the robot's frames to a candump log, and its truth to a labels CSV.
fn write_log(
    cfg: SimConfig,
    a: &SimArgs,
    log: &std::path::Path,
    tap: Option<&record::LiveTap>,
    observe: &mut dyn FnMut(u64, &SimRobot),
) -> Result<ExitCode> {
    let duration_us = (a.duration.unwrap_or(0.0).max(0.0) * 1e6) as u64;
    let file = std::fs::File::create(log).with_context(|| format!("--log {}", log.display()))?;
    let mut tap = |st: &protocol::Stamped| {
        if let Some(tap) = tap {
            tap.offer(st);
        }
    };
    let (frames, steps) = sim::runner::record_candump(
        cfg,
        a.seed,
        duration_us,
        observe,
        &mut tap,
        &mut std::io::BufWriter::new(file),
    )
    .with_context(|| format!("writing --log {}", log.display()))?;
    if let Some(p) = &a.truth {
        let end = sim::runner::LOG_EPOCH_US + duration_us;
        std::fs::write(p, sim::runner::truth_labels(&steps, end))
            .with_context(|| format!("writing --truth {}", p.display()))?;
    }
    eprintln!(
        "presrs lab sim: {:.1} s simulated, {} steps, {frames} frames written to {}",
        duration_us as f64 * 1e-6,
        steps.len(),
        log.display()
    );
    Ok(ExitCode::SUCCESS)
}
