//! The classifier commands end to end through the `presrs` binary, on a synthetic PGM dataset
//! and the real TekScan export.

use std::path::Path;
use std::process::Command;

use rand::{Rng, SeedableRng};

/// `presrs` as a command: this build's binary, or `PRESRS_TEST_BIN` when set, e.g. a
/// workstation build for another architecture (the arm64 package holds the robot's build,
/// without these commands: scripts/test-package.sh checks it). Another architecture's binary
/// runs under qemu-user, named by `PRESRS_TEST_RUNNER` ("qemu-aarch64 -L
/// /usr/aarch64-linux-gnu"): there is no binfmt_misc here to start it by itself.
fn presrs_command() -> Command {
    let bin =
        std::env::var("PRESRS_TEST_BIN").unwrap_or_else(|_| env!("CARGO_BIN_EXE_presrs").into());
    let runner = std::env::var("PRESRS_TEST_RUNNER").unwrap_or_default();
    let mut words = runner.split_whitespace();
    match words.next() {
        Some(program) => {
            let mut cmd = Command::new(program);
            cmd.args(words).arg(bin);
            cmd
        }
        None => Command::new(bin),
    }
}

fn presrs(args: &[&str]) -> (bool, String, String) {
    let o = presrs_command().args(args).output().unwrap();
    (
        o.status.success(),
        String::from_utf8_lossy(&o.stdout).into(),
        String::from_utf8_lossy(&o.stderr).into(),
    )
}

fn write_dataset(dir: &Path) {
    let mut rng = rand::rngs::StdRng::seed_from_u64(4);
    for (name, period, fill) in [
        ("wood", 4usize, 0.5f64),
        ("carpet", 7, 0.5),
        ("grass", 11, 0.35),
    ] {
        let d = dir.join(name);
        std::fs::create_dir_all(&d).unwrap();
        for i in 0..30 {
            let (dy, dx) = (rng.random_range(0..period), rng.random_range(0..period));
            let mut b = b"P2\n44 44\n255\n".to_vec();
            for p in 0..44 * 44 {
                let (r, c) = (p / 44 + dy, p % 44 + dx);
                let on = ((r % period) as f64) < fill * period as f64
                    && ((c % period) as f64) < fill * period as f64;
                let v: f64 = if on { 150.0 } else { 10.0 } + rng.random_range(-8.0..8.0);
                b.extend_from_slice(format!("{} ", v.clamp(0.0, 255.0) as u16).as_bytes());
            }
            std::fs::write(d.join(format!("{i:03}.pgm")), b).unwrap();
        }
    }
}

#[test]
fn train_eval_classify_features_repair() {
    let dir = std::env::temp_dir().join(format!("presrs-cli-{}", std::process::id()));
    let data = dir.join("data");
    write_dataset(&data);
    let model = dir.join("model.json");
    let train = |out: &Path, extra: &[&str]| {
        let mut args = vec!["train", "--data", data.to_str().unwrap()];
        args.extend(["--out", out.to_str().unwrap()]);
        args.extend(extra);
        presrs(&args)
    };
    let (ok, out, err) = train(&model, &["--crop", "2,2,2,2"]);
    assert!(ok, "{out}{err}");
    assert!(
        out.contains("fitted on 39 images and its kernel width chosen on 21 (13 + 7 per terrain"),
        "{out}"
    );

    let (ok, out, err) = presrs(&[
        "eval",
        "--model",
        model.to_str().unwrap(),
        "--data",
        data.to_str().unwrap(),
        "--json",
    ]);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
    assert_eq!(v["n_skipped"], 60);
    assert_eq!(v["n_tested"], 30);
    assert!(v["overall_accuracy"].as_f64().unwrap() >= 0.95, "{v}");
    for key in [
        "per_class",
        "confusion",
        "classify_us_median",
        "classify_us_p99",
    ] {
        assert!(!v[key].is_null(), "{key} missing");
    }
    let (ok, out, _) = presrs(&[
        "eval",
        "--model",
        model.to_str().unwrap(),
        "--data",
        data.to_str().unwrap(),
    ]);
    assert!(
        ok && out.contains("detected \\ actual") && out.contains("overall accuracy"),
        "{out}"
    );

    let img = data.join("grass/029.pgm");
    let classify_with = |model: &Path, file: &Path| {
        presrs(&[
            "lab",
            "classify",
            "--model",
            model.to_str().unwrap(),
            file.to_str().unwrap(),
        ])
    };
    let classify = |file: &Path| classify_with(&model, file);
    let (ok, out, _) = classify(&img);
    assert!(ok && out.contains("\tgrass\t"), "{out}");

    // A blank frame is no terrain (it was one at confidence 1.000), and a 16-bit
    // image (maxval 65535) on a model of 8-bit images is refused with the fix.
    let flat = |name: &str, maxval: u32, value: u32| {
        let path = dir.join(name);
        let mut b = format!("P2\n44 44\n{maxval}\n").into_bytes();
        b.extend(format!("{value} ").repeat(44 * 44).into_bytes());
        std::fs::write(&path, b).unwrap();
        path
    };
    let (ok, out, _) = classify(&flat("blank.pgm", 255, 0));
    assert!(ok && out.contains("\tunknown (no contact)\t-"), "{out}");
    let (ok, _, err) = classify(&flat("deep.pgm", 65535, 4000));
    assert!(
        !ok && err.contains("deep.pgm") && err.contains("train a model on 16-bit images"),
        "{err}"
    );

    // Messages: a write says write and names the missing folder; a missing model is said
    // once; a downsampling of 0 is refused with its range.
    let nowhere = dir.join("no-such-folder").join("m.json");
    let (ok, _, err) = train(&nowhere, &[]);
    assert!(
        !ok && err.contains("cannot write model") && err.contains("does not exist"),
        "{err}"
    );
    let missing = dir.join("missing.json");
    let (ok, _, err) = classify_with(&missing, &img);
    assert!(!ok && err.matches("No such file").count() == 1, "{err}");
    assert_eq!(err.matches("missing.json").count(), 1, "{err}");
    let (ok, _, err) = train(&nowhere, &["--downsample", "0"]);
    assert!(
        !ok && err.contains("--downsample") && err.contains("1..=8"),
        "{err}"
    );

    let (ok, out, _) = presrs(&[
        "lab",
        "features",
        img.to_str().unwrap(),
        "--crop",
        "2,2,2,2",
        "--json",
    ]);
    assert!(ok);
    let f: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
    assert_eq!(f["features"].as_array().unwrap().len(), 1025);

    let asf = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/tekscan/FrasP01L.asf");
    let (ok, out, err) = presrs(&["lab", "features", asf.to_str().unwrap(), "--json"]);
    assert!(ok, "{err}");
    let f: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
    assert_eq!(f["features"].as_array().unwrap().len(), 1025); // 60x21 = 1260 -> N = 2048

    let fixed = dir.join("fixed.pgm");
    let broken = dir.join("broken.pgm");
    let mut b = b"P2\n3 3\n255\n1 2 3\n0 0 0\n7 8 9\n".to_vec();
    std::fs::write(&broken, &b).unwrap();
    let (ok, out, _) = presrs(&[
        "lab",
        "repair",
        broken.to_str().unwrap(),
        "--out",
        fixed.to_str().unwrap(),
    ]);
    assert!(ok && out.contains("filled 1 dead rows"), "{out}");
    let back = node::classifier::dataset::read_image(&fixed).unwrap();
    assert_eq!(back.pixels, vec![1, 2, 3, 1, 2, 3, 7, 8, 9]);

    // Bad input: named file and line, non-zero exit, no panic.
    b = b"P2\n3 3\n255\n1 2 3\n0 x 0\n7 8 9\n".to_vec();
    std::fs::write(&broken, &b).unwrap();
    let (ok, _, err) = presrs(&[
        "lab",
        "classify",
        "--model",
        model.to_str().unwrap(),
        broken.to_str().unwrap(),
    ]);
    assert!(
        !ok && err.contains("broken.pgm:5") && !err.contains("panicked"),
        "{err}"
    );
    let (ok, _, err) = presrs(&[
        "lab",
        "classify",
        "--model",
        broken.to_str().unwrap(),
        img.to_str().unwrap(),
    ]);
    assert!(!ok && err.contains("not a PreSRS model"), "{err}");
    let (ok, _, err) = presrs(&["lab", "sim"]);
    assert!(!ok && err.contains("--iface"), "{err}");
    let (ok, _, err) = presrs(&["node", "--model", "m.json"]);
    assert!(!ok && err.contains("--iface"), "{err}");
    let (ok, _, err) = presrs(&["lab", "experiment", "tables"]);
    assert!(!ok && err.contains("invalid value 'tables'"), "{err}");
}

/// `train --calibrate DIR` calibrates the unknown-terrain rejection on another run,
/// refuses a run of terrains the model does not know and an empty one (naming the run and the
/// fix), and `classify --json` gives each image's novelty and the threshold it was held to.
#[test]
fn calibration_runs_and_classify_json() {
    let dir = std::env::temp_dir().join(format!("presrs-cal-test-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let (set, run2) = (dir.join("set"), dir.join("run2"));
    write_dataset(&set);
    write_dataset(&run2);
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let model = dir.join("m.json");
    // `presrs train` on the set into `out`, calibrated on `cal` when given.
    let train = |out: &Path, cal: Option<&Path>| {
        let (set_s, out_s) = (s(&set), s(out));
        let mut args = vec![
            "train", "--data", &set_s, "--out", &out_s, "--crop", "2,2,2,2",
        ];
        let cal_s = cal.map(s);
        if let Some(c) = &cal_s {
            args.extend(["--calibrate", c]);
        }
        presrs(&args)
    };
    let (ok, out, err) = train(&model, None);
    assert!(ok, "{err}");
    assert!(
        out.contains("margin") && out.contains("record a second session"),
        "{out}"
    );
    let (ok, out, err) = train(&model, Some(&run2));
    assert!(ok, "{err}");
    assert!(
        out.contains("held-out runs") && out.contains("run2"),
        "{out}"
    );
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&model).unwrap()).unwrap();
    assert_eq!(
        m["unknown"]["novelty"]["calibration"]["source"],
        "held-out-runs"
    );
    assert_eq!(m["unknown"]["novelty"]["score"], "knn-residual");
    // A run with a terrain the model does not know (sand: in the catalog, not in the model).
    std::fs::rename(run2.join("grass"), run2.join("sand")).unwrap();
    let refused = dir.join("x.json");
    let (ok, _, err) = train(&refused, Some(&run2));
    assert!(!ok);
    assert!(
        err.contains("`sand`") && err.contains("run2") && err.contains("not trained on"),
        "{err}"
    );
    assert!(!refused.exists(), "a refused calibration writes no model");
    // An empty run.
    let empty = dir.join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    let (ok, _, err) = train(&refused, Some(&empty));
    assert!(!ok);
    assert!(
        err.contains("empty") && err.contains("no class sub-directories"),
        "{err}"
    );
    // classify --json: one object per image, a known image below its threshold.
    let img = set.join("wood/003.pgm");
    let (ok, out, err) = presrs(&["lab", "classify", "--json", "--model", &s(&model), &s(&img)]);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
    assert_eq!(v["terrain"], "wood");
    let (nov, thr) = (
        v["novelty"].as_f64().unwrap(),
        v["threshold"].as_f64().unwrap(),
    );
    assert!(nov > 0.0 && nov <= thr, "{v}");
    assert!(
        v["confidence"].as_f64().unwrap() > 0.5 && v["file"].as_str().unwrap().ends_with("003.pgm")
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Two demo sessions whose model takes much of the calibration run for another terrain
/// (seeds 11 and 12: h = 24 PCA dimensions chosen on 28 validation images) are warned about,
/// with the figures the warning is made of; the README's seeds 1 and 2 are not.
#[test]
fn train_warns_when_the_model_takes_the_calibration_run_for_other_terrains() {
    let dir = std::env::temp_dir().join(format!("presrs-cli-wrong-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let p = |name: &str| dir.join(name).display().to_string();
    let warned = |seeds: [u64; 2], set: &str| {
        for s in seeds {
            let (log, csv) = (p(&format!("r{s}.log")), p(&format!("r{s}.csv")));
            let seed = s.to_string();
            let args = ["demo", "--steps", "300", "--seed", &seed, "--candump", &log];
            let (ok, _, err) = presrs(&[&args[..], &["--truth", &csv]].concat());
            assert!(ok, "{err}");
            let (ok, _, err) = presrs(&[
                "capture",
                "--replay",
                &log,
                "--labels",
                &csv,
                "--out",
                &p(set),
            ]);
            assert!(ok, "{err}");
            let _ = std::fs::remove_file(&log);
        }
        let (ok, out, err) = presrs(&["train", "--data", &p(set), "--out", &p("m.json")]);
        assert!(ok, "{err}");
        out.lines()
            .find(|l| l.starts_with("warning: the model took"))
            .map(str::to_string)
    };
    let w = warned([11, 12], "set11").expect("a warning for seeds 11 and 12");
    let share: f64 = w
        .split("took ")
        .nth(1)
        .and_then(|t| t.split('%').next())
        .and_then(|t| t.parse().ok())
        .unwrap_or_else(|| panic!("{w}"));
    assert!(share > 10.0, "{w}");
    assert!(
        w.contains("r12.log") && w.contains("h = ") && w.contains("validation images"),
        "{w}"
    );
    assert_eq!(warned([1, 2], "set1"), None);
    let _ = std::fs::remove_dir_all(&dir);
}
