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
/// `kept.csv` that says why; keeping the same log again adds nothing; `presrs discover`
/// proposes the fourth terrain from them, and nothing when the model knows all four; `--add`
/// makes it a terrain that a fresh run decides, the known terrains no worse.
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
    let all_rows: Vec<&str> = table.lines().skip(1).collect();
    // The session's known stances (reason `known`, under session/) beside the unknown ones.
    let rows: Vec<&str> = all_rows
        .iter()
        .copied()
        .filter(|r| r.split(',').nth(3) != Some("known"))
        .collect();
    let session = all_rows.len() - rows.len();
    assert!(
        session > 0 && session <= 3 * 40,
        "{session} known stances kept"
    );
    for r in all_rows
        .iter()
        .filter(|r| r.split(',').nth(3) == Some("known"))
    {
        assert!(r.starts_with("session/"), "{r}");
    }
    assert_eq!(rows.len(), on_image.len(), "{table}");
    for (row, v) in rows.iter().zip(&on_image) {
        let cols: Vec<&str> = row.split(',').collect();
        assert_eq!(cols[1], v["foot"].to_string());
        assert_eq!(cols[2], v["step"].to_string());
        assert_eq!(cols[3], v["unknown_reason"].as_str().unwrap());
        assert_eq!(
            cols[5], "",
            "an unknown stance chose no terrain, so no confidence: {row}"
        );
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
    // `presrs discover`: the kept stances give one proposed terrain, the clay the model never
    // saw: at least 80% of the run's clay steps at 90% purity or more.
    let found = dir.join("found");
    let discover = |kept: &std::path::Path, model: &std::path::Path| -> serde_json::Value {
        let out = common::output_ok(
            Command::new(env!("CARGO_BIN_EXE_presrs"))
                .arg("discover")
                .arg(kept)
                .arg("--model")
                .arg(model)
                .arg("--json")
                .arg("--out")
                .arg(&found),
        );
        serde_json::from_slice(&out.stdout).unwrap()
    };
    let d = discover(&kept, &model_path);
    let clay_of = |file: &str| {
        let k = rows
            .iter()
            .position(|r| r.split(',').next() == Some(file))
            .unwrap();
        truth(on_image[k]["t_us"].as_u64().unwrap()).as_deref() == Some("clay")
    };
    let new: Vec<&serde_json::Value> = d["groups"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|g| g["new_ground"] == true)
        .collect();
    assert_eq!(new.len(), 1, "{d}");
    let files: Vec<&str> = new[0]["files"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f.as_str().unwrap())
        .collect();
    let clay_in = files.iter().filter(|f| clay_of(f)).count();
    // Why the node kept them, per reason: counts that add up to the group, each a reason
    // of kept.csv.
    let reasons = new[0]["reasons"].as_object().unwrap();
    let counted: u64 = reasons.values().map(|n| n.as_u64().unwrap()).sum();
    assert_eq!(counted as usize, files.len(), "{d}");
    for r in reasons.keys() {
        assert!(
            rows.iter()
                .any(|row| row.split(',').nth(3) == Some(r.as_str())),
            "{r}: {d}"
        );
    }
    eprintln!(
        "discover: {} groups, the new one {} stances, {clay_in} of them clay (of {clay_steps} clay steps)",
        d["groups"].as_array().unwrap().len(),
        files.len()
    );
    assert!(
        clay_in * 10 >= clay_steps * 8,
        "{clay_in} of {clay_steps}: {d}"
    );
    assert!(
        clay_in * 10 >= files.len() * 9,
        "purity {clay_in}/{}: {d}",
        files.len()
    );
    // Every stance in groups.csv, and a contact sheet per group, read back.
    let groups = std::fs::read_to_string(found.join("groups.csv")).unwrap();
    assert_eq!(groups.lines().count(), all_rows.len() + 1);
    for g in 1..=d["groups"].as_array().unwrap().len() {
        let png = std::fs::read(found.join(format!("group-{g}.png"))).unwrap();
        assert_eq!(&png[1..4], b"PNG");
    }
    // The same run with a model that knows all four terrains: nothing new proposed.
    let full_path = dir.join("full.json");
    common::model_without("none").save(&full_path).unwrap();
    let kept_full = dir.join("kept-full");
    common::output_ok(
        Command::new(env!("CARGO_BIN_EXE_presrs"))
            .args(["node", "--replay", log.to_str().unwrap()])
            .args(["--model", full_path.to_str().unwrap(), "--keep-unknown"])
            .arg(&kept_full),
    );
    if kept_full.join("kept.csv").exists()
        && std::fs::read_to_string(kept_full.join("kept.csv"))
            .unwrap()
            .lines()
            .count()
            > 1
    {
        let d = discover(&kept_full, &full_path);
        assert!(
            d["groups"]
                .as_array()
                .unwrap()
                .iter()
                .all(|g| g["new_ground"] == false),
            "known ground only: {d}"
        );
    }
    // `--add mud`: the group as a terrain. On a fresh run (another seed), the clay steps are
    // mud at 90% or more, and the known terrains lose at most a point against the old model.
    let mud = dir.join("mud.json");
    let terrains = dir.join("terrains.toml");
    let add = |extra: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_presrs"))
            .arg("discover")
            .arg(&kept)
            .arg("--model")
            .arg(&model_path)
            .args(["--add", "mud", "--out-model"])
            .arg(&mud)
            .arg("--terrains")
            .arg(&terrains)
            .args(extra)
            .output()
            .unwrap()
    };
    let o = add(&[]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let said = String::from_utf8_lossy(&o.stderr);
    assert!(said.contains("as `mud` (terrain id 20"), "{said}");
    // Again: the model file exists, refused, nothing overwritten.
    let written = std::fs::read(&mud).unwrap();
    let o = add(&[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("exists"), "{err}");
    assert_eq!(std::fs::read(&mud).unwrap(), written);
    // A name the model has: refused by name.
    let o = Command::new(env!("CARGO_BIN_EXE_presrs"))
        .arg("discover")
        .arg(&kept)
        .arg("--model")
        .arg(&model_path)
        .args(["--add", "wood", "--out-model"])
        .arg(dir.join("wood.json"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("`wood`"), "{err}");
    assert!(!dir.join("wood.json").exists());
    // Groups that are not there, or 0 (the table counts from 1): refused, nothing written
    // (clay: a name of the paper's catalog, which the model left out).
    for bad in ["1,1", "0", "9"] {
        let o = Command::new(env!("CARGO_BIN_EXE_presrs"))
            .arg("discover")
            .arg(&kept)
            .arg("--model")
            .arg(&model_path)
            .args(["--add", "clay", "--group", bad, "--out-model"])
            .arg(dir.join("clay.json"))
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            !o.status.success() && err.contains("--group"),
            "{bad}: {err}"
        );
        assert!(!dir.join("clay.json").exists(), "{bad}");
    }
    // A name the catalog has (the paper's clay, which the model left out): added under the
    // catalog's id, and the terrains file is left as it was, said so.
    let before = std::fs::read(&terrains).unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_presrs"))
        .arg("discover")
        .arg(&kept)
        .arg("--model")
        .arg(&model_path)
        .args(["--add", "clay", "--group", "1", "--out-model"])
        .arg(dir.join("clay.json"))
        .arg("--terrains")
        .arg(&terrains)
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&o.stderr);
    assert!(
        o.status.success() && said.contains("left as it was (the catalog has `clay`)"),
        "{said}"
    );
    assert_eq!(std::fs::read(&terrains).unwrap(), before);
    // The lab's word instead of a group: the kept stances named in a file; and the gait the
    // controller will run there, added to its config with the lab's consent.
    let mine = dir.join("mine.txt");
    std::fs::write(&mine, files.join("\n")).unwrap();
    let ctl = dir.join("controller.toml");
    std::fs::write(&ctl, "safe_gait = 1\n\n[terrain_gaits]\nwood = 3\n").unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_presrs"))
        .arg("discover")
        .arg(&kept)
        .arg("--model")
        .arg(&model_path)
        .args(["--add", "clay", "--stances"])
        .arg(&mine)
        .arg("--controller-config")
        .arg(&ctl)
        .arg("--out-model")
        .arg(dir.join("clay-word.json"))
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{said}");
    assert!(
        said.contains(&format!("--stances: {} of the", files.len())),
        "{said}"
    );
    assert!(said.contains("added `clay = 1` (its safe gait)"), "{said}");
    let cfg = controller::ControllerConfig::load(&ctl).unwrap();
    assert_eq!(cfg.terrain_gaits.get("clay"), Some(&1));
    let word = node::classifier::Model::load(&dir.join("clay-word.json")).unwrap();
    assert_eq!(word.classes.last().map(|c| c.name.as_str()), Some("clay"));
    // Steps that name no kept stance: refused by what it found, nothing written.
    let o = Command::new(env!("CARGO_BIN_EXE_presrs"))
        .arg("discover")
        .arg(&kept)
        .arg("--model")
        .arg(&model_path)
        .args(["--add", "clay", "--stances", "9000-9001", "--out-model"])
        .arg(dir.join("clay-none.json"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("0 stances to add"),
        "{err}"
    );
    assert!(!dir.join("clay-none.json").exists());
    let mut fresh = SimRobot::new(SimConfig::default(), 6);
    let log2 = dir.join("run2.log");
    let mut w = std::io::BufWriter::new(std::fs::File::create(&log2).unwrap());
    let mut t = 0;
    while t < 40_000_000 {
        t += 1000;
        fresh.advance_to(t, &mut |frame| {
            protocol::candump::write_record(&mut w, "vcan0", &Stamped { t_us: t, frame }).unwrap()
        });
    }
    drop(w);
    let decide = |model: &std::path::Path| -> Vec<(String, String)> {
        let out = common::output_ok(
            Command::new(env!("CARGO_BIN_EXE_presrs"))
                .args(["node", "--json", "--replay"])
                .arg(&log2)
                .arg("--model")
                .arg(model)
                .arg("--terrains")
                .arg(&terrains),
        );
        String::from_utf8_lossy(&out.stdout)
            .lines()
            .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
            .filter_map(|v| {
                let t_us = v["t_us"].as_u64()?;
                let truth = fresh
                    .steps
                    .iter()
                    .rev()
                    .find(|s| s.touchdown_us <= t_us)?
                    .terrain
                    .name()
                    .to_string();
                Some((truth, v["terrain"].as_str()?.to_string()))
            })
            .collect()
    };
    let (before, after) = (decide(&model_path), decide(&mud));
    let scratch = decide(&full_path);
    let share = |d: &[(String, String)], known: bool| {
        let on: Vec<_> = d.iter().filter(|(t, _)| (t != "clay") == known).collect();
        let right = on
            .iter()
            .filter(|(t, c)| c == t || (t == "clay" && c == "mud"))
            .count();
        (right as f64 / on.len().max(1) as f64, on.len())
    };
    let ((known_before, n_known), (known_after, _)) = (share(&before, true), share(&after, true));
    let (clay_after, n_clay) = share(&after, false);
    let scratch_tally = {
        let mut m = std::collections::BTreeMap::new();
        for p in &scratch {
            *m.entry(p.clone()).or_insert(0) += 1;
        }
        m
    };
    eprintln!("a model trained on all four from the start: {scratch_tally:?}");
    eprintln!(
        "after --add mud, a fresh run: clay steps mud {:.1}% of {n_clay}; known terrains right \
         {:.1}% -> {:.1}% of {n_known}",
        clay_after * 100.0,
        known_before * 100.0,
        known_after * 100.0
    );
    assert!(clay_after >= 0.9, "{after:?}");
    let tally = |d: &[(String, String)]| {
        let mut m = std::collections::BTreeMap::new();
        for p in d {
            *m.entry(p.clone()).or_insert(0) += 1;
        }
        m
    };
    assert!(
        known_after >= known_before - 0.01,
        "{:?}\n{:?}",
        tally(&before),
        tally(&after)
    );
    // A stance of another sensor size in the keep: refused, naming the file, nothing written.
    let odd = dir.join("odd");
    std::fs::create_dir_all(odd.join("unknown")).unwrap();
    std::fs::copy(kept.join("kept.csv"), odd.join("kept.csv")).unwrap();
    for r in &all_rows {
        let f = r.split(',').next().unwrap();
        if let Some(parent) = odd.join(f).parent() {
            std::fs::create_dir_all(parent).unwrap();
        }
        std::fs::copy(kept.join(f), odd.join(f)).unwrap();
    }
    let first = rows[0].split(',').next().unwrap();
    std::fs::write(
        odd.join(first),
        b"P5\n32 32\n255\n"
            .iter()
            .copied()
            .chain([7u8; 1024])
            .collect::<Vec<u8>>(),
    )
    .unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_presrs"))
        .arg("discover")
        .arg(&odd)
        .arg("--model")
        .arg(&model_path)
        .arg("--out")
        .arg(dir.join("odd-found"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains(first), "{err}");
    assert!(!dir.join("odd-found").exists());
    // A folder that is not a keep: refused, naming what it lacks.
    let o = Command::new(env!("CARGO_BIN_EXE_presrs"))
        .args([
            "discover",
            dir.to_str().unwrap(),
            "--model",
            model_path.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("kept.csv"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}
