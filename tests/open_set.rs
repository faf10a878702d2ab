//! Unknown ground on data this project did not shape: the real plantar-pressure maps
//! of the `jiku-data` package's SpeedPP2D set (10 subjects as classes, written by
//! `scripts/speedpp2d.py` from the installed package; needs `--features interop`, as the
//! README's test command runs), and the simulator on sensors, seeds and gaits the model never
//! saw. Each asserts the figures `presrs lab experiment open-set` measured (docs/results.md), with
//! a margin, so that a change that loses them fails here.

// Without `--features interop` the tests that need Python's packages are left out, and the
// helpers only they use with them.
#![cfg_attr(not(feature = "interop"), allow(unused_imports, dead_code))]
mod common;

use lab::open_set::{
    OpenSetMeans, OpenSetRow, OpenSetSource, leave_class_out, leave_one_class_out,
};
use lab::simdata::TrainingSet;
use lab::study::dataset_on;
use node::classifier::image::Crop;
use node::classifier::options::{Candidate, UnknownChecks};
use node::classifier::train::TrainOptions;
use sim::dataset::Kind;

fn means(rows: &[OpenSetRow]) -> OpenSetRow {
    OpenSetMeans::of(rows).row
}

/// One run on sensor `sensor`: `per_gait` images per terrain in each of `gaits`, the j-th
/// gait's seeded `seed + 10 j`.
fn gait_run(
    kind: Kind,
    gaits: &[controller::Gait],
    per_gait: usize,
    seed: u64,
    sensor: u64,
) -> TrainingSet {
    let mut t = dataset_on(kind, per_gait, gaits[0].clone(), seed, sensor);
    for (j, g) in gaits.iter().enumerate().skip(1) {
        let u = dataset_on(kind, per_gait, g.clone(), seed + 10 * j as u64, sensor);
        t.images.extend(u.images);
        t.labels.extend(u.labels);
        t.runs.extend(u.runs);
        t.gaits.extend(u.gaits);
    }
    t
}

/// The shares of `set`'s images that `model` calls unknown and classifies right (the rest it
/// takes for another class).
fn judge(model: &node::classifier::Model, set: &TrainingSet) -> (f64, f64) {
    let mut c = node::classifier::Classifier::new(model.clone());
    let (mut unknown, mut right) = (0, 0);
    for (img, &l) in set.images.iter().zip(&set.labels) {
        let want = model
            .classes
            .iter()
            .position(|k| k.name == set.classes[l].name);
        let d = c.classify_image(img, false).unwrap();
        unknown += d.class.is_none() as usize;
        right += (d.class.is_some() && d.class == want) as usize;
    }
    let n = set.images.len() as f64;
    (unknown as f64 / n, right as f64 / n)
}

/// Three runs of a simulated set on sensor serials 1, 2 and 3 (train, calibrate, fresh), as the
/// experiment makes them.
fn sim_source(kind: Kind, crop: Crop, normalize_load: bool, n: usize) -> OpenSetSource {
    let gaits = if kind == Kind::Dynamic {
        controller::Gait::paper_gaits()
    } else {
        vec![controller::Gait::g2()]
    };
    let run = |i: u64, m: usize| gait_run(kind, &gaits, m / gaits.len(), 41 + i, 1 + i);
    OpenSetSource {
        name: format!("{kind:?}"),
        train: run(0, n),
        calibration: Some(run(1, n / 2)),
        fresh: Some(run(2, n / 2)),
        opts: TrainOptions {
            crop: crop.into(),
            normalize_load,
            ..Default::default()
        },
    }
}

const STATIC_CROP: Crop = Crop {
    top: 2,
    bottom: 2,
    left: 2,
    right: 2,
};

#[test]
fn a_left_out_static_terrain_is_unknown_on_a_fresh_sensor_and_the_known_ones_are_not() {
    let rows = leave_one_class_out(&sim_source(Kind::Static, STATIC_CROP, false, 60)).unwrap();
    let m = means(&rows);
    // Measured (experiment open-set, seeds 1-3): AUROC 1.000, left out 99-100% unknown, fresh
    // known 0.3-0.8% unknown, accuracy 99.2-99.7% with rejection and 100% without. (Before the
    // calibration run's images were references: fresh known 2.2-3.3%, accuracy 96.7-97.8%.)
    assert!(m.auroc >= 0.97, "{rows:?}");
    assert!(m.unknown_held_out >= 0.9, "{rows:?}");
    assert!(m.unknown_known <= 0.03, "{rows:?}");
    assert!(m.known_accuracy_open - m.known_accuracy <= 0.02, "{rows:?}");
    // The old density rule ranks as well here; the plain nearest neighbour does not.
    assert!(m.nn_auroc < m.auroc, "{rows:?}");
}

#[test]
fn a_left_out_coarse_grit_is_unknown_and_the_finest_two_pass_for_each_other() {
    let rows = leave_one_class_out(&sim_source(Kind::Sandpaper, STATIC_CROP, false, 60)).unwrap();
    let row = |name: &str| rows.iter().find(|r| r.held_out == name).unwrap();
    // Measured (experiment open-set, seeds 1-3): AUROC 0.993-1.000, left out 90-100% unknown.
    for t in ["aluminum", "sandpaper_100", "sandpaper_60"] {
        assert!(row(t).auroc >= 0.95, "{t}: {rows:?}");
        assert!(row(t).unknown_held_out >= 0.85, "{t}: {rows:?}");
    }
    // Since the simulated sandpaper lies on a cloth backing, 220 and 150 grit differ
    // only in texture at one or two sensels: even the plain nearest neighbour ranks a left-out
    // one barely above known images (AUROC 0.56-0.68 measured), the ceiling of a distance here.
    for t in ["sandpaper_220", "sandpaper_150"] {
        assert!(row(t).nn_auroc < 0.75, "{t}: {rows:?}");
    }
    // Measured: fresh known 0.8-2.7% unknown (4.2-5.8% before the calibration run's images
    // were references), accuracy 0.7-1.0 points below that without rejection.
    let m = means(&rows);
    assert!(m.unknown_known <= 0.035, "{rows:?}");
    assert!(m.known_accuracy_open - m.known_accuracy <= 0.02, "{rows:?}");
}

#[test]
fn dynamic_stances_tell_clay_and_grass_but_not_wood_from_carpet() {
    let crop = Crop {
        top: 0,
        bottom: 3,
        left: 6,
        right: 0,
    };
    let rows = leave_one_class_out(&sim_source(Kind::Dynamic, crop, true, 60)).unwrap();
    let row = |name: &str| rows.iter().find(|r| r.held_out == name).unwrap();
    // Clay and grass left out: separable, and found.
    for t in ["clay", "grass"] {
        assert!(row(t).auroc >= 0.95, "{t}: {rows:?}");
        assert!(row(t).unknown_held_out >= 0.9, "{t}: {rows:?}");
    }
    // Wood and carpet pass for each other on the simulator: even the plain nearest neighbour
    // ranks a left-out wood stance below known ones (AUROC 0.24-0.30 measured), the ceiling
    // that no distance in this feature space beats.
    assert!(row("wood").nn_auroc < 0.5, "{rows:?}");
    // Carpet the plain nearest neighbour misses too (0.33 over seeds 1-10) but our score ranks
    // (0.97): separable, so it counts. The targets where they apply (`experiment open-set
    // --seeds 10`, the last table): over carpet, clay and grass, AUROC 0.986 and left out 98.2%
    // called unknown on average; on this seed carpet 46.7%, the three 82.2%.
    let separable: Vec<&OpenSetRow> = rows.iter().filter(|r| r.held_out != "wood").collect();
    let mean = |f: fn(&OpenSetRow) -> f64| {
        separable.iter().map(|r| f(r)).sum::<f64>() / separable.len() as f64
    };
    assert!(row("carpet").auroc >= 0.9, "{rows:?}");
    assert!(mean(|r| r.auroc) >= 0.95, "{rows:?}");
    assert!(mean(|r| r.unknown_held_out) >= 0.75, "{rows:?}");
    let m = means(&rows);
    // Measured (seeds 1-10): fresh known 0-8.3% unknown, median 4.2% (3.6-11.1% on seeds 1-3
    // before the calibration run's images were references; the dynamic runs are 10 stances
    // per gait and terrain: the widest spread of any source).
    assert!(m.unknown_known <= 0.1, "{rows:?}");
    // Most of them are stances the model took for another terrain (grass for clay), where
    // unknown costs no accuracy and spares the robot that terrain's gait: the cost, stances it
    // had right and called unknown, is the accuracy gap (seed 1: 2.5% unknown, 0.3 points;
    // seeds 1-10: 0-5 points, median 0.65).
    assert!(m.unknown_known_misclassified <= m.unknown_known, "{rows:?}");
    assert!(m.unknown_known_misclassified >= 0.01, "{rows:?}");
    assert!(m.known_accuracy_open - m.known_accuracy <= 0.02, "{rows:?}");
}

/// The texture check (`train --check-texture`, opt-in): on the simulator it finds the left-out
/// classes that no distance in the feature space separates (the hopping stances' wood, 220 and
/// 150 grit) at the cost of no more known images it had right; on the real maps (below) it
/// changes nothing.
#[test]
fn the_texture_check_finds_what_no_distance_does_on_the_simulator() {
    let dynamic = Crop {
        top: 0,
        bottom: 3,
        left: 6,
        right: 0,
    };
    for (kind, crop, normalize_load, found) in [
        (Kind::Dynamic, dynamic, true, &["wood"][..]),
        (
            Kind::Sandpaper,
            STATIC_CROP,
            false,
            &["sandpaper_220", "sandpaper_150"][..],
        ),
    ] {
        let mut src = sim_source(kind, crop, normalize_load, 60);
        let plain = means(&leave_one_class_out(&src).unwrap());
        src.opts.check_texture = true;
        let rows = leave_one_class_out(&src).unwrap();
        // Measured (experiment open-set --check-texture, seeds 1-10): each left-out class of
        // both sources 100% unknown on every seed but 220 grit, 83-100% (mean 97.0%), and 150
        // grit, 90-100% (98.3%); without it wood 0-37%, 220 grit 0-20%, 150 grit 0-3%. The
        // accuracy gap 0.7 and 1.4 points on average, 0.1 more than without.
        for t in found {
            let r = rows.iter().find(|r| r.held_out == *t).unwrap();
            assert!(r.unknown_held_out >= 0.9, "{t}: {rows:?}");
        }
        let m = means(&rows);
        assert!(m.unknown_held_out >= 0.95, "{kind:?}: {rows:?}");
        assert!(
            m.known_accuracy_open - m.known_accuracy <= 0.02,
            "{kind:?}: {rows:?}"
        );
        // The check only adds rejections: never fewer unknowns than without it.
        assert!(m.unknown_known >= plain.unknown_known, "{kind:?}");
        assert!(m.unknown_held_out >= plain.unknown_held_out, "{kind:?}");
    }
}

/// The real pressure maps: 10 subjects, runs = blocks of later trials.
#[cfg(feature = "interop")]
#[test]
fn speedpp2d_a_left_out_subject_is_unknown_more_often_than_not_and_known_ones_rarely() {
    let dir = std::env::temp_dir().join(format!("presrs-pp2d-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    common::jiku_script("speedpp2d.py", &[], &dir);
    let catalog = protocol::TerrainCatalog::load(Some(&dir.join("terrains.toml"))).unwrap();
    let (set, bad) = TrainingSet::load(&dir, &catalog, false).unwrap();
    assert!(bad.is_empty());
    assert_eq!(set.images.len(), 600);
    assert_eq!(set.classes.len(), 10);
    assert_eq!(set.run_names().len(), 3);
    // Load-normalised, as `experiment --normalize-load` and `train --normalize-load`: the three
    // walking speeds load the foot differently, and a person is in the shape, not the load.
    let opts = TrainOptions {
        normalize_load: true,
        ..Default::default()
    };
    let mut src = OpenSetSource::from_runs("pp2d".into(), &set, opts);
    assert!(src.calibration.is_some() && src.fresh.is_some());
    let rows = leave_one_class_out(&src).unwrap();
    let m = means(&rows);
    // The texture check: people differ in shape, not in roughness. Measured (seeds 1-10):
    // every figure the same with it as without; asserted here on three subjects left out, the
    // choice fixed (all ten cost two minutes of the test command).
    let plain = Candidate {
        normalize_load: true,
        ..Candidate::PLAIN
    };
    let some_out = |src: &OpenSetSource| -> Vec<OpenSetRow> {
        [0, 4, 8]
            .iter()
            .map(|&k| leave_class_out(src, k).unwrap())
            .collect()
    };
    src.opts.unknown_checks = UnknownChecks::Fixed(plain);
    let without = some_out(&src);
    src.opts.unknown_checks = UnknownChecks::Fixed(Candidate {
        texture: true,
        ..plain
    });
    for (a, b) in without.iter().zip(&some_out(&src)) {
        assert_eq!(
            (a.unknown_held_out, a.unknown_known, a.known_accuracy),
            (b.unknown_held_out, b.unknown_known, b.known_accuracy),
            "{}",
            a.held_out
        );
    }
    // Measured (seeds 1-3): AUROC 0.986-0.987 (the plain nearest neighbour 0.961-0.980, the old
    // density 0.770-0.835), left out 83-89% unknown, fresh known 1.9-3.1% unknown, accuracy
    // 1.4-2.0 points below that without rejection. Before the calibration run's images were
    // references: AUROC 0.980-0.983, left out 87-93%, fresh known 2.7-4.4%, 2.7-3.1 points.
    // Without load normalisation: AUROC 0.915-0.936, left out 55-63% unknown.
    // With the checks `train` chooses (seed 1): AUROC 0.989 against 0.986 for the
    // plain load-normalised model above, left out 88.7% against 82.7%, fresh known 3.6%
    // against 1.9%: more new ground found for more known ground called unknown, within the
    // issue's 5%.
    let w = means(&without);
    let chosen = means(&[0, 4, 8].map(|k| rows[k].clone()));
    assert!(m.auroc >= 0.97, "{rows:?}");
    assert!(
        chosen.auroc >= w.auroc - 0.005,
        "chosen {} plain {} (subjects 0, 4, 8 left out)",
        chosen.auroc,
        w.auroc
    );
    assert!(m.auroc >= m.nn_auroc, "{rows:?}");
    assert!(m.auroc > m.density_auroc + 0.1, "{rows:?}");
    assert!(m.unknown_held_out >= 0.8, "{rows:?}");
    assert!(m.unknown_known <= 0.05, "{rows:?}");
    assert!(m.known_accuracy_open - m.known_accuracy <= 0.04, "{rows:?}");
    // `presrs train` on the same folder holds out a run for calibration and says so, and
    // `classify --json` gives every image's novelty and threshold.
    let model = dir.join("model.json");
    let stdout = |o: std::process::Output| String::from_utf8_lossy(&o.stdout).to_string();
    let out = stdout(common::output_ok(
        std::process::Command::new(env!("CARGO_BIN_EXE_presrs"))
            .args(["train", "--data"])
            .arg(&dir)
            .arg("--out")
            .arg(&model)
            .arg("--normalize-load")
            .arg("--terrains")
            .arg(dir.join("terrains.toml")),
    ));
    assert!(
        out.contains("held-out runs") && out.contains("trials15-19"),
        "{out}"
    );
    let out = stdout(common::output_ok(
        std::process::Command::new(env!("CARGO_BIN_EXE_presrs"))
            .args(["lab", "classify", "--json", "--model"])
            .arg(&model)
            .arg("--terrains")
            .arg(dir.join("terrains.toml"))
            .arg(dir.join("subj03/speed2_trial17.pgm")),
    ));
    let v: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
    assert!(v["novelty"].as_f64().unwrap() > 0.0 && v["threshold"].as_f64().unwrap() > 0.0);
    assert_eq!(v["best"], "subj03");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A gait the model never saw is known ground: trained and calibrated on two of the paper's
/// gaits (sensors 1 and 2), the third gait's stances on a fresh sensor are called unknown no
/// more often than a fresh run of the trained gaits. What a lab that adds a gait after
/// training meets; the load normalisation is what makes it hold (the load at 70 ms differs
/// between gaits, see docs/results.md, Table 5).
#[test]
fn a_gait_the_model_never_saw_is_not_unknown_ground() {
    use controller::Gait;
    let crop = Crop {
        top: 0,
        bottom: 3,
        left: 6,
        right: 0,
    };
    let run = |gaits: &[Gait], sensor: u64, n: usize| {
        gait_run(Kind::Dynamic, gaits, n, 70 + 10 * sensor, sensor)
    };
    // (trained gaits, the unseen one): between the two, and beyond the faster one.
    for (trained, unseen) in [
        ([Gait::g1(), Gait::g3()], Gait::g2()),
        ([Gait::g1(), Gait::g2()], Gait::g3()),
    ] {
        let opts = TrainOptions {
            crop: crop.into(),
            normalize_load: true,
            per_class: 60,
            train: 40,
            ..Default::default()
        };
        let cal = run(&trained, 2, 40);
        let names = ["sensor 2".to_string()];
        let model = run(&trained, 1, 60)
            .train_calibrated(&opts, Some((&cal, &names)))
            .unwrap()
            .model;
        let (own_unknown, own_right) = judge(&model, &run(&trained, 3, 30));
        let (new_unknown, new_right) = judge(&model, &run(std::slice::from_ref(&unseen), 3, 60));
        eprintln!(
            "unseen G{}: unknown {new_unknown:.3} right {new_right:.3}; trained gaits' fresh run: \
             unknown {own_unknown:.3} right {own_right:.3}",
            unseen.id
        );
        // Measured: G2 unseen 3.3% unknown, 96.7% right; G3 unseen 4.2%, 95.8% (the trained
        // gaits' fresh runs 2.5% unknown, 97.5% right). Without load normalisation the unseen
        // G2 was 6.7% unknown (its trained gaits' fresh run 2.9%). With the CLI on other seeds
        // (scripts/unseen_gait.sh, seeds 1-3): unseen G2 0.4-2.5%, G3 2.9-3.8%, G1 0-2.5%,
        // against 0.2-3.8% on the trained gaits' fresh runs; without load normalisation
        // unseen G2 5.8-16.2%.
        // With the checks `train` chooses: unseen G2 4.6%, G3 7.1% unknown, the
        // trained gaits' fresh runs 5.0%: the choice keeps more new ground found for more
        // known ground called unknown (the bound for a fresh run: 5%); the unseen gait
        // stays within 3 points of the gaits the model was trained in.
        assert!(own_unknown <= 0.05, "{own_unknown}");
        assert!(
            new_unknown <= own_unknown + 0.03,
            "{new_unknown} {own_unknown}"
        );
        assert!(new_right >= 0.9, "{new_right}");
    }
}

/// A walking speed the model never saw, on the real maps (runs = speed and block of trials):
/// trained and calibrated on two speeds, the speed between them is known ground; a speed
/// beyond them is not, and the model says unknown rather than naming another person. The
/// simulator's gaits were kinder (`a_gait_the_model_never_saw_is_not_unknown_ground`).
#[cfg(feature = "interop")]
#[test]
fn speedpp2d_a_speed_between_the_trained_ones_is_known_and_one_beyond_is_often_unknown() {
    let dir = std::env::temp_dir().join(format!("presrs-pp2d-speeds-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    common::jiku_script("speedpp2d.py", &["--runs", "speed-blocks"], &dir);
    let catalog = protocol::TerrainCatalog::load(Some(&dir.join("terrains.toml"))).unwrap();
    let (set, bad) = TrainingSet::load(&dir, &catalog, false).unwrap();
    assert!(bad.is_empty());
    // The images of `speeds` whose run ends with `block` ("" for every block).
    let pick = |speeds: &[u8], block: &str| {
        let keep: Vec<usize> = (0..set.images.len())
            .filter(|&i| {
                let run = set.runs[i].as_deref().unwrap_or("");
                speeds
                    .iter()
                    .any(|s| run.starts_with(&format!("speed{s}/")))
                    && run.ends_with(block)
            })
            .collect();
        set.subset(&keep)
    };
    let opts = TrainOptions {
        normalize_load: true,
        // 20 images per person in the training block: 6 left out for the calibration.
        per_class: 14,
        train: 9,
        ..Default::default()
    };
    let mut seen = Vec::new();
    for (trained, unseen) in [([1, 3], 2), ([1, 2], 3)] {
        let cal = pick(&trained, "trials10-14");
        let names = cal.run_names();
        let model = pick(&trained, "trials00-09")
            .train_calibrated(&opts, Some((&cal, &names)))
            .unwrap()
            .model;
        let (own_unknown, own_right) = judge(&model, &pick(&trained, "trials15-19"));
        let (new_unknown, new_right) = judge(&model, &pick(&[unseen], ""));
        eprintln!(
            "speeds {trained:?}, their fresh trials: unknown {own_unknown:.3} right \
             {own_right:.3}; unseen speed {unseen}: unknown {new_unknown:.3} right \
             {new_right:.3}"
        );
        seen.push((new_unknown, new_right));
    }
    // Measured: between, 2.5% of speed 2 unknown, 97.5% right (trials 15-19 of speeds 1
    // and 3: 4.0% / 95.0%); beyond, 34.5% of speed 3 unknown, 65.5% right, none taken for
    // another person. (With `presrs train --calibrate` and `eval` on the same folders, the
    // same figures; trained on speeds 2 and 3, speed 1: 19.5% unknown, 2% another person.
    // Without load normalisation: between 4.5%, faster 83.0% unknown.)
    let ((between_unknown, between_right), (beyond_unknown, beyond_right)) = (seen[0], seen[1]);
    assert!(between_unknown <= 0.06, "{seen:?}");
    assert!(between_right >= 0.9, "{seen:?}");
    assert!(beyond_unknown >= 0.2, "{seen:?}");
    // What is not unknown beyond is still mostly right: the model does not name another
    // person for a speed it never saw.
    assert!(1.0 - beyond_unknown - beyond_right <= 0.05, "{seen:?}");
    let _ = std::fs::remove_dir_all(&dir);
}
