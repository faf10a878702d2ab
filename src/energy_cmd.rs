//! `presrs lab energy`: fits a model's energy check on the robot's closed-loop runs on known
//! ground. The work is [`node::unknown::energy_fit`]; this module reads the arguments and the logs and
//! prints what was fitted.

use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use node::capture::Labelling;
use node::classifier::Model;
use node::unknown::energy_fit::{EnergyRun, describe, fit_energy};
use presrs_cli::energy::EnergyArgs;

pub fn run(a: EnergyArgs) -> Result<ExitCode> {
    let cfg =
        node::NodeConfig::load_or_default(a.config.as_deref(), &a.terrains).context("--config")?;
    let catalog = cfg.catalog()?;
    let mut model = Model::load(&a.model)?;
    // One --label for every log, or one --labels file per log.
    let labellings: Vec<Labelling> = match (&a.label, a.labels.len()) {
        (Some(_), _) => {
            let l = Labelling::from_args(a.label.as_deref(), None, &catalog)?;
            vec![l; a.replay.len()]
        }
        (None, n) if n == a.replay.len() => a
            .labels
            .iter()
            .map(|p| Labelling::from_args(None, Some(p), &catalog))
            .collect::<Result<_, _>>()?,
        (None, n) => bail!(
            "{n} --labels for {} --replay: give --label TERRAIN, or one --labels FILE.csv per log, in the same order",
            a.replay.len()
        ),
    };
    // Every log checked to its end before the fit, then each streamed in turn.
    let logs = a
        .replay
        .iter()
        .map(|p| {
            protocol::candump::LogFile::check(p)
                .with_context(|| format!("--replay {}", p.display()))
        })
        .collect::<Result<Vec<_>>>()?;
    let mut streams = logs
        .iter()
        .map(|l| l.records())
        .collect::<Result<Vec<_>, _>>()?;
    let labels: Vec<_> = labellings
        .iter()
        .map(|l| move |foot: u8, t0: u64, t1: u64| l.label(foot, t0, t1))
        .collect();
    let mut runs: Vec<EnergyRun> = a
        .replay
        .iter()
        .zip(&mut streams)
        .zip(&labels)
        .map(|((p, records), label)| EnergyRun {
            name: p.display().to_string(),
            records,
            label,
        })
        .collect();
    let rep = fit_energy(&cfg, &mut model, &mut runs)?;
    drop(runs);
    for s in streams {
        s.finish()?;
    }
    model
        .save(&a.out)
        .with_context(|| format!("--out {}", a.out.display()))?;
    if a.json {
        println!(
            "{}",
            serde_json::json!({ "out": a.out, "report": rep, "maps": model.unknown.energy })
        );
    } else {
        for l in describe(&model, &rep) {
            eprintln!("{l}");
        }
        eprintln!("{}; wrote {}", rep.summary(), a.out.display());
    }
    Ok(ExitCode::SUCCESS)
}
