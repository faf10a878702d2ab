//! `presrs node --replay`: the node's pipeline on a candump log, with the log's timestamps.
//! The log comes from the simulated robot; the expected stream is the library pipeline run on the
//! same records in-process, so the command must neither lose, add nor reorder a decision.

mod common;

use std::process::Command;

use node::{NodeConfig, StancePipeline};
use protocol::Stamped;
use sim::runner::{SimConfig, SimRobot};

/// `presrs node --replay LOG --model MODEL --json`, its lines parsed.
fn replay_json(log: &std::path::Path, model: &std::path::Path) -> Vec<serde_json::Value> {
    let out = common::output_ok(
        Command::new(env!("CARGO_BIN_EXE_presrs"))
            .args(["node", "--replay", log.to_str().unwrap()])
            .args(["--model", model.to_str().unwrap(), "--json"]),
    );
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

#[test]
fn replay_prints_the_pipelines_decisions_with_the_logs_timestamps() {
    let dir = std::env::temp_dir().join(format!("presrs-replay-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let model_path = common::small_model(&dir);
    // 6 s of the robot on the default track, as candump would have logged it.
    let mut robot = SimRobot::new(SimConfig::default(), 9);
    let mut records = Vec::new();
    let base = 1_700_000_000_000_000u64;
    let mut t = 0;
    while t < 6_000_000 {
        t += 1000;
        robot.advance_to(t, &mut |frame| {
            records.push(Stamped {
                t_us: base + t,
                frame,
            })
        });
    }
    let log = dir.join("run.log");
    let mut w = std::io::BufWriter::new(std::fs::File::create(&log).unwrap());
    for r in &records {
        protocol::candump::write_record(&mut w, "vcan0", r).unwrap();
    }
    drop(w);

    let model = node::classifier::Model::load(&model_path).unwrap();
    let mut p = StancePipeline::new(NodeConfig::default(), Some(model));
    let mut want = Vec::new();
    for r in &records {
        p.on_frame(r, &mut |d: node::stance::Decided| {
            want.push((r.t_us, d.foot, d.class))
        });
    }
    assert!(want.len() > 5, "only {} decisions in 6 s", want.len());

    let got = replay_json(&log, &model_path);
    assert_eq!(got.len(), want.len());
    step_table_matches(&log, &model_path, &got, &robot.steps, base);
    for (g, (t_us, foot, tc)) in got.iter().zip(&want) {
        assert_eq!(g["t_us"], *t_us);
        assert_eq!(g["foot"], *foot);
        assert_eq!(g["step"], tc.step);
        assert_eq!(g["terrain_id"], tc.terrain);
        assert_eq!(g["flags"], tc.flags);
        // The printed latency is the value the CAN field carries (saturated, and 0
        // for a step without a sampled frame).
        let ids = protocol::IdConfig::default();
        let frame = protocol::Message::TerrainClass(*tc)
            .to_frame(&ids, *foot)
            .unwrap();
        let Ok(Some((_, protocol::Message::TerrainClass(on_bus)))) =
            protocol::messages::decode(&frame, &ids)
        else {
            panic!("TerrainClass does not decode");
        };
        assert_eq!(g["latency_us"], on_bus.latency_us, "{g}");
        if tc.flags & protocol::messages::flags::NO_SAMPLE != 0 {
            assert_eq!(on_bus.latency_us, 0);
        }
    }

    // A damaged log, at its start or only at its end (the log streams, but is checked to its
    // end first): the error names the line and the expected format, nothing is printed.
    let text = std::fs::read_to_string(&log).unwrap();
    let n = text.lines().count();
    let bad = dir.join("bad.log");
    for (damaged, line) in [
        (format!("(1.0) vcan0 12Z#00\n{text}"), 1),
        (format!("{text}(1.0) vcan0 12Z#00\n"), n + 1),
    ] {
        std::fs::write(&bad, damaged).unwrap();
        let out = Command::new(env!("CARGO_BIN_EXE_presrs"))
            .args(["node", "--replay", bad.to_str().unwrap(), "--json"])
            .args(["--model", model_path.to_str().unwrap()])
            .output()
            .unwrap();
        assert!(!out.status.success());
        assert!(out.stdout.is_empty(), "decisions printed from a bad log");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            err.contains(&format!("line {line}")) && err.contains("bad.log"),
            "{err}"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// `--csv`: one row per step, the same decisions as `--json`, each touchdown within one frame
/// (10 ms) of the simulator's.
fn step_table_matches(
    log: &std::path::Path,
    model: &std::path::Path,
    json: &[serde_json::Value],
    truth: &[sim::runner::StepTruth],
    base: u64,
) {
    let csv = log.with_extension("csv");
    common::output_ok(
        Command::new(env!("CARGO_BIN_EXE_presrs"))
            .args(["node", "--replay", log.to_str().unwrap()])
            .args(["--model", model.to_str().unwrap(), "--csv"])
            .arg(&csv),
    );
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some(node::step_table::HEADER));
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), json.len(), "one row per decision");
    let secs = |s: &str| protocol::candump::parse_seconds(s).unwrap();
    for (r, j) in rows.iter().zip(json) {
        assert_eq!(r.len(), 8, "{r:?}");
        assert_eq!(r[0], j["foot"].to_string());
        assert_eq!(r[1], j["step"].to_string());
        assert_eq!(secs(r[3]), j["t_us"].as_u64().unwrap(), "decision time");
        assert_eq!(r[4], j["terrain"].as_str().unwrap());
        assert_eq!(r[5], j["unknown_reason"].as_str().unwrap_or(""));
        match j["confidence_pct"].as_f64() {
            Some(c) => assert!(
                (r[6].parse::<f64>().unwrap() - c).abs() < 0.051,
                "{r:?} {j}"
            ),
            None => assert_eq!(r[6], "", "an unknown step has no confidence"),
        }
        // The step counter numbers touchdowns from 1, as the simulator's truth lists them.
        let step: usize = r[1].parse().unwrap();
        let td = truth[step - 1];
        let got = secs(r[2]);
        let want = base + td.touchdown_us;
        assert!(
            got.abs_diff(want) <= 10_000,
            "step {step}: touchdown {got} against the truth's {want}"
        );
        assert!(got <= secs(r[3]), "touchdown after its decision: {r:?}");
    }
}

#[test]
fn the_example_configs_parse_and_equal_the_defaults() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let p = root.join("examples/node.toml");
    let node = NodeConfig::from_toml(&std::fs::read_to_string(&p).unwrap(), "node.toml").unwrap();
    assert_eq!(node, NodeConfig::default());
    let p = root.join("examples/controller.toml");
    let c = controller::ControllerConfig::parse(
        &std::fs::read_to_string(&p).unwrap(),
        "controller.toml",
    )
    .unwrap();
    assert_eq!(c, controller::ControllerConfig::default());
}

/// The firmware example (the `no_std` foot sender over an `embedded_can` driver)
/// writes a candump log; the node replays it and decides every stance from an image sampled
/// about 70 ms after its touchdown, by the foot's clock.
#[test]
fn the_firmware_examples_log_is_a_run_the_node_decides() {
    let dir = std::env::temp_dir().join(format!("presrs-firmware-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let model_path = common::small_model(&dir);
    let log = dir.join("foot.log");
    common::output_ok(&mut common::protocol_example(
        "foot_firmware",
        &["--steps", "8", "--log", log.to_str().unwrap()],
    ));
    let got = replay_json(&log, &model_path);
    assert_eq!(got.len(), 8, "{got:?}");
    let log_start_us = 1_700_000_000_000_000u64;
    for (k, g) in got.iter().enumerate() {
        assert_eq!(g["step"], k as u64 + 1);
        let flags = g["flags"].as_u64().unwrap() as u8;
        use protocol::messages::flags;
        assert_eq!(flags & (flags::NO_SAMPLE | flags::NO_CONTACT), 0, "{g}");
        // Touchdowns every 440 ms of foot time; images every 10 ms; decided on the 70 ms image.
        let since_touchdown = g["t_us"].as_u64().unwrap() - log_start_us - k as u64 * 440_000;
        assert!((70_000..75_000).contains(&since_touchdown), "{g}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// `--keep-unknown DIR` over a replay: a model that knows three of the track's four terrains
/// keeps exactly the steps it calls unknown on their image, as images `train` reads and a
/// `kept.csv` that says why; keeping the same log again adds nothing.
#[test]
fn keep_unknown_keeps_each_step_called_unknown_on_its_image_and_nothing_twice() {
    let dir = std::env::temp_dir().join(format!("presrs-keep-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    // Trained without clay (the default track's third segment).
    let model = common::model_without("clay");
    let model_path = dir.join("model.json");
    model.save(&model_path).unwrap();
    let mut robot = SimRobot::new(SimConfig::default(), 5);
    let log = dir.join("run.log");
    let mut w = std::io::BufWriter::new(std::fs::File::create(&log).unwrap());
    let mut t = 0;
    while t < 40_000_000 {
        t += 1000;
        robot.advance_to(t, &mut |frame| {
            protocol::candump::write_record(&mut w, "vcan0", &Stamped { t_us: t, frame }).unwrap()
        });
    }
    drop(w);
    let kept = dir.join("kept");
    let keep = |args: &[&str]| {
        common::output_ok(
            Command::new(env!("CARGO_BIN_EXE_presrs"))
                .args(["node", "--replay", log.to_str().unwrap()])
                .args(["--model", model_path.to_str().unwrap(), "--keep-unknown"])
                .arg(&kept)
                .args(args),
        )
    };
    let out = keep(&["--json"]);
    let on_image: Vec<serde_json::Value> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .filter(|v| {
            ["novelty", "load", "texture", "energy"]
                .contains(&v["unknown_reason"].as_str().unwrap_or(""))
        })
        .collect();
    assert!(on_image.len() >= 3, "only {} unknown steps", on_image.len());
    // Each kept step's true terrain: the robot's last touchdown before the decision.
    let truth = |t_us: u64| {
        robot
            .steps
            .iter()
            .rev()
            .find(|s| s.touchdown_us <= t_us)
            .map(|s| s.terrain.name().to_string())
    };
    let on_clay = on_image
        .iter()
        .filter(|v| truth(v["t_us"].as_u64().unwrap()).as_deref() == Some("clay"))
        .count();
    let clay_steps = robot
        .steps
        .iter()
        .filter(|s| s.terrain.name() == "clay")
        .count();
    eprintln!(
        "kept {} unknown steps, {on_clay} of them on clay (of {clay_steps} clay steps)",
        on_image.len()
    );
    let table = std::fs::read_to_string(kept.join("kept.csv")).unwrap();
    let rows: Vec<&str> = table.lines().skip(1).collect();
    assert_eq!(rows.len(), on_image.len(), "{table}");
    for (row, v) in rows.iter().zip(&on_image) {
        let cols: Vec<&str> = row.split(',').collect();
        assert_eq!(cols[1], v["foot"].to_string());
        assert_eq!(cols[2], v["step"].to_string());
        assert_eq!(cols[3], v["unknown_reason"].as_str().unwrap());
        let img = node::classifier::dataset::read_image(&kept.join(cols[0])).unwrap();
        assert_eq!((img.rows, img.cols), (44, 44));
        assert!(
            img.pixels.iter().any(|&p| p > 0),
            "{}: a blank image",
            cols[0]
        );
    }
    // The same log again: everything is there already.
    let out = keep(&[]);
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(said.contains("kept 0 unknown stances"), "{said}");
    assert!(
        said.contains(&format!("{} already there", rows.len())),
        "{said}"
    );
    assert_eq!(
        std::fs::read_to_string(kept.join("kept.csv")).unwrap(),
        table
    );
    let _ = std::fs::remove_dir_all(&dir);
}
