//! `presrs demo`: the simulator, the node and the controller in one process on the in-process
//! bus, in simulated time (as fast as the machine runs).

use std::process::ExitCode;

use anyhow::{Context, Result};
use controller::ControllerConfig;
use lab::{LoopParams, StepRecord, Summary};
use presrs_cli::demo::DemoArgs;
use sim::runner::Track;

pub fn run(a: DemoArgs) -> Result<ExitCode> {
    sim::check_damage(a.damage)?;
    let payload_kg = sim::check_payload(a.payload)?;
    let catalog = a.terrains.catalog()?;
    let track =
        sim::runner::Track::load_or_default(a.track.as_deref(), &catalog).context("--track")?;
    let (model, ctrl_cfg, node_cfg) = setup(&a)?;
    let known: Vec<String> = model.classes.iter().map(|c| c.name.clone()).collect();
    let fixed = a.fixed_gait.as_ref().map(|g| g.id);
    let lp = LoopParams {
        node: node_cfg,
        controller: if fixed.is_some() {
            None
        } else {
            Some(&ctrl_cfg)
        },
        fixed_gait: fixed,
        damage_pct: a.damage,
        steps: a.steps,
        seed: a.seed,
        controller_restart: None,
        node_restart: None,
        link_down: None,
        leg: leg_config(&a)?,
        leg_stall: None,
        payload_kg,
    };
    let live_recording = a.live.mcap.is_some() || a.live.foxglove.is_some() || a.ros2.any();
    let recording = live_recording || a.candump.is_some();
    anyhow::ensure!(
        !(recording && a.realtime),
        "--mcap, --foxglove, --ros2 and --ros2-bag record the lock-step demo (paced to real time with --foxglove); drop --realtime"
    );
    let (falls, rows, leg_report) = if a.realtime {
        let (falls, rows) = realtime(&a, &track, model, &lp)?;
        (falls, rows, None)
    } else {
        lockstep(&a, &track, model, &lp, &catalog, live_recording)?
    };
    summarize(&rows, falls, &track, &ctrl_cfg, &known, &a, leg_report)
}

/// The leg through motors, with `--leg`.
fn leg_config(a: &DemoArgs) -> Result<Option<leg::LegConfig>> {
    a.leg
        .map(|k| leg::LegConfig::for_driver(k, a.leg_config.as_deref()))
        .transpose()
        .context("--leg-config")
}

/// The model (its checks as the flags ask), the controller's and the node's configs.
fn setup(a: &DemoArgs) -> Result<(node::classifier::Model, ControllerConfig, node::NodeConfig)> {
    let mut model = lab::model::load_or_train_logged(a.model.as_deref()).context("--model")?;
    if let (None, Some(l), Some(k)) = (&a.model, leg_config(a)?, a.leg) {
        // The demo model's energy check was fitted on the direct leg: fit it on this one.
        model = lab::model::with_leg_energy(model, l, k.name(), a.leg_config.is_none())?;
    }
    if a.check_load {
        anyhow::ensure!(
            node::classifier::train::add_load_check(&mut model),
            "--check-load: the model holds no training images (an older file); retrain it"
        );
    }
    let mut ctrl_cfg = ControllerConfig::default();
    let node_cfg = node::NodeConfig::load_or_default(a.node_config.as_deref(), &a.terrains)
        .context("--node-config")?;
    if a.terrains.terrains.is_some() {
        ctrl_cfg.terrains = a.terrains.terrains.clone();
    }
    if let Some(n) = a.sweep {
        ctrl_cfg.sweep_steps = n;
        ctrl_cfg.validate(&ctrl_cfg.catalog()?).context("--sweep")?;
    }
    model.check_catalog(&node_cfg.catalog()?)?;
    Ok((model, ctrl_cfg, node_cfg))
}

/// `--realtime`: three concurrent tasks on the wall clock.
fn realtime(
    a: &DemoArgs,
    track: &Track,
    model: node::classifier::Model,
    lp: &LoopParams,
) -> Result<(u64, Vec<StepRecord>)> {
    let show = !a.json;
    if show {
        eprintln!(
            "running simulator, node and controller in real time for {:.0} s...",
            lab::closed_loop::realtime_seconds(a.steps)
        );
    }
    let (run, switches) = lab::closed_loop::run_realtime(track, model, lp)?;
    if show {
        run.rows.iter().for_each(|r| println!("{r}"));
        println!(
            "(controller: {switches} gait switches; {} falls)",
            run.falls()
        );
    }
    Ok((run.falls(), run.rows))
}

type LegReport = (sim::service::LegStateCheck, leg::LegCounters);

/// The lock-step demo, with its recordings (MCAP, Foxglove, ROS 2, candump, truth labels).
fn lockstep(
    a: &DemoArgs,
    track: &Track,
    model: node::classifier::Model,
    lp: &LoopParams,
    catalog: &protocol::TerrainCatalog,
    live_recording: bool,
) -> Result<(u64, Vec<StepRecord>, Option<LegReport>)> {
    let show = !a.json;
    let live = if live_recording {
        Some(crate::ros2_cmd::LiveOutputs::start(
            &a.live,
            &a.ros2,
            &lp.node.ids,
            catalog,
            true,
        )?)
    } else {
        None
    };
    let mut log = match &a.candump {
        Some(p) => Some(std::io::BufWriter::new(
            std::fs::File::create(p)
                .with_context(|| format!("--candump {}: cannot create the log", p.display()))?,
        )),
        None => None,
    };
    let on_step = |row: &StepRecord| {
        if show {
            println!("{row}")
        }
    };
    // Ctrl-C ends a recorded run properly (the file's summary written); without a
    // recording it ends the process as always.
    let recorder = live.as_ref().and_then(|l| l.recorder.as_ref());
    let run = if recorder.is_some() || log.is_some() {
        let signals = protocol::component::Signals::install()?;
        let out = lab::closed_loop::DemoOutputs {
            live: recorder,
            log: log.as_mut().map(|w| w as &mut dyn std::io::Write),
            paced: a.live.foxglove.is_some(),
            stop: &signals.stop,
        };
        lab::closed_loop::run_to(track, model, lp, on_step, out)
    } else {
        lab::closed_loop::run(track, model, lp, on_step)
    };
    if let Some(l) = live {
        l.finish();
    }
    let run = match (run, &a.candump) {
        (Err(e @ lab::LabError::Log(_)), Some(p)) => {
            return Err(e).with_context(|| format!("--candump {}", p.display()));
        }
        (r, _) => r?,
    };
    if let (Some(w), Some(p)) = (log.as_mut(), &a.candump) {
        use std::io::Write;
        w.flush()
            .with_context(|| format!("--candump {}: writing the log", p.display()))?;
        eprintln!("wrote {}: the run's bus as a candump log", p.display());
    }
    if let Some(p) = &a.truth {
        // The last step's range to a second after its touchdown (the log's clock).
        let end = run.truth.last().map_or(0, |s| s.touchdown_us) + 1_000_000;
        std::fs::write(p, sim::runner::truth_labels(&run.truth, end))
            .with_context(|| format!("writing --truth {}", p.display()))?;
        eprintln!(
            "wrote {}: the true terrain of its {} steps (`presrs capture --labels`)",
            p.display(),
            run.truth.len()
        );
    }
    let falls = run.falls();
    Ok((falls, run.rows, run.leg_state.zip(run.leg_counters)))
}

/// The step CSV and the summary (a table, or one JSON object with `--json`).
fn summarize(
    rows: &[StepRecord],
    falls: u64,
    track: &Track,
    cfg: &ControllerConfig,
    known: &[String],
    a: &DemoArgs,
    leg: Option<LegReport>,
) -> Result<ExitCode> {
    if let Some(p) = &a.csv {
        let csv = std::fs::File::create(p).with_context(|| format!("--csv {}", p.display()))?;
        lab::score::write_steps(std::io::BufWriter::new(csv), rows)
            .with_context(|| format!("--csv {}", p.display()))?;
    }
    let report = lab::score::DemoReport {
        summary: Summary::of(rows, &cfg.terrain_gaits).with_unknown(rows, known, cfg.safe_gait),
        falls,
        realtime: a.realtime,
        track_m: track.length(),
        safe_gait: cfg.safe_gait,
        csv: a.csv.as_ref().map(|p| p.display().to_string()),
        leg: leg
            .zip(a.leg)
            .map(|((state, counters), kind)| (kind.name().to_string(), state, counters)),
    };
    if a.json {
        println!("{}", report.to_json());
    } else {
        print!("{report}");
    }
    Ok(ExitCode::SUCCESS)
}
