//! candump logs of our traffic, decoded by our reader and by cantools (someone else's).

use super::*;

#[test]
#[ignore = "needs vcan interfaces: tests/vcan/run.sh runs it"]
fn candump_records_our_traffic_and_both_readers_decode_it() {
    let _time = Timed(
        "candump_records_our_traffic_and_both_readers_decode_it",
        Instant::now(),
    );
    let ids = IdConfig::default();
    let iface = fd_iface();
    let log_path = std::env::temp_dir().join(format!("presrs-candump-{}.log", std::process::id()));
    let file = std::fs::File::create(&log_path).unwrap();
    let mut candump = std::process::Command::new("candump")
        .args(["-L", &iface])
        .stdout(file)
        .spawn()
        .expect("candump from can-utils must be installed (apt-get install can-utils)");
    std::thread::sleep(Duration::from_millis(500));
    let mut tx = open(&iface);
    let mut rng = rand::rngs::StdRng::seed_from_u64(5);
    let mut sent = Vec::new();
    for foot in 0..3u8 {
        for m in random_messages(&mut rng, foot) {
            let f = m.to_frame(&ids, foot).unwrap();
            tx.send(&f).unwrap();
            sent.push(f);
        }
        let px: Vec<u16> = (0..44 * 44).map(|_| rng.random_range(0..256)).collect();
        for f in frames_44x44(&ids, Variant::Fd, foot, 0, 0, &px) {
            tx.send(&f).unwrap();
            sent.push(f);
        }
    }
    std::thread::sleep(Duration::from_millis(700));
    let _ = candump.kill();
    let _ = candump.wait();
    let text = std::fs::read_to_string(&log_path).unwrap();
    let recs = protocol::candump::read_log(text.as_bytes()).unwrap();
    let frames: Vec<_> = recs.iter().map(|r| r.stamped.frame).collect();
    assert_eq!(frames, sent, "candump's log differs from what we sent");
    let dbc = root().join("protocol/presrs.dbc");
    let out = python(&["log", dbc.to_str().unwrap(), log_path.to_str().unwrap()]);
    let v: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
    assert_eq!(v["frames"].as_u64(), Some(sent.len() as u64));
    assert_eq!(v["tactile_headers"].as_u64(), Some(3));
}

#[test]
#[ignore = "needs vcan interfaces: tests/vcan/run.sh runs it"]
fn sim_traffic_is_recorded_by_candump_and_decoded_by_cantools() {
    let _time = Timed(
        "sim_traffic_is_recorded_by_candump_and_decoded_by_cantools",
        Instant::now(),
    );
    let iface = fd_iface();
    let log_path = candump_during(&iface, "simdump", || {
        let status = std::process::Command::new(presrs())
            .args([
                "lab",
                "sim",
                "--iface",
                &iface,
                "--duration",
                "3",
                "--seed",
                "2",
            ])
            .status()
            .unwrap();
        assert!(status.success());
    });
    let dbc = root().join("protocol/presrs.dbc");
    let out = python(&["log", dbc.to_str().unwrap(), log_path.to_str().unwrap()]);
    let v: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
    eprintln!("presrs lab sim, 3 s simulated, as candump logged and cantools decoded it: {v}");
    // 100 Hz for 3 s: 300 images, each a header + 32 pixel segments; LegState at 100 Hz.
    let images = v["tactile_headers"].as_u64().unwrap();
    assert!((295..=301).contains(&images), "{images} tactile images");
    assert!(v["kinds"]["LegState"].as_u64().unwrap() >= 295);
    assert!(
        v["kinds"]["FootContact"].as_u64().unwrap() >= 6,
        "a few steps with bounce"
    );
}
