//! The classifier commands: argument handling and printing around `node::classifier`.

use std::process::ExitCode;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use node::classifier::dataset::{load_dataset, read_image, read_images, write_pgm};
use node::classifier::{Classifier, Model, repair as repair_mod};
use node::training::TrainingSet;
use presrs_cli::classifier::{
    ClassifyArgs, DatasetArgs, DbcArgs, EvalArgs, FeaturesArgs, RepairArgs, TrainArgs,
};

pub fn train(a: &TrainArgs) -> Result<ExitCode> {
    let catalog = a.terrains.catalog()?;
    let (set, _) = TrainingSet::load(&a.data, &catalog, a.skip_bad)?;
    let opts = &a.opts;
    if let Some(note) = set.gait_note(a.verbose) {
        println!("{note}");
    }
    let cal = match &a.calibrate {
        Some(dir) if opts.unknown_rate > 0.0 => {
            let (s, _) = TrainingSet::load(dir, &catalog, a.skip_bad)
                .with_context(|| format!("the calibration run --calibrate {}", dir.display()))?;
            Some((s, vec![dir.display().to_string()]))
        }
        Some(dir) => bail!(
            "--calibrate {} with --unknown-rate 0: a model that rejects nothing has nothing to \
             calibrate; drop one of them",
            dir.display()
        ),
        None => None,
    };
    let t0 = Instant::now();
    let trained = set.train_calibrated(opts, cal.as_ref().map(|(s, n)| (s, n.as_slice())))?;
    let took = t0.elapsed();
    trained.model.save(&a.out)?;
    let (out, rate) = (a.out.display().to_string(), opts.unknown_rate);
    match a.verbose {
        true => print!("{}", trained.report(rate, took, &out, true)),
        false => print!("{}", trained.summary(rate, took, &out)),
    }
    Ok(ExitCode::SUCCESS)
}

pub fn eval(a: &EvalArgs) -> Result<ExitCode> {
    let model = Model::load(&a.model)?;
    model.check_catalog(&a.terrains.catalog()?)?;
    let ds = load_dataset(&a.data, a.skip_bad)?;
    let names: Vec<String> = model.classes.iter().map(|c| c.name.clone()).collect();
    let ev = tools::eval::evaluate(model, &ds, &a.spec)?;
    if a.json {
        println!("{}", ev.to_json(&names, &a.spec));
    } else {
        print!("{}", ev.table(&names, &a.spec));
    }
    Ok(ExitCode::SUCCESS)
}

pub fn classify(a: &ClassifyArgs) -> Result<ExitCode> {
    let model = Model::load(&a.model)?;
    model.check_catalog(&a.terrains.catalog()?)?;
    let names: Vec<String> = model.classes.iter().map(|c| c.name.clone()).collect();
    let mut c = Classifier::new(model);
    for f in &a.files {
        for (i, img) in read_images(f)?.iter().enumerate() {
            let d = c
                .classify_image(img, false)
                .with_context(|| f.display().to_string())?;
            let file = match i {
                0 => f.display().to_string(),
                i => format!("{}#{i}", f.display()),
            };
            if a.json {
                println!("{}", d.to_json(&file, &names));
            } else {
                // Unknown ground chose no terrain: no confidence (`--json` gives the nearest
                // class's, as `best`).
                let confidence = match d.class {
                    Some(_) => format!("{:.3}", d.confidence),
                    None => "-".into(),
                };
                println!("{file}\t{}\t{confidence}", d.label(&names));
            }
        }
    }
    Ok(ExitCode::SUCCESS)
}

pub fn features(a: &FeaturesArgs) -> Result<ExitCode> {
    let (file, crop) = (&a.file, &a.crop);
    let img = read_image(file)?;
    let img = img
        .crop(crop)
        .with_context(|| format!("crop {crop:?} leaves nothing of {}", file.display()))?;
    let mut fx = node::classifier::features::FeatureExtractor::new(img.rows * img.cols);
    let f = fx.features(&img.pixels, 1.0);
    if a.json {
        println!("{}", serde_json::json!({ "features": f }));
    } else {
        for v in f {
            println!("{v}");
        }
    }
    Ok(ExitCode::SUCCESS)
}

pub fn repair(a: &RepairArgs) -> Result<ExitCode> {
    let mut img = read_image(&a.file)?;
    let (r, c) = repair_mod::repair(&mut img);
    write_pgm(&img, &a.out).with_context(|| format!("writing {}", a.out.display()))?;
    println!(
        "filled {r} dead rows and {c} dead columns; wrote {}",
        a.out.display()
    );
    Ok(ExitCode::SUCCESS)
}

pub fn dbc(a: &DbcArgs) -> Result<ExitCode> {
    let cfg = match &a.ids {
        None => protocol::IdConfig::default(),
        Some(p) => protocol::config::ids_from_file(p)?,
    };
    let text = protocol::dbc::generate(&cfg, &a.terrains.catalog()?);
    match &a.out {
        Some(p) => std::fs::write(p, text).with_context(|| format!("writing {}", p.display()))?,
        None => print!("{text}"),
    }
    Ok(ExitCode::SUCCESS)
}

pub fn dataset(a: &DatasetArgs) -> Result<ExitCode> {
    use sim::dataset::{Options, generate};
    // A bad --terrains file is refused as by every command. The simulator generates only the
    // paper's terrains, which every catalog starts from and none may redefine
    // (`TerrainCatalog::add`), so the samples need no check against it.
    a.terrains.catalog()?;
    let out = &a.out;
    let (gait, damage) = a.foot.checked()?;
    let samples = generate(&Options {
        kind: a.kind,
        n: a.n,
        gait,
        damage_pct: damage,
        sensor: a.foot.sensor,
        seed: a.seed,
    });
    lab::simdata::write_images(&samples, out)?;
    print!("{}", lab::simdata::describe(&samples, a.kind));
    println!("wrote {} images to {}", samples.len(), out.display());
    Ok(ExitCode::SUCCESS)
}
