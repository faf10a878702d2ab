//! `presrs discover`: kept unknown stances grouped into proposed terrains
//! ([`node::unknown::discover`]), shown by [`tools::discover_report`]; `--add NAME` makes one
//! of them a terrain of the model.

use std::process::ExitCode;

use anyhow::{Context, Result};
use node::classifier::Model;
use node::classifier::model::ClassInfo;
use node::unknown::add::add_group;
use node::unknown::discover::{discover_at, read_kept};
use presrs_cli::discover::DiscoverArgs;
use protocol::TerrainCatalog;
use tools::discover_report::{added, json, table, write_out};

pub fn run(a: DiscoverArgs) -> Result<ExitCode> {
    let model = Model::load(&a.model).context("--model")?;
    let kept = read_kept(&a.dir)?;
    let d = discover_at(&model, &kept, a.min_separation)
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
    // A terrains file not made yet is the paper's catalog; --add makes it.
    let catalog =
        TerrainCatalog::load(a.terrains.as_deref().filter(|p| p.exists())).context("--terrains")?;
    let (id, in_catalog) = match catalog.by_name(name) {
        Some(t) => (t.id(), true),
        None => {
            anyhow::ensure!(
                a.terrains.is_some(),
                "--add {name}: the catalog has no `{name}`; give --terrains FILE (the node's \
                 terrains file, made if missing) for its entry"
            );
            let id = catalog
                .free_id()
                .context("--terrains: every terrain id is taken")?;
            (id, false)
        }
    };
    let group = a.group.map(|g| g.saturating_sub(1));
    let terrain = ClassInfo {
        name: name.clone(),
        terrain_id: id,
    };
    let add =
        add_group(&model, &d, &kept, group, terrain).with_context(|| format!("--add {name}"))?;
    add.model.save(out_model).context("--out-model")?;
    Model::load(out_model).context("--out-model: reading the written model back")?;
    if let (false, Some(path)) = (in_catalog, &a.terrains)
        && let Err(e) = protocol::terrain::append_entry(path, id, name)
    {
        // The model names a terrain no catalog has: not left behind.
        let _ = std::fs::remove_file(out_model);
        return Err(e).context("--terrains (the model was not written)");
    }
    eprint!(
        "{}",
        added(
            &add,
            &model,
            name,
            id,
            out_model,
            a.terrains.as_deref(),
            in_catalog
        )
    );
    Ok(ExitCode::SUCCESS)
}
