//! Training and classification end to end on synthetic textures (three surfaces that differ in
//! their spatial statistics, as the paper's terrains do), and the model file's guards.

use presrs_node::classifier::model::{MODEL_VERSION, ModelError};
use presrs_node::classifier::train::{Labelled, TrainOptions, train};
use presrs_node::classifier::{ClassInfo, Classifier, Crop, Kernels, Model, PressureImage, repair};
use presrs_node::unknown::novelty::{HELD_OUT_RATE_FACTOR, NUISANCE_DIRECTIONS, Novelty};
use rand::SeedableRng;

mod common;
use common::texture;

fn dataset(seed: u64, n: usize) -> (Vec<PressureImage>, Vec<usize>) {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let kinds = [(4, 0.5), (7, 0.5), (11, 0.35)];
    let mut imgs = Vec::new();
    let mut labels = Vec::new();
    for (k, &(p, f)) in kinds.iter().enumerate() {
        for _ in 0..n {
            imgs.push(texture(&mut rng, p, f));
            labels.push(k);
        }
    }
    (imgs, labels)
}

fn labelled<'a>(imgs: &'a [PressureImage], labels: &[usize]) -> Vec<Labelled<'a>> {
    imgs.iter()
        .zip(labels)
        .map(|(image, &class)| Labelled::new(image, class))
        .collect()
}

fn classes() -> Vec<ClassInfo> {
    ["wood", "carpet", "grass"]
        .iter()
        .map(|n| ClassInfo {
            name: n.to_string(),
            terrain_id: protocol::TerrainCatalog::paper().by_name(n).unwrap().id(),
        })
        .collect()
}

fn trained() -> (Model, Vec<PressureImage>, Vec<usize>, Vec<usize>) {
    let (imgs, labels) = dataset(1, 40);
    let data = labelled(&imgs, &labels);
    let opts = TrainOptions {
        crop: "2,2,2,2".parse::<Crop>().unwrap().into(),
        ..TrainOptions::default()
    };
    let (model, split) = train(&data, &classes(), &opts).unwrap();
    (model, imgs, labels, split.test)
}

#[test]
fn trains_with_the_paper_split_and_classifies_held_out_images() {
    let (model, imgs, labels, test) = trained();
    assert_eq!(
        model.n_samples(),
        60,
        "20 per class stored (13 train + 7 validation)"
    );
    assert_eq!(model.train_hashes.len(), 39);
    assert_eq!(model.val_hashes.len(), 21);
    assert_eq!(model.n_fft, 2048);
    assert!(model.h <= 52 && model.h >= 50, "h = {}", model.h);
    assert_eq!(model.unknown.rate, 0.02);
    let mut c = Classifier::new(model);
    let (mut correct, mut unknown) = (0, 0);
    for &i in &test {
        let d = c.classify(&imgs[i].pixels, 44, 44, false).unwrap();
        unknown += d.class.is_none() as usize;
        correct += (d.best == labels[i]) as usize;
        assert!(d.contact);
        let p: f64 = c.log_posteriors().iter().map(|lp| lp.exp()).sum();
        assert!((p - 1.0).abs() < 1e-9);
    }
    let acc = correct as f64 / test.len() as f64;
    assert!(acc >= 0.95, "held-out accuracy {acc}");
    // Calibrated to call 2% of held-out training images unknown: a few known test images are.
    assert!(
        unknown * 10 <= test.len(),
        "{unknown} of {} known test images called unknown",
        test.len()
    );
}

/// A model trained on two textures calls the third unknown, nearly always, and
/// few of the known ones; `--unknown-rate 0` (each class's least typical image less 10 nats)
/// calls no known image unknown and less of the novel one.
#[test]
fn a_texture_the_model_never_saw_is_unknown() {
    let (imgs, labels) = dataset(3, 40);
    let known: Vec<Labelled> = imgs
        .iter()
        .zip(&labels)
        .filter(|(_, l)| **l < 2)
        .map(|(image, &class)| Labelled::new(image, class))
        .collect();
    let novel: Vec<&PressureImage> = imgs
        .iter()
        .zip(&labels)
        .filter(|(_, l)| **l == 2)
        .map(|(i, _)| i)
        .collect();
    let shares = |rate: f64| {
        let opts = TrainOptions {
            crop: "2,2,2,2".parse::<Crop>().unwrap().into(),
            unknown_rate: rate,
            ..TrainOptions::default()
        };
        let (model, split) = train(&known, &classes()[..2], &opts).unwrap();
        let thresholds = model.unknown.density_thresholds.clone();
        assert_eq!(thresholds.len(), 2);
        assert!(thresholds.iter().all(|t| t.is_finite()));
        let mut c = Classifier::new(model);
        let mut unknown = |img: &PressureImage| {
            c.classify(&img.pixels, 44, 44, false)
                .unwrap()
                .class
                .is_none() as usize
        };
        let k: usize = split.test.iter().map(|&i| unknown(known[i].image)).sum();
        let n: usize = novel.iter().map(|i| unknown(i)).sum();
        (
            k as f64 / split.test.len() as f64,
            n as f64 / novel.len() as f64,
        )
    };
    let (known_unknown, novel_unknown) = shares(0.02);
    assert!(
        novel_unknown >= 0.9,
        "only {novel_unknown} of the novel texture unknown"
    );
    assert!(
        known_unknown <= 0.1,
        "{known_unknown} of the known textures unknown"
    );
    let (known_unknown, novel_unknown_0) = shares(0.0);
    assert_eq!(known_unknown, 0.0);
    assert!(
        novel_unknown_0 < novel_unknown,
        "{novel_unknown_0} >= {novel_unknown}"
    );
}

#[test]
fn portable_kernels_decide_as_the_native_ones() {
    // What an ARM computer runs against what this CPU runs fastest (AVX2/FMA/F16C on most
    // x86-64): the same class for every image, and densities that differ only by rounding.
    let (model, imgs, ..) = trained();
    let mut native = Classifier::new(model.clone());
    let mut portable = Classifier::with_kernels(model, Kernels::Portable);
    assert_eq!(portable.kernels(), Kernels::Portable);
    eprintln!(
        "native kernels: {}, portable: {}",
        Kernels::Native.describe(),
        Kernels::Portable.describe()
    );
    for (i, img) in imgs.iter().enumerate() {
        for repair in [false, true] {
            let a = native.classify(&img.pixels, 44, 44, repair).unwrap();
            let b = portable.classify(&img.pixels, 44, 44, repair).unwrap();
            assert_eq!((a.best, a.class), (b.best, b.class), "image {i}");
            let tol = 1e-3 * a.log_density.abs().max(1.0);
            assert!(
                (a.log_density - b.log_density).abs() <= tol,
                "image {i}: log density {} vs {}",
                a.log_density,
                b.log_density
            );
        }
    }
}

#[test]
fn something_unlike_any_terrain_is_unknown() {
    let (model, ..) = trained();
    let mut c = Classifier::new(model);
    let stripes: Vec<u16> = (0..44 * 44)
        .map(|i| if (i / 44) % 2 == 0 { 255 } else { 0 })
        .collect();
    let d = c.classify(&stripes, 44, 44, false).unwrap();
    assert_eq!(d.class, None);
    assert_eq!(d.terrain_id, 0xFF);
    assert!(c.classify(&stripes, 40, 40, false).is_err());
}

/// A blank frame, a few noisy pixels or a stuck line is no foot on the ground: never a terrain
/// (a blank frame used to come out as one class at confidence 1.0).
#[test]
fn an_image_without_contact_is_never_a_terrain() {
    let (model, imgs, ..) = trained();
    let min = model
        .contact
        .expect("a trained model carries its contact figures");
    assert!(min.load > 0 && min.area > 0, "{min:?}");
    let mut c = Classifier::new(model);
    let mut noisy = vec![0u16; 44 * 44];
    for i in (0..44 * 44).step_by(97) {
        noisy[i] = 12;
    }
    let mut stuck = vec![0u16; 44 * 44];
    stuck[20 * 44..21 * 44].fill(255);
    for (what, px) in [
        ("blank", vec![0u16; 44 * 44]),
        ("noise", noisy),
        ("stuck row", stuck),
    ] {
        let d = c.classify(&px, 44, 44, false).unwrap();
        assert!(!d.contact, "{what}");
        assert_eq!(
            (d.class, d.terrain_id, d.confidence),
            (None, 0xFF, 0.0),
            "{what}"
        );
    }
    // The same press as a 16-bit image: refused, not read on the 8-bit scale.
    let deep = PressureImage::new(44, 44, 16, imgs[0].pixels.clone());
    let e = c.classify_image(&deep, false).unwrap_err().to_string();
    assert!(
        e.contains("16-bit image") && e.contains("8-bit images"),
        "{e}"
    );
    assert!(c.classify_image(&imgs[0], false).is_ok());
    // A real press at a third of its load still is one.
    let light: Vec<u16> = imgs[0].pixels.iter().map(|&p| p / 3).collect();
    assert!(c.classify(&light, 44, 44, false).unwrap().contact);
}

/// A lab with more terrains than the paper's twelve: 20 classes (the limit is the catalog's
/// 255 ids), each decided right, and the per-class buffers sized by the model.
#[test]
fn a_model_holds_more_than_sixteen_classes() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(5);
    let (mut imgs, mut labels) = (Vec::new(), Vec::new());
    for k in 0..20usize {
        for _ in 0..12 {
            // Twenty textures: patch period 3..=22.
            imgs.push(texture(&mut rng, 3 + k, 0.5));
            labels.push(k);
        }
    }
    let data = labelled(&imgs, &labels);
    let classes: Vec<ClassInfo> = (0..20)
        .map(|k| ClassInfo {
            name: format!("lab_{k}"),
            terrain_id: 100 + k as u8,
        })
        .collect();
    let o = TrainOptions {
        per_class: 10,
        train: 6,
        ..TrainOptions::default()
    };
    let (model, split) = train(&data, &classes, &o).unwrap();
    assert_eq!(model.classes.len(), 20);
    let mut c = Classifier::new(model);
    let right = split
        .test
        .iter()
        .filter(|&&i| c.classify(&imgs[i].pixels, 44, 44, false).unwrap().best == labels[i])
        .count();
    assert_eq!(c.log_posteriors().len(), 20);
    assert!(
        right * 10 >= split.test.len() * 8,
        "{right}/{}",
        split.test.len()
    );
}

#[test]
fn repair_recovers_accuracy_on_damaged_images() {
    let (model, imgs, labels, test) = trained();
    let mut c = Classifier::new(model);
    let mut rng = rand::rngs::StdRng::seed_from_u64(9);
    let pct = 60.0;
    let (mut raw, mut fixed) = (0, 0);
    for &i in &test {
        let mut img = imgs[i].clone();
        repair::damage(&mut img, pct, &mut rng);
        raw += (c.classify(&img.pixels, 44, 44, false).unwrap().best == labels[i]) as usize;
        fixed += (c.classify(&img.pixels, 44, 44, true).unwrap().best == labels[i]) as usize;
    }
    eprintln!("damage {pct}: raw {raw} repaired {fixed}");
    assert!(
        fixed as f64 >= 0.9 * test.len() as f64 && raw < fixed,
        "repair did not help: {fixed} vs {raw} of {}",
        test.len()
    );
}

#[test]
fn model_file_round_trips_and_guards_its_version() {
    let (model, imgs, ..) = trained();
    let dir = std::env::temp_dir().join(format!("presrs-model-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("m.json");
    model.save(&path).unwrap();
    let back = Model::load(&path).unwrap();
    let (mut a, mut b) = (Classifier::new(model.clone()), Classifier::new(back));
    let da = a.classify(&imgs[0].pixels, 44, 44, false).unwrap();
    let db = b.classify(&imgs[0].pixels, 44, 44, false).unwrap();
    assert_eq!(da, db);

    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    v["version"] = (MODEL_VERSION + 1).into();
    let e = Model::from_json(&v.to_string(), "old.json").unwrap_err();
    assert!(matches!(e, ModelError::Version { .. }));
    assert!(
        e.to_string().contains("old.json") && e.to_string().contains("presrs train"),
        "{e}"
    );

    v["version"] = MODEL_VERSION.into();
    // Every field that could disable the model silently is refused, naming it.
    for (key, bad) in [
        ("h", serde_json::json!(3)),
        ("downsample", serde_json::json!(0)),
        ("normalize_load", serde_json::json!(0.0)),
        ("input_rows", serde_json::json!(65)),
        ("kernel_width", serde_json::json!(-1.0)),
        ("bits", serde_json::json!(12)),
    ] {
        let mut w = v.clone();
        w[key] = bad;
        let e = Model::from_json(&w.to_string(), "m.json").unwrap_err();
        assert!(
            matches!(e, ModelError::Invalid { .. } | ModelError::Parse { .. }),
            "{key}: {e}"
        );
        assert!(e.to_string().contains(key), "{key}: {e}");
    }
    let mut nan = model.clone();
    nan.unknown.density_thresholds[0] = f64::NAN;
    assert!(
        nan.validate()
            .unwrap_err()
            .to_string()
            .contains("unknown.density_thresholds")
    );
    let mut w = v.clone();
    w["classes"][0]["terrain_id"] = 255.into();
    let e = Model::from_json(&w.to_string(), "m.json")
        .unwrap_err()
        .to_string();
    assert!(e.contains("terrain id 255"), "{e}");
    let e = Model::from_json(
        &{
            let mut w = v.clone();
            w["h"] = 3.into();
            w
        }
        .to_string(),
        "m.json",
    )
    .unwrap_err();
    assert!(matches!(e, ModelError::Invalid { .. }), "{e}");
    assert!(matches!(
        Model::from_json("{not json", "x").unwrap_err(),
        ModelError::Parse { .. }
    ));
    assert!(matches!(
        Model::load(&dir.join("missing.json")).unwrap_err(),
        ModelError::Io { .. }
    ));
}

#[test]
fn training_rejects_bad_requests() {
    let (imgs, labels) = dataset(2, 10);
    let data = labelled(&imgs, &labels);
    let e = train(&data, &classes(), &TrainOptions::default()).unwrap_err();
    assert!(e.to_string().contains("has 10 images"), "{e}");
    let o = TrainOptions {
        per_class: 10,
        train: 10,
        ..TrainOptions::default()
    };
    assert!(train(&data, &classes(), &o).is_err());
    // A valid split, so that the one option changed is what is refused.
    let split = TrainOptions {
        per_class: 10,
        train: 6,
        ..TrainOptions::default()
    };
    let refusal = |o: TrainOptions| train(&data, &classes(), &o).unwrap_err().to_string();
    // A downsampling of 0 would disable the model silently: refused in training and in a file.
    let e = refusal(TrainOptions {
        downsample: 0,
        ..split.clone()
    });
    assert!(
        e.contains("--downsample 0") && e.contains("1 (full resolution) to 8"),
        "{e}"
    );
    // An unknown rate the model file could not load with: refused before training.
    let e = refusal(TrainOptions {
        unknown_rate: 0.9,
        ..split
    });
    assert!(
        e.contains("--unknown-rate 0.9") && e.contains("0 to 0.5"),
        "{e}"
    );
    let (mut model, ..) = trained();
    model.downsample = 0;
    let json = serde_json::to_string(&model).unwrap();
    let e = Model::from_json(&json, "m.json").unwrap_err().to_string();
    assert!(
        e.contains("m.json") && e.contains("downsample") && e.contains("1..=8"),
        "{e}"
    );
}

/// The novelty's parts as the classifier computes them (its SIMD kernels, half-precision PCA)
/// against a plain f64 computation from the model file: the residual outside the PCA subspace
/// and the mean distance to the best class's three nearest stored samples.
#[test]
fn novelty_parts_match_a_direct_computation() {
    use presrs_node::classifier::features::FeatureExtractor;
    let (model, imgs, ..) = trained();
    let nv = model
        .unknown
        .novelty
        .clone()
        .expect("a model trained with a rate has a novelty score");
    assert_eq!(nv.k, 3);
    let (h, n) = (model.h, model.feature_len());
    let crop: Crop = "2,2,2,2".parse().unwrap();
    let mut fx = FeatureExtractor::new(40 * 40);
    for kernels in [Kernels::Native, Kernels::Portable] {
        let mut c = Classifier::with_kernels(model.clone(), kernels);
        for img in imgs.iter().step_by(7) {
            let d = c.classify(&img.pixels, 44, 44, false).unwrap();
            let (knn, res) = c.novelty_parts();
            let work = img.crop(&crop).unwrap().pixels;
            let f = fx.features(&work, 1.0);
            let cen: Vec<f64> = f
                .iter()
                .zip(&model.pca_mean)
                .map(|(a, b)| (*a - *b) as f64)
                .collect();
            let q: Vec<f64> = (0..h)
                .map(|j| {
                    (0..n)
                        .map(|k| model.pca_matrix[j * n + k] as f64 * cen[k])
                        .sum()
                })
                .collect();
            let c2: f64 = cen.iter().map(|v| v * v).sum();
            let q2: f64 = q.iter().map(|v| v * v).sum();
            let want_res = (c2 - q2).max(0.0).sqrt();
            let mut dist: Vec<f64> = (0..model.n_samples())
                .filter(|&i| model.sample_classes[i] == d.best)
                .map(|i| {
                    (0..h)
                        .map(|j| (model.samples[i * h + j] as f64 - q[j]).powi(2))
                        .sum::<f64>()
                        .sqrt()
                })
                .collect();
            dist.sort_by(f64::total_cmp);
            let want_knn = dist[..3].iter().sum::<f64>() / 3.0;
            // Against the f32 weights' subspace: the half-precision rows span one turned by
            // about 5e-4 rad (pwe.rs's half_matrix), which moves the residual by less than that
            // share of |F - mean|.
            assert!(
                (res - want_res).abs() <= 0.01 * want_res + 5e-4 * c2.sqrt(),
                "{kernels:?}: residual {res} vs {want_res}"
            );
            assert!(
                (knn - want_knn).abs() <= 1e-3 * want_knn.max(1.0),
                "{kernels:?}: kNN {knn} vs {want_knn}"
            );
            let want = nv.score_of(d.best, knn, res);
            assert_eq!(d.novelty, want);
            assert_eq!(d.threshold, nv.thresholds[d.best]);
            assert_eq!(d.class.is_none(), d.novelty > d.threshold);
        }
    }
}

/// A model file written before the novelty score loads and decides as it did: by the density
/// and its per-class thresholds, the novelty being the negated log density.
#[test]
fn a_model_without_a_novelty_score_decides_by_density_as_before() {
    let (mut model, imgs, ..) = trained();
    model.unknown.novelty = None;
    let text = serde_json::to_string(&model).unwrap();
    assert!(!text.contains("novelty"));
    let model = Model::from_json(&text, "old.json").unwrap();
    let t = model.unknown.density_thresholds.clone();
    let mut c = Classifier::new(model);
    for img in &imgs {
        let d = c.classify(&img.pixels, 44, 44, false).unwrap();
        assert_eq!(d.novelty, -d.log_density);
        assert_eq!(d.threshold, -t[d.best]);
        assert_eq!(d.class.is_none(), d.log_density < t[d.best]);
        assert!(c.novelty_parts().0.is_nan());
    }
}

/// `model` calibrated on another run of the same three textures (`n` images each, made with
/// `seed`, named `name`): the run's images and the calibration's check.
fn calibrate_on_another_run(
    model: &mut Model,
    seed: u64,
    n: usize,
    name: &str,
) -> (Vec<PressureImage>, f64) {
    let (imgs, labels) = dataset(seed, n);
    let names = ["wood", "carpet", "grass"];
    let run: Vec<(&PressureImage, &str)> = imgs
        .iter()
        .zip(&labels)
        .map(|(i, &k)| (i, names[k]))
        .collect();
    let check =
        presrs_node::classifier::train::calibrate_on_runs(model, &run, &[name.into()]).unwrap();
    (imgs, check)
}

/// Calibration on another run: the thresholds move to that run's images, the model says where
/// they came from, and bad runs are refused naming the run and the fix.
#[test]
fn calibration_on_another_run_and_its_bad_inputs() {
    use presrs_node::classifier::train::{CalibrateError, calibrate_on_runs};
    use presrs_node::unknown::novelty::CalibrationSource;
    let (mut model, ..) = trained();
    let same = model.unknown.novelty.clone().unwrap();
    // One session: calibrated in its own time blocks, at a margin chosen on its last quarter.
    assert_eq!(same.calibration.source, CalibrationSource::TimeBlocks);
    assert!(
        [1.5, 1.3, 1.15, 1.0].contains(&same.calibration.margin),
        "{}",
        same.calibration.margin
    );
    // Another run of the same three textures.
    let (imgs, check) = calibrate_on_another_run(&mut model, 9, 30, "run2.log");
    let nv = model.unknown.novelty.clone().unwrap();
    assert_eq!(nv.calibration.source, CalibrationSource::HeldOutRuns);
    assert_eq!(nv.calibration.runs, vec!["run2.log".to_string()]);
    assert_eq!(nv.calibration.margin, 1.0);
    // 90 images of the other run and up to 60 unused ones of the training run.
    assert!(nv.calibration.images >= 90, "{}", nv.calibration.images);
    assert!(check <= 0.05, "the check called {check} unknown");
    // The other run's images classified right are the kNN's references, and the residual
    // leaves out the directions they show; the thresholds are set at 1.5x the rate.
    assert_eq!(nv.calibration.held_out_images, 90);
    let n_ref = nv.reference_classes.len();
    assert!((80..=90).contains(&n_ref), "{n_ref} references");
    assert_eq!(nv.reference.len(), n_ref * model.h);
    let n_feat = model.pca_mean.len();
    assert_eq!(nv.nuisance.len(), NUISANCE_DIRECTIONS * n_feat);
    assert_eq!(nv.calibration.rate, 0.02 * HELD_OUT_RATE_FACTOR);
    // Unit rows, orthogonal to each other and to the PCA rows (to f32 rounding).
    let row = |m: &[f32], i: usize| m[i * n_feat..(i + 1) * n_feat].to_vec();
    let dot = |a: &[f32], b: &[f32]| {
        a.iter()
            .zip(b)
            .map(|(x, y)| *x as f64 * *y as f64)
            .sum::<f64>()
    };
    for i in 0..NUISANCE_DIRECTIONS {
        let v = row(&nv.nuisance, i);
        assert!((dot(&v, &v) - 1.0).abs() < 1e-4);
        for j in 0..model.h {
            assert!(dot(&v, &row(&model.pca_matrix, j)).abs() < 1e-3);
        }
        for j in 0..i {
            assert!(dot(&v, &row(&nv.nuisance, j)).abs() < 1e-4);
        }
    }
    // The references and nuisance directions make the held-out run's own images less novel
    // than they scored when the thresholds were set (where they were measured as new).
    let mut without = model.clone();
    if let Some(n) = without.unknown.novelty.as_mut() {
        n.reference.clear();
        n.reference_classes.clear();
        n.nuisance.clear();
    }
    let (mut with_c, mut without_c) = (Classifier::new(model.clone()), Classifier::new(without));
    let (mut lower, mut n) = (0, 0);
    for img in &imgs {
        let a = with_c
            .classify(&img.pixels, img.rows, img.cols, false)
            .unwrap();
        let b = without_c
            .classify(&img.pixels, img.rows, img.cols, false)
            .unwrap();
        n += 1;
        lower += (a.novelty < b.novelty) as usize;
        assert!(
            a.novelty <= b.novelty + 1e-9,
            "{} > {}",
            a.novelty,
            b.novelty
        );
    }
    assert!(lower * 10 >= n * 9, "{lower} of {n} lower");
    // The model with its calibration survives the file.
    let text = serde_json::to_string(&model).unwrap();
    assert_eq!(Model::from_json(&text, "m.json").unwrap(), model);
    // Bad runs: nothing, a terrain the model does not know, another sensor size.
    let e = calibrate_on_runs(&mut model.clone(), &[], &["empty/".into()]).unwrap_err();
    assert!(matches!(e, CalibrateError::Empty { .. }));
    assert!(e.to_string().contains("empty/") && e.to_string().contains("terrains the model knows"));
    let e = calibrate_on_runs(&mut model.clone(), &[(&imgs[0], "sand")], &["r3".into()])
        .unwrap_err()
        .to_string();
    assert!(e.contains("`sand`") && e.contains("r3"), "{e}");
    let small = PressureImage::new(40, 40, 8, vec![0; 1600]);
    let e = calibrate_on_runs(&mut model.clone(), &[(&small, "wood")], &["r4".into()])
        .unwrap_err()
        .to_string();
    assert!(e.contains("40x40") && e.contains("44x44"), "{e}");
    // A hand-edited novelty entry is refused by name.
    for edit in [
        (|n: &mut Novelty| {
            n.thresholds.pop();
        }) as fn(&mut Novelty),
        |n| {
            n.reference.pop();
        },
        |n| n.reference_classes[0] = 7,
        |n| {
            n.nuisance.pop();
        },
    ] {
        let mut bad = model.clone();
        edit(bad.unknown.novelty.as_mut().unwrap());
        let e = Model::from_json(&serde_json::to_string(&bad).unwrap(), "bad.json")
            .unwrap_err()
            .to_string();
        assert!(e.contains("novelty") && e.contains("bad.json"), "{e}");
    }
    // A file from before the references (no `reference`, `nuisance`, `held_out_images`) loads
    // and scores as it did.
    let mut old: serde_json::Value = serde_json::to_value(&model).unwrap();
    let o = old["unknown"]["novelty"].as_object_mut().unwrap();
    for key in ["reference", "reference_classes", "nuisance"] {
        assert!(o.remove(key).is_some());
    }
    o["calibration"]
        .as_object_mut()
        .unwrap()
        .remove("held_out_images");
    let old = Model::from_json(&old.to_string(), "old.json").unwrap();
    let nv = old.unknown.novelty.as_ref().unwrap();
    assert!(nv.reference.is_empty() && nv.nuisance.is_empty());
    assert_eq!(nv.calibration.held_out_images, 0);
}

/// The refit to dead sensor lines calibrates the novelty again on the same images with the same
/// lines dead, and keeps the undamaged ones for the next refit.
#[test]
fn a_refit_recalibrates_the_novelty() {
    use presrs_node::classifier::train::refit;
    let (model, ..) = trained();
    let mut dead_rows = vec![false; 40];
    let dead_cols = vec![false; 40];
    dead_rows[10] = true;
    dead_rows[25] = true;
    let m = refit(&model, &dead_rows, &dead_cols).unwrap();
    let (a, b) = (
        model.unknown.novelty.as_ref().unwrap(),
        m.unknown.novelty.as_ref().unwrap(),
    );
    assert_ne!(a.thresholds, b.thresholds);
    assert_eq!(a.calibration.pixels, b.calibration.pixels);
    assert_eq!(a.calibration.margin, b.calibration.margin);
    assert_eq!(m.images, model.images);
    assert!(b.calibration.called_unknown <= 0.1);
    // Calibrated on another run: the references and nuisance directions are found again in
    // the new PCA space.
    let mut model = model;
    calibrate_on_another_run(&mut model, 9, 20, "r2");
    let m = refit(&model, &dead_rows, &dead_cols).unwrap();
    let (a, b) = (
        model.unknown.novelty.as_ref().unwrap(),
        m.unknown.novelty.as_ref().unwrap(),
    );
    assert_eq!(b.calibration.held_out_images, 60);
    assert!(
        !b.reference_classes.is_empty() && b.reference.len() == b.reference_classes.len() * m.h
    );
    assert_eq!(b.nuisance.len(), a.nuisance.len());
    assert_ne!(a.reference, b.reference);
}

/// `check_texture`: per class a roughness band over the training images, held against each
/// image's best class; a refit to dead lines drops it; a file with a bad band is refused.
#[test]
fn the_texture_check_holds_each_image_to_its_best_classs_band() {
    use presrs_node::classifier::train::refit;
    let (imgs, labels) = dataset(1, 40);
    let data = labelled(&imgs, &labels);
    let opts = TrainOptions {
        crop: "2,2,2,2".parse::<Crop>().unwrap().into(),
        check_texture: true,
        ..TrainOptions::default()
    };
    let (model, split) = train(&data, &classes(), &opts).unwrap();
    let bands = model.unknown.texture_bands.clone().unwrap();
    assert_eq!(bands.len(), 3);
    assert!(
        bands.iter().all(|[lo, hi]| lo.is_finite() && lo < hi),
        "{bands:?}"
    );
    let known = |m: &Model| {
        let mut c = Classifier::new(m.clone());
        split
            .test
            .iter()
            .filter(|&&i| c.classify_image(&imgs[i], false).unwrap().class == Some(labels[i]))
            .count()
    };
    // Known images of the training textures pass their class's band as they passed without it.
    let mut without = model.clone();
    without.unknown.texture_bands = None;
    assert_eq!(known(&model), known(&without));
    assert!(known(&model) * 10 >= split.test.len() * 9);
    // A band no image reaches: every one unknown.
    let mut none_fit = model.clone();
    none_fit.unknown.texture_bands = Some(vec![[1e9, 2e9]; 3]);
    assert_eq!(known(&none_fit), 0);
    // A refit to dead lines goes without it (its bands were drawn on a whole sensor).
    let mut dead_rows = vec![false; 40];
    dead_rows[10] = true;
    assert!(
        refit(&model, &dead_rows, &[false; 40])
            .unwrap()
            .unknown
            .texture_bands
            .is_none()
    );
    // A file whose bands do not fit its classes is refused, naming the key and the file.
    for bad in [vec![[0.0, 1.0]; 2], vec![[1.0, 0.0]; 3]] {
        let mut m = model.clone();
        m.unknown.texture_bands = Some(bad);
        let e = Model::from_json(&serde_json::to_string(&m).unwrap(), "bad.json")
            .unwrap_err()
            .to_string();
        assert!(e.contains("texture_bands") && e.contains("bad.json"), "{e}");
    }
}

/// A model file of format version 1, written by `presrs train` before version 2 (the build at
/// 27d1bca: `presrs lab dataset static --n 16 --seed 3`, `presrs train --crop 2,2,2,2 --downsample 4
/// --per-class 10 --train 6`), loads and decides every image as that build did
/// (`decisions.jsonl` is its `presrs lab classify --json`): the same terrain, unknown where it was,
/// the same novelty and threshold.
#[test]
fn a_version_1_model_file_decides_as_the_build_that_wrote_it() {
    let unknown = decides_as_written("model-v1", 1);
    assert_eq!(unknown, [("novelty".to_string(), 4)].into());
}

/// A model file of format version 2 (every check in its own top-level key), written by the
/// format-2 build from the demo's runs: `presrs capture` of two 160-step demos (seeds 3 and 4,
/// `--candump --truth`), `presrs train --crop 0,3,6,0 --downsample 4 --unknown-checks
/// knn-residual,load,texture` (calibrated on the second run: references and nuisance
/// directions), `presrs lab energy` on both runs; the images are the second run's and a sand run's
/// stances. It loads into format 3's `unknown` section and decides every image as it did, its
/// energy maps kept.
#[test]
fn a_version_2_model_file_decides_as_the_build_that_wrote_it() {
    let unknown = decides_as_written("model-v2", 2);
    assert_eq!(unknown, [("load".to_string(), 1)].into());
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/model-v2");
    let text = std::fs::read_to_string(dir.join("model.json")).unwrap();
    let v2: serde_json::Value = serde_json::from_str(&text).unwrap();
    let m = Model::from_json(&text, "model.json").unwrap();
    let maps: Vec<Option<presrs_node::unknown::energy::ReturnMap>> =
        serde_json::from_value(v2["energy"].clone()).unwrap();
    assert_eq!(m.unknown.energy.as_ref(), Some(&maps));
    assert!(maps.iter().any(Option::is_some));
    for (old, new) in [
        (
            "load_ranges",
            serde_json::to_value(&m.unknown.load_bands).unwrap(),
        ),
        (
            "texture_ranges",
            serde_json::to_value(&m.unknown.texture_bands).unwrap(),
        ),
        (
            "unknown_thresholds",
            serde_json::to_value(&m.unknown.density_thresholds).unwrap(),
        ),
        (
            "unknown_choice",
            serde_json::to_value(&m.unknown.choice).unwrap(),
        ),
    ] {
        assert_eq!(v2[old], new, "{old}");
    }
    // Saved again it is a format 3 file, which reads back the same.
    assert_eq!(m.version, presrs_node::classifier::model::MODEL_VERSION);
    let again = Model::from_json(&serde_json::to_string(&m).unwrap(), "again.json").unwrap();
    assert_eq!(again, m);
}

/// Loads `tests/fixtures/NAME/model.json` (format `version`) and classifies each image of its
/// `decisions.jsonl` as the build that wrote it did; returns the unknown images per reason.
fn decides_as_written(name: &str, version: u64) -> std::collections::BTreeMap<String, usize> {
    use presrs_node::classifier::dataset::read_image;
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name);
    let text = std::fs::read_to_string(dir.join("model.json")).unwrap();
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(v["version"], version);
    let model = Model::load(&dir.join("model.json")).unwrap();
    let names: Vec<String> = model.classes.iter().map(|c| c.name.clone()).collect();
    let mut cls = Classifier::new(model);
    let text = std::fs::read_to_string(dir.join("decisions.jsonl")).unwrap();
    let mut unknown = std::collections::BTreeMap::new();
    for line in text.lines() {
        let then: serde_json::Value = serde_json::from_str(line).unwrap();
        let file = then["file"].as_str().unwrap();
        let img = read_image(&dir.join(file)).unwrap();
        let d = cls.classify_image(&img, false).unwrap();
        let now = d.to_json(file, &names);
        assert_eq!(now["terrain"], then["terrain"], "{file}");
        assert_eq!(now["best"], then["best"], "{file}");
        // Format 1's build printed no reason (every unknown was the novelty's).
        let reason = then.get("reason").map_or_else(
            || (then["terrain"] == "unknown").then_some("novelty").into(),
            Clone::clone,
        );
        assert_eq!(now["reason"], reason, "{file}");
        // The same to rounding: the files were written on x86-64 with the AVX2 kernels; the
        // portable ones (aarch64 under qemu) round differently (measured: 0.7120 against
        // 0.7127); the decision is the same.
        let native = presrs_node::classifier::Kernels::Native.describe();
        let tol = if native.starts_with("avx2") {
            1e-9
        } else {
            5e-3
        };
        for key in ["novelty", "threshold", "confidence"] {
            let (a, b) = (now[key].as_f64().unwrap(), then[key].as_f64().unwrap());
            assert!(
                (a - b).abs() <= tol * b.abs().max(1.0),
                "{file} {key}: {a} {b}"
            );
        }
        if let Some(r) = reason.as_str() {
            *unknown.entry(r.to_string()).or_default() += 1;
        }
    }
    unknown
}
