//! MCAP recording and the live Foxglove view of the node and the simulator.

use super::*;

/// On real SocketCAN: `presrs node --mcap --foxglove` records and serves the robot's
/// traffic while it classifies, and `presrs lab sim --mcap` records the same run with its truth.
/// An independent WebSocket client receives an image and a TerrainClass live; after SIGTERM
/// Python's `mcap` reads both files whole: a schema on every channel, time going forward, one
/// RawImage per complete image candump saw, one TerrainClass per step the simulator heard.
#[test]
#[ignore = "needs vcan interfaces: tests/vcan/run.sh runs it"]
fn node_and_sim_record_mcap_and_serve_a_live_foxglove_view() {
    let _time = Timed(
        "node_and_sim_record_mcap_and_serve_a_live_foxglove_view",
        Instant::now(),
    );
    let iface = fd_iface();
    let model = system_model();
    let dir = std::env::temp_dir().join(format!("presrs-vcan-mcap-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (node_mcap, sim_mcap) = (dir.join("node.mcap"), dir.join("sim.mcap"));
    // The node binds port 0 and logs the port it got: a port picked here and bound later by
    // the node could be taken in between (the host's live-view test failed a CI run that way).
    let mut node = Proc(
        std::process::Command::new(presrs())
            .args([
                "node",
                "--iface",
                &iface,
                "--model",
                model.to_str().unwrap(),
            ])
            .args([
                "--mcap",
                node_mcap.to_str().unwrap(),
                "--foxglove",
                "127.0.0.1:0",
            ])
            .env("RUST_LOG", "warn,presrs_record=info")
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap(),
    );
    let (port_tx, port_rx) = std::sync::mpsc::channel();
    let node_err = node.0.stderr.take().unwrap();
    std::thread::spawn(move || {
        use std::io::BufRead;
        const SAYS: &str = "Foxglove view on ws://";
        for line in std::io::BufReader::new(node_err)
            .lines()
            .map_while(Result::ok)
        {
            eprintln!("node: {line}");
            if let Some(i) = line.find(SAYS)
                && let Some(addr) = line[i + SAYS.len()..].split(' ').next()
                && let Some(Ok(port)) = addr.rsplit_once(':').map(|(_, p)| p.parse::<u16>())
            {
                let _ = port_tx.send(port);
            }
        }
    });
    let port = port_rx
        .recv_timeout(Duration::from_secs(120))
        .expect("the node named no Foxglove port within 120 s");
    let fox = format!("127.0.0.1:{port}");
    let ready = dir.join("client-ready");
    let mut client = std::process::Command::new("python3")
        .arg(root().join("tests/interop/foxglove_client.py"))
        .arg(format!("ws://{fox}"))
        .args([
            "/foot0/image",
            "/foot0/terrain",
            "--timeout",
            "600",
            "--ready",
        ])
        .arg(&ready)
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // The robot starts once the client is connected: under TCG and a loaded guest the client
    // took up to 80 s to connect, and a simulator started after a fixed 1.5 s had finished
    // its 8 s of robot time before (the client then subscribed in time for nothing).
    let asked = Instant::now();
    while !ready.exists() {
        if let Some(status) = client.try_wait().unwrap() {
            panic!("the Foxglove client ended before it connected: {status}");
        }
        assert!(
            asked.elapsed() < Duration::from_secs(600),
            "the Foxglove client did not connect within 600 s"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    eprintln!(
        "foxglove client connected {:.1} s after it was started",
        asked.elapsed().as_secs_f64()
    );
    let mut report = serde_json::Value::Null;
    let log = candump_during(&iface, "mcap", || {
        report = sim_report(
            &iface,
            &["--mcap", sim_mcap.to_str().unwrap()],
            8.0,
            4,
            "mcap",
        );
    });
    let live = client.wait_with_output().unwrap();
    assert!(
        live.status.success(),
        "foxglove client: {}",
        String::from_utf8_lossy(&live.stdout)
    );
    let got: Vec<serde_json::Value> = String::from_utf8_lossy(&live.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    eprintln!(
        "live view, first messages: image {} terrain {}",
        got[0]["log_time"], got[1]["message"]
    );
    assert_eq!(got[0]["message"]["encoding"], "mono8");
    assert_eq!(got[1]["schema_name"], "presrs.TerrainClass");
    // SIGTERM: the node finishes its file.
    // SAFETY: kill(2) on our own child.
    unsafe {
        libc::kill(node.0.id() as i32, libc::SIGTERM);
    }
    let status = node.0.wait().unwrap();
    assert!(status.success(), "presrs node after SIGTERM: {status}");

    // What candump saw: complete images per foot 0.
    let records =
        protocol::candump::read_log(std::io::BufReader::new(std::fs::File::open(&log).unwrap()))
            .unwrap();
    let ids = protocol::IdConfig::default();
    let mut reasm = protocol::tactile::Reassembler::default();
    let mut images = 0u64;
    for r in &records {
        if let Ok(Some((foot, protocol::Message::TactileSegment(v)))) =
            protocol::messages::decode(&r.stamped.frame, &ids)
            && reasm
                .push(v, foot, r.stamped.frame.data(), r.stamped.t_us)
                .is_some()
        {
            images += 1;
        }
    }
    let heard = report["steps"].as_array().unwrap().len() as u64;
    for (name, file) in [("node", &node_mcap), ("sim", &sim_mcap)] {
        let out = common::output_ok(
            std::process::Command::new("python3")
                .arg(root().join("tests/interop/mcap_check.py"))
                .arg(file),
        );
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        for (topic, c) in v["channels"].as_object().unwrap() {
            assert_eq!(c["schema_encoding"], "jsonschema", "{name} {topic}");
        }
        assert_eq!(v["file_order_nondecreasing"], true, "{name}");
        assert_eq!(v["statistics_messages"], v["messages"], "{name}");
        let n_images = v["images"]["/foot0/image"].as_array().unwrap().len() as u64;
        let steps = v["steps"]["/foot0/terrain"].as_array().unwrap().len() as u64;
        eprintln!(
            "{name}.mcap: {} messages, {n_images} images (candump: {images}), {steps} TerrainClass (sim heard {heard})",
            v["messages"]
        );
        assert_eq!(n_images, images, "{name}: one RawImage per complete image");
        // The node may decide one stance after the simulator stopped listening.
        assert!(
            (heard..=heard + 1).contains(&steps),
            "{name}: one TerrainClass per step"
        );
        if name == "sim" {
            assert!(v["channels"]["/sim/leg0"]["count"].as_u64().unwrap() > 100);
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}
