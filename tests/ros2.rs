//! The robot in ROS 2, checked by clients that are not ours: Python `eclipse-zenoh` subscribes
//! through a Zenoh router by rmw_zenoh's key expressions and liveliness tokens; `rosbags`
//! deserialises every payload (CDR) with `ros2/presrs_msgs` and the standard definitions,
//! recomputes every RIHS01 hash and reads the rosbag2 directories; cantools decodes the same
//! candump log (`tests/interop/ros2_check.py`). Needs those Python packages: `--features interop`.
#![cfg(feature = "interop")]

mod common;

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use serde_json::Value;

fn presrs() -> Command {
    Command::new(env!("CARGO_BIN_EXE_presrs"))
}

fn check_script() -> PathBuf {
    common::root().join("tests/interop/ros2_check.py")
}

fn tempdir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("presrs-ros2-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn dbc(dir: &Path) -> PathBuf {
    let p = dir.join("presrs.dbc");
    common::output_ok(presrs().args(["lab", "dbc", "--out"]).arg(&p));
    p
}

/// `ros2_check.py ARGS`, its JSON summary.
fn check(args: &[&std::ffi::OsStr], env: &[(&str, &str)]) -> Value {
    let mut cmd = Command::new("python3");
    cmd.arg(check_script()).args(args);
    for (k, v) in env {
        cmd.env(k, v);
    }
    let out = common::output_ok(&mut cmd);
    serde_json::from_slice(&out.stdout).unwrap()
}

/// A port nobody listens on now.
fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// A Python process of ros2_check.py, killed when dropped; started once it printed its ready
/// line.
struct Py(Child);

impl Py {
    fn start(args: &[&str]) -> Py {
        let mut child = Command::new("python3")
            .arg(check_script())
            .args(args)
            .stdout(Stdio::piped())
            .spawn()
            .unwrap();
        let mut line = String::new();
        let mut out = BufReader::new(child.stdout.take().unwrap());
        out.read_line(&mut line).unwrap();
        assert!(line.contains("ready"), "ros2_check.py {args:?}: {line}");
        // The rest (the subscriber's summary) is read from its JSON file.
        std::thread::spawn(move || std::io::copy(&mut out, &mut std::io::sink()));
        Py(child)
    }

    fn wait(mut self) {
        let st = self.0.wait().unwrap();
        assert!(st.success(), "ros2_check.py: {st}");
    }
}

impl Drop for Py {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn demo_ros2(port: u16, ns: &str, steps: usize, bag: &Path) -> Command {
    let mut cmd = presrs();
    cmd.args(["demo", "--json", "--steps", &steps.to_string(), "--ros2"])
        .args(["--namespace", ns])
        .args(["--zenoh-connect", &format!("tcp/127.0.0.1:{port}")])
        .arg("--ros2-bag")
        .arg(bag)
        .arg("--csv")
        .arg(bag.with_extension("csv"));
    cmd
}

#[test]
fn the_demo_bag_and_the_logs_bag_equal_the_log_decoded_by_cantools() {
    let dir = tempdir("bag");
    let log = dir.join("demo.log");
    let live = dir.join("live");
    let offline = dir.join("offline");
    common::output_ok(
        presrs()
            .args([
                "demo",
                "--steps",
                "30",
                "--namespace",
                "robot1",
                "--candump",
            ])
            .arg(&log)
            .arg("--ros2-bag")
            .arg(&live)
            .arg("--csv")
            .arg(dir.join("steps.csv")),
    );
    common::output_ok(
        presrs()
            .args(["mcap", "--ros2", "--namespace", "robot1"])
            .arg(&log)
            .arg("--out")
            .arg(&offline),
    );
    let dbc = dbc(&dir);
    let env = [("PRESRS_NS", "/robot1")];
    let mut reports = Vec::new();
    for bag in [&live, &offline] {
        let r = check(
            &[
                "bag".as_ref(),
                bag.as_os_str(),
                dbc.as_os_str(),
                log.as_os_str(),
            ],
            &env,
        );
        assert_eq!(r["checked"]["TerrainClass_F0"], 30, "{r}");
        assert!(
            r["checked"]["FootContact_F0"].as_u64().unwrap() > 100,
            "{r}"
        );
        assert!(r["checked"]["LegState_F0"].as_u64().unwrap() > 100, "{r}");
        assert!(r["checked"]["GaitStatus_F0"].as_u64().unwrap() > 0, "{r}");
        assert!(r["diagnostics"].as_u64().unwrap() > 0, "{r}");
        assert!(
            r["images"]["/robot1/foot0/image"].as_u64().unwrap() > 100,
            "{r}"
        );
        reports.push(r);
    }
    // Live and offline: the same messages.
    assert_eq!(reports[0], reports[1]);
    // A second bag into the same directory is refused, saying why.
    let again = presrs()
        .args(["mcap", "--ros2"])
        .arg(&log)
        .arg("--out")
        .arg(&offline)
        .output()
        .unwrap();
    assert!(!again.status.success());
    assert!(
        String::from_utf8_lossy(&again.stderr).contains("already exists"),
        "{}",
        String::from_utf8_lossy(&again.stderr)
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `presrs mcap --ros2 LOG --model M`: the model's decisions on `footN/terrain/model` beside
/// the log's, equal to `presrs node --replay LOG --model M --csv`'s rows (unknown ground with a
/// NaN confidence, an empty one in the CSV), and every topic offered with the bridge's QoS,
/// read back by rosbags and Python's `mcap`.
#[test]
fn the_logs_bag_carries_the_models_decisions_as_the_step_table_lists_them() {
    let dir = tempdir("model");
    let log = dir.join("sand.log");
    common::output_ok(
        presrs()
            .args(["demo", "--steps", "40", "--track"])
            .arg(common::root().join("examples/sand-track.toml"))
            .arg("--candump")
            .arg(&log)
            .env("XDG_CACHE_HOME", &dir),
    );
    let model = common::small_model(&dir);
    let csv = dir.join("steps.csv");
    common::output_ok(
        presrs()
            .args(["node", "--replay"])
            .arg(&log)
            .arg("--model")
            .arg(&model)
            .arg("--csv")
            .arg(&csv),
    );
    let bag = dir.join("bag");
    common::output_ok(
        presrs()
            .args(["mcap", "--ros2"])
            .arg(&log)
            .arg("--out")
            .arg(&bag)
            .arg("--model")
            .arg(&model),
    );
    let text = std::fs::read_to_string(&csv).unwrap();
    let rows = text.lines().count() - 1;
    assert!(rows >= 38, "{rows} steps in the table");
    assert!(
        text.lines()
            .any(|l| l.contains(",unknown,") && l.split(',').nth(6) == Some("")),
        "no unknown step (sand is not the model's) in\n{text}"
    );
    let r = check(&["model".as_ref(), bag.as_os_str(), csv.as_os_str()], &[]);
    assert_eq!(r["compared"], rows as u64, "{r}");
    assert_eq!(
        (r["version"].as_u64(), r["ros_distro"].as_str()),
        (Some(9), Some("jazzy"))
    );
    let qos = &r["qos"]["/foot0/terrain/model"];
    assert_eq!(
        (
            &qos["reliability"],
            &qos["durability"],
            &qos["history"],
            &qos["depth"]
        ),
        (
            &"reliable".into(),
            &"volatile".into(),
            &"keep_last".into(),
            &10.into()
        ),
        "{r}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The subscriber's JSON file.
fn read_json(p: &Path) -> Value {
    serde_json::from_slice(&std::fs::read(p).unwrap()).unwrap()
}

fn stop_subscriber(out: &Path, sub: Py) {
    std::fs::write(out.with_extension("json.stop"), b"").unwrap();
    sub.wait();
}

#[test]
fn a_zenoh_subscriber_sees_the_tokens_the_hashes_and_every_message() {
    let dir = tempdir("zenoh");
    let port = free_port();
    let _router = Py::start(&["router", &port.to_string()]);
    let out = dir.join("sub.json");
    let sub = Py::start(&["subscribe", &port.to_string(), out.to_str().unwrap(), "120"]);
    let bag = dir.join("bag");
    let demo = common::output_ok(&mut demo_ros2(port, "robot1", 40, &bag));
    let summary: Value = serde_json::from_slice(&demo.stdout).unwrap();
    assert_eq!(summary["falls"], 0);
    stop_subscriber(&out, sub);
    // Every message of the bag (the same messages the demo put on Zenoh), once, in order.
    let live = check(&["live".as_ref(), out.as_os_str(), bag.as_os_str()], &[]);
    assert!(
        live["topics"]["/robot1/foot0/terrain"].as_u64().unwrap() == 40,
        "{live}"
    );
    let sub = read_json(&out);
    // rosbags' RIHS01 of each type equals ours (the subscriber checked each key; here every
    // type was seen).
    let hashes = sub["hashes"].as_object().unwrap();
    for t in [
        "presrs_msgs/msg/TerrainClass",
        "presrs_msgs/msg/FootContact",
        "presrs_msgs/msg/GaitState",
        "presrs_msgs/msg/StepState",
        "sensor_msgs/msg/Image",
        "sensor_msgs/msg/JointState",
        "diagnostic_msgs/msg/DiagnosticArray",
    ] {
        assert!(hashes.contains_key(t), "no {t} seen: {hashes:?}");
    }
    // rmw_zenoh's graph: the node's token and one publisher token per topic, with the
    // topic's type and hash.
    let tokens: Vec<&str> = sub["tokens"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| t.as_str().unwrap())
        .collect();
    assert!(
        tokens
            .iter()
            .any(|t| t.starts_with("@ros2_lv/0/") && t.ends_with("/0/0/NN/%/%robot1/presrs_bridge")),
        "{tokens:?}"
    );
    for (topic, t) in sub["topics"].as_object().unwrap() {
        let mangled = topic.replace('/', "%");
        let hash = &hashes[t["type"].as_str().unwrap()];
        assert!(
            tokens.iter().any(
                |k| k.contains(&format!("/MP/%/%robot1/presrs_bridge/{mangled}/"))
                    && k.contains(hash.as_str().unwrap())
            ),
            "no publisher token for {topic}: {tokens:?}"
        );
        // One GID per publisher, sequence numbers from 1.
        assert_eq!(t["gids"].as_array().unwrap().len(), 1, "{topic}");
        assert_eq!(t["seqs"][0], 1, "{topic}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Messages on `topic` in a bag's metadata.yaml.
fn bag_count(bag: &Path, topic: &str) -> u64 {
    let meta = std::fs::read_to_string(bag.join("metadata.yaml")).unwrap();
    let at = meta
        .find(&format!("name: \"{topic}\""))
        .unwrap_or_else(|| panic!("{topic} not in {}", bag.display()));
    let rest = &meta[at..];
    let i = rest.find("      message_count: ").unwrap() + "      message_count: ".len();
    rest[i..].lines().next().unwrap().trim().parse().unwrap()
}

fn now_s() -> f64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap()
        .as_secs_f64()
}

/// Demos of `robots` on the router at `port`, each with its bag under `dir`, started at once.
fn start_demos(port: u16, robots: &[&str], steps: usize, dir: &Path) -> Vec<Child> {
    robots
        .iter()
        .map(|r| {
            demo_ros2(port, r, steps, &dir.join(r))
                .stdout(Stdio::piped())
                .stderr(Stdio::piped())
                .spawn()
                .unwrap()
        })
        .collect()
}

/// Waits for the demos; each ran without a fall.
fn wait_demos(demos: Vec<Child>, robots: &[&str]) {
    for (d, r) in demos.into_iter().zip(robots) {
        let o = d.wait_with_output().unwrap();
        assert!(
            o.status.success(),
            "{r}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        let s: Value = serde_json::from_slice(&o.stdout).unwrap();
        // The robots keep hopping whatever the network does.
        assert_eq!(s["falls"], 0, "{r}");
    }
}

#[test]
fn a_fleet_on_one_router_every_message_once_in_order_and_a_router_restart() {
    let dir = tempdir("fleet");
    let port = free_port();
    let router = Py::start(&["router", &port.to_string()]);
    let out = dir.join("sub.json");
    let sub = Py::start(&["subscribe", &port.to_string(), out.to_str().unwrap(), "300"]);
    // Two robots, one router, one subscriber: everything each published.
    let fleet = ["robot1", "robot2"];
    wait_demos(start_demos(port, &fleet, 150, &dir), &fleet);
    // Two more, and mid-run the router goes away for a second and comes back on its port.
    let restarted_fleet = ["robot3", "robot4"];
    let t0 = Instant::now();
    let demos = start_demos(port, &restarted_fleet, 1200, &dir);
    std::thread::sleep(Duration::from_secs(3));
    drop(router);
    let killed = now_s();
    std::thread::sleep(Duration::from_secs(1));
    let _router = Py::start(&["router", &port.to_string()]);
    let restarted = now_s();
    wait_demos(demos, &restarted_fleet);
    assert!(
        t0.elapsed() > Duration::from_secs(6),
        "the demos ended before the router was back: make them longer"
    );
    stop_subscriber(&out, sub);
    let bags: Vec<PathBuf> = fleet.iter().map(|r| dir.join(r)).collect();
    let mut args: Vec<&std::ffi::OsStr> = vec!["live".as_ref(), out.as_os_str()];
    args.extend(bags.iter().map(|b| b.as_os_str()));
    let live = check(&args, &[]);
    for r in fleet {
        let n = bag_count(&dir.join(r), &format!("/{r}/foot0/terrain"));
        assert_eq!(live["topics"][format!("/{r}/foot0/terrain")], n, "{live}");
    }
    let sub = read_json(&out);
    for r in restarted_fleet {
        let topic = format!("/{r}/foot0/terrain");
        let t = &sub["topics"][&topic];
        let seqs: Vec<u64> = t["seqs"]
            .as_array()
            .unwrap_or_else(|| panic!("nothing on {topic}"))
            .iter()
            .map(|v| v.as_u64().unwrap())
            .collect();
        // Each once, in order; only the outage's messages missing.
        assert!(seqs.windows(2).all(|w| w[0] < w[1]), "{topic}: {seqs:?}");
        let recv: Vec<f64> = t["recv"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        let before = recv.iter().filter(|&&x| x < killed).count();
        let first_after = recv.iter().copied().find(|&x| x > restarted);
        assert!(before > 0, "{topic}: nothing before the router was killed");
        let resumed = first_after.map(|x| x - restarted);
        assert!(
            resumed.is_some_and(|d| d <= 2.0),
            "{topic}: publishing resumed {resumed:?} s after the router came back (at most 2 s)"
        );
        // Everything but the outage: each gap in the sequence lies around it (the messages
        // on either side were sent before it ended and after it began), and the last message
        // the robot published arrived.
        let src: Vec<f64> = t["src"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        for (i, w) in seqs.windows(2).enumerate() {
            if w[1] > w[0] + 1 {
                assert!(
                    src[i] <= restarted + 2.0 && src[i + 1] >= killed - 0.5,
                    "{topic}: messages {}..{} lost at {:.2}..{:.2} s, not around the outage \
                     ({:.2}..{:.2} s)",
                    w[0] + 1,
                    w[1] - 1,
                    src[i],
                    src[i + 1],
                    killed,
                    restarted
                );
            }
        }
        let n = bag_count(&dir.join(r), &topic);
        assert_eq!(
            *seqs.last().unwrap(),
            n,
            "{topic}: the last message is missing"
        );
        let missing = n as usize - seqs.len();
        eprintln!(
            "{topic}: {} received of {n} (seq), {missing} lost in the outage, resumed after {:.2} s",
            seqs.len(),
            resumed.unwrap_or(f64::NAN)
        );
        assert!(
            missing as f64 <= n as f64 * 0.5,
            "{topic}: {missing} of {n} lost"
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
