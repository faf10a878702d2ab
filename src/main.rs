//! `presrs`: the one user-facing binary. It only parses arguments and wires the library crates.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};

mod bench_node;
mod capture_cmd;
mod cli;
mod controller_cmd;
mod demo;
mod energy_cmd;
mod experiment;
mod leg_cmd;
mod mcap_cmd;
mod node_cmd;
mod ros2_cmd;
mod sim_cmd;

#[derive(Parser)]
#[command(
    name = "presrs",
    version,
    about = "PreSRS terrain node: classify terrain from a tactile foot over CAN"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Write the DBC file for an identifier map (defaults, or a TOML file with an [ids] table).
    Dbc {
        /// TOML file with the identifier map (`extended`, `leg_command`, ... `tactile_frame_classic`).
        #[arg(long)]
        ids: Option<PathBuf>,
        /// Output file (stdout when absent).
        #[arg(long)]
        out: Option<PathBuf>,
        #[command(flatten)]
        terrains: protocol::TerrainsArg,
    },
    /// The terrain node: foot switch and tactile frames in, one TerrainClass per step out
    /// (on a CAN interface, or `--replay` of a candump log).
    Node(node_cmd::NodeArgs),
    /// The gait controller on a CAN interface: LegCommand out, gait switched per terrain.
    Controller(controller_cmd::ControllerArgs),
    /// The leg bridge on a CAN interface: LegCommand to the motor drivers (moteus, ODrive,
    /// MIT protocol), LegState and LegStatus from their encoders.
    Leg(leg_cmd::LegArgs),
    /// A training set from the robot's own runs: one image per step (the node's stance logic),
    /// labelled, into DIR/<terrain>/ with a manifest.
    Capture(capture_cmd::CaptureArgs),
    /// Fit a model's energy check on the robot's closed-loop runs on known ground: ground that
    /// looks like a known terrain but takes a different share of the hop's energy is unknown.
    Energy(energy_cmd::EnergyArgs),
    /// The simulated hopper and foot on a CAN interface, in real time.
    Sim(sim_cmd::SimArgs),
    /// A candump log to an MCAP file (Foxglove, PlotJuggler, any MCAP reader): each message on
    /// its own JSON channel per foot, each pressure image a foxglove.RawImage; with --ros2, a
    /// rosbag2 directory that `ros2 bag play` reads (CDR, the bridge's topics).
    Mcap(mcap_cmd::McapArgs),
    /// The robot's bus as ROS 2 topics, beside the node: terrain per step, contact, pressure
    /// images, joint states, gait and /diagnostics, on Zenoh in rmw_zenoh's format (no ROS
    /// install on the robot).
    Bridge(ros2_cmd::BridgeArgs),
    /// A recording at a glance: a foot's pressure image beside what the recording holds
    /// (terrain, contact, gait, speed), as a PNG.
    View(mcap_cmd::ViewArgs),
    /// Simulator, node and controller in one process on the in-process bus: the closed loop.
    Demo(demo::DemoArgs),
    /// The node's speed: sampled frame -> TerrainClass latency, CPU and memory with N feet at
    /// 100 Hz (in-process, or `presrs node` on `--iface`).
    BenchNode(bench_node::BenchNodeArgs),
    /// Train a terrain classifier on DIR/<class>/<images> (the paper's 13/7 split per class).
    Train(cli::TrainArgs),
    /// Evaluate a model on a dataset: confusion matrix (detected vs actual, %) and accuracy.
    Eval {
        #[arg(long)]
        model: PathBuf,
        #[arg(long)]
        data: PathBuf,
        #[command(flatten)]
        spec: lab::score::EvalSpec,
        #[arg(long)]
        json: bool,
        /// Skip unreadable files (counted) instead of stopping.
        #[arg(long)]
        skip_bad: bool,
        #[command(flatten)]
        terrains: protocol::TerrainsArg,
    },
    /// Classify image files: one line per image (file, terrain, confidence), or with --json one
    /// object per image (file, terrain, confidence, novelty, threshold).
    Classify {
        #[arg(long)]
        model: PathBuf,
        files: Vec<PathBuf>,
        /// One JSON object per line: `file`, `terrain`, `confidence`, `novelty` (larger = less
        /// like any known terrain) and `threshold` (above it: unknown), so that the score's
        /// ROC can be drawn on your own images.
        #[arg(long)]
        json: bool,
        #[command(flatten)]
        terrains: protocol::TerrainsArg,
    },
    /// Print an image's feature vector (eqs. 1-3).
    Features {
        file: PathBuf,
        #[arg(long, default_value = "0,0,0,0")]
        crop: node::classifier::Crop,
        #[arg(long)]
        json: bool,
    },
    /// Apply the paper's repair filter to an image; writes a PGM of the same size and depth.
    Repair {
        file: PathBuf,
        #[arg(long)]
        out: PathBuf,
    },
    /// Generate a simulated dataset: DIR/<terrain>/<n>.pgm, as `train` and `eval` read it.
    Dataset(cli::DatasetArgs),
    /// Reproduce the paper's tables and figures on simulated data: Markdown and PNG plots.
    Experiment(experiment::ExperimentArgs),
}

fn run(cli: Cli) -> Result<ExitCode> {
    match cli.cmd {
        Cmd::Dbc { ids, out, terrains } => {
            let cfg = match ids {
                None => protocol::IdConfig::default(),
                Some(p) => protocol::IdConfig::from_file(&p)?,
            };
            let text = protocol::dbc::generate(&cfg, &terrains.catalog()?);
            match out {
                Some(p) => {
                    std::fs::write(&p, text).with_context(|| format!("writing {}", p.display()))?
                }
                None => print!("{text}"),
            }
            Ok(ExitCode::SUCCESS)
        }
        Cmd::Node(a) => node_cmd::run(a),
        Cmd::Controller(a) => controller_cmd::run(a),
        Cmd::Leg(a) => leg_cmd::run(a),
        Cmd::Sim(a) => sim_cmd::run(a),
        Cmd::Capture(a) => capture_cmd::run(a),
        Cmd::Energy(a) => energy_cmd::run(a),
        Cmd::Mcap(a) => mcap_cmd::run(a),
        Cmd::Bridge(a) => ros2_cmd::bridge(a),
        Cmd::View(a) => mcap_cmd::view(a),
        Cmd::Demo(args) => demo::run(args),
        Cmd::BenchNode(args) => bench_node::run(args),
        Cmd::Train(a) => cli::train(&a),
        Cmd::Eval {
            model,
            data,
            spec,
            json,
            skip_bad,
            terrains,
        } => cli::eval(&model, &data, &spec, json, skip_bad, &terrains),
        Cmd::Classify {
            model,
            files,
            json,
            terrains,
        } => cli::classify(&model, &files, json, &terrains),
        Cmd::Features { file, crop, json } => cli::features(&file, &crop, json),
        Cmd::Repair { file, out } => cli::repair(&file, &out),
        Cmd::Dataset(a) => cli::dataset(&a),
        Cmd::Experiment(args) => experiment::run(args),
    }
}

fn main() -> ExitCode {
    // A command-line tool piped into `head` should stop quietly, as `cat` does, not panic on
    // EPIPE: restore the default SIGPIPE action that the Rust runtime sets to "ignore".
    #[cfg(unix)]
    // SAFETY: called before any thread starts; SIG_DFL is a valid action for SIGPIPE.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "info".into()),
        )
        .with_writer(std::io::stderr)
        // Colour codes only for a terminal: a log file or a CI page shows them as `[2m...`.
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .init();
    match run(Cli::parse()) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {}", message(&e));
            ExitCode::FAILURE
        }
    }
}

/// The error and its causes, each said once: our library errors already name their cause in
/// their message ("cannot read model m.json: No such file ..."), and `{:#}` repeated it.
fn message(e: &anyhow::Error) -> String {
    let mut out = String::new();
    for cause in e.chain() {
        let text = cause.to_string();
        if !out.contains(&text) {
            if !out.is_empty() {
                out.push_str(": ");
            }
            out.push_str(&text);
        }
    }
    out
}
