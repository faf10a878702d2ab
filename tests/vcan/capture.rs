//! The capture path over SocketCAN: candump logs to a deployed model, unknown ground to the
//! safe gait.

use super::*;

/// Over real SocketCAN, the path of docs/real-robot.md with the simulator
/// standing in for the robot: `presrs lab sim` on one terrain at a time while candump records,
/// `presrs capture` builds the set from the logs, `presrs train`, and the node with that model
/// classifies a fresh run over all four terrains as a process on the bus (>= 95% of steps).
/// Then a model captured without grass meets grass with the controller on the bus: the node
/// calls it unknown and the controller puts the leg in the safe gait within 3 steps.
#[test]
#[ignore = "needs vcan interfaces: tests/vcan/run.sh runs it"]
fn capture_path_over_socketcan_from_candump_logs_to_a_deployed_model() {
    let _time = Timed(
        "capture_path_over_socketcan_from_candump_logs_to_a_deployed_model",
        Instant::now(),
    );
    let iface = fd_iface();
    let dir = std::env::temp_dir().join(format!("presrs-capture-vcan-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let set = dir.join("set");
    let s = |p: &std::path::Path| p.to_str().unwrap().to_string();
    for (i, t) in ["wood", "grass", "clay", "carpet"].iter().enumerate() {
        let track = dir.join(format!("{t}.toml"));
        std::fs::write(
            &track,
            format!("diameter_m = 2.8\n[[segments]]\nterrain = \"{t}\"\nlength_m = 8.8\n"),
        )
        .unwrap();
        let log = candump_during(&iface, t, || {
            sim_report(&iface, &["--track", &s(&track)], 15.0, 30 + i as u64, t);
        });
        let out = presrs_ok(&[
            "capture",
            "--replay",
            &s(&log),
            "--label",
            t,
            "--out",
            &s(&set),
            "--json",
        ]);
        let j: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
        eprintln!("capture of {t}: {j}");
        assert!(j["written"].as_u64().unwrap() >= 40, "{t}: {j}");
        let _ = std::fs::remove_file(&log);
    }
    let model = dir.join("model.json");
    // 25 of each terrain's ~45 images: the other ~20 calibrate the rejection (one run per
    // terrain here, so the training run's unused images, with the margin). Measured on the
    // host with the same sim seeds and four fresh runs (seeds 77-80, 61 steps each): 59-61
    // steps right with 25, 57-61 with 40 (5 unused images per terrain gave thresholds too
    // tight for wood's spread in the mixed run).
    let common_train = [
        "--per-class",
        "25",
        "--train",
        "17",
        "--normalize-load",
        "--crop",
        "0,3,6,0",
    ];
    let mut args = vec!["train", "--data"];
    let (set_s, model_s) = (s(&set), s(&model));
    args.extend([set_s.as_str(), "--out", model_s.as_str()]);
    args.extend(common_train);
    presrs_ok(&args);

    // The deployed model on a fresh mixed run (the default track: a quarter of each).
    let node = spawn(&["node", "--iface", &iface, "--model", &model_s]);
    std::thread::sleep(Duration::from_millis(1500));
    let r = sim_report(&iface, &[], 15.0, 77, "fresh");
    drop(node);
    let (correct, n) = accuracy(&r);
    eprintln!("fresh mixed run on vcan, model from captured logs: {correct}/{n} steps right");
    assert!(n >= 35, "{n} steps");
    // 95% per step, judged as a sample can judge it. Each VM run is another
    // trajectory (the simulator's chunks follow the wall clock): 20 s runs scored 57, 59, 59,
    // 59, 60, 60, 61, 61 of 61 in the CI runs logged (97.5% in all), so `>= 95%` of one run
    // failed about one run in ten with nothing wrong (the 57, CI of 2026-11-24, under a loaded
    // host). The run is 15 s (about 45 steps) and fails when it shows the accuracy below 95% at
    // 5% significance (of 45, 39 right or fewer; at the 97.5% measured, a false failure about
    // once in 1,100 runs); the 95% itself is asserted on 100+ steps of a deterministic replay
    // (tests/capture.rs).
    let p_low = binomial_cdf(correct, n, 0.95);
    // The CDF itself, against scipy's binom.cdf(54, 61, 0.95) = 0.03215.
    assert!((binomial_cdf(54, 61, 0.95) - 0.03215).abs() < 1e-4);
    assert!(
        p_low >= 0.05,
        "{correct}/{n}: P(at most {correct} right | 95%) = {p_low:.4}"
    );

    // Grass left out of the set: the node must not call it anything else for long.
    let no_grass = dir.join("no-grass");
    for t in ["wood", "clay", "carpet"] {
        std::fs::create_dir_all(no_grass.join(t)).unwrap();
        for e in std::fs::read_dir(set.join(t)).unwrap() {
            let p = e.unwrap().path();
            std::fs::copy(&p, no_grass.join(t).join(p.file_name().unwrap())).unwrap();
        }
    }
    let model2 = dir.join("no-grass.json");
    let (ng_s, m2_s) = (s(&no_grass), s(&model2));
    let mut args = vec!["train", "--data", ng_s.as_str(), "--out", m2_s.as_str()];
    args.extend(common_train);
    presrs_ok(&args);
    let node = spawn(&["node", "--iface", &iface, "--model", &m2_s]);
    let speed = system_speed().to_string();
    let controller = spawn(&["controller", "--iface", &iface, "--time-scale", &speed]);
    std::thread::sleep(Duration::from_millis(1500));
    // Half a metre of wood (the controller settles into its gait), then grass.
    let track = dir.join("wood-grass.toml");
    std::fs::write(
        &track,
        "diameter_m = 2.8\n[[segments]]\nterrain = \"wood\"\nlength_m = 0.5\n\
         [[segments]]\nterrain = \"grass\"\nlength_m = 8.3\n",
    )
    .unwrap();
    let mut r = serde_json::Value::Null;
    // The whole bus, controller included, as a lab records it: its GaitStatus gives each
    // captured step its gait (checked below against the simulator's own record).
    let bus_log = candump_during(&iface, "whole-bus", || {
        r = sim_report(&iface, &["--track", &s(&track)], 6.0, 78, "unknown");
    });
    drop((node, controller));
    let steps = r["steps"].as_array().unwrap();
    let grass: Vec<&serde_json::Value> = steps.iter().filter(|s| s["truth"] == "grass").collect();
    let unknown = grass
        .iter()
        .filter(|s| s["classified"] == "unknown")
        .count();
    let safe = controller::ControllerConfig::default().safe_gait;
    let first_safe = grass.iter().position(|s| s["gait"] == safe);
    eprintln!(
        "grass, not in the model, with the controller: {unknown}/{} steps unknown, safe gait G{safe} after {first_safe:?} steps",
        grass.len()
    );
    assert!(grass.len() >= 8, "{} grass steps", grass.len());
    assert!(
        unknown * 10 >= grass.len() * 8,
        "{unknown}/{} grass steps unknown",
        grass.len()
    );
    assert!(
        first_safe.is_some_and(|d| d <= 3),
        "safe gait after {first_safe:?} grass steps"
    );

    // Captured from the whole bus over SocketCAN, each step carries the gait the controller
    // announced at its touchdown; the simulator records the gait the leg ran when the node's
    // decision arrived, which is the same gait unless a switch fell between the two.
    let gait_set = dir.join("gait-set");
    let out = presrs_ok(&[
        "capture",
        "--replay",
        &s(&bus_log),
        "--label",
        "wood",
        "--out",
        &s(&gait_set),
        "--json",
    ]);
    let _ = std::fs::remove_file(&bus_log);
    let j: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
    eprintln!("capture of the whole bus: {j}");
    let ran: std::collections::HashMap<(u64, u64), u64> = steps
        .iter()
        .map(|s| {
            let k = (s["foot"].as_u64().unwrap(), s["step"].as_u64().unwrap());
            (k, s["gait"].as_u64().unwrap())
        })
        .collect();
    let manifest = std::fs::read_to_string(gait_set.join("manifest.csv")).unwrap();
    let (mut same, mut differ, mut none) = (0, 0, 0);
    for line in manifest.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let k = (f[2].parse().unwrap(), f[3].parse().unwrap());
        match (f[9].parse::<u64>().ok(), ran.get(&k)) {
            (None, _) => none += 1,
            (Some(g), Some(&want)) if g == want => same += 1,
            (Some(_), Some(_)) => differ += 1,
            (Some(_), None) => {}
        }
    }
    eprintln!(
        "whole-bus capture: {same} steps with the simulator's gait, {differ} another, {none} none"
    );
    // The controller's first GaitStatus comes at its first gait switch or 10 Hz beat; a switch
    // between touchdown and decision can put a step on either side.
    assert!(
        same >= 10 && differ <= 2 && none <= 3,
        "{same} same, {differ} differ, {none} none"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
