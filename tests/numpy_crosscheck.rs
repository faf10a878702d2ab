//! The classifier against an independent implementation: `scripts/compare_numpy.py` runs the
//! same pipeline in numpy (and scikit-learn's KernelDensity) from the same model file, and must
//! pick the same terrain as `presrs lab classify` for every image. Needs numpy and scikit-learn
//! (`tests/requirements.txt`); run with `--features interop`, as the README's test command does.
//! Speed is not asserted here (debug build, noisy machine): the ratio is measured by running the
//! script against the release binary (see the README).
#![cfg(feature = "interop")]

use std::process::Command;

#[test]
fn numpy_and_sklearn_pick_the_same_terrains_as_presrs() {
    let bin = env!("CARGO_BIN_EXE_presrs");
    let dir = std::env::temp_dir().join(format!("presrs-numpy-{}", std::process::id()));
    let data = dir.join("static");
    let model = dir.join("static.json");
    let run = |args: &[&str]| {
        let out = Command::new(bin).args(args).output().expect("run presrs");
        assert!(
            out.status.success(),
            "presrs {args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    };
    let d = data.to_str().expect("utf-8 temp path");
    let m = model.to_str().expect("utf-8 temp path");
    run(&[
        "lab", "dataset", "static", "--out", d, "--n", "30", "--seed", "5",
    ]);
    run(&[
        "train", "--data", d, "--out", m, "--crop", "2,2,2,2", "--dims", "52",
    ]);
    let out = Command::new("python3")
        .args([
            "scripts/compare_numpy.py",
            "--model",
            m,
            "--data",
            d,
            "--presrs",
            bin,
        ])
        .args(["--repeats", "1"])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("run python3");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "compare_numpy.py failed:\n{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report: serde_json::Value = serde_json::from_str(&stdout).expect("one JSON object");
    assert_eq!(report["images"], 120);
    assert_eq!(report["numpy_vs_presrs_disagreements"], 0);
    assert_eq!(report["sklearn_vs_numpy_disagreements"], 0);
    let _ = std::fs::remove_dir_all(&dir);
}
