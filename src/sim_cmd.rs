//! `presrs lab sim`: the simulated hopper and foot on a CAN interface, in real time (or `--speed`
//! times faster), as a separate process: it publishes FootContact, LegState and the tactile
//! frames, obeys LegCommand, and holds its configured gait when no controller is on the bus.
//!
//! Because the simulator knows the truth, it also scores what others put on the bus: every
//! TerrainClass it hears is matched to the stance in progress on that foot, and the gait the
//! leg runs is recorded per step. `--report FILE.json` writes that record at exit; the system
//! tests read it.

use std::process::ExitCode;

use anyhow::{Context, Result};
use presrs_cli::sim::SimArgs;
use sim::faults::FaultParams;
use sim::runner::SimConfig;
use sim::service::RunOptions;

use std::sync::atomic::Ordering;

use protocol::bus::{BusSource, Tap};
use protocol::component::Signals;
use sim::runner::SimRobot;

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
