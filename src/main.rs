//! `presrs`: the one user-facing binary. It only parses arguments and wires the library crates.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};

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
    },
    /// Run the terrain node on a CAN interface (not implemented yet: issue 5).
    Node,
    /// Run the gait controller on a CAN interface (not implemented yet: issue 6).
    Controller,
    /// Run the simulated hopper and foot (not implemented yet: issue 4).
    Sim,
    /// Simulator, node and controller in one process on the in-process bus (not implemented yet: issue 6).
    Demo,
    /// Train a terrain classifier (not implemented yet: issue 3).
    Train,
    /// Evaluate a classifier (not implemented yet: issue 3).
    Eval,
    /// Classify images with a model (not implemented yet: issue 3).
    Classify,
    /// Print an image's feature vector (not implemented yet: issue 3).
    Features,
    /// Apply the repair filter to an image (not implemented yet: issue 3).
    Repair,
    /// Generate a simulated dataset (not implemented yet: issue 4).
    Dataset,
    /// Reproduce the paper's tables and figures (not implemented yet: issue 7).
    Experiment,
}

fn not_yet(name: &str, issue: u32) -> Result<ExitCode> {
    eprintln!("presrs {name}: not implemented yet (tracked in issue {issue}).");
    Ok(ExitCode::from(2))
}

fn run(cli: Cli) -> Result<ExitCode> {
    match cli.cmd {
        Cmd::Dbc { ids, out } => {
            let cfg = match ids {
                None => protocol::IdConfig::default(),
                Some(p) => {
                    let text = std::fs::read_to_string(&p)
                        .with_context(|| format!("reading {}", p.display()))?;
                    #[derive(serde::Deserialize)]
                    struct File {
                        ids: protocol::IdConfig,
                    }
                    let f: File = toml_from_str(&text)
                        .with_context(|| format!("parsing the [ids] table of {}", p.display()))?;
                    f.ids
                }
            };
            cfg.validate().context("identifier map")?;
            let text = protocol::dbc::generate(&cfg);
            match out {
                Some(p) => {
                    std::fs::write(&p, text).with_context(|| format!("writing {}", p.display()))?
                }
                None => print!("{text}"),
            }
            Ok(ExitCode::SUCCESS)
        }
        Cmd::Node => not_yet("node", 5),
        Cmd::Controller => not_yet("controller", 6),
        Cmd::Sim => not_yet("sim", 4),
        Cmd::Demo => not_yet("demo", 6),
        Cmd::Train => not_yet("train", 3),
        Cmd::Eval => not_yet("eval", 3),
        Cmd::Classify => not_yet("classify", 3),
        Cmd::Features => not_yet("features", 3),
        Cmd::Repair => not_yet("repair", 3),
        Cmd::Dataset => not_yet("dataset", 4),
        Cmd::Experiment => not_yet("experiment", 7),
    }
}

fn toml_from_str<T: serde::de::DeserializeOwned>(s: &str) -> Result<T> {
    Ok(toml::from_str(s)?)
}

fn main() -> ExitCode {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "info".into()),
        )
        .with_writer(std::io::stderr)
        .init();
    match run(Cli::parse()) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
