//! `presrs lab feet`: the README's path walked on feet that are not the paper's. The work is
//! [`lab::feet`]; this module reads the arguments, finds the emulator and prints the table.

use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use lab::feet::{EMULATOR_FEET, Emulator, FeetOptions, Foot, Source};
use presrs_cli::feet::FeetArgs;

pub fn run(a: FeetArgs) -> Result<ExitCode> {
    let seeds = parse_seeds(&a.seeds).context("--seeds")?;
    let emulator = Emulator::find(a.emulator.as_deref())
        .map_err(anyhow::Error::msg)
        .context("--emulator")?;
    let mut feet: Vec<Foot> = sim::foot_model::FootModel::presets()
        .into_iter()
        .map(Foot::Sim)
        .collect();
    match &emulator {
        Some(e) => {
            eprintln!("foot emulator: {}", e.script.display());
            feet.extend(EMULATOR_FEET.iter().map(|(name, flags)| Foot::Emulator {
                name: name.to_string(),
                flags: flags.iter().map(|f| f.to_string()).collect(),
            }));
        }
        None => eprintln!(
            "foot emulator: not found at ../shared/foot-emulator/foot.py (--emulator FOOT.PY): \
             the simulator's feet only"
        ),
    }
    if !a.only.is_empty() {
        feet.retain(|f| a.only.iter().any(|w| f.name().contains(w.as_str())));
    }
    if feet.is_empty() {
        bail!(
            "--only {}: no foot's name contains any of these",
            a.only.join(",")
        );
    }
    let mut sources = vec![Source::Simulator];
    if let Some(dir) = &a.speedpp2d {
        if !dir.join("subj00").is_dir() {
            bail!(
                "--speedpp2d {}: no subj00 folder; write it with `python3 scripts/speedpp2d.py --out {}`",
                dir.display(),
                dir.display()
            );
        }
        sources.push(Source::SpeedPp2d(dir.clone()));
    }
    let defaults = FeetOptions::default();
    let opts = FeetOptions {
        seeds,
        steps: a.steps,
        third_steps: a.third_steps,
        keep: a.keep.is_some(),
        grouping: node::unknown::discover::Grouping {
            no_patches: a.no_patches,
            patch_link: a.patch_link,
            ..Default::default()
        },
        scratch: a.keep.clone().unwrap_or(defaults.scratch),
    };
    let started = std::time::Instant::now();
    let table = lab::feet::run(&feet, &sources, emulator.as_ref(), &opts, &mut |t| {
        eprintln!(
            "  {} on {} seed {}: known {}/{} right, {} unknown; new {}/{} found ({:.0} s){}",
            t.foot,
            t.source,
            t.seed,
            t.known.1,
            t.known.0,
            t.known.2,
            t.new.1,
            t.new.0,
            started.elapsed().as_secs_f64(),
            t.error
                .as_deref()
                .map_or(String::new(), |e| format!(": {e}"))
        )
    });
    if !opts.keep {
        let _ = std::fs::remove_dir_all(&opts.scratch);
    }
    eprintln!("{table}");
    if a.json {
        println!("{}", table.to_json());
    }
    Ok(ExitCode::SUCCESS)
}

/// `1-5` or `1,3,7`.
fn parse_seeds(s: &str) -> Result<Vec<u64>> {
    let bad = || anyhow::anyhow!("`{s}`: want a range like 1-5 or a list like 1,3,7");
    if let Some((a, b)) = s.split_once('-') {
        let (a, b): (u64, u64) = (
            a.trim().parse().map_err(|_| bad())?,
            b.trim().parse().map_err(|_| bad())?,
        );
        if a > b {
            return Err(bad());
        }
        return Ok((a..=b).collect());
    }
    s.split(',')
        .map(|x| x.trim().parse().map_err(|_| bad()))
        .collect()
}
