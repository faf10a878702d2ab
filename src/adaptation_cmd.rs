//! `presrs lab adaptation`: a recorded run's speed per terrain and gait ([`tools::adaptation`]).

use std::process::ExitCode;

use anyhow::{Context, Result};
use presrs_cli::adaptation::AdaptationArgs;
use tools::adaptation::{SETTLE_STRIDES, csv, report, strides};

pub fn run(a: AdaptationArgs) -> Result<ExitCode> {
    let cfg =
        node::NodeConfig::load_or_default(a.config.as_deref(), &a.terrains).context("--config")?;
    let catalog = cfg.catalog().context("--config terrains")?;
    let file = protocol::candump::LogFile::check(&a.log)?;
    let mut records = file.records()?;
    let all = strides(records.by_ref().map(|r| r.stamped), &cfg.ids, &catalog);
    records.finish()?;
    let md = report(&a.log.display().to_string(), &all, &catalog).with_context(|| {
        format!(
            "{}: no settled stride on known ground with a gait ({} strides measured): the log \
             needs FootContact and LegState of a foot, the controller's GaitStatus and the \
             node's TerrainClass, and {SETTLE_STRIDES} strides in a row on one terrain and gait",
            a.log.display(),
            all.len()
        )
    })?;
    print!("{md}");
    if let Some(dir) = &a.out {
        std::fs::create_dir_all(dir).with_context(|| format!("--out {}", dir.display()))?;
        for (name, text) in [
            ("adaptation.md", md.clone()),
            ("strides.csv", csv(&all, &catalog)),
        ] {
            let path = dir.join(name);
            std::fs::write(&path, text).with_context(|| format!("--out {}", path.display()))?;
        }
        eprintln!("wrote {}/adaptation.md and strides.csv", dir.display());
    }
    Ok(ExitCode::SUCCESS)
}
