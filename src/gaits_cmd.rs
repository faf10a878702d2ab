//! `presrs lab gaits`: each gait on each ground in the simulator, and the safe gait by margin.
//! The work is [`lab::gait_table`]; this module reads the arguments and prints.

use std::process::ExitCode;

use anyhow::{Context, Result};
use presrs_cli::gaits::GaitsArgs;
use sim::terrain::Physics;

pub fn run(a: GaitsArgs) -> Result<ExitCode> {
    let catalog = protocol::TerrainCatalog::paper();
    let grounds: Vec<Physics> = if a.terrains.is_empty() {
        lab::gait_table::default_grounds()
    } else {
        a.terrains
            .iter()
            .map(|name| {
                let t = catalog
                    .by_name(name)
                    .with_context(|| format!("--terrains {name}: not in the paper's catalog"))?;
                Ok(Physics::of(t)?)
            })
            .collect::<Result<_>>()
            .context("--terrains")?
    };
    let mut params = sim::hopper::HopperParams::default();
    params.mass_kg += sim::check_payload(a.payload)?;
    let table = lab::gait_table::measure(
        &controller::Gait::paper_gaits(),
        &grounds,
        &params,
        &sim::gait_score::ScoreOptions::default(),
    );
    if a.json {
        println!("{}", serde_json::to_string_pretty(&table.to_json())?);
        eprintln!("{}", table.safe_line());
    } else {
        print!("{}", table.markdown());
    }
    Ok(ExitCode::SUCCESS)
}
