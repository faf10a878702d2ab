//! `presrs`: the one user-facing binary. It only parses arguments and wires the library crates.

use std::process::ExitCode;

use anyhow::Result;
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

/// The lab's path: what a lab runs to put the node on its robot and use it. Everything else is
/// under `presrs lab`.
#[derive(Subcommand)]
enum Cmd {
    /// Simulator, node and controller in one process on the in-process bus: the closed loop.
    Demo(demo::DemoArgs),
    /// A training set from the robot's own runs: one image per step (the node's stance logic),
    /// labelled, into DIR/<terrain>/ with a manifest.
    Capture(capture_cmd::CaptureArgs),
    /// Train a terrain classifier on DIR/<terrain>/<images>, as `capture` writes them.
    Train(cli::TrainArgs),
    /// Evaluate a model on a dataset: confusion matrix (detected vs actual, %) and accuracy.
    Eval(cli::EvalArgs),
    /// The terrain node: foot switch and tactile frames in, one TerrainClass per step out
    /// (on a CAN interface, or `--replay` of a candump log).
    Node(node_cmd::NodeArgs),
    /// The gait controller on a CAN interface: LegCommand out, gait switched per terrain.
    Controller(controller_cmd::ControllerArgs),
    /// The leg bridge on a CAN interface: LegCommand to the motor drivers (moteus, ODrive,
    /// MIT protocol), LegState and LegStatus from their encoders.
    Leg(leg_cmd::LegArgs),
    /// The robot's bus as ROS 2 topics, beside the node: terrain per step, contact, pressure
    /// images, joint states, gait and /diagnostics, on Zenoh in rmw_zenoh's format (no ROS
    /// install on the robot).
    Bridge(ros2_cmd::BridgeArgs),
    /// A candump log to an MCAP file (Foxglove, PlotJuggler, any MCAP reader): each message on
    /// its own JSON channel per foot, each pressure image a foxglove.RawImage; with --ros2, a
    /// rosbag2 directory that `ros2 bag play` reads (CDR, the bridge's topics).
    Mcap(mcap_cmd::McapArgs),
    /// A recording at a glance: a foot's pressure image beside what the recording holds
    /// (terrain, contact, gait, speed), as a PNG.
    View(mcap_cmd::ViewArgs),
    /// The lab bench: the simulator and its datasets, the paper's experiments, the node's
    /// benchmark, the classifier's parts (classify, features, repair), the DBC, the energy fit.
    #[command(subcommand)]
    Lab(LabCmd),
}

/// `presrs lab`: what a lab needs now and then, beside its path.
#[derive(Subcommand)]
enum LabCmd {
    /// The simulated hopper and foot on a CAN interface, in real time.
    Sim(sim_cmd::SimArgs),
    /// Generate a simulated dataset: DIR/<terrain>/<n>.pgm, as `train` and `eval` read it.
    Dataset(cli::DatasetArgs),
    /// Reproduce the paper's tables and figures on simulated data: Markdown and PNG plots.
    Experiment(experiment::ExperimentArgs),
    /// The node's speed: sampled frame -> TerrainClass latency, CPU and memory with N feet at
    /// 100 Hz (in-process, or `presrs node` on `--iface`).
    BenchNode(bench_node::BenchNodeArgs),
    /// Classify image files: one line per image (file, terrain, confidence), or with --json one
    /// object per image (file, terrain, confidence, novelty, threshold).
    Classify(cli::ClassifyArgs),
    /// Print an image's feature vector (eqs. 1-3).
    Features(cli::FeaturesArgs),
    /// Apply the paper's repair filter to an image; writes a PGM of the same size and depth.
    Repair(cli::RepairArgs),
    /// Write the DBC file for an identifier map (defaults, or a TOML file with an [ids] table).
    Dbc(cli::DbcArgs),
    /// Fit a model's energy check on the robot's closed-loop runs on known ground: ground that
    /// looks like a known terrain but takes a different share of the hop's energy is unknown.
    Energy(energy_cmd::EnergyArgs),
}

/// The commands that moved under `presrs lab`; their old names still run, with a pointer, for
/// one release.
const MOVED_TO_LAB: [&str; 9] = [
    "sim",
    "dataset",
    "experiment",
    "bench-node",
    "classify",
    "features",
    "repair",
    "dbc",
    "energy",
];

fn run(cli: Cli) -> Result<ExitCode> {
    match cli.cmd {
        Cmd::Demo(a) => demo::run(a),
        Cmd::Capture(a) => capture_cmd::run(a),
        Cmd::Train(a) => cli::train(&a),
        Cmd::Eval(a) => cli::eval(&a),
        Cmd::Node(a) => node_cmd::run(a),
        Cmd::Controller(a) => controller_cmd::run(a),
        Cmd::Leg(a) => leg_cmd::run(a),
        Cmd::Bridge(a) => ros2_cmd::bridge(a),
        Cmd::Mcap(a) => mcap_cmd::run(a),
        Cmd::View(a) => mcap_cmd::view(a),
        Cmd::Lab(cmd) => match cmd {
            LabCmd::Sim(a) => sim_cmd::run(a),
            LabCmd::Dataset(a) => cli::dataset(&a),
            LabCmd::Experiment(a) => experiment::run(a),
            LabCmd::BenchNode(a) => bench_node::run(a),
            LabCmd::Classify(a) => cli::classify(&a),
            LabCmd::Features(a) => cli::features(&a),
            LabCmd::Repair(a) => cli::repair(&a),
            LabCmd::Dbc(a) => cli::dbc(&a),
            LabCmd::Energy(a) => energy_cmd::run(a),
        },
    }
}

/// The arguments, with a command that moved under `presrs lab` put there (and said so once).
fn args() -> Vec<std::ffi::OsString> {
    let mut args: Vec<_> = std::env::args_os().collect();
    if let Some(cmd) = args
        .get(1)
        .and_then(|a| a.to_str())
        .filter(|c| MOVED_TO_LAB.contains(c))
    {
        eprintln!(
            "note: `presrs {cmd}` is now `presrs lab {cmd}`; the old name goes in the next release"
        );
        args.insert(1, "lab".into());
    }
    args
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
    match run(Cli::parse_from(args())) {
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
