//! `presrs capture` builds a training set from the robot's own logs, and
//! the whole path a lab walks (record per terrain, capture, train, deploy, classify a fresh
//! mixed run) works from the CLI. The simulator stands in for the robot (`presrs lab sim --log`);
//! the vcan suite walks the same path over real SocketCAN with candump.

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

fn presrs() -> Command {
    Command::new(env!("CARGO_BIN_EXE_presrs"))
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("presrs-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn json(out: &std::process::Output) -> serde_json::Value {
    serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(&out.stdout)))
}

/// A one-terrain track of the paper's circle.
fn track(dir: &Path, terrain: &str) -> PathBuf {
    let p = dir.join(format!("{terrain}.toml"));
    let text = format!("diameter_m = 2.8\n[[segments]]\nterrain = \"{terrain}\"\nlength_m = 8.8\n");
    std::fs::write(&p, text).unwrap();
    p
}

fn sim_log(dir: &Path, name: &str, track: Option<&Path>, secs: u32, seed: u64) -> PathBuf {
    let log = dir.join(format!("{name}.log"));
    let mut cmd = presrs();
    cmd.args([
        "lab",
        "sim",
        "--log",
        s(&log),
        "--duration",
        &secs.to_string(),
    ])
    .args(["--seed", &seed.to_string()]);
    if let Some(t) = track {
        cmd.args(["--track", s(t)]);
    } else {
        cmd.args(["--truth", s(&dir.join(format!("{name}.csv")))]);
    }
    common::output_ok(&mut cmd);
    log
}

/// (foot, step) -> terrain name from a JSON-lines stream.
fn by_step(lines: &str) -> BTreeMap<(u64, u64), String> {
    lines
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .map(|v| {
            let k = (v["foot"].as_u64().unwrap(), v["step"].as_u64().unwrap());
            (k, v["terrain"].as_str().unwrap().to_string())
        })
        .collect()
}

#[test]
fn a_lab_records_captures_trains_and_classifies_a_fresh_run() {
    let dir = tmp("capture-path");
    let set = dir.join("set");
    let terrains = ["wood", "grass", "clay", "carpet"];
    let mut first = BTreeMap::new();
    for (i, t) in terrains.iter().enumerate() {
        let log = sim_log(&dir, t, Some(&track(&dir, t)), 30, 10 + i as u64);
        let out = common::output_ok(
            presrs()
                .args(["capture", "--replay", s(&log), "--label", t])
                .args(["--out", s(&set), "--json"]),
        );
        let j = json(&out);
        assert!(j["written"].as_u64().unwrap() >= 60, "{t}: {j}");
        assert_eq!(
            j["written"], j["steps"],
            "{t}: every step has its image: {j}"
        );
        assert_eq!(j["per_terrain"][t], j["written"]);
        first.insert(t.to_string(), (log, j["written"].as_u64().unwrap()));
    }
    // The manifest lists every image once, and every listed file exists with its terrain.
    let manifest = std::fs::read_to_string(set.join("manifest.csv")).unwrap();
    let rows: Vec<&str> = manifest.lines().skip(1).collect();
    let total: u64 = first.values().map(|(_, n)| n).sum();
    assert_eq!(rows.len() as u64, total);
    for r in &rows {
        let f: Vec<&str> = r.split(',').collect();
        // `presrs lab sim --log` is the foot's traffic only: no controller, no GaitStatus, no gait.
        assert_eq!((f.len(), f[9]), (12, ""), "{r}");
        // The flights beside the stance (the foot switch's), empty where the log has none.
        for flight in &f[10..12] {
            assert!(
                flight.is_empty() || (0.0..2.0).contains(&flight.parse::<f64>().unwrap()),
                "flight: {r}"
            );
        }
        assert!(f[0].starts_with(&format!("{}/", f[1])), "{r}");
        assert!(set.join(f[0]).is_file(), "{r}");
        assert!(f[6].parse::<u64>().unwrap() > 0, "load sum: {r}");
    }
    // Every step but a run's last has the flight after it (the next touchdown ends it).
    let with_flight = rows.iter().filter(|r| !r.ends_with(',')).count();
    assert!(
        with_flight + terrains.len() >= rows.len(),
        "{with_flight} of {}",
        rows.len()
    );
    // Capturing the same log again adds nothing.
    let (wood_log, _) = &first["wood"];
    let again = json(&common::output_ok(
        presrs()
            .args(["capture", "--replay", s(wood_log), "--label", "wood"])
            .args(["--out", s(&set), "--json"]),
    ));
    assert_eq!(again["written"], 0);
    assert_eq!(again["duplicates"], again["steps"]);
    assert_eq!(again["set_total"].as_u64().unwrap(), total);

    // Train on the captured set; the node classifies a fresh run over all four terrains.
    let model = dir.join("model.json");
    common::output_ok(
        presrs()
            .args(["train", "--data", s(&set), "--out", s(&model)])
            .args(["--per-class", "60", "--train", "40", "--normalize-load"])
            .args(["--crop", "0,3,6,0"]),
    );
    let mixed = sim_log(&dir, "mixed", None, 40, 99);
    let node = common::output_ok(presrs().args([
        "node",
        "--replay",
        s(&mixed),
        "--model",
        s(&model),
        "--json",
    ]));
    let said = by_step(&String::from_utf8_lossy(&node.stdout));
    // The truth per step: capture with the simulator's labels (a second, labelled set).
    let truth_set = dir.join("truth-set");
    let labelled = json(&common::output_ok(
        presrs()
            .args([
                "capture",
                "--replay",
                s(&mixed),
                "--labels",
                s(&dir.join("mixed.csv")),
            ])
            .args(["--out", s(&truth_set), "--json"]),
    ));
    assert_eq!(labelled["unlabelled"], 0);
    assert_eq!(labelled["spans_labels"], 0);
    let manifest = std::fs::read_to_string(truth_set.join("manifest.csv")).unwrap();
    let (mut n, mut right) = (0, 0);
    for r in manifest.lines().skip(1) {
        let f: Vec<&str> = r.split(',').collect();
        let key = (f[2].parse().unwrap(), f[3].parse().unwrap());
        n += 1;
        right += (said.get(&key).map(String::as_str) == Some(f[1])) as u32;
    }
    assert!(n >= 100, "{n} steps");
    let acc = right as f64 / n as f64;
    eprintln!(
        "fresh mixed run: {right}/{n} steps right ({:.1}%)",
        100.0 * acc
    );
    assert!(acc >= 0.95, "{right}/{n} steps right");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A whole robot bus (the demo's, controller included) carries GaitStatus: each captured step
/// gets the gait its stance touched down in, `train` lists them, and a manifest line that is
/// not one stops `train` naming it rather than dropping the runs it holds.
#[test]
fn a_capture_of_the_whole_bus_records_each_stances_gait_and_train_lists_them() {
    let dir = tmp("capture-gait");
    let (log, truth, steps) = (
        dir.join("bus.log"),
        dir.join("truth.csv"),
        dir.join("steps.csv"),
    );
    common::output_ok(
        presrs()
            .args([
                "demo",
                "--steps",
                "120",
                "--candump",
                s(&log),
                "--truth",
                s(&truth),
            ])
            .args(["--csv", s(&steps)]),
    );
    let set = dir.join("set");
    let j = json(&common::output_ok(
        presrs()
            .args(["capture", "--replay", s(&log), "--labels", s(&truth)])
            .args(["--out", s(&set), "--json"]),
    ));
    // The demo's own step log says which gait ran each step.
    let ran: BTreeMap<u64, String> = std::fs::read_to_string(&steps)
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            (f[1].parse().unwrap(), f[5].to_string())
        })
        .collect();
    let manifest = std::fs::read_to_string(set.join("manifest.csv")).unwrap();
    let (mut same, mut unknown, mut n) = (0, 0, 0);
    for r in manifest.lines().skip(1) {
        let f: Vec<&str> = r.split(',').collect();
        n += 1;
        match f[9] {
            // Before the controller's first GaitStatus.
            "" => unknown += 1,
            g => same += (ran.get(&f[3].parse().unwrap()).map(String::as_str) == Some(g)) as u32,
        }
    }
    // Measured: 119 of 120, the first step touching down before the first GaitStatus.
    assert!(
        n >= 100 && unknown <= 2 && same == n - unknown,
        "{same} of {n}, {unknown} without"
    );
    let per_gait = j["per_gait"].as_object().unwrap();
    assert!(per_gait.len() >= 3, "the demo's track runs every gait: {j}");

    let model = dir.join("model.json");
    let train = |data: &Path| {
        presrs()
            .args(["train", "--data", s(data), "--out", s(&model)])
            .args(["--per-class", "12", "--train", "8", "--normalize-load"])
            .args(["--crop", "0,3,6,0", "--verbose"])
            .output()
            .unwrap()
    };
    let out = train(&set);
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{said}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        said.contains("gaits at touchdown (capture manifest): G1 "),
        "{said}"
    );
    assert_eq!(said.contains("without a GaitStatus"), unknown > 0, "{said}");
    // The model says which gaits it has seen, and the node's replay counts unknowns by gait.
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&model).unwrap()).unwrap();
    assert_eq!(
        m["gaits"],
        serde_json::json!([1, 2, 3]),
        "the demo runs G1-G3"
    );
    let replay = common::output_ok(presrs().args([
        "node",
        "--replay",
        s(&log),
        "--model",
        s(&model),
        "--json",
    ]));
    let lines = String::from_utf8_lossy(&replay.stdout);
    let mut by_gait = 0;
    for l in lines.lines() {
        let v: serde_json::Value = serde_json::from_str(l).unwrap();
        let step = v["step"].as_u64().unwrap();
        match v["gait"].as_u64() {
            Some(g) => {
                by_gait += 1;
                assert_eq!(ran.get(&step), Some(&g.to_string()), "{l}");
            }
            None => assert!(v["gait"].is_null() && step <= 2, "{l}"),
        }
    }
    assert!(by_gait >= 100, "{lines}");
    let summary = String::from_utf8_lossy(&replay.stderr);
    assert!(summary.contains("\n  unknown by gait: G1 "), "{summary}");
    assert!(!summary.contains("not trained"), "{summary}");

    std::fs::write(
        set.join("manifest.csv"),
        format!("{manifest}wood/x.pgm,wood,0,7,1.0,1.07,5,0.0,bus.log,fast\n"),
    )
    .unwrap();
    let out = train(&set);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    let line = manifest.lines().count() + 1;
    assert!(
        err.contains(&format!("manifest.csv line {line}")) && err.contains("gait `fast`"),
        "{err}"
    );
    assert!(err.contains("delete the manifest"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn labels_that_cross_terrains_skip_and_count_the_steps_they_do_not_cover() {
    let dir = tmp("capture-labels");
    let log = sim_log(&dir, "run", None, 8, 5);
    // Only the first 3 s are labelled, and a range boundary at 1.9 s falls inside a stance
    // (touchdowns are ~0.35 s apart, the sample 70 ms after).
    let labels = dir.join("labels.csv");
    std::fs::write(
        &labels,
        "start_s,end_s,terrain\n1700000000.0,1700000001.9,wood\n1700000001.9,1700000003,grass\n",
    )
    .unwrap();
    let j = json(&common::output_ok(
        presrs()
            .args(["capture", "--replay", s(&log), "--labels", s(&labels)])
            .args(["--out", s(&dir.join("set")), "--json"]),
    ));
    let n = |k: &str| j[k].as_u64().unwrap();
    assert_eq!(
        n("written") + n("unlabelled") + n("spans_labels") + n("no_image") + n("blank"),
        n("steps"),
        "{j}"
    );
    assert!(n("unlabelled") >= 10, "{j}");
    assert!(n("written") >= 6 && n("written") <= 9, "{j}");
    assert_eq!(
        j["per_terrain"]["wood"].as_u64().unwrap() + j["per_terrain"]["grass"].as_u64().unwrap(),
        n("written")
    );

    // Bad labels name the file and line; bad terrains name the catalog; nothing is written.
    std::fs::write(
        &labels,
        "1700000000.0,1700000001.0,wood\n1700000001.0,1700000002.0,moon\n",
    )
    .unwrap();
    let out = presrs()
        .args(["capture", "--replay", s(&log), "--labels", s(&labels)])
        .args(["--out", s(&dir.join("bad")), "--json"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains("labels.csv line 2") && err.contains("`moon` is not a terrain"),
        "{err}"
    );
    assert!(!dir.join("bad").exists(), "nothing written on bad labels");
    let bad_out = dir.join("bad");
    let err = capture_fails(&log, "moon", &bad_out);
    assert!(err.contains("--label moon"), "{err}");

    // An output that cannot be a folder: a clear error naming it.
    let file = dir.join("a-file");
    std::fs::write(&file, "x").unwrap();
    let err = capture_fails(&log, "wood", &file.join("set"));
    assert!(err.contains("a-file/set"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// `presrs capture --replay LOG --label TERRAIN --out OUT`, which must fail: its stderr.
fn capture_fails(log: &Path, terrain: &str, out: &Path) -> String {
    let o = presrs()
        .args([
            "capture",
            "--replay",
            s(log),
            "--label",
            terrain,
            "--out",
            s(out),
        ])
        .output()
        .unwrap();
    assert!(!o.status.success());
    String::from_utf8_lossy(&o.stderr).to_string()
}

/// Logs are streamed (an hours-long log is not held in memory), yet a line that is bad only at
/// the end of a long log still stops the capture before it starts: no set created, no image
/// written; the error names the file and the line. (`node --replay` and `mcap`: their tests.)
#[test]
fn a_log_bad_at_its_end_writes_nothing() {
    let dir = tmp("capture-bad-end");
    let log = sim_log(&dir, "wood", Some(&track(&dir, "wood")), 8, 3);
    let good = std::fs::read_to_string(&log).unwrap();
    let n = good.lines().count();
    assert!(n > 5_000, "{n} lines");
    let bad = dir.join("bad-end.log");
    std::fs::write(&bad, format!("{good}(1700009999.000000) can0 123#0\n")).unwrap();

    let out = dir.join("set");
    let err = capture_fails(&bad, "wood", &out);
    assert!(
        err.contains("bad-end.log") && err.contains(&format!("line {}", n + 1)),
        "{err}"
    );
    assert!(!out.exists(), "nothing written from a bad log");

    // The same log without its bad line is captured.
    let o = common::output_ok(
        presrs()
            .args(["capture", "--replay", s(&log), "--label", "wood"])
            .args(["--out", s(&out), "--json"]),
    );
    assert!(json(&o)["written"].as_u64().unwrap() >= 10);
    let _ = std::fs::remove_dir_all(&dir);
}
