//! `presrs`: the one user-facing binary. It only parses arguments and wires the library crates.

use std::process::ExitCode;

use anyhow::Result;
use clap::Parser;
#[cfg(feature = "lab")]
use presrs_cli::LabCmd;
use presrs_cli::{Cli, Cmd};

// What the robot runs: in every build.
mod controller_cmd;
mod leg_cmd;
mod node_cmd;
mod ros2_cmd;
// The lab's commands: only in the workstation build (the `lab` feature, on by default).
#[cfg(feature = "lab")]
mod adaptation_cmd;
#[cfg(feature = "lab")]
mod bench_node_cmd;
#[cfg(feature = "lab")]
mod capture_cmd;
#[cfg(feature = "lab")]
mod classifier_cmd;
#[cfg(feature = "lab")]
mod demo_cmd;
#[cfg(feature = "lab")]
mod discover_cmd;
#[cfg(feature = "lab")]
mod energy_cmd;
#[cfg(feature = "lab")]
mod experiment_cmd;
#[cfg(feature = "lab")]
mod feet_cmd;
#[cfg(feature = "lab")]
mod gaits_cmd;
#[cfg(feature = "lab")]
mod mcap_cmd;
#[cfg(feature = "lab")]
mod sim_cmd;

fn run(cli: Cli) -> Result<ExitCode> {
    match cli.cmd {
        Cmd::Node(a) => node_cmd::run(a),
        Cmd::Controller(a) => controller_cmd::run(a),
        Cmd::Leg(a) => leg_cmd::run(a),
        Cmd::Bridge(a) => ros2_cmd::bridge(a),
        #[cfg(feature = "lab")]
        Cmd::Demo(a) => demo_cmd::run(a),
        #[cfg(feature = "lab")]
        Cmd::Capture(a) => capture_cmd::run(a),
        #[cfg(feature = "lab")]
        Cmd::Train(a) => classifier_cmd::train(&a),
        #[cfg(feature = "lab")]
        Cmd::Eval(a) => classifier_cmd::eval(&a),
        #[cfg(feature = "lab")]
        Cmd::Discover(a) => discover_cmd::run(a),
        #[cfg(feature = "lab")]
        Cmd::Mcap(a) => mcap_cmd::run(a),
        #[cfg(feature = "lab")]
        Cmd::View(a) => mcap_cmd::view(a),
        #[cfg(feature = "lab")]
        Cmd::Lab(cmd) => run_lab(cmd),
    }
}

/// `presrs lab ...` (the workstation build).
#[cfg(feature = "lab")]
fn run_lab(cmd: LabCmd) -> Result<ExitCode> {
    match cmd {
        LabCmd::Sim(a) => sim_cmd::run(a),
        LabCmd::Dataset(a) => classifier_cmd::dataset(&a),
        LabCmd::Experiment(a) => experiment_cmd::run(a),
        LabCmd::BenchNode(a) => bench_node_cmd::run(a),
        LabCmd::Classify(a) => classifier_cmd::classify(&a),
        LabCmd::Features(a) => classifier_cmd::features(&a),
        LabCmd::Repair(a) => classifier_cmd::repair(&a),
        LabCmd::Dbc(a) => classifier_cmd::dbc(&a),
        LabCmd::Energy(a) => energy_cmd::run(a),
        LabCmd::Adaptation(a) => adaptation_cmd::run(a),
        LabCmd::Feet(a) => feet_cmd::run(a),
        LabCmd::Gaits(a) => gaits_cmd::run(a),
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
    match run(Cli::parse_from(presrs_cli::args())) {
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
    let mut said: Vec<String> = Vec::new();
    for text in e.chain().map(|c| c.to_string()) {
        if !said.iter().any(|s| s.contains(&text)) {
            said.push(text);
        }
    }
    said.join(": ")
}
