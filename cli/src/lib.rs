//! Every argument type of the `presrs` command line, in one place: what `presrs --help` shows
//! is declared here, and the binary (`src/`) parses into these and wires the member crates.
//! A robot team's own binary can flatten the same groups (`#[command(flatten)]`).
//!
//! The option groups that carry their own behaviour (`protocol::TerrainsArg`,
//! `record::LiveOptions`, `ros2::Ros2Options`, `sim::FootOptions`, `tools::eval::EvalSpec`,
//! `node::classifier::train::TrainOptions`, `node::NodeThreads`) stay beside that behaviour in
//! their crates, behind each crate's `clap` feature, and are flattened here.
#![forbid(unsafe_code)]

// What the robot runs: in every build.
pub mod bridge;
pub mod controller;
pub mod leg;
pub mod node;
// The lab's commands: only in the workstation build (the `lab` feature, on by default).
#[cfg(feature = "lab")]
pub mod adaptation;
#[cfg(feature = "lab")]
pub mod bench_node;
#[cfg(feature = "lab")]
pub mod capture;
#[cfg(feature = "lab")]
pub mod classifier;
#[cfg(feature = "lab")]
pub mod demo;
#[cfg(feature = "lab")]
pub mod discover;
#[cfg(feature = "lab")]
pub mod energy;
#[cfg(feature = "lab")]
pub mod experiment;
#[cfg(feature = "lab")]
pub mod feet;
#[cfg(feature = "lab")]
pub mod gaits;
#[cfg(feature = "lab")]
pub mod mcap;
#[cfg(feature = "lab")]
pub mod sim;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[cfg_attr(
    feature = "lab",
    command(
        name = "presrs",
        version,
        about = "PreSRS terrain node: classify terrain from a tactile foot over CAN",
        after_help = "On the robot: node, controller, leg, bridge (systemd units in the .deb). On the lab's computer: demo, capture, train, eval, discover, mcap, view, and `presrs lab` for the rest."
    )
)]
#[cfg_attr(
    not(feature = "lab"),
    command(
        name = "presrs",
        version,
        about = "PreSRS terrain node, the robot's build: classify terrain from a tactile foot over CAN",
        after_help = ROBOT_BUILD
    )
)]
pub struct Cli {
    #[command(subcommand)]
    pub cmd: Cmd,
}

/// The lab's path: what a lab runs to put the node on its robot and use it. Everything else is
/// under `presrs lab`.
#[derive(Subcommand)]
pub enum Cmd {
    #[cfg(feature = "lab")]
    /// Simulator, node and controller in one process on the in-process bus: the closed loop.
    Demo(demo::DemoArgs),
    #[cfg(feature = "lab")]
    /// A training set from the robot's own runs: one image per step (the node's stance logic),
    /// labelled, into DIR/<terrain>/ with a manifest.
    Capture(capture::CaptureArgs),
    #[cfg(feature = "lab")]
    /// Train a terrain classifier on DIR/<terrain>/<images>, as `capture` writes them.
    ///
    /// A first try needs only `--data` and `--out`: the crop, the stance's frame and the
    /// unknown-ground checks are measured on your runs, and the summary says what was chosen.
    Train(classifier::TrainArgs),
    #[cfg(feature = "lab")]
    /// Evaluate a model on a dataset: confusion matrix (detected vs actual, %) and accuracy.
    Eval(classifier::EvalArgs),
    /// The terrain node: foot switch and tactile frames in, one TerrainClass per step out
    /// (on a CAN interface, or `--replay` of a candump log).
    Node(node::NodeArgs),
    /// The gait controller on a CAN interface: LegCommand out, gait switched per terrain.
    Controller(controller::ControllerArgs),
    /// The leg bridge on a CAN interface: LegCommand to the motor drivers (moteus, ODrive,
    /// MIT protocol), LegState and LegStatus from their encoders.
    Leg(leg::LegArgs),
    /// The robot's bus as ROS 2 topics, beside the node: terrain per step, contact, pressure
    /// images, joint states, gait and /diagnostics, on Zenoh in rmw_zenoh's format (no ROS
    /// install on the robot).
    Bridge(bridge::BridgeArgs),
    #[cfg(feature = "lab")]
    /// A candump log to an MCAP file (Foxglove, PlotJuggler, any MCAP reader): each message on
    /// its own JSON channel per foot, each pressure image a foxglove.RawImage; with --ros2, a
    /// rosbag2 directory that `ros2 bag play` reads (CDR, the bridge's topics).
    Mcap(mcap::McapArgs),
    #[cfg(feature = "lab")]
    /// New ground: the stances a node kept as unknown (`node --keep-unknown DIR`) grouped into
    /// proposed terrains, each with its size, how far it lies from the known terrains and a
    /// contact sheet.
    Discover(discover::DiscoverArgs),
    #[cfg(feature = "lab")]
    /// A recording at a glance: a foot's pressure image beside what the recording holds
    /// (terrain, contact, gait, speed), as a PNG.
    View(mcap::ViewArgs),
    #[cfg(feature = "lab")]
    /// The lab bench: the simulator and its datasets, the paper's experiments, the node's
    /// benchmark, the classifier's parts (classify, features, repair), the DBC, the energy fit.
    #[command(
        subcommand,
        after_help = "On a real robot's recordings or bus: adaptation (a run's speed per terrain and gait), energy (the energy check's fit), dbc (the bus for cantools, SavvyCAN, ...), bench-node --iface (a node on the robot's bus, from a workstation build on a machine there), classify, features, repair (image files). On the simulator: sim, dataset, experiment, feet, gaits."
    )]
    Lab(LabCmd),
}

/// `presrs lab`: what a lab needs now and then, beside its path.
#[cfg(feature = "lab")]
#[derive(Subcommand)]
pub enum LabCmd {
    /// The simulated hopper and foot on a CAN interface, in real time.
    Sim(sim::SimArgs),
    /// Generate a simulated dataset: DIR/<terrain>/<n>.pgm, as `train` and `eval` read it.
    Dataset(classifier::DatasetArgs),
    /// Reproduce the paper's tables and figures on simulated data: Markdown and PNG plots.
    Experiment(experiment::ExperimentArgs),
    /// The node's speed: sampled frame -> TerrainClass latency, CPU and memory with N feet at
    /// 100 Hz (in-process, or `presrs node` on `--iface`).
    BenchNode(bench_node::BenchNodeArgs),
    /// Classify image files: one line per image (file, terrain, confidence), or with --json one
    /// object per image (file, terrain, confidence, novelty, threshold).
    Classify(classifier::ClassifyArgs),
    /// Print an image's feature vector (eqs. 1-3).
    Features(classifier::FeaturesArgs),
    /// Apply the paper's repair filter to an image; writes a PGM of the same size and depth.
    Repair(classifier::RepairArgs),
    /// Write the DBC file for an identifier map (defaults, or a TOML file with an [ids] table).
    Dbc(classifier::DbcArgs),
    /// Fit a model's energy check on the robot's closed-loop runs on known ground: ground that
    /// looks like a known terrain but takes a different share of the hop's energy is unknown.
    Energy(energy::EnergyArgs),
    /// The paper's Table 3 for your robot: forward speed per terrain and gait from a recorded
    /// run (each hop measured from the foot switch and LegState, as the controller does).
    Adaptation(adaptation::AdaptationArgs),
    /// The README's path (two small sessions, capture, train, a third session with new ground)
    /// walked on feet that are not the paper's: the simulator's and the independent foot
    /// emulator's; a table per foot and the worst foot.
    Feet(feet::FeetArgs),
    /// Each of the paper's gaits on each ground in the simulator: stride speed, cost of
    /// transport, energy ratio and margin (the largest sudden speed loss it survives), and the
    /// safe gait for unknown ground chosen by margin.
    Gaits(gaits::GaitsArgs),
}

/// What the robot's build says where a lab command was asked for, and in its `--help`.
pub const ROBOT_BUILD: &str = "This is the robot's build of presrs: node, controller, leg, bridge (systemd units in the .deb). The lab's commands (demo, capture, train, eval, discover, mcap, view, lab) are in the workstation build: `cargo build --release` (its default features), on the lab's computer.";

/// The lab's commands: not in the robot's build, which names where they are.
pub const LAB_COMMANDS: [&str; 8] = [
    "demo", "capture", "train", "eval", "discover", "mcap", "view", "lab",
];

/// The commands that moved under `presrs lab`; their old names still run, with a pointer, for
/// one release.
pub const MOVED_TO_LAB: [&str; 9] = [
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

/// The arguments, with a command that moved under `presrs lab` put there (and said so once).
/// In the robot's build a lab command is an error that says where it is (exit status 2, as
/// clap's usage errors).
pub fn args() -> Vec<std::ffi::OsString> {
    let mut args: Vec<_> = std::env::args_os().collect();
    let cmd = args.get(1).and_then(|a| a.to_str()).map(str::to_owned);
    let Some(cmd) = cmd else { return args };
    let lab_command = LAB_COMMANDS.contains(&cmd.as_str()) || MOVED_TO_LAB.contains(&cmd.as_str());
    if !cfg!(feature = "lab") && lab_command {
        eprintln!("error: `presrs {cmd}` is a lab command. {ROBOT_BUILD}");
        std::process::exit(2);
    }
    if MOVED_TO_LAB.contains(&cmd.as_str()) {
        eprintln!(
            "note: `presrs {cmd}` is now `presrs lab {cmd}`; the old name goes in the next release"
        );
        args.insert(1, "lab".into());
    }
    args
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    /// Every option and argument of every command says what it is in `--help`.
    #[test]
    fn every_argument_has_help() {
        fn walk(cmd: &clap::Command, path: &str, missing: &mut Vec<String>) {
            for a in cmd.get_arguments() {
                let id = a.get_id().as_str();
                if a.get_help().is_none() && !["help", "version"].contains(&id) {
                    missing.push(format!("{path} --{id}"));
                }
            }
            for sub in cmd.get_subcommands() {
                walk(sub, &format!("{path} {}", sub.get_name()), missing);
            }
        }
        let mut missing = Vec::new();
        walk(&Cli::command(), "presrs", &mut missing);
        assert!(missing.is_empty(), "without help: {missing:#?}");
    }

    /// Every command but the robot's is one the robot's build names as the lab's (and says
    /// where it is), and every name it names is a command.
    #[cfg(feature = "lab")]
    #[test]
    fn the_robot_build_names_every_lab_command() {
        let robot = ["node", "controller", "leg", "bridge"];
        let names: Vec<String> = Cli::command()
            .get_subcommands()
            .map(|c| c.get_name().to_string())
            .collect();
        for n in &names {
            assert!(
                robot.contains(&n.as_str()) || LAB_COMMANDS.contains(&n.as_str()),
                "{n}: neither the robot's nor in LAB_COMMANDS"
            );
        }
        for n in LAB_COMMANDS.iter().chain(&robot) {
            assert!(names.iter().any(|m| m == n), "{n} is no command");
        }
    }

    /// A name moved under `presrs lab` still runs there.
    #[cfg(feature = "lab")]
    #[test]
    fn moved_commands_are_lab_commands() {
        let lab = Cli::command();
        let lab = lab.find_subcommand("lab").map(|c| {
            c.get_subcommands()
                .map(|s| s.get_name().to_string())
                .collect::<Vec<_>>()
        });
        for name in MOVED_TO_LAB {
            assert!(
                lab.as_ref().is_some_and(|l| l.iter().any(|n| n == name)),
                "{name}"
            );
        }
    }
}
