//! Known ground of the next session called unknown, and a left-out terrain found, with one or
//! two sessions, per source, over seeds: the measurement behind
//! docs/decisions/unknown-one-session.md (not part of `presrs`).
//!
//!   cargo run --release -p presrs-lab --example next_session -- SOURCE SESSIONS SEEDS [PER_CLASS]
//!   SOURCE: static | sandpaper | dynamic | DIR (a captured set with runs; DIR/terrains.toml)
//!   SESSIONS: 1, 2, or 3 (one session cut in time: its last quarter calibrates)
//!   Environment: CROP=1 keeps the source's given crop (default: measured from the footprint);
//!   CHECKS=LIST fixes the unknown checks (`--unknown-checks`); SAME_SENSOR=1 judges on the
//!   training sensor.

use std::error::Error;

use node::classifier::Crop;
use node::classifier::train::TrainOptions;
use presrs_lab::open_set::{OpenSetSource, leave_one_class_out};
use sim::dataset::Kind;

fn main() -> Result<(), Box<dyn Error>> {
    let a: Vec<String> = std::env::args().collect();
    let arg = |i: usize, default: &str| a.get(i).cloned().unwrap_or_else(|| default.to_string());
    let source = arg(1, "static");
    let sessions: usize = arg(2, "1").parse()?;
    let seeds: u64 = arg(3, "3").parse()?;
    let per_class: usize = arg(4, "20").parse()?;
    let mut known = Vec::new();
    let mut found = Vec::new();
    for seed in 1..=seeds {
        let mut src = build(&source, sessions.min(2), seed, per_class)?;
        if sessions == 3 {
            // One session cut in time: its last quarter calibrates, as a second session would.
            let t = &src.train;
            let blocks = node::classifier::train::time_blocks(&t.labels, t.classes.len());
            let (early, late): (Vec<usize>, Vec<usize>) =
                (0..t.labels.len()).partition(|&i| blocks[i] < 3);
            let (e, l) = (t.subset(&early), t.subset(&late));
            src.train = e;
            src.calibration = Some(l);
            src.opts.per_class = src.opts.per_class * 3 / 4;
            src.opts.train = src.opts.per_class * 13 / 20;
        }
        let rows = leave_one_class_out(&src)?;
        let k: f64 = rows.iter().map(|r| r.unknown_known).sum::<f64>() / rows.len() as f64;
        let f: f64 = rows.iter().map(|r| r.unknown_held_out).sum::<f64>() / rows.len() as f64;
        let au: f64 = rows.iter().map(|r| r.auroc).sum::<f64>() / rows.len() as f64;
        let nn: f64 = rows.iter().map(|r| r.nn_auroc).sum::<f64>() / rows.len() as f64;
        let per: Vec<String> = rows
            .iter()
            .map(|r| {
                format!(
                    "{}:{:.0}/{:.0}",
                    r.held_out,
                    100.0 * r.unknown_held_out,
                    100.0 * r.unknown_known
                )
            })
            .collect();
        println!(
            "seed {seed}: known->unknown {:.1}%  left-out found {:.1}%  auroc {au:.3} nn {nn:.3}  [{}] checks {}",
            100.0 * k,
            100.0 * f,
            per.join(" "),
            rows.iter()
                .map(|r| r.checks.as_str())
                .collect::<Vec<_>>()
                .join("|")
        );
        known.push(k);
        found.push(f);
    }
    let s = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        format!(
            "median {:.1}% ({:.1}-{:.1})",
            100.0 * v[v.len() / 2],
            100.0 * v[0],
            100.0 * v[v.len() - 1]
        )
    };
    println!(
        "{source} sessions {sessions}: known->unknown {}; found {}",
        s(&mut known),
        s(&mut found)
    );
    Ok(())
}

fn build(
    source: &str,
    sessions: usize,
    seed: u64,
    per_class: usize,
) -> Result<OpenSetSource, Box<dyn Error>> {
    let checks = match std::env::var("CHECKS") {
        Ok(c) => c.parse()?,
        Err(_) => node::classifier::options::UnknownChecks::Auto,
    };
    let train_opts = |crop: Crop, normalize_load: bool| TrainOptions {
        crop: match std::env::var("CROP") {
            Ok(_) => crop.into(),
            Err(_) => node::classifier::CropSpec::Auto,
        },
        normalize_load,
        seed,
        per_class,
        train: per_class * 13 / 20,
        unknown_checks: checks,
        ..TrainOptions::default()
    };
    let (kind, crop) = match source {
        "static" => (Kind::Static, "2,2,2,2"),
        "sandpaper" => (Kind::Sandpaper, "2,2,2,2"),
        "dynamic" => (Kind::Dynamic, "0,3,6,0"),
        dir => {
            let catalog = protocol::TerrainCatalog::load(Some(
                &std::path::Path::new(dir).join("terrains.toml"),
            ))?;
            let (set, _) =
                node::training::TrainingSet::load(std::path::Path::new(dir), &catalog, false)?;
            let mut src =
                OpenSetSource::from_runs(dir.to_string(), &set, train_opts(Crop::default(), true));
            if sessions != 2 {
                src.calibration = None;
            }
            return Ok(src);
        }
    };
    let s = seed + 40;
    let gaits = if kind == Kind::Dynamic {
        vec![
            controller::Gait::g1(),
            controller::Gait::g2(),
            controller::Gait::g3(),
        ]
    } else {
        vec![controller::Gait::g2()]
    };
    let same_sensor = std::env::var("SAME_SENSOR").is_ok();
    let serial = move |i: u64| if same_sensor { 1 } else { 1 + i };
    let run = |i: u64, m: usize| {
        let mut t = presrs_lab::study::dataset_on(
            kind,
            m / gaits.len(),
            gaits[0].clone(),
            s + i,
            serial(i),
        );
        for (j, g) in gaits.iter().enumerate().skip(1) {
            let u = presrs_lab::study::dataset_on(
                kind,
                m / gaits.len(),
                g.clone(),
                s + i + 10 * j as u64,
                serial(i),
            );
            t.images.extend(u.images);
            t.labels.extend(u.labels);
            t.runs.extend(u.runs);
            t.gaits.extend(u.gaits);
        }
        t
    };
    // The dynamic source draws in thirds: round up so each gait gets its share.
    let n = per_class.div_ceil(gaits.len()) * gaits.len();
    Ok(OpenSetSource {
        name: source.into(),
        train: run(0, n),
        calibration: (sessions == 2).then(|| run(1, n)),
        fresh: Some(run(2, n)),
        opts: train_opts(crop.parse()?, false),
    })
}
