//! `presrs demo`: the simulator, the node and the controller in one process on the in-process
//! bus, in simulated time (as fast as the machine runs).

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result};
use controller::ControllerConfig;
use lab::{LoopParams, StepRecord, Summary};
use sim::runner::Track;

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
    /// Write every step to this CSV (time, step, true and classified terrain, confidence,
    /// gait, speed); nothing is written without it.
    #[arg(long, value_name = "FILE")]
    pub csv: Option<PathBuf>,
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
    pub fixed_gait: Option<controller::Gait>,
    /// The node's configuration (as `presrs node --config`); default: the node's defaults.
    #[arg(long, value_name = "FILE")]
    pub node_config: Option<PathBuf>,
    /// Sensor damage from the start, percent of sensels on dead rows and columns (eq. 6).
    #[arg(long, default_value_t = 0.0, value_name = "PCT")]
    pub damage: f64,
    /// Also reject stances whose load lies outside the class's training range (`train
    /// --check-load`): catches ground that reads like a known terrain but yields differently.
    #[arg(long)]
    pub check_load: bool,
    /// For the track's terrain names and the node's and controller's catalogs.
    #[command(flatten)]
    pub terrains: protocol::TerrainsArg,
    /// The leg through motors: the simulated leg answers as two motors of this protocol
    /// (moteus, odrive, mit) and a leg bridge (`presrs leg`) stands between the controller and
    /// them.
    #[arg(long, value_name = "PROTOCOL", conflicts_with = "realtime")]
    pub leg: Option<leg::DriverKind>,
    /// The leg's config for `--leg` (default: a prismatic leg on that protocol's motors,
    /// `LegConfig::example`).
    #[arg(long, value_name = "FILE", requires = "leg")]
    pub leg_config: Option<PathBuf>,
    /// `--mcap FILE` records every frame on the bus and the simulator's truth; `--foxglove`
    /// serves them live, with the loop paced to real time so there is something to watch.
    #[command(flatten)]
    pub live: record::LiveOptions,
    /// `--ros2`: the demo's bus as ROS 2 topics on Zenoh (it waits up to 5 s for the router,
    /// and delivers every message before it exits); `--ros2-bag DIR`: as a rosbag2.
    #[command(flatten)]
    pub ros2: ros2::Ros2Options,
    /// Every frame of the demo's bus (motor frames included) as a candump log (`candump -L`
    /// format, interface can0, as `presrs lab sim --log` writes): `canplayer vcan0=can0 -I FILE`
    /// replays it, `presrs mcap` and python-can read it.
    #[arg(long, value_name = "FILE", conflicts_with = "realtime")]
    pub candump: Option<PathBuf>,
    /// Mass the hopper carries, kg (0 to 2; its body is 2 kg): a load the demo model and its
    /// energy maps were not made with (the controller is not told either).
    #[arg(long, value_name = "KG", default_value_t = 0.0)]
    pub payload: f64,
    /// With --candump: the true terrain of every step as a labels CSV in the log's timestamps
    /// (`start_s,end_s,terrain,foot`, as `presrs lab sim --truth` writes it), for `presrs capture
    /// --labels` and `presrs lab energy --labels`.
    #[arg(long, value_name = "FILE", requires = "candump")]
    pub truth: Option<PathBuf>,
}

pub fn run(a: DemoArgs) -> Result<ExitCode> {
    sim::check_damage(a.damage)?;
    let payload_kg = sim::check_payload(a.payload)?;
    let catalog = a.terrains.catalog()?;
    let track =
        sim::runner::Track::load_or_default(a.track.as_deref(), &catalog).context("--track")?;
    let mut model = lab::model::load_or_train_logged(a.model.as_deref()).context("--model")?;
    let leg = a
        .leg
        .map(|k| leg::LegConfig::for_driver(k, a.leg_config.as_deref()))
        .transpose()
        .context("--leg-config")?;
    if let (None, Some(l), Some(k)) = (&a.model, &leg, a.leg) {
        // The demo model's energy check was fitted on the direct leg: fit it on this one.
        model = lab::model::with_leg_energy(model, l.clone(), k.name(), a.leg_config.is_none())?;
    }
    if a.check_load {
        anyhow::ensure!(
            node::classifier::train::add_load_check(&mut model),
            "--check-load: the model holds no training images (an older file); retrain it"
        );
    }
    let known: Vec<String> = model.classes.iter().map(|c| c.name.clone()).collect();
    let mut ctrl_cfg = ControllerConfig::default();
    let node_cfg = node::NodeConfig::load_or_default(a.node_config.as_deref(), &a.terrains)
        .context("--node-config")?;
    if a.terrains.terrains.is_some() {
        ctrl_cfg.terrains = a.terrains.terrains.clone();
    }
    model.check_catalog(&node_cfg.catalog()?)?;
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
        leg,
        leg_stall: None,
        payload_kg,
    };
    let show = !a.json;
    let live_recording = a.live.mcap.is_some() || a.live.foxglove.is_some() || a.ros2.any();
    let recording = live_recording || a.candump.is_some();
    anyhow::ensure!(
        !(recording && a.realtime),
        "--mcap, --foxglove, --ros2 and --ros2-bag record the lock-step demo (paced to real time with --foxglove); drop --realtime"
    );
    let mut leg_report = None;
    let (falls, rows) = if a.realtime {
        if show {
            eprintln!(
                "running simulator, node and controller in real time for {:.0} s...",
                lab::closed_loop::realtime_seconds(a.steps)
            );
        }
        let (run, switches) = lab::closed_loop::run_realtime(&track, model, &lp)?;
        if show {
            run.rows.iter().for_each(print_row);
            println!(
                "(controller: {switches} gait switches; {} falls)",
                run.falls()
            );
        }
        (run.falls(), run.rows)
    } else {
        let live = if live_recording {
            Some(crate::ros2_cmd::LiveOutputs::start(
                &a.live,
                &a.ros2,
                &lp.node.ids,
                &catalog,
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
                print_row(row)
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
            lab::closed_loop::run_to(&track, model, &lp, on_step, out)
        } else {
            lab::closed_loop::run(&track, model, &lp, on_step)
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
        }
        if let Some(p) = &a.truth {
            // The last step's range to a second after its touchdown (the log's clock).
            let end = run.truth.last().map_or(0, |s| s.touchdown_us) + 1_000_000;
            std::fs::write(p, sim::runner::truth_labels(&run.truth, end))
                .with_context(|| format!("writing --truth {}", p.display()))?;
        }
        let falls = run.falls();
        leg_report = run.leg_state.zip(run.leg_counters);
        (falls, run.rows)
    };
    summarize(&rows, falls, &track, &ctrl_cfg, &known, &a, leg_report)
}

/// One step's line of the live log.
fn print_row(row: &StepRecord) {
    // An unknown step has no confidence: the frame's is the rejected class's.
    let confidence = if row.classified == protocol::Terrain::UNKNOWN.name() {
        "-".to_string()
    } else {
        format!("{:.1}%", row.confidence_pct)
    };
    println!(
        "t {:7.2} s  step {:4}  true {:<8} classified {:<8} {confidence:>6}  gait G{}  {:.2} m/s",
        row.t_s, row.step, row.truth, row.classified, row.gait, row.speed_m_s
    );
}

/// The step CSV and the summary (a table, or one JSON object with `--json`).
fn summarize(
    rows: &[StepRecord],
    falls: u64,
    track: &Track,
    cfg: &ControllerConfig,
    known: &[String],
    a: &DemoArgs,
    leg: Option<(sim::service::LegStateCheck, leg::LegCounters)>,
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
