//! `presrs discover`: kept unknown stances grouped into proposed terrains
//! ([`node::unknown::discover`]), shown by [`tools::discover_report`]; `--add NAME` makes one
//! of them a terrain of the model.

use std::process::ExitCode;

use anyhow::{Context, Result};
use node::classifier::Model;
use node::unknown::add::{add_group, add_stances, new_terrain, write_added};
use node::unknown::discover::{Grouping, discover_at, read_kept};
use node::unknown::lab_word::LabWord;
use presrs_cli::discover::DiscoverArgs;
use tools::discover_report::{added, json, table, write_out};

pub fn run(a: DiscoverArgs) -> Result<ExitCode> {
    let model = Model::load(&a.model).context("--model")?;
    let kept = read_kept(&a.dir)?;
    let how = Grouping {
        min_separation: a.min_separation,
        split_at: if a.no_split {
            Some(f64::INFINITY)
        } else {
            a.split_at
        },
        no_patches: a.no_patches,
        patch_link: a.patch_link,
    };
    let d = discover_at(&model, &kept, how)
        .with_context(|| format!("--model {}", a.model.display()))?;
    if a.json {
        println!("{}", json(&d, &kept, &model));
    } else {
        print!("{}", table(&d, &kept, &model, &a.dir.display().to_string()));
    }
    if let Some(out) = &a.out {
        write_out(out, &d, &kept, &model).context("--out")?;
        eprintln!(
            "wrote {}/groups.csv and {} contact sheets",
            out.display(),
            d.groups.len()
        );
    }
    let (Some(name), Some(out_model)) = (&a.add, &a.out_model) else {
        return Ok(ExitCode::SUCCESS);
    };
    anyhow::ensure!(
        !out_model.exists(),
        "--out-model {}: the file exists; give a new path (nothing was written)",
        out_model.display()
    );
    let t = new_terrain(name, a.terrains.as_deref())?;
    let add = match &a.stances {
        Some(spec) => {
            let word = LabWord::parse(spec, name)?;
            let members = word.select(&kept);
            eprintln!(
                "--stances: {} of the {} kept unknown stances ({})",
                members.len(),
                kept.iter().filter(|s| s.known.is_none()).count(),
                word.describe()
            );
            add_stances(&model, &kept, &members, t.class.clone())
        }
        None => {
            let groups: Vec<usize> = a.group.iter().map(|g| g - 1).collect();
            add_group(&model, &d, &kept, &groups, t.class.clone())
        }
    }
    .with_context(|| format!("--add {name}"))?;
    write_added(&add, &t, out_model, a.terrains.as_deref())?;
    eprint!(
        "{}",
        added(
            &add,
            &model,
            name,
            t.class.terrain_id,
            out_model,
            a.terrains.as_deref(),
            t.in_catalog
        )
    );
    eprintln!("{}", gait_line(name, a.controller_config.as_deref())?);
    Ok(ExitCode::SUCCESS)
}

/// Which gait the controller runs on the new terrain, and the `[terrain_gaits]` line: added to
/// the controller's config when the lab gave it, else printed.
fn gait_line(name: &str, config: Option<&std::path::Path>) -> Result<String> {
    let Some(path) = config else {
        let safe = controller::ControllerConfig::default().safe_gait;
        return Ok(format!(
            "gait: the controller runs its safe gait (G{safe} by default) on `{name}` until its \
             config names one; add `{name} = {safe}` under [terrain_gaits] in its config (or \
             give --controller-config FILE to add it)"
        ));
    };
    let cfg = controller::ControllerConfig::load(path).context("--controller-config")?;
    let (gait, named) = cfg.gait_for(name);
    if named {
        return Ok(format!(
            "gait: {} names `{name}` already: G{gait}",
            path.display()
        ));
    }
    controller::config::add_terrain_gait(path, name, cfg.safe_gait)
        .context("--controller-config (left as it was)")?;
    Ok(format!(
        "gait: added `{name} = {}` (its safe gait) under [terrain_gaits] in {}; the controller \
         reads it at its next start",
        cfg.safe_gait,
        path.display()
    ))
}
