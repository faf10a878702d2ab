//! The README's run command: the closed loop on the in-process bus.

mod common;

use std::process::Command;

#[test]
fn demo_runs_the_loop_and_reports_json() {
    let dir = std::env::temp_dir().join(format!("presrs-demo-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let csv = dir.join("steps.csv");
    let out = common::output_ok(
        Command::new(env!("CARGO_BIN_EXE_presrs"))
            .args(["demo", "--steps", "60", "--json", "--csv"])
            .arg(&csv)
            .env("XDG_CACHE_HOME", &dir),
    );
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(j["steps"], 60);
    for k in ["accuracy", "switches", "steps_to_switch_max"] {
        assert!(j.get(k).is_some(), "missing {k}: {j}");
    }
    // The default track changes terrain, so the controller must have switched gait, and the
    // node must beat chance (25 %) by far.
    assert!(j["switches"].as_u64().unwrap() >= 1, "{j}");
    assert!(j["accuracy"].as_f64().unwrap() > 0.5, "{j}");
    let lines = std::fs::read_to_string(&csv).unwrap().lines().count();
    assert_eq!(lines, 61, "header and one line per step");
    // The model is cached for the next run, under a name that changes with the model format and
    // the simulator.
    let cached = std::fs::read_dir(dir.join("presrs"))
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with("demo-model-v"))
        .count();
    assert_eq!(cached, 1, "one cached demo model");
    let _ = std::fs::remove_dir_all(&dir);
}
