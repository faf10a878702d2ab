//! Recordings people can look at: `presrs mcap` (a candump log to MCAP), live recording
//! (`--mcap`) and the live Foxglove view (`--foxglove`), each read back by an independent
//! client: Python's `mcap` package (`tests/interop/mcap_check.py`) and a plain WebSocket
//! client speaking the Foxglove protocol (`tests/interop/foxglove_client.py`).

// Without `--features interop` the tests that need Python's packages are left out, and the
// helpers only they use with them.
#![cfg_attr(not(feature = "interop"), allow(unused_imports, dead_code))]
mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use node::{NodeConfig, NodeService};
use protocol::tactile::{Reassembler, pixel_crc};
use protocol::{IdConfig, Message, Stamped};
use serde_json::Value;
use sim::runner::{LOG_EPOCH_US, SimConfig, SimRobot};

fn presrs() -> Command {
    Command::new(env!("CARGO_BIN_EXE_presrs"))
}

fn tempdir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("presrs-mcap-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// `mcap_check.py FILE [--stream]`, parsed.
#[cfg(feature = "interop")]
fn read_mcap(path: &Path, stream: bool) -> Value {
    let mut cmd = Command::new("python3");
    cmd.arg(common::root().join("tests/interop/mcap_check.py"))
        .arg(path);
    if stream {
        cmd.arg("--stream");
    }
    let out = common::output_ok(&mut cmd);
    serde_json::from_slice(&out.stdout).unwrap()
}

/// Every channel has a JSON schema and JSON messages.
fn assert_schemas(v: &Value) {
    let channels = v["channels"].as_object().unwrap();
    assert!(!channels.is_empty());
    for (topic, c) in channels {
        assert_ne!(c["schema_id"], 0, "{topic} has no schema");
        assert_eq!(c["schema_encoding"], "jsonschema", "{topic}");
        assert_eq!(c["schema_is_json"], true, "{topic}");
        assert_eq!(c["message_encoding"], "json", "{topic}");
    }
}

/// Two feet on the default track for `seconds`, with a node deciding every step; the log holds
/// the robot's frames and the node's (TerrainClass, NodeStatus), as candump on the robot's bus
/// would. Returns the log's records.
fn robot_with_node(model: &Path, seconds: u64) -> Vec<Stamped> {
    let cfg = SimConfig {
        feet: 2,
        ..Default::default()
    };
    let mut robot = SimRobot::new(cfg, 5);
    let mut node_cfg = NodeConfig {
        feet: 2,
        ..Default::default()
    };
    node_cfg.refit = node_cfg.refit.reproducible();
    let model = node::classifier::Model::load(model).unwrap();
    let mut node = NodeService::new(node_cfg, model).unwrap();
    let mut log = Vec::new();
    let mut frames = Vec::new();
    let mut said = Vec::new();
    for ms in 1..=seconds * 1000 {
        let t = ms * 1000;
        robot.advance_to(t, &mut frames);
        let t_us = LOG_EPOCH_US + t;
        for frame in frames.drain(..) {
            let st = Stamped { t_us, frame };
            node.tick(t_us, &mut said);
            node.process(&st, &mut said);
            log.push(st);
            for o in said.drain(..) {
                log.push(Stamped {
                    t_us,
                    frame: node.frame(&o).unwrap(),
                });
            }
        }
    }
    log
}

#[test]
#[cfg(feature = "interop")]
fn a_candump_log_becomes_mcap_that_an_independent_reader_takes_whole() {
    let dir = tempdir("log");
    let model = common::small_model(&dir);
    let records = robot_with_node(&model, 8);
    let log = dir.join("run.log");
    let mut w = std::io::BufWriter::new(std::fs::File::create(&log).unwrap());
    for st in &records {
        protocol::candump::write_record(&mut w, "can0", st).unwrap();
    }
    drop(w);
    // What the log holds, by our own decoding: complete images (their CRC) and TerrainClass
    // steps, per foot.
    let ids = IdConfig::default();
    let mut reasm = Reassembler::default();
    let mut images: BTreeMap<u8, Vec<u32>> = BTreeMap::new();
    let mut steps: BTreeMap<u8, Vec<u16>> = BTreeMap::new();
    for st in &records {
        match protocol::messages::decode(&st.frame, &ids).unwrap() {
            Some((foot, Message::TactileSegment(v))) => {
                if let Some(img) = reasm.push(v, foot, st.frame.data(), st.t_us) {
                    images
                        .entry(foot)
                        .or_default()
                        .push(pixel_crc(img.pixels(), img.bits));
                }
            }
            Some((foot, Message::TerrainClass(tc))) => steps.entry(foot).or_default().push(tc.step),
            _ => {}
        }
    }
    assert_eq!(images.len(), 2, "both feet sent images");
    assert!(steps.values().all(|s| s.len() >= 15), "{steps:?}");
    let config = dir.join("node.toml");
    std::fs::write(&config, "feet = 2\n").unwrap();
    let out = dir.join("run.mcap");
    let o = common::output_ok(
        presrs()
            .arg("mcap")
            .arg(&log)
            .arg("--out")
            .arg(&out)
            .arg("--model")
            .arg(&model)
            .arg("--config")
            .arg(&config)
            .arg("--json"),
    );
    let report: Value = serde_json::from_slice(&o.stdout).unwrap();
    let v = read_mcap(&out, false);
    assert_schemas(&v);
    assert_eq!(v["file_order_nondecreasing"], true);
    assert!(
        v["chunks"].as_u64().unwrap() >= 2,
        "chunked: {}",
        v["chunks"]
    );
    assert_eq!(v["statistics_messages"], v["messages"]);
    assert_eq!(v["messages"], report["stats"]["messages"]);
    for foot in [0u8, 1] {
        // One RawImage per complete image, pixel for pixel (the CRC is zlib's over the
        // decoded base64, the transfer's own CRC on our side).
        let got: Vec<u32> = v["images"][format!("/foot{foot}/image")]
            .as_array()
            .unwrap()
            .iter()
            .map(|i| {
                assert_eq!(i[0], 44);
                assert_eq!(i[1], 44);
                assert_eq!(i[2], "mono8");
                i[3].as_u64().unwrap() as u32
            })
            .collect();
        assert_eq!(got, images[&foot], "foot {foot}'s images");
        // One TerrainClass per step, from the log and from the model run on the way.
        let logged: Vec<u64> = v["steps"][format!("/foot{foot}/terrain")]
            .as_array()
            .unwrap()
            .iter()
            .map(|s| s.as_u64().unwrap())
            .collect();
        let want: Vec<u64> = steps[&foot].iter().map(|&s| s as u64).collect();
        assert_eq!(logged, want, "foot {foot}'s logged TerrainClass");
        assert_eq!(
            v["steps"][format!("/foot{foot}/terrain/model")],
            v["steps"][format!("/foot{foot}/terrain")],
            "the model's steps are the node's"
        );
        assert_eq!(
            v["terrains"][format!("/foot{foot}/terrain/model")],
            v["terrains"][format!("/foot{foot}/terrain")],
            "the same node on the same log decides the same"
        );
        assert!(
            v["channels"][format!("/foot{foot}/contact")]["count"]
                .as_u64()
                .unwrap()
                > 10
        );
        assert!(
            v["channels"][format!("/leg{foot}/state")]["count"]
                .as_u64()
                .unwrap()
                > 100
        );
    }
    assert!(v["channels"]["/node/status"]["count"].as_u64().unwrap() >= 70);
    let _ = std::fs::remove_dir_all(&dir);
}

fn stderr_of(cmd: &mut Command) -> (bool, String) {
    let o = cmd.output().unwrap();
    (
        o.status.success(),
        String::from_utf8_lossy(&o.stderr).to_string(),
    )
}

#[test]
fn bad_paths_and_logs_are_named_and_a_live_run_goes_on_without_its_recording() {
    let dir = tempdir("bad");
    let log = dir.join("run.log");
    common::output_ok(
        presrs()
            .args(["lab", "sim", "--duration", "2", "--log"])
            .arg(&log),
    );
    for (out, says) in [
        ("/nonexistent-presrs-dir/x.mcap", "folder does not exist"),
        ("/dev/full", "the disk is full"),
    ] {
        let (ok, err) = stderr_of(presrs().arg("mcap").arg(&log).args(["--out", out]));
        assert!(!ok, "{out}");
        assert!(err.contains(out) && err.contains(says), "{out}: {err}");
    }
    let bad = dir.join("bad.log");
    std::fs::write(
        &bad,
        "(1700000000.000000) can0 123#00\nnot a candump line\n",
    )
    .unwrap();
    let (ok, err) = stderr_of(
        presrs()
            .arg("mcap")
            .arg(&bad)
            .arg("--out")
            .arg(dir.join("x.mcap")),
    );
    assert!(!ok);
    assert!(err.contains("bad.log") && err.contains("line 2"), "{err}");
    assert!(!dir.join("x.mcap").exists(), "no recording from a bad log");

    // Live: the run goes on and ends well; the log names the path and why.
    for (out, says) in [
        (
            "/nonexistent-presrs-dir/x.mcap",
            "running without the recording",
        ),
        ("/dev/full", "the disk is full"),
    ] {
        let (ok, err) = stderr_of(
            presrs()
                .args(["demo", "--steps", "12", "--json", "--csv"])
                .arg(dir.join("steps.csv"))
                .args(["--mcap", out]),
        );
        assert!(ok, "{out}: {err}");
        assert!(err.contains(out) && err.contains(says), "{out}: {err}");
        let steps = std::fs::read_to_string(dir.join("steps.csv")).unwrap();
        assert_eq!(steps.lines().count(), 13, "12 steps and the header");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A demo's stderr, read to the end on a thread (an unread pipe would stall the demo once
/// it fills), and the port of its Foxglove view once the demo has said it.
struct DemoLog {
    text: std::sync::Arc<std::sync::Mutex<String>>,
    port: std::sync::mpsc::Receiver<u16>,
}

impl DemoLog {
    fn read(child: &mut Child) -> DemoLog {
        use std::io::BufRead;
        let text = std::sync::Arc::new(std::sync::Mutex::new(String::new()));
        let (tx, port) = std::sync::mpsc::channel();
        let err = child.stderr.take().unwrap();
        let t = text.clone();
        std::thread::spawn(move || {
            for line in std::io::BufReader::new(err).lines().map_while(Result::ok) {
                if let Some(p) = foxglove_port(&line) {
                    let _ = tx.send(p);
                }
                let mut t = t.lock().unwrap();
                t.push_str(&line);
                t.push('\n');
            }
        });
        DemoLog { text, port }
    }

    /// The port the demo's live view listens on: it binds port 0 and logs the one it got
    /// (a port picked by the test and bound later by the demo can be taken in between).
    fn port(&self) -> u16 {
        self.port
            .recv_timeout(Duration::from_secs(60))
            .unwrap_or_else(|_| panic!("the demo named no Foxglove port:\n{}", self.text()))
    }

    fn text(&self) -> String {
        self.text.lock().unwrap().clone()
    }
}

/// `... Foxglove view on ws://127.0.0.1:36995 (...)` -> 36995.
fn foxglove_port(line: &str) -> Option<u16> {
    const SAYS: &str = "Foxglove view on ws://";
    let addr = line[line.find(SAYS)? + SAYS.len()..].split(' ').next()?;
    addr.rsplit_once(':')?.1.parse().ok()
}

fn signal(child: &Child, sig: i32) {
    // SAFETY: kill(2) on our own child's pid.
    unsafe {
        libc::kill(child.id() as i32, sig);
    }
}

fn wait(child: &mut Child, within: Duration) -> std::process::ExitStatus {
    let end = Instant::now() + within;
    loop {
        if let Some(s) = child.try_wait().unwrap() {
            return s;
        }
        assert!(Instant::now() < end, "the process did not end");
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
#[cfg(feature = "interop")]
fn live_view_serves_images_and_terrain_and_a_killed_recording_keeps_its_chunks() {
    let dir = tempdir("live");
    // Paced to real time by --foxglove: 300 steps is two minutes, longer than the test.
    let demo = |mcap: &str| {
        presrs()
            .args(["demo", "--steps", "300", "--json", "--csv"])
            .arg(dir.join(format!("{mcap}.csv")))
            .arg("--mcap")
            .arg(dir.join(mcap))
            .args(["--foxglove", "127.0.0.1:0"])
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap()
    };
    let mut killed = demo("killed.mcap");
    let mut stopped = demo("stopped.mcap");
    let killed_log = DemoLog::read(&mut killed);
    let stopped_log = DemoLog::read(&mut stopped);
    let port = killed_log.port();
    let client = Command::new("python3")
        .arg(common::root().join("tests/interop/foxglove_client.py"))
        .arg(format!("ws://127.0.0.1:{port}"))
        .args(["/foot0/image", "/foot0/terrain", "/gait", "/sim/leg0"])
        .args(["--timeout", "90"])
        .output()
        .unwrap();
    assert!(
        client.status.success(),
        "foxglove_client.py: {}\n{}{}\nthe demo's log:\n{}",
        client.status,
        String::from_utf8_lossy(&client.stdout),
        String::from_utf8_lossy(&client.stderr),
        killed_log.text()
    );
    let got: Vec<Value> = String::from_utf8_lossy(&client.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let image = &got[0];
    assert_eq!(image["schema_name"], "foxglove.RawImage");
    assert_eq!(image["message"]["width"], 44);
    assert_eq!(image["message"]["encoding"], "mono8");
    assert_eq!(image["message"]["data"].as_str().unwrap().len(), 2584);
    let terrain = &got[1];
    assert_eq!(terrain["schema_name"], "presrs.TerrainClass");
    assert_eq!(terrain["schema_is_json"], true);
    let name = terrain["message"]["Terrain"].as_str().unwrap();
    assert!(
        protocol::TerrainCatalog::paper()
            .iter()
            .any(|t| t.name() == name)
            || name == "unknown",
        "{name}"
    );
    assert!(terrain["message"]["Step"].as_u64().unwrap() >= 1);
    assert!(got[2]["message"]["Omega"].as_f64().unwrap() > 0.0);
    assert!(got[3]["message"]["SpeedMps"].is_number());

    // Both have run at least 3 s of robot time by now (a TerrainClass came), 3 flushes.
    std::thread::sleep(Duration::from_secs(3));
    signal(&killed, libc::SIGKILL);
    signal(&stopped, libc::SIGTERM);
    wait(&mut killed, Duration::from_secs(10));
    let status = wait(&mut stopped, Duration::from_secs(30));
    assert!(
        status.success(),
        "SIGTERM ends the demo normally: {status}\n{}",
        stopped_log.text()
    );

    // Killed: every chunk closed before the kill reads back; the torn tail, if any, is the
    // only loss.
    let k = read_mcap(&dir.join("killed.mcap"), true);
    assert_schemas(&k);
    assert_eq!(k["file_order_nondecreasing"], true);
    let images = k["images"]["/foot0/image"]
        .as_array()
        .map_or(0, |a| a.len());
    assert!(
        images >= 100,
        "at least 1 s of images survived the kill: {images}"
    );
    // Stopped: a complete file, summary and indexes.
    let s = read_mcap(&dir.join("stopped.mcap"), false);
    assert_schemas(&s);
    assert_eq!(s["statistics_messages"], s["messages"]);
    assert_eq!(s["file_order_nondecreasing"], true);
    let steps: Vec<u64> = s["steps"]["/foot0/terrain"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap())
        .collect();
    assert!(steps.len() >= 5, "{steps:?}");
    assert!(
        steps.windows(2).all(|w| w[1] == w[0] + 1),
        "one TerrainClass per step: {steps:?}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// `docs/foxglove-layout.json` shows only topics the recorder writes, and fields their
/// schemas have: a renamed signal breaks this test, not a researcher's layout.
#[test]
fn the_foxglove_layout_names_topics_and_fields_the_recorder_writes() {
    use protocol::MessageKind;
    use record::Topic;
    let text = std::fs::read_to_string(common::root().join("docs/foxglove-layout.json")).unwrap();
    let layout: Value = serde_json::from_str(&text).unwrap();
    let mut topics: BTreeMap<String, Value> = BTreeMap::new();
    let mut all = vec![Topic::Image(0), Topic::ModelTerrain(0), Topic::SimTruth(0)];
    all.extend(MessageKind::ALL.iter().map(|&k| Topic::Message(k, 0)));
    for t in all {
        let schema = match t {
            Topic::Image(_) => record::schema::raw_image(),
            Topic::SimTruth(_) => record::schema::sim_truth(),
            Topic::ModelTerrain(_) => record::schema::message(MessageKind::TerrainClass).unwrap(),
            Topic::Message(k, _) => match record::schema::message(k) {
                Some(s) => s,
                None => continue,
            },
        };
        topics.insert(t.name(), serde_json::from_str(&schema.json).unwrap());
    }
    let mut checked = 0;
    for (id, panel) in layout["configById"].as_object().unwrap() {
        let mut refs: Vec<String> = panel["paths"]
            .as_array()
            .map(|p| {
                p.iter()
                    .map(|x| x["value"].as_str().unwrap().to_string())
                    .collect()
            })
            .unwrap_or_default();
        if let Some(s) = panel["topicPath"].as_str() {
            refs.push(s.to_string());
        }
        if let Some(s) = panel["imageMode"]["imageTopic"].as_str() {
            assert_eq!(topics[s]["title"], "foxglove.RawImage", "{id}");
            checked += 1;
        }
        for r in refs {
            let (topic, field) = match r.rsplit_once('.') {
                Some((t, f)) => (t.to_string(), Some(f.to_string())),
                None => (r.clone(), None),
            };
            let schema = topics
                .get(&topic)
                .unwrap_or_else(|| panic!("{id}: {topic} is not a recorded topic"));
            if let Some(f) = field {
                assert!(
                    schema["properties"][&f].is_object(),
                    "{id}: {topic} has no field {f}"
                );
            }
            checked += 1;
        }
    }
    assert!(checked >= 10, "{checked} references checked");
}
