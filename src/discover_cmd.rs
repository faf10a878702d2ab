//! `presrs discover`: kept unknown stances grouped into proposed terrains
//! ([`node::unknown::discover`]), shown by [`tools::discover_report`]; `--add NAME` makes one
//! of them a terrain of the model.

use std::process::ExitCode;

use anyhow::{Context, Result};
use node::classifier::Model;
use node::unknown::add::{add_group, new_terrain, write_added};
use node::unknown::discover::{Grouping, discover_at, read_kept};
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
    let groups: Vec<usize> = a.group.iter().map(|g| g - 1).collect();
    let add = add_group(&model, &d, &kept, &groups, t.class.clone())
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
    Ok(ExitCode::SUCCESS)
}
