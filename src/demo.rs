//! `presrs demo`: the simulator, the node and the controller in one process on the in-process
//! bus, in simulated time (as fast as the machine runs).

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Duration;

use anyhow::{Context, Result};
use controller::{Controller, ControllerConfig};
use node::classifier::train::{TrainOptions, train};
use node::classifier::{Crop, Model};
use node::{NodeConfig, NodeService, Output};
use presrs::simdata::TrainingSet;
use protocol::bus::{CanBus, InProcBus};
use protocol::clock::ManualClock;
use protocol::messages;
use sim::runner::{SimConfig, SimRobot, Track};

/// Where the demo keeps the model it trains on first run.
fn cache_path() -> PathBuf {
    let base = std::env::var_os("XDG_CACHE_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache")))
        .unwrap_or_else(std::env::temp_dir);
    base.join("presrs").join(format!(
        "demo-model-v{}-sim{}.json",
        node::classifier::model::MODEL_VERSION,
        sim::SIM_VERSION
    ))
}

/// A model for the dynamic terrains from simulator data of all three gaits.
pub fn sim_model(seed: u64) -> Result<Model> {
    let mut samples = Vec::new();
    for (i, g) in controller::Gait::paper_gaits().into_iter().enumerate() {
        let opts = sim::dataset::Options {
            kind: sim::dataset::Kind::Dynamic,
            n: Some(30),
            gait: g,
            damage_pct: 0.0,
            // The sensor the demo's foot wears (SimConfig's default).
            sensor: sim::DEFAULT_SENSOR,
            seed: seed + i as u64,
        };
        samples.extend(sim::dataset::generate(&opts));
    }
    let set = TrainingSet::from_samples(samples, &sim::dataset::Kind::Dynamic.terrains());
    // Load-normalised (the paper's intensity scaling): a gait switch or a terrain change
    // changes the load at 70 ms for a few steps, and the texture should decide, not the load.
    let opts = TrainOptions {
        per_class: 45,
        train: 30,
        normalize_load: true,
        crop: Crop {
            top: 0,
            bottom: 3,
            left: 6,
            right: 0,
        },
        seed,
        ..Default::default()
    };
    let (model, _) =
        train(&set.labelled(), &set.classes, &opts).context("training the demo model")?;
    Ok(model)
}

pub(crate) fn load_or_train(model: Option<&Path>) -> Result<Model> {
    if let Some(p) = model {
        return Model::load(p).with_context(|| format!("loading --model {}", p.display()));
    }
    let cache = cache_path();
    if let Ok(m) = Model::load(&cache) {
        eprintln!("using the cached demo model {}", cache.display());
        return Ok(m);
    }
    eprintln!("no model given: training one on simulated G1-G3 stances (first run only)...");
    let m = sim_model(11)?;
    if let Some(dir) = cache.parent() {
        let _ = std::fs::create_dir_all(dir);
    }
    match m.save(&cache) {
        Ok(()) => eprintln!("cached the model at {}", cache.display()),
        Err(e) => eprintln!("could not cache the model ({e}); it will be trained again next time"),
    }
    Ok(m)
}

#[derive(Clone, Debug, serde::Serialize)]
pub(crate) struct StepRow {
    pub t_s: f64,
    pub step: u16,
    pub truth: String,
    pub classified: String,
    pub confidence_pct: f64,
    pub gait: u8,
    pub speed_m_s: f64,
}

#[derive(clap::Args)]
pub struct DemoArgs {
    /// Steps to run.
    #[arg(long, default_value_t = 120)]
    pub steps: usize,
    /// Track file (TOML: diameter_m, [[segments]] terrain, length_m); default: wood, grass,
    /// clay, carpet.
    #[arg(long)]
    pub track: Option<PathBuf>,
    /// Model file; default: one trained on simulated data on first run, then cached.
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Print the summary as one JSON object.
    #[arg(long)]
    pub json: bool,
    /// Step log (CSV).
    #[arg(long, default_value = "demo-steps.csv")]
    pub csv: PathBuf,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Run the simulator, the node and the controller as three concurrent tasks on the wall
    /// clock (the node with its own receive/pipeline/send threads), as they run as processes
    /// on CAN, instead of in lock-step simulated time.
    #[arg(long)]
    pub realtime: bool,
    /// No controller: the hopper holds this gait (G1, G2 or G3) on every terrain, as in the
    /// paper's data collection; the node still classifies every step.
    #[arg(long, value_name = "GAIT", conflicts_with = "realtime")]
    pub fixed_gait: Option<String>,
    /// The node's configuration (as `presrs node --config`); default: the node's defaults.
    #[arg(long, value_name = "FILE")]
    pub node_config: Option<PathBuf>,
    /// Sensor damage from the start, percent of sensels on dead rows and columns (eq. 6).
    #[arg(long, default_value_t = 0.0, value_name = "PCT")]
    pub damage: f64,
    /// For the track's terrain names and the node's and controller's catalogs.
    #[command(flatten)]
    pub terrains: crate::cli::TerrainsArg,
}

pub fn run(a: DemoArgs) -> Result<ExitCode> {
    anyhow::ensure!(
        (0.0..=100.0).contains(&a.damage),
        "--damage {}: expected a percentage in 0..=100",
        a.damage
    );
    let catalog = a.terrains.catalog()?;
    let track = crate::sim_cmd::load_track(a.track.as_deref(), &catalog)?;
    let model = load_or_train(a.model.as_deref())?;
    let mut ctrl_cfg = ControllerConfig::default();
    let mut node_cfg = crate::node_cmd::load_config(a.node_config.as_deref())?;
    if a.terrains.terrains.is_some() {
        ctrl_cfg.terrains = a.terrains.terrains.clone();
        node_cfg.terrains = a.terrains.terrains.clone();
    }
    model.check_catalog(&node_cfg.catalog()?)?;
    let fixed = match &a.fixed_gait {
        Some(g) => Some(
            controller::Gait::by_name(g)
                .with_context(|| format!("--fixed-gait {g}: expected G1, G2 or G3"))?
                .id,
        ),
        None => None,
    };
    let (rows, falls) = if a.realtime {
        closed_loop_realtime(&track, model, node_cfg, &ctrl_cfg, &a)?
    } else {
        let ctrl = if fixed.is_some() {
            None
        } else {
            Some(&ctrl_cfg)
        };
        let lp = LoopParams {
            node: node_cfg,
            controller: ctrl,
            fixed_gait: fixed,
            damage_pct: a.damage,
            steps: a.steps,
            seed: a.seed,
            show: !a.json,
        };
        closed_loop_with_falls(&track, model, &lp)?
    };
    summarize(&rows, falls, &track, &ctrl_cfg, &a)
}

/// The closed loop on the wall clock: `presrs sim`, `presrs node` and `presrs controller`'s own
/// loops on one in-process bus, each on its own thread. Returns the step rows and the falls.
fn closed_loop_realtime(
    track: &Track,
    model: Model,
    node_cfg: NodeConfig,
    ctrl_cfg: &ControllerConfig,
    a: &DemoArgs,
) -> Result<(Vec<StepRow>, u64)> {
    use crate::runtime::Signals;
    use protocol::bus::BusSource;
    let (steps, seed, show) = (a.steps, a.seed, !a.json);
    let bus = protocol::bus::InProcBus::new();
    let signals = Signals::manual();
    let node = node::NodeService::new(node_cfg, model)?.start(BusSource::InProc(bus.clone()))?;
    let controller = {
        let (cfg, src, sig) = (
            ctrl_cfg.clone(),
            BusSource::InProc(bus.clone()),
            signals.clone(),
        );
        std::thread::Builder::new()
            .name("controller".into())
            .spawn(move || crate::controller_cmd::run_on(cfg, src, 1.0, &sig))?
    };
    // About 0.35 s per step: run long enough for `steps` TerrainClass.
    let sim_args = crate::sim_cmd::SimArgs {
        iface: String::new(),
        track: None,
        feet: 1,
        speed: 1.0,
        gait: "G2".into(),
        damage: a.damage,
        sensor: sim::DEFAULT_SENSOR,
        duration: Some(steps as f64 * 0.4 + 1.0),
        report: None,
        seed,
        terrains: a.terrains.clone(),
    };
    if show {
        eprintln!(
            "running simulator, node and controller in real time for {:.0} s...",
            sim_args.duration.unwrap_or(0.0)
        );
    }
    let report = crate::sim_cmd::run_on(&sim_args, track.clone(), BusSource::InProc(bus), &signals);
    signals
        .stop
        .store(true, std::sync::atomic::Ordering::Relaxed);
    let switches = controller
        .join()
        .map_err(|_| anyhow::anyhow!("the controller thread panicked"))??;
    node.stop();
    let report = report?;
    let rows: Vec<StepRow> = report
        .steps
        .into_iter()
        .take(steps)
        .map(|r| StepRow {
            t_s: r.t_s,
            step: r.step,
            truth: r.truth,
            classified: r.classified,
            confidence_pct: r.confidence_pct,
            gait: r.gait,
            speed_m_s: r.speed_m_s,
        })
        .collect();
    if show {
        for row in &rows {
            print_row(row);
        }
        println!(
            "(controller: {switches} gait switches; {} falls)",
            report.falls
        );
    }
    Ok((rows, report.falls))
}

fn print_row(row: &StepRow) {
    println!(
        "t {:7.2} s  step {:4}  true {:<8} classified {:<8} {:5.1}%  gait G{}  {:.2} m/s",
        row.t_s, row.step, row.truth, row.classified, row.confidence_pct, row.gait, row.speed_m_s
    );
}

/// Simulator, node and controller on one in-process bus, 1 ms at a time, for `steps` steps:
/// one row per TerrainClass (printed as it comes when `show`).
pub(crate) fn closed_loop(
    track: &Track,
    model: Model,
    ctrl_cfg: &ControllerConfig,
    steps: usize,
    seed: u64,
    show: bool,
) -> Result<Vec<StepRow>> {
    let lp = LoopParams {
        node: NodeConfig::default(),
        controller: Some(ctrl_cfg),
        fixed_gait: None,
        damage_pct: 0.0,
        steps,
        seed,
        show,
    };
    Ok(closed_loop_with_falls(track, model, &lp)?.0)
}

/// What runs in the lock-step loop besides the simulator.
struct LoopParams<'a> {
    node: NodeConfig,
    /// `None`: no controller, the hopper holds `fixed_gait` (default G2).
    controller: Option<&'a ControllerConfig>,
    fixed_gait: Option<u8>,
    damage_pct: f64,
    steps: usize,
    seed: u64,
    show: bool,
}

/// [`closed_loop`] with any node config and optionally no controller; also returns how often
/// the hopper fell.
fn closed_loop_with_falls(
    track: &Track,
    model: Model,
    p: &LoopParams,
) -> Result<(Vec<StepRow>, u64)> {
    let (steps, seed, show) = (p.steps, p.seed, p.show);
    let clock = ManualClock::new(0);
    let bus = InProcBus::with_clock(Arc::new(clock.clone()), 1 << 16);
    let (mut sim_ep, mut node_ep, mut ctrl_ep) = (bus.endpoint(), bus.endpoint(), bus.endpoint());
    let mut sim_cfg = SimConfig {
        track: track.clone(),
        ..Default::default()
    };
    if let Some(g) = p.fixed_gait {
        sim_cfg.gait = g;
    }
    sim_cfg.faults.initial_damage_pct = p.damage_pct;
    let ids = sim_cfg.ids.clone();
    let mut robot = SimRobot::new(sim_cfg, seed);
    let mut node_cfg = p.node.clone();
    // Lock-step simulated time: a refit lands at the step that asked for it, as in a replay.
    node_cfg.refit = node_cfg.refit.reproducible();
    let catalog = node_cfg.catalog()?;
    let mut node = NodeService::new(node_cfg, model)?;
    let mut ctrl = match p.controller {
        Some(c) => Some(Controller::new(c.clone(), &c.catalog()?)),
        None => None,
    };
    let mut rows: Vec<StepRow> = Vec::new();
    let mut t_us = 0u64;
    let zero = Duration::ZERO;
    let limit_us = (steps as u64 + 20) * 1_000_000;
    // Reused every millisecond: the loop allocates only when a step is logged.
    let mut sent = Vec::new();
    let mut said = Vec::new();
    let mut out = Vec::new();
    while rows.len() < steps && t_us < limit_us {
        t_us += 1000;
        clock.set_us(t_us);
        robot.advance_to(t_us, &mut |f| sent.push(f));
        for f in sent.drain(..) {
            sim_ep.send(&f).context("simulator send")?;
        }
        // The node: frames, then what is due by now (deadlines, the heartbeat).
        while let Some(st) = node_ep.recv(zero).context("node receive")? {
            node.process(&st, &mut |o| said.push(o));
        }
        node.tick(t_us, &mut |o| said.push(o));
        for o in said.drain(..) {
            if let Some(f) = node.frame(&o) {
                node_ep.send(&f).context("node send")?;
            }
            let Output::Class { foot, class: tc } = o else {
                continue;
            };
            let truth = robot
                .step_at(foot, t_us)
                .map(|s| s.terrain.name())
                .unwrap_or("?");
            let (speed, _) = robot.speed_and_position(foot).unwrap_or((0.0, 0.0));
            let row = StepRow {
                t_s: t_us as f64 * 1e-6,
                step: tc.step,
                truth: truth.to_string(),
                classified: catalog.describe(tc.terrain),
                confidence_pct: tc.confidence_pct,
                gait: robot.gait_in_effect(foot).unwrap_or(0),
                speed_m_s: speed,
            };
            if show {
                print_row(&row);
            }
            rows.push(row);
        }
        // The controller.
        while let Some(st) = ctrl_ep.recv(zero).context("controller receive")? {
            if let (Some(ctrl), Ok(Some((foot, m)))) =
                (ctrl.as_mut(), messages::decode(&st.frame, &ids))
            {
                ctrl.on_message(foot, &m, t_us, &mut |o| out.push(o));
            }
        }
        if let Some(ctrl) = ctrl.as_mut() {
            ctrl.tick(t_us, &mut |o| out.push(o));
        }
        for m in out.drain(..) {
            if let Some(f) = m.to_frame(&ids, 0) {
                ctrl_ep.send(&f).context("controller send")?;
            }
        }
        // The robot hears the controller.
        while let Some(st) = sim_ep.recv(zero).context("simulator receive")? {
            robot.on_frame(&st.frame);
        }
    }
    Ok((rows, robot.falls.len() as u64))
}

fn summarize(
    rows: &[StepRow],
    falls: u64,
    track: &Track,
    cfg: &ControllerConfig,
    a: &DemoArgs,
) -> Result<ExitCode> {
    let n = rows.len();
    let correct = rows.iter().filter(|r| r.truth == r.classified).count();
    let accuracy = if n > 0 {
        correct as f64 / n as f64
    } else {
        0.0
    };
    let mut switches = 0;
    for w in rows.windows(2) {
        switches += (w[0].gait != w[1].gait) as usize;
    }
    // Steps from each terrain change to the terrain's gait.
    let mut delays = Vec::new();
    let mut i = 1;
    while i < n {
        if rows[i].truth != rows[i - 1].truth {
            let want = cfg.terrain_gaits.get(&rows[i].truth).copied();
            let mut j = i;
            while j < n && rows[j].truth == rows[i].truth && Some(rows[j].gait) != want {
                j += 1;
            }
            if j < n && rows[j].truth == rows[i].truth && want.is_some() {
                delays.push(j - i);
            }
        }
        i += 1;
    }
    let mut speeds: std::collections::BTreeMap<(String, u8), (f64, usize)> = Default::default();
    for r in rows {
        let e = speeds.entry((r.truth.clone(), r.gait)).or_insert((0.0, 0));
        e.0 += r.speed_m_s;
        e.1 += 1;
    }
    let mut csv =
        std::fs::File::create(&a.csv).with_context(|| format!("creating {}", a.csv.display()))?;
    writeln!(
        csv,
        "t_s,step,true_terrain,classified,confidence_pct,gait,speed_m_s"
    )?;
    for r in rows {
        writeln!(
            csv,
            "{:.3},{},{},{},{:.1},{},{:.3}",
            r.t_s, r.step, r.truth, r.classified, r.confidence_pct, r.gait, r.speed_m_s
        )?;
    }
    let max_delay = delays.iter().copied().max().unwrap_or(0);
    if a.json {
        let table: Vec<serde_json::Value> = speeds
            .iter()
            .map(|((t, g), (s, k))| serde_json::json!({"terrain": t, "gait": g, "mean_speed_m_s": s / *k as f64, "steps": k}))
            .collect();
        let j = serde_json::json!({
            "steps": n,
            "accuracy": accuracy,
            "switches": switches,
            "steps_to_switch": delays,
            "steps_to_switch_max": max_delay,
            "falls": falls,
            "realtime": a.realtime,
            "speed_per_terrain_and_gait": table,
            "track_m": track.length(),
            "csv": a.csv.display().to_string(),
        });
        println!("{j}");
    } else {
        println!(
            "\nsummary: {n} steps, per-step accuracy {:.1}% ({correct}/{n}), {switches} gait switches",
            accuracy * 100.0
        );
        println!("steps from a terrain change to its gait: {delays:?} (max {max_delay})");
        println!("falls: {falls}");
        println!("mean speed (m/s) per terrain and gait:");
        for ((t, g), (s, k)) in &speeds {
            println!("  {t:<8} G{g}: {:.2} ({k} steps)", s / *k as f64);
        }
        println!("step log: {}", a.csv.display());
    }
    Ok(ExitCode::SUCCESS)
}
