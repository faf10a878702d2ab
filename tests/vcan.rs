//! The vcan suite: real SocketCAN sockets on a virtual CAN interface.
//!
//! Needs `vcan0` up with MTU 72 (CAN FD) and `vcan1` up with MTU 16 (classic only); names can be
//! changed with PRESRS_VCAN and PRESRS_VCAN_CLASSIC (tests/vcan/lanes.sh runs two lanes of tests
//! at once, the second on vcan2 and vcan3, and sets the four up). `tests/vcan/run.sh` runs
//! this suite through it, in User-mode Linux (or a virtme-ng VM) when this kernel has no CAN.
//! Behind the `vcan` feature, and each test ignored, so that `cargo test` does not need CAN:
//! ./test-all.sh's `cargo test --features interop,vcan` builds this binary with the rest (a
//! build of it alone recompiled part of the workspace, 84 s) and lists its tests as ignored;
//! run.sh runs them all (`--include-ignored`) and fails when fewer pass than the binary lists.
#![cfg(feature = "vcan")]

mod common;

use std::time::{Duration, Instant};

use common::*;
use protocol::bus::{CanBus, SocketCanBus};
use protocol::ids::{IdConfig, MessageKind};
use protocol::messages::decode;
use protocol::tactile::{ImageRef, Reassembler, Segmenter, Variant};
use protocol::{BusError, Message};
use rand::{Rng, SeedableRng};

fn fd_iface() -> String {
    std::env::var("PRESRS_VCAN").unwrap_or_else(|_| "vcan0".into())
}
fn classic_iface() -> String {
    std::env::var("PRESRS_VCAN_CLASSIC").unwrap_or_else(|_| "vcan1".into())
}

/// Says how long its test took when dropped (also when the test fails), for the suite's time
/// budget: the emulated kernel's tests are most of the test command (tests/vcan/lanes.sh runs them alone or
/// in two lanes, and says which).
struct Timed(&'static str, Instant);

impl Drop for Timed {
    fn drop(&mut self) {
        eprintln!(
            "vcan test {} took {:.1} s",
            self.0,
            self.1.elapsed().as_secs_f64()
        );
    }
}

fn open(iface: &str) -> SocketCanBus {
    SocketCanBus::open(iface).unwrap_or_else(|e| panic!("{e}"))
}

#[test]
#[ignore = "needs vcan interfaces: tests/vcan/run.sh runs it"]
fn every_message_round_trips_through_the_kernel() {
    let _time = Timed(
        "every_message_round_trips_through_the_kernel",
        Instant::now(),
    );
    let ids = IdConfig::default();
    let iface = fd_iface();
    let mut tx = open(&iface);
    let mut rx = open(&iface);
    let mut rng = rand::rngs::StdRng::seed_from_u64(1);
    let mut sent = Vec::new();
    for foot in 0..8u8 {
        for m in random_messages(&mut rng, foot) {
            tx.send(&m.to_frame(&ids, foot).unwrap()).unwrap();
            sent.push((foot, m));
        }
    }
    let mut got = Vec::new();
    let mut last_t = 0;
    while got.len() < sent.len() {
        let st = rx
            .recv(Duration::from_secs(2))
            .unwrap()
            .expect("frame lost in the kernel");
        assert!(st.t_us >= last_t, "kernel timestamps go backwards");
        assert!(
            st.t_us > 1_600_000_000_000_000,
            "no kernel receive timestamp: {}",
            st.t_us
        );
        last_t = st.t_us;
        let (foot, m) = decode(&st.frame, &ids).unwrap().unwrap();
        got.push((foot, m));
    }
    for ((fa, a), (fb, b)) in sent.iter().zip(&got) {
        assert_eq!(a, b);
        if a.kind().per_foot() {
            assert_eq!(fa, fb);
        }
    }
    // Tactile segments: both variants through the kernel.
    for v in [Variant::Fd, Variant::Classic] {
        let px: Vec<u16> = (0..44 * 44).map(|_| rng.random_range(0..256)).collect();
        let frames = frames_44x44(&ids, v, 4, 9, 1, &px);
        for f in &frames {
            tx.send(f).unwrap();
        }
        let n = frames.len();
        let mut r = Reassembler::default();
        let mut img = None;
        for _ in 0..n {
            let st = rx
                .recv(Duration::from_secs(2))
                .unwrap()
                .expect("segment lost");
            assert_eq!(st.frame.is_fd(), v == Variant::Fd);
            assert_eq!(st.frame.is_brs(), v == Variant::Fd);
            let Ok(Some((foot, Message::TactileSegment(var)))) = decode(&st.frame, &ids) else {
                panic!("not tactile")
            };
            if let Some(i) = r.push(var, foot, st.frame.data(), st.t_us) {
                img = Some(i.pixels().to_vec());
            }
        }
        assert_eq!(img.as_deref(), Some(&px[..]), "{v:?}");
    }
}

#[test]
#[ignore = "needs vcan interfaces: tests/vcan/run.sh runs it"]
fn images_stream_at_100_hz_for_10_s_none_lost() {
    let _time = Timed("images_stream_at_100_hz_for_10_s_none_lost", Instant::now());
    let ids = IdConfig::default();
    let iface = fd_iface();
    let mut rx = open(&iface);
    rx.set_filters(&ids.filters(&[MessageKind::TactileFrame]))
        .unwrap();
    let tx_ids = ids.clone();
    let tx_iface = iface.clone();
    const N: usize = 1000;
    let sender = std::thread::spawn(move || {
        let mut tx = open(&tx_iface);
        let seg = Segmenter::new(Variant::Fd, tx_ids);
        let start = Instant::now();
        let mut px = vec![0u16; 44 * 44];
        for k in 0..N {
            for (i, p) in px.iter_mut().enumerate() {
                *p = ((i * 7 + k * 13) % 256) as u16;
            }
            seg.frames(
                0,
                k as u8,
                &ImageRef {
                    rows: 44,
                    cols: 44,
                    bits: 8,
                    timestamp_us: (k * 10_000) as u32,
                    pixels: &px,
                },
                &mut |f: protocol::CanFrame| {
                    // A full queue on vcan is transient: retry briefly, as a driver would.
                    let mut tries = 0;
                    while let Err(e) = tx.send(&f) {
                        tries += 1;
                        assert!(tries < 1000, "send failed: {e}");
                        std::thread::sleep(Duration::from_micros(100));
                    }
                },
            )
            .unwrap();
            let next = start + Duration::from_millis(10 * (k as u64 + 1));
            if let Some(d) = next.checked_duration_since(Instant::now()) {
                std::thread::sleep(d);
            }
        }
        start.elapsed()
    });
    let mut r = Reassembler::default();
    let mut delivered = 0;
    let mut wrong = 0;
    let deadline = Instant::now() + Duration::from_secs(60);
    while delivered < N && Instant::now() < deadline {
        let Some(st) = rx.recv(Duration::from_millis(500)).unwrap() else {
            continue;
        };
        if let Some(img) = r.push(Variant::Fd, 0, st.frame.data(), st.t_us) {
            let k = (img.timestamp_us / 10_000) as usize;
            if img
                .pixels()
                .iter()
                .enumerate()
                .any(|(i, p)| *p != ((i * 7 + k * 13) % 256) as u16)
            {
                wrong += 1;
            }
            delivered += 1;
        }
    }
    let took = sender.join().unwrap();
    println!(
        "streamed {delivered} images of 44x44 in {took:?}; reassembly stats {:?}",
        r.stats()
    );
    assert_eq!(wrong, 0);
    assert_eq!(delivered, N, "images lost: {:?}", r.stats());
    assert!(
        took >= Duration::from_millis(9_900),
        "not paced at 100 Hz: {took:?}"
    );
}

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
fn fd_frames_on_a_classic_interface_get_a_clear_error() {
    let _time = Timed(
        "fd_frames_on_a_classic_interface_get_a_clear_error",
        Instant::now(),
    );
    let iface = classic_iface();
    assert_eq!(
        protocol::bus::interface_mtu(&iface),
        Some(16),
        "{iface} must be a classic (MTU 16) vcan"
    );
    let mut tx = open(&iface);
    let f = protocol::CanFrame::fd(
        protocol::frame::make_id(0x600, false).unwrap(),
        &[0; 64],
        true,
    )
    .unwrap();
    let e = tx.send(&f).unwrap_err();
    assert!(matches!(e, BusError::FdNotSupported { .. }), "{e:?}");
    let msg = e.to_string();
    assert!(
        msg.contains("MTU 16") && msg.contains("mtu 72") && msg.contains("classic tactile variant"),
        "{msg}"
    );
    // Classic frames still go.
    let c = protocol::CanFrame::classic(protocol::frame::make_id(0x100, false).unwrap(), &[1; 8])
        .unwrap();
    tx.send(&c).unwrap();
}

#[test]
#[ignore = "needs vcan interfaces: tests/vcan/run.sh runs it"]
fn a_classic_socket_never_sees_fd_frames() {
    let _time = Timed("a_classic_socket_never_sees_fd_frames", Instant::now());
    use socketcan::{CanSocket, Socket};
    let iface = fd_iface();
    let classic = CanSocket::open(&iface).unwrap();
    classic
        .set_read_timeout(Duration::from_millis(300))
        .unwrap();
    let mut fd_rx = open(&iface);
    let mut tx = open(&iface);
    let f = protocol::CanFrame::fd(
        protocol::frame::make_id(0x600, false).unwrap(),
        &[3; 64],
        true,
    )
    .unwrap();
    tx.send(&f).unwrap();
    assert!(fd_rx.recv(Duration::from_secs(1)).unwrap().is_some());
    assert!(
        classic.read_frame().is_err(),
        "a classic CanSocket received an FD frame"
    );
}

#[test]
#[ignore = "needs vcan interfaces: tests/vcan/run.sh runs it"]
fn missing_interface_names_the_fix() {
    let _time = Timed("missing_interface_names_the_fix", Instant::now());
    let e = SocketCanBus::open("nosuchcan9")
        .err()
        .expect("opened a missing interface");
    let msg = e.to_string();
    assert!(
        msg.contains("nosuchcan9") && msg.contains("vcan-setup.sh"),
        "{msg}"
    );
}

// ---- System tests: `presrs sim`, `presrs node` and `presrs controller` as separate processes
// on vcan0, watched by the test through its own socket.

/// The binary under test: PRESRS_BIN (run.sh passes the release build: the simulator must keep
/// real time, in the VM too), else this build's.
fn presrs() -> std::path::PathBuf {
    std::env::var_os("PRESRS_BIN")
        .map(Into::into)
        .unwrap_or_else(|| env!("CARGO_BIN_EXE_presrs").into())
}

/// A model trained on simulated G2 stances; run.sh makes it on the host (PRESRS_MODEL).
fn system_model() -> std::path::PathBuf {
    let p: std::path::PathBuf = std::env::var_os("PRESRS_MODEL").map(Into::into).expect(
        "PRESRS_MODEL must name a model (tests/vcan/run.sh trains one on simulated G2 data)",
    );
    assert!(p.exists(), "PRESRS_MODEL {} does not exist", p.display());
    p
}

/// A child process killed when dropped, so that a failing test leaves nothing running.
struct Proc(std::process::Child);

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Waits (at most `limit` of wall time) for a NodeStatus: the node has its model and is on the bus.
fn wait_for_heartbeat(watch: &mut SocketCanBus, ids: &IdConfig, limit: Duration) -> bool {
    let t0 = Instant::now();
    while t0.elapsed() < limit {
        if let Ok(Some(st)) = watch.recv(Duration::from_millis(50))
            && let Ok(Some((_, Message::NodeStatus(_)))) = decode(&st.frame, ids)
        {
            return true;
        }
    }
    false
}

/// `presrs ARGS` at real-time priority (SCHED_FIFO 20, `chrt`), as a robot runs its motor
/// loop (docs/real-robot.md); as [`spawn`] where this machine does not allow it. Under
/// emulation the simulator takes most of the one CPU, and the leg's bridge and controller,
/// commanding motors at 500 Hz, waited behind it: in User-mode Linux at 0.5, 2 of 3 runs of
/// the leg test fell (at gait switches, 1.7-2.7 robot s) as plain processes, 0 of 3 at
/// real-time priority.
fn spawn_rt(args: &[&str]) -> Proc {
    static RT: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    let rt = *RT.get_or_init(|| {
        let ok = std::process::Command::new("chrt")
            .args(["-f", "20", "true"])
            .status()
            .is_ok_and(|s| s.success());
        if !ok {
            eprintln!("chrt -f 20 not allowed here: the leg's processes run at normal priority");
        }
        ok
    });
    if !rt {
        return spawn(args);
    }
    Proc(
        std::process::Command::new("chrt")
            .args(["-f", "20"])
            .arg(presrs())
            .args(args)
            .env("RUST_LOG", "warn")
            .spawn()
            .unwrap_or_else(|e| panic!("starting presrs {args:?} under chrt: {e}")),
    )
}

fn spawn(args: &[&str]) -> Proc {
    Proc(
        std::process::Command::new(presrs())
            .args(args)
            .env("RUST_LOG", "warn")
            .spawn()
            .unwrap_or_else(|e| panic!("starting presrs {args:?}: {e}")),
    )
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
            .args(["sim", "--iface", &iface, "--duration", "3", "--seed", "2"])
            .status()
            .unwrap();
        assert!(status.success());
    });
    let dbc = root().join("protocol/presrs.dbc");
    let out = python(&["log", dbc.to_str().unwrap(), log_path.to_str().unwrap()]);
    let v: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
    eprintln!("presrs sim, 3 s simulated, as candump logged and cantools decoded it: {v}");
    // 100 Hz for 3 s: 300 images, each a header + 32 pixel segments; LegState at 100 Hz.
    let images = v["tactile_headers"].as_u64().unwrap();
    assert!((295..=301).contains(&images), "{images} tactile images");
    assert!(v["kinds"]["LegState"].as_u64().unwrap() >= 295);
    assert!(
        v["kinds"]["FootContact"].as_u64().unwrap() >= 6,
        "a few steps with bounce"
    );
}

/// A fault of the drill below, at robot times (s).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Fault {
    /// `ip link set IFACE down`, then up.
    LinkDown,
    /// Error frames: error-passive, then bus-off, then the controller restarted.
    ErrorFrames,
    /// The node stopped (SIGSTOP), then continued.
    NodeStop,
    /// The node killed, then started again.
    NodeRestart,
    /// The controller killed, then started again.
    ControllerRestart,
}

/// `kill -SIG pid` (the test runs as root in the VM, or as the processes' owner).
fn signal(p: &Proc, sig: &str) {
    let ok = std::process::Command::new("kill")
        .args([sig, &p.0.id().to_string()])
        .status()
        .is_ok_and(|s| s.success());
    assert!(ok, "kill {sig} {}", p.0.id());
}

fn ip_link(iface: &str, state: &str) {
    let ok = std::process::Command::new("ip")
        .args(["link", "set", iface, state])
        .status()
        .is_ok_and(|s| s.success());
    assert!(ok, "ip link set {iface} {state} (needs root)");
}

/// Issues 6 and 28: simulator, node and controller as processes on vcan, in a 40 s run with one
/// fault at a time: the link down 1 s, error frames (error-passive, bus-off, restarted), the
/// node stopped 1.5 s, the node killed for 3 s, the controller killed for 1 s. Asserts survival
/// (every process answers after each fault), recovery (the first TerrainClass within 2 steps of
/// each fault's end, the safe gait while the node is silent past the controller's timeout, the
/// node's state and BusErrors from the error frames, a LatencyUs that shows the stall), the
/// terrain switches outside the faults, and no fall.
#[test]
#[ignore = "needs vcan interfaces: tests/vcan/run.sh runs it"]
fn sim_node_and_controller_as_processes_classify_steps_and_survive_bus_and_process_faults() {
    let _time = Timed(
        "sim_node_and_controller_as_processes_classify_steps_and_survive_bus_and_process_faults",
        Instant::now(),
    );
    use protocol::messages::{GaitReason, NodeState};
    let iface = fd_iface();
    let ids = IdConfig::default();
    let model = system_model();
    let model_s = model.to_str().unwrap();
    let report = std::env::temp_dir().join(format!("presrs-loop-{}.json", std::process::id()));
    let mut watch = open(&iface);
    // The robot's time runs at `speed` of the wall clock: under TCG emulation the simulator
    // cannot keep real time (3 s simulated took 5.4 s alone). The node runs on the foot's
    // timestamps; the controller is told the rate. Times below are in robot time.
    let speed = system_speed();
    let speed_s = speed.to_string();
    let wall = |robot_s: f64| Duration::from_secs_f64(robot_s / speed);
    let mut node = spawn(&["node", "--iface", &iface, "--model", model_s]);
    // The controller runs the simulator's leg (foot 0): it sends the stance law and the
    // touchdown angle, and switches gait per the node's terrain.
    let controller_args = ["controller", "--iface", &iface, "--time-scale", &speed_s];
    let mut controller = spawn(&controller_args);
    std::thread::sleep(Duration::from_millis(1500));
    let sim_s = 40.0;
    let mut sim = spawn(&[
        "sim",
        "--iface",
        &iface,
        "--duration",
        &sim_s.to_string(),
        "--seed",
        "3",
        "--speed",
        &speed_s,
        "--report",
        report.to_str().unwrap(),
    ]);
    // (fault, start, end), robot time from the simulator's start.
    // Packed so that terrain changes before the first and after the last are still judged
    // (changes come every 3-5 s; 5 of them fall outside the faults' windows): each robot second
    // costs about three in the VM, where this test is the suite's third-longest.
    let schedule = [
        (Fault::LinkDown, 7.5, 8.5),
        (Fault::ErrorFrames, 11.5, 13.0),
        (Fault::NodeStop, 15.0, 16.5),
        (Fault::NodeRestart, 19.0, 22.0),
        (Fault::ControllerRestart, 25.0, 26.0),
    ];
    // Per fault: wall time it started and ended.
    let mut began: Vec<Option<Instant>> = vec![None; schedule.len()];
    let mut ended: Vec<Option<Instant>> = vec![None; schedule.len()];
    // Per fault: time from its end to the first TerrainClass, robot s.
    let mut first_class: Vec<Option<f64>> = vec![None; schedule.len()];
    let mut node_lost_in: Vec<bool> = vec![false; schedule.len()];
    let mut states_seen: Vec<NodeState> = Vec::new();
    let mut bus_errors: Option<(u8, u8)> = None;
    let mut stall_latency_us = 0u32;
    let mut commands_after_controller_restart = 0usize;
    let mut classes_before_first_fault = 0usize;
    let t0 = Instant::now();
    let mut sim_done = false;
    let mut watch_errors = 0u64;
    // (robot s from the leg's last LegState, when it came).
    let mut leg_clock: Option<(f64, Instant)> = None;
    // Per fault: robot time it started and ended.
    let mut windows = vec![(f64::NAN, f64::NAN); schedule.len()];
    let mut bus_off_sent = false;
    while !sim_done {
        // The robot's clock: the leg's latest timestamp, carried on by the wall clock at
        // `speed` while the leg is not heard (the link fault). Wall time alone runs ahead of
        // it: under TCG the simulator falls behind `speed`, and a fault scheduled by the wall
        // clock landed 0.9 robot s early, inside a terrain switch judged as clean.
        let robot_now = leg_clock.map_or(t0.elapsed().as_secs_f64() * speed, |(r, at)| {
            r + at.elapsed().as_secs_f64() * speed
        });
        let got = match watch.recv(Duration::from_millis(5)) {
            Ok(g) => g,
            Err(_) => {
                // The link fault: our own socket sees it too; reopen.
                watch_errors += 1;
                std::thread::sleep(Duration::from_millis(20));
                if let Ok(w) = SocketCanBus::open(&iface) {
                    watch = w;
                }
                None
            }
        };
        if let Some(st) = got {
            match decode(&st.frame, &ids) {
                Ok(Some((_, Message::TerrainClass(tc)))) => {
                    if began[0].is_none() {
                        classes_before_first_fault += 1;
                    }
                    for k in 0..schedule.len() {
                        if let (Some(e), None) = (ended[k], first_class[k]) {
                            first_class[k] = Some(e.elapsed().as_secs_f64() * speed);
                        }
                        // The decisions of the backlog the stopped node takes up.
                        if schedule[k].0 == Fault::NodeStop
                            && ended[k].is_some_and(|e| e.elapsed() < wall(1.0))
                        {
                            stall_latency_us = stall_latency_us.max(tc.latency_us);
                        }
                    }
                }
                Ok(Some((_, Message::LegState(ls)))) => {
                    leg_clock = Some((ls.timestamp_us as f64 * 1e-6, Instant::now()));
                }
                Ok(Some((_, Message::GaitStatus(g)))) => {
                    for (k, lost) in node_lost_in.iter_mut().enumerate() {
                        if began[k].is_some()
                            && ended[k].is_none()
                            && g.reason == GaitReason::NodeLost
                        {
                            *lost = true;
                        }
                    }
                }
                Ok(Some((_, Message::NodeStatus(s)))) => {
                    let k = 1; // the error frames
                    if began[k].is_some() && ended[k].is_none_or(|e| e.elapsed() < wall(2.0)) {
                        if states_seen.last() != Some(&s.state) {
                            states_seen.push(s.state);
                        }
                        bus_errors = Some((bus_errors.map_or(s.bus_errors, |b| b.0), s.bus_errors));
                    }
                }
                Ok(Some((_, Message::LegCommand(_)))) if ended[4].is_some() => {
                    commands_after_controller_restart += 1;
                }
                _ => {}
            }
        }
        for (k, &(fault, start, end)) in schedule.iter().enumerate() {
            if began[k].is_none() && robot_now >= start {
                began[k] = Some(Instant::now());
                windows[k].0 = robot_now;
                match fault {
                    Fault::LinkDown => ip_link(&iface, "down"),
                    Fault::ErrorFrames => {
                        // CAN_ERR_CRTL with rx and tx error-passive (linux/can/error.h).
                        protocol::bus::send_error_frame(&iface, 0x4, &[0, 0x30]).unwrap();
                    }
                    Fault::NodeStop => signal(&node, "-STOP"),
                    Fault::NodeRestart => {
                        let _ = node.0.kill();
                        let _ = node.0.wait();
                    }
                    Fault::ControllerRestart => {
                        let _ = controller.0.kill();
                        let _ = controller.0.wait();
                    }
                }
            }
            let active = began[k].is_some() && ended[k].is_none();
            if fault == Fault::ErrorFrames
                && active
                && !bus_off_sent
                && began[k].is_some_and(|b| b.elapsed() >= wall(0.5))
                && states_seen.contains(&NodeState::ErrorPassive)
            {
                // CAN_ERR_BUSOFF, once the node has said error-passive.
                protocol::bus::send_error_frame(&iface, 0x40, &[]).unwrap();
                bus_off_sent = true;
            }
            if active && robot_now >= end {
                match fault {
                    Fault::LinkDown => ip_link(&iface, "up"),
                    // CAN_ERR_RESTARTED.
                    Fault::ErrorFrames => {
                        protocol::bus::send_error_frame(&iface, 0x100, &[]).unwrap()
                    }
                    Fault::NodeStop => signal(&node, "-CONT"),
                    Fault::NodeRestart => {
                        node = spawn(&["node", "--iface", &iface, "--model", model_s]);
                    }
                    Fault::ControllerRestart => controller = spawn(&controller_args),
                }
                ended[k] = Some(Instant::now());
                windows[k].1 = robot_now;
            }
        }
        if let Ok(Some(status)) = sim.0.try_wait() {
            assert!(status.success(), "presrs sim exited with {status}");
            sim_done = true;
        }
        assert!(t0.elapsed() < wall(sim_s) * 3, "presrs sim did not finish");
    }
    assert!(
        node.0.try_wait().unwrap().is_none() && controller.0.try_wait().unwrap().is_none(),
        "the node or the controller exited"
    );
    drop(node);
    drop(controller);
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    let steps = r["steps"].as_array().unwrap();
    let touchdowns = r["touchdowns"].as_u64().unwrap() as usize;
    let correct = steps
        .iter()
        .filter(|s| s["truth"] == s["classified"])
        .count();
    let accuracy = correct as f64 / steps.len().max(1) as f64;
    // Steps from each terrain change to that terrain's gait (the controller's default table),
    // for changes outside the faults: from half a second before each until 3 s after it (the
    // 2 steps a switch needs, and the robot's clock running behind ours).
    let table = controller::ControllerConfig::default().terrain_gaits;
    let in_fault = |t: f64| {
        windows
            .iter()
            .any(|&(a, b)| (a - 0.5..b + 3.0).contains(&t))
    };
    let mut delays = Vec::new();
    for i in 1..steps.len() {
        let t = |k: usize| steps[k]["t_s"].as_f64().unwrap_or(f64::NAN);
        if steps[i]["truth"] != steps[i - 1]["truth"] && !in_fault(t(i)) {
            let truth = steps[i]["truth"].as_str().unwrap();
            let want = table.get(truth).copied().map(u64::from);
            let run = (i..steps.len())
                .take_while(|&j| steps[j]["truth"] == steps[i]["truth"])
                .count();
            if i + run == steps.len() && run <= 3 {
                // The run ended within 3 steps of this change (one CI run's last step was
                // the first on a new terrain): too soon to judge the switch.
                continue;
            }
            let switch = (i..steps.len())
                .take_while(|&j| steps[j]["truth"] == steps[i]["truth"])
                .find(|&j| steps[j]["gait"].as_u64() == want);
            // A fault fell between this change and its switch: not the controller's delay.
            let until = t(switch.unwrap_or(i + run - 1));
            if windows.iter().any(|&(a, _)| (t(i)..=until).contains(&a)) {
                continue;
            }
            if let Some(j) = switch {
                // Steps the node got wrong before the switch: each one restarts the
                // controller's count of consecutive steps (the policy's N = 2).
                let wrong = (i..j)
                    .filter(|&k| steps[k]["truth"] != steps[k]["classified"])
                    .count();
                delays.push((j - i, wrong));
            } else {
                delays.push((usize::MAX, 0));
            }
        }
    }
    let falls = r["falls"].as_u64().unwrap();
    let timeline: Vec<String> = steps
        .iter()
        .map(|s| {
            format!(
                "{:.1}:{}{}g{}",
                s["t_s"].as_f64().unwrap_or(0.0),
                &s["truth"].as_str().unwrap_or("?")[..2],
                if s["truth"] == s["classified"] {
                    ""
                } else {
                    "!"
                },
                s["gait"]
            )
        })
        .collect();
    eprintln!(
        "steps (robot time s: truth, ! if misclassified, gait): {}\nfalls at {:?} s",
        timeline.join(" "),
        r["fall_times_s"]
    );
    eprintln!(
        "closed loop over vcan, 3 processes, robot time at {speed} x wall: {:.1} s simulated in {:.1} s wall; {touchdowns} touchdowns, {falls} falls, \
         {} TerrainClass, per-step accuracy {:.1}% ({correct}/{}); steps from a terrain change to its gait {delays:?}\n\
         faults (robot s) {windows:.1?}: first TerrainClass after each fault's end {first_class:.2?} robot s; \
         safe gait (NodeLost) during each {node_lost_in:?}; node states around the error frames {states_seen:?}, \
         BusErrors {bus_errors:?}; largest LatencyUs in the second after the stop {stall_latency_us}; \
         LegCommand frames after the controller restart {commands_after_controller_restart}; watcher socket errors {watch_errors}",
        r["simulated_s"].as_f64().unwrap(),
        r["wall_s"].as_f64().unwrap(),
        steps.len(),
        accuracy * 100.0,
        steps.len()
    );
    assert!(classes_before_first_fault > 0);
    // The node answered the steps it was up for: touchdowns minus about 6 s (of 40) of faults.
    assert!(
        steps.len() * 10 >= touchdowns * 7,
        "{} TerrainClass for {touchdowns} touchdowns",
        steps.len()
    );
    // Recovery: a TerrainClass within 2 steps (0.8 s of robot time at the slowest gait) of
    // the end of every fault that silenced the node or the bus.
    for (k, &(fault, _, _)) in schedule.iter().enumerate() {
        if matches!(
            fault,
            Fault::LinkDown | Fault::NodeStop | Fault::NodeRestart
        ) {
            let back = first_class[k].unwrap_or_else(|| panic!("no TerrainClass after {fault:?}"));
            // A restarted node loads its model first (about 1 s of wall time in the VM).
            let limit = if fault == Fault::NodeRestart {
                0.8 + 1.0 * speed * 2.0
            } else {
                0.8
            };
            assert!(
                back <= limit,
                "{fault:?}: first TerrainClass {back:.2} robot s after its end"
            );
        }
    }
    // The safe gait while the node was silent past the controller's timeout (0.5 s).
    for (k, &(fault, a, b)) in schedule.iter().enumerate() {
        if matches!(fault, Fault::NodeStop | Fault::NodeRestart) {
            assert!(
                b - a > 0.5 && node_lost_in[k],
                "{fault:?}: no NodeLost GaitStatus"
            );
        }
    }
    // The error frames: error-passive, bus-off, then running again, and counted.
    let order = [
        NodeState::ErrorPassive,
        NodeState::BusOff,
        NodeState::Running,
    ];
    let mut it = states_seen.iter();
    assert!(
        order.iter().all(|s| it.any(|x| x == s)),
        "node states around the error frames: {states_seen:?}"
    );
    // Three error frames; the first may already be in the first heartbeat seen.
    let (b0, b1) = bus_errors.expect("NodeStatus during the error frames");
    assert!(
        (2..=3).contains(&b1.wrapping_sub(b0)),
        "BusErrors {b0} -> {b1}"
    );
    // A stalled node says so: the decisions it took up after 1.5 s stopped were late.
    assert!(
        stall_latency_us >= 50_000,
        "LatencyUs after the stop: {stall_latency_us}"
    );
    assert!(
        commands_after_controller_restart > 0,
        "the restarted controller never commanded"
    );
    // Issue 6 and 28: no fall, through the faults and the controller's restart included.
    assert_eq!(falls, 0, "the hopper fell {falls} times");
    assert!(
        delays.len() >= 3,
        "terrain changes seen outside the faults: {delays:?}"
    );
    // Within 3 steps of every change, plus one step for each step the node misclassified in
    // between: the controller's part is exact, the node's is ~97% per step (one CI run had a
    // 4-step delay behind one misclassified step).
    assert!(
        delays.iter().all(|&(d, wrong)| d <= 3 + wrong),
        "(steps from a terrain change to its gait, misclassified steps before it): {delays:?}"
    );
    assert!(accuracy >= 0.9, "per-step accuracy {accuracy}");
}

/// Issue 5's speed figures on a real SocketCAN interface: `presrs bench-node` plays 6 feet at
/// 100 Hz to `presrs node` as a separate process. The report is printed for the note (labelled
/// emulated when run.sh runs it in the VM); the test asserts that the node answered the steps,
/// not a timing: the figures belong to the benchmark.
///
/// `PRESRS_BENCH_FEET` sets fewer feet where the kernel cannot carry six: bench-node plays on
/// the wall clock, and in User-mode Linux every frame's system calls go through ptrace. There
/// (2026-11-26, 2-core host, UML pinned to one core as run.sh does) 1 foot was answered 17 of
/// 17 steps (median latency 4.9 ms), 3 feet 19 of 50 and 6 feet 18 of 99 (latencies of
/// seconds, the node at 97% of UML's one CPU).
#[test]
#[ignore = "needs vcan interfaces: tests/vcan/run.sh runs it"]
fn node_bench_on_vcan_reports_latency_cpu_and_memory() {
    let _time = Timed(
        "node_bench_on_vcan_reports_latency_cpu_and_memory",
        Instant::now(),
    );
    let iface = fd_iface();
    let feet: u32 = match std::env::var("PRESRS_BENCH_FEET") {
        Ok(s) => s
            .parse()
            .ok()
            .filter(|&n| (1..=6).contains(&n))
            .unwrap_or_else(|| panic!("PRESRS_BENCH_FEET is `{s}`; give 1 to 6")),
        Err(_) => 6,
    };
    let feet_s = feet.to_string();
    let label = std::env::var("PRESRS_BENCH_LABEL").unwrap_or_else(|_| "vcan".into());
    let model = system_model();
    let out = common::output_ok(
        std::process::Command::new(presrs())
            .args([
                "bench-node",
                "--iface",
                &iface,
                "--feet",
                &feet_s,
                "--seconds",
                "5",
            ])
            .args(["--json", "--label", &label, "--model"])
            .arg(&model)
            .env("RUST_LOG", "warn"),
    );
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    eprintln!("presrs bench-node on {iface}: {j}");
    let steps = j["steps"].as_u64().unwrap();
    let answered = j["terrain_class"].as_u64().unwrap();
    // A step every 300 ms per foot, 5 s measured: 100 steps for 6 feet, 95 or more played.
    let due = f64::from(feet) * 5.0 / 0.3;
    assert!(
        steps as f64 >= 0.95 * due,
        "{steps} steps played by {feet} feet"
    );
    assert!(
        answered * 10 >= steps * 9,
        "{answered} TerrainClass for {steps} steps: {j}"
    );
    for k in ["median", "p99"] {
        assert!(j["latency_us"][k].as_f64().is_some(), "latency {k}: {j}");
    }
    assert!(j["node_cpu_pct_of_one_core"].as_f64().is_some(), "{j}");
    assert!(j["peak_rss_mb"].as_f64().is_some(), "{j}");
}

/// One `presrs sim` run against a fresh `presrs node` (G2 model): the per-step report.
fn sim_run(iface: &str, gait: &str, damage: f64, seed: u64, sim_s: f64) -> serde_json::Value {
    let model = system_model();
    let _node = spawn(&["node", "--iface", iface, "--model", model.to_str().unwrap()]);
    std::thread::sleep(Duration::from_millis(1500));
    let damage = damage.to_string();
    let name = format!("run-{gait}-{damage}");
    sim_report(
        iface,
        &["--gait", gait, "--damage", &damage],
        sim_s,
        seed,
        &name,
    )
}

fn accuracy(r: &serde_json::Value) -> (usize, usize) {
    let steps = r["steps"].as_array().unwrap();
    let correct = steps
        .iter()
        .filter(|s| s["truth"] == s["classified"])
        .count();
    (correct, steps.len())
}

/// Issue 5's system test: simulator and node as separate processes, the node's model trained
/// on G2 only, the hopper on G1, G2 and G3, the G2 run with cangen flooding the bus with other
/// traffic and garbage frames on the node's own identifiers; then 50% sensor damage.
///
/// The flood rides on the G2 run rather than on a run of its own (it was a fourth 20 s run,
/// compared step by step with a quiet G2 run: about 60 s of the VM's time, with the CI over
/// its budget). What it must not do is the same: lose or invent a stance (one TerrainClass per
/// touchdown), or cost accuracy: flooded, G2 is held to 90%.
///
/// Each run is a sample, judged as one: a gait fails when its run shows the accuracy below the
/// bound at 1% significance. `>= 95%` of 59 steps failed a CI run (2026-11-24) with nothing
/// wrong: at the ~97% measured, 3 wrong steps of 59 come about one run in three. The 95% per
/// gait itself is asserted where a sample can show it, on 300 steps a gait of the same model in
/// the lock-step loop (lab/tests/gaits.rs), so the runs here are short: G1 and G3 12 s (about
/// 35-41 steps; of 35, 29 right or fewer fails; at 96.5% a false failure about once in 800
/// runs), the flooded G2 run 15 s (about 46 steps: 35 or fewer fails).
#[test]
#[ignore = "needs vcan interfaces: tests/vcan/run.sh runs it"]
fn node_classifies_every_gait_with_a_g2_model_survives_damage_and_ignores_a_flood() {
    let _time = Timed(
        "node_classifies_every_gait_with_a_g2_model_survives_damage_and_ignores_a_flood",
        Instant::now(),
    );
    let iface = fd_iface();
    let mut per_gait = Vec::new();
    for gait in ["G1", "G2", "G3"] {
        // The flood: other traffic every 0.2 ms, and short (undecodable) frames every 2 ms on
        // FootContact's and TerrainClass's identifiers, in robot time: where the robot's clock
        // runs at a fraction of the wall clock, so does the flood, keeping its share of the
        // bus against the robot's own traffic (5000 frames a robot second against the foot's
        // 3100). Unscaled in User-mode Linux at 0.35, 42 of 46 touchdowns were classified.
        let gap_ms = |robot_ms: f64| format!("{}", robot_ms / system_speed());
        let flood: Vec<Proc> = if gait == "G2" {
            [(0.2, "7A0", "8"), (2.0, "100", "2"), (2.0, "203", "3")]
                .into_iter()
                .map(|(gap, id, len)| {
                    let gap = gap_ms(gap);
                    Proc(
                        std::process::Command::new("cangen")
                            .arg(&iface)
                            .args(["-g", &gap, "-I", id, "-L", len, "-D", "r"])
                            .spawn()
                            .expect("cangen from can-utils must be installed"),
                    )
                })
                .collect()
        } else {
            Vec::new()
        };
        let flooded = !flood.is_empty();
        let sim_s = if flooded { 15.0 } else { 12.0 };
        let r = sim_run(&iface, gait, 0.0, 5, sim_s);
        drop(flood);
        let (c, n) = accuracy(&r);
        let touchdowns = r["touchdowns"].as_u64().unwrap_or(0) as usize;
        eprintln!(
            "{gait}{}, G2 model: {c}/{n} steps correct ({:.1}%), {touchdowns} touchdowns",
            if flooded { " under a cangen flood" } else { "" },
            100.0 * c as f64 / n.max(1) as f64,
        );
        // G1 (the slowest) steps every 0.33 s.
        assert!(
            n as f64 >= 2.5 * sim_s,
            "{gait}: {n} TerrainClass in {sim_s} s"
        );
        // The first touchdown may come before the node is listening, the last after the
        // simulator stopped reading.
        assert!(
            n + 2 >= touchdowns && n <= touchdowns,
            "{gait}: {n} steps classified of {touchdowns} touchdowns"
        );
        per_gait.push((gait, c, n, if flooded { 0.9 } else { 0.95 }));
    }
    // Long enough that the first stances, before the node has learned the dead lines (5
    // stances) and refitted its model to them, do not decide the figure alone.
    let damaged = sim_run(&iface, "G2", 50.0, 5, 30.0);
    let (c, n) = accuracy(&damaged);
    let dmg: Vec<f64> = damaged["steps"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|s| s["damage_pct"].as_f64())
        .collect();
    eprintln!(
        "G2 with 50% damage: {c}/{n} correct ({:.1}%); node's learned damage at the end {:?}%",
        100.0 * c as f64 / n.max(1) as f64,
        dmg.last()
    );
    let damaged_acc = c as f64 / n.max(1) as f64;
    let learned: Vec<&serde_json::Value> = damaged["steps"]
        .as_array()
        .unwrap()
        .iter()
        .skip_while(|s| s["damage_pct"].as_f64().unwrap_or(0.0) == 0.0)
        .collect();
    let learned_correct = learned
        .iter()
        .filter(|s| s["truth"] == s["classified"])
        .count();
    eprintln!(
        "G2 with 50% damage, from the first step that reported learned damage: {learned_correct}/{} correct",
        learned.len()
    );
    let learning_steps = n - learned.len();

    // Issue 5's targets: 95% per gait (the paper's Table 5: 98.6-99.3%), 90% at 50% damage,
    // the learning stances included. The node's model comes from the sensor the simulated foot
    // wears (`presrs dataset` and `presrs sim` default to the same sensor serial), as a robot's
    // model comes from its own foot.
    for (gait, c, n, bound) in per_gait {
        let p_low = binomial_cdf(c, n, bound);
        assert!(
            p_low >= 0.01,
            "{gait}: {c}/{n} right: P(at most {c} right | {bound}) = {p_low:.4}"
        );
    }
    // 50% damage is judged once the node has learned the dead lines (the learning stances
    // before it are few but each is likely wrong), as a sample: each VM run is another
    // trajectory of the hopper (the simulator integrates in chunks set by the wall clock).
    // 40 s runs logged 106, 108, 109, 111, 112 and 116 of 119 learned steps (89-97.5%); in-process,
    // `presrs demo --fixed-gait G2 --damage 50 --steps 123` over seeds 1-8 gives 907 of 944
    // steps after the first five (96.1%, 91.5-98.3% per seed). The run is 30 s (about 88
    // learned steps) and fails when it shows the accuracy below the issue's 90% at 1%
    // significance (71 right of 88 or fewer; at 93% a false failure about once in 8,000
    // runs); the refit's own bound (85% in-process) is node_steps.rs's.
    let p_low = binomial_cdf(learned_correct, learned.len(), 0.9);
    assert!(
        p_low >= 0.01,
        "50% damage, damage learned: {learned_correct}/{} right: P(at most that | 90%) = {p_low:.4}",
        learned.len()
    );
    assert!(
        learning_steps <= 10,
        "{learning_steps} steps before the node reported learned damage"
    );
    assert!(
        damaged_acc >= 0.8,
        "50% damage, whole run: accuracy {damaged_acc}"
    );
}

/// P(X <= k) for X ~ Binomial(n, p).
fn binomial_cdf(k: usize, n: usize, p: f64) -> f64 {
    // ln C(n, i) by sums of logs: exact enough for n in the hundreds.
    let ln_fact = |m: usize| (1..=m).map(|x| (x as f64).ln()).sum::<f64>();
    (0..=k.min(n))
        .map(|i| {
            (ln_fact(n) - ln_fact(i) - ln_fact(n - i)
                + i as f64 * p.ln()
                + (n - i) as f64 * (1.0 - p).ln())
            .exp()
        })
        .sum()
}

/// `candump -L IFACE > log` while `run` runs; returns the log's path.
fn candump_during(iface: &str, name: &str, run: impl FnOnce()) -> std::path::PathBuf {
    let log = std::env::temp_dir().join(format!("presrs-{name}-{}.log", std::process::id()));
    let file = std::fs::File::create(&log).unwrap();
    let mut candump = Proc(
        std::process::Command::new("candump")
            // 10 000 frames/s of tactile segments: under TCG on a busy host, candump's default
            // socket buffer overflowed (290 of 300 images logged, sim reporting 0 send errors).
            .args(["-r", "8388608", "-L", iface])
            .stdout(file)
            .spawn()
            .expect("candump from can-utils must be installed (apt-get install can-utils)"),
    );
    std::thread::sleep(Duration::from_millis(500));
    run();
    std::thread::sleep(Duration::from_millis(500));
    let _ = candump.0.kill();
    let _ = candump.0.wait();
    log
}

fn system_speed() -> f64 {
    std::env::var("PRESRS_SYSTEM_SPEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1.0)
}

/// `presrs sim` on `iface` for `sim_s` of robot time; returns its per-step report.
fn sim_report(iface: &str, extra: &[&str], sim_s: f64, seed: u64, name: &str) -> serde_json::Value {
    let report = std::env::temp_dir().join(format!("presrs-{name}-{}.json", std::process::id()));
    let status = std::process::Command::new(presrs())
        .args(["sim", "--iface", iface, "--duration", &sim_s.to_string()])
        .args([
            "--seed",
            &seed.to_string(),
            "--speed",
            &system_speed().to_string(),
        ])
        .args(extra)
        .arg("--report")
        .arg(&report)
        .env("RUST_LOG", "warn")
        .status()
        .unwrap();
    assert!(status.success(), "presrs sim {extra:?}: {status}");
    let r = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    let _ = std::fs::remove_file(&report);
    r
}

fn presrs_ok(args: &[&str]) -> String {
    let out = std::process::Command::new(presrs())
        .args(args)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "presrs {args:?}: {}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).to_string()
}

/// Issue 17 §4 and §2 over real SocketCAN, the path of docs/real-robot.md with the simulator
/// standing in for the robot: `presrs sim` on one terrain at a time while candump records,
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
    // Issue 17's 95% per step, judged as a sample can judge it. Each VM run is another
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
    let first_safe = grass.iter().position(|s| s["gait"] == 1);
    eprintln!(
        "grass, not in the model, with the controller: {unknown}/{} steps unknown, safe gait G1 after {first_safe:?} steps",
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

/// Issue 17 §3: the firmware example sends a foot's switch and images through socketcan's
/// `embedded_can::blocking::Can` driver; the node on the bus decides every stance.
#[test]
#[ignore = "needs vcan interfaces: tests/vcan/run.sh runs it"]
fn firmware_example_on_vcan_gets_a_terrain_class_per_stance() {
    let _time = Timed(
        "firmware_example_on_vcan_gets_a_terrain_class_per_stance",
        Instant::now(),
    );
    let iface = fd_iface();
    let Some(fw) = std::env::var_os("PRESRS_FIRMWARE") else {
        panic!("PRESRS_FIRMWARE must name the foot_firmware example (tests/vcan/run.sh builds it)");
    };
    let ids = IdConfig::default();
    let mut watch = open(&iface);
    let model = system_model();
    let _node = spawn(&[
        "node",
        "--iface",
        &iface,
        "--model",
        model.to_str().unwrap(),
    ]);
    // The firmware keeps its own (wall) time and does not wait for anyone: it starts once the
    // node's heartbeat says the node is listening. A fixed 1.5 s head start was not always
    // enough under TCG on a loaded CI host (a CI run failed this test; alone it passed in 7 s).
    let heard = wait_for_heartbeat(&mut watch, &ids, Duration::from_secs(120));
    assert!(heard, "the node sent no NodeStatus within 120 s");
    let status = std::process::Command::new(&fw)
        .args(["--iface", &iface, "--steps", "6"])
        .status()
        .unwrap();
    assert!(status.success(), "foot_firmware: {status}");
    // Each stance's class comes within milliseconds of robot time; the limit only bounds a
    // slow host's wall clock, and the count is judged whole, not per window.
    let t0 = Instant::now();
    let mut steps = Vec::new();
    while steps.len() < 6 && t0.elapsed() < Duration::from_secs(60) {
        if let Some(st) = watch.recv(Duration::from_millis(20)).unwrap()
            && let Ok(Some((0, Message::TerrainClass(tc)))) = decode(&st.frame, &ids)
        {
            steps.push(tc);
        }
    }
    // Nothing more may follow: one class per stance.
    let t1 = Instant::now();
    while t1.elapsed() < Duration::from_millis(500) {
        if let Some(st) = watch.recv(Duration::from_millis(20)).unwrap()
            && let Ok(Some((0, Message::TerrainClass(tc)))) = decode(&st.frame, &ids)
        {
            steps.push(tc);
        }
    }
    eprintln!(
        "firmware example on vcan: {} TerrainClass: {steps:?}",
        steps.len()
    );
    // The bus was watched from before the first stance: all six, each with a sampled image.
    assert_eq!(steps.len(), 6, "{steps:?}");
    use protocol::messages::flags;
    assert!(
        steps
            .iter()
            .all(|tc| tc.flags & (flags::NO_SAMPLE | flags::NO_CONTACT) == 0)
    );
}

/// Issue 18 on real SocketCAN: `presrs node --mcap --foxglove` records and serves the robot's
/// traffic while it classifies, and `presrs sim --mcap` records the same run with its truth.
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

/// The first impedance command each joint's driver got in `frames` (0 hip, 1 length), as the
/// motor reads it, for the example leg of `proto` (MIT ids 1-2, moteus 3-4, ODrive nodes 1-2):
/// `(kp, kd)`, N m/rad and N m s/rad at the driver. ODrive's gains are sent only when they
/// change, so for it: the last position gain in `frames` (stiffness is pos_gain * vel_gain).
fn first_gains(proto: &str, frames: &[protocol::CanFrame]) -> [Option<(f64, f64)>; 2] {
    use leg::driver::{mit, moteus, odrive};
    let mut out = [None; 2];
    for (j, slot) in out.iter_mut().enumerate() {
        let n = j as u8 + 1;
        for f in frames {
            let g = match proto {
                "mit" => {
                    let r = mit::Ranges::of_model("AK80-6-V1.1").unwrap();
                    match mit::Server::new(n, 0, r).on_frame(f) {
                        Some(Ok(mit::Order::Command(c))) => Some((c.kp, c.kd)),
                        _ => None,
                    }
                }
                "moteus" => match moteus::Server::new(n + 2, 200.0, 5.0).on_frame(f) {
                    Some(Ok((moteus::Order::Position(c), _))) => Some((c.kp, c.kd)),
                    _ => None,
                },
                _ => match odrive::Server::new(n).on_frame(f) {
                    // The damped stop sends pos_gain 0 (stiffness) before its set point.
                    Some(Ok(odrive::Order::PosGain(g))) => Some((g, f64::NAN)),
                    _ => None,
                },
            };
            if g.is_some() {
                *slot = g;
                if proto != "odrive" {
                    break;
                }
            }
        }
    }
    out
}

/// Issue 27 on real SocketCAN, per motor protocol: `presrs sim --leg P` (the hopper's leg as two
/// motors of that protocol), `presrs leg` (the bridge), the node and the controller as
/// processes. The hopper hops with no fall and the gait adapts per terrain within 3 steps; the
/// bridge's LegState (from the encoders) agrees with the truth within 0.01 rad and 2 mm (95th
/// percentile across processes; the largest error is bounded in-process, tests/demo.rs); the
/// controller killed: LegStatus says the damped stop by the command timeout plus a period (its
/// own CommandAgeMs: robot time) and the motors get no stiffness; the length joint's driver
/// silenced: LegStatus names it.
#[test]
#[ignore = "needs vcan interfaces: tests/vcan/run.sh runs it"]
fn leg_bridge_drives_each_protocols_simulated_motors_as_processes() {
    let _time = Timed(
        "leg_bridge_drives_each_protocols_simulated_motors_as_processes",
        Instant::now(),
    );
    use protocol::messages::{LegMode, LegStatus};
    use std::sync::{Arc, Mutex, atomic::AtomicBool, atomic::Ordering};
    let iface = fd_iface();
    let ids = IdConfig::default();
    let model = system_model();
    let speed = system_speed();
    let speed_s = speed.to_string();
    let dir = std::env::temp_dir().join(format!("presrs-vcan-leg-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let track = dir.join("track.toml");
    std::fs::write(
        &track,
        "diameter_m = 2.8\n[[segments]]\nterrain = \"wood\"\nlength_m = 0.8\n\
         [[segments]]\nterrain = \"grass\"\nlength_m = 1.0\n\
         [[segments]]\nterrain = \"clay\"\nlength_m = 1.0\n\
         [[segments]]\nterrain = \"carpet\"\nlength_m = 6.0\n",
    )
    .unwrap();
    let table = controller::ControllerConfig::default().terrain_gaits;
    let (kill_at, silent_at, sim_s) = (7.5, 8.0, 8.6);
    for proto in ["mit", "moteus", "odrive"] {
        let cfg = dir.join(format!("{proto}.toml"));
        // The simulated drivers answer from the simulator, which under TCG falls behind the
        // others' clocks and stalls now and then: 50 ms of robot time is 143 ms of wall time
        // at 0.35, and one stall that long read as a silent driver, stopped the leg and
        // felled the hopper for the rest of the run (measured: MIT, falls from 3.2 s on). A
        // real driver does not stall; the drill below still finds a silenced one.
        let example = presrs_ok(&["leg", "--example", proto])
            .replace("reply_timeout_ms = 50", "reply_timeout_ms = 300");
        assert!(example.contains("reply_timeout_ms = 300"), "{example}");
        std::fs::write(&cfg, example).unwrap();
        let cfg_s = cfg.to_str().unwrap();
        // Everything on the bus from here on, with its arrival time.
        let heard: Arc<Mutex<Vec<(Instant, protocol::CanFrame)>>> = Arc::default();
        let stop = Arc::new(AtomicBool::new(false));
        let watcher = {
            let (heard, stop, iface) = (heard.clone(), stop.clone(), iface.clone());
            std::thread::spawn(move || {
                let mut w = open(&iface);
                while !stop.load(Ordering::Relaxed) {
                    if let Ok(Some(st)) = w.recv(Duration::from_millis(20))
                        && !matches!(
                            ids_kind(&st.frame),
                            Some(MessageKind::TactileFrame | MessageKind::TactileFrameClassic)
                        )
                    {
                        heard.lock().unwrap().push((Instant::now(), st.frame));
                    }
                }
            })
        };
        let _node = spawn(&[
            "node",
            "--iface",
            &iface,
            "--model",
            model.to_str().unwrap(),
        ]);
        let controller = spawn_rt(&["controller", "--iface", &iface, "--time-scale", &speed_s]);
        let _leg = spawn_rt(&[
            "leg",
            "--iface",
            &iface,
            "--config",
            cfg_s,
            "--time-scale",
            &speed_s,
        ]);
        // The leg's first LegStatus: it is on the bus (and has moved nothing).
        let t0 = Instant::now();
        let first_status = loop {
            let s = heard
                .lock()
                .unwrap()
                .iter()
                .find_map(|(_, f)| match decode(f, &ids) {
                    Ok(Some((0, Message::LegStatus(s)))) => Some(s),
                    _ => None,
                });
            if let Some(s) = s {
                break s;
            }
            assert!(
                t0.elapsed() < Duration::from_secs(120),
                "{proto}: no LegStatus in 120 s"
            );
            std::thread::sleep(Duration::from_millis(50));
        };
        assert_eq!(
            first_status.mode,
            LegMode::Waiting,
            "{proto}: {first_status:?}"
        );
        std::thread::sleep(Duration::from_millis(1000));
        let report = dir.join(format!("{proto}-report.json"));
        let mut sim = Proc(
            std::process::Command::new(presrs())
                .args(["sim", "--iface", &iface, "--duration", &sim_s.to_string()])
                .args(["--seed", "5", "--speed", &speed_s, "--track"])
                .arg(&track)
                .args(["--leg", proto, "--leg-config", cfg_s])
                .args(["--leg-silent-at", &silent_at.to_string(), "--report"])
                .arg(&report)
                .env("RUST_LOG", "warn")
                .spawn()
                .unwrap(),
        );
        let sim_start = Instant::now();
        // The controller dies at `kill_at` of robot time: when the foot's clock says so. (It
        // slept `kill_at / speed` of wall time before, and a loaded machine ran the simulator
        // at a sixth of `speed`: the kill came at 1.3 s of robot time, 0 steps judged.)
        // The foot's clock (s) in the last FootContact heard by `by`.
        let foot_clock = |heard: &[(Instant, protocol::CanFrame)], by: Instant| {
            heard
                .iter()
                .rev()
                .filter(|(t, _)| *t <= by)
                .find_map(|(_, f)| match decode(f, &ids) {
                    Ok(Some((0, Message::FootContact(fc)))) => Some(fc.timestamp_us as f64 * 1e-6),
                    _ => None,
                })
        };
        while foot_clock(&heard.lock().unwrap(), Instant::now()).is_none_or(|t| t < kill_at) {
            assert!(
                sim_start.elapsed() < Duration::from_secs_f64(20.0 * sim_s / speed),
                "{proto}: the simulator's clock did not reach {kill_at} s"
            );
            std::thread::sleep(Duration::from_millis(50));
        }
        drop(controller);
        let killed = Instant::now();
        let status = sim.0.wait().unwrap();
        assert!(status.success(), "{proto}: presrs sim: {status}");
        stop.store(true, Ordering::Relaxed);
        watcher.join().unwrap();
        let r: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
        let heard = heard.lock().unwrap().clone();
        let statuses: Vec<(Instant, LegStatus)> = heard
            .iter()
            .filter_map(|(t, f)| match decode(f, &ids) {
                Ok(Some((0, Message::LegStatus(s)))) => Some((*t, s)),
                _ => None,
            })
            .collect();
        // Robot time of the kill on the simulator's clock: the foot's last timestamp heard
        // before it (the simulator falls behind `speed` under TCG: by 5 s, 2 s behind);
        // steps and falls are judged before it, less a second.
        let kill_robot = foot_clock(&heard, killed)
            .unwrap_or_else(|| (killed - sim_start).as_secs_f64() * speed);
        let before = kill_robot - 1.0;
        let steps: Vec<&serde_json::Value> = r["steps"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|s| s["t_s"].as_f64().unwrap_or(f64::MAX) < before)
            .collect();
        let falls: Vec<f64> = r["fall_times_s"]
            .as_array()
            .unwrap()
            .iter()
            .filter_map(|t| t.as_f64())
            .filter(|&t| t < before)
            .collect();
        let mut delays = Vec::new();
        for i in 1..steps.len() {
            if steps[i]["truth"] == steps[i - 1]["truth"] {
                continue;
            }
            let want = table
                .get(steps[i]["truth"].as_str().unwrap())
                .copied()
                .map(u64::from);
            let run: Vec<usize> = (i..steps.len())
                .take_while(|&j| steps[j]["truth"] == steps[i]["truth"])
                .collect();
            if run.len() <= 3 {
                continue; // the judged window ends too soon after this change
            }
            delays.push(run.iter().position(|&j| steps[j]["gait"].as_u64() == want));
        }
        let ls = &r["leg_state"];
        let timeout = statuses.iter().find(|(t, s)| {
            *t > killed - Duration::from_millis(200) && s.mode == LegMode::CommandTimeout
        });
        let silent = statuses
            .iter()
            .find(|(t, s)| *t > killed && s.mode == LegMode::DriverSilent);
        let after_timeout: Vec<protocol::CanFrame> = timeout
            .map(|(t, _)| {
                heard
                    .iter()
                    .filter(|(u, _)| proto == "odrive" || u > t)
                    .filter(|(u, _)| silent.is_none_or(|(s, _)| u < s))
                    .map(|(_, f)| *f)
                    .collect()
            })
            .unwrap_or_default();
        let gains = first_gains(proto, &after_timeout);
        eprintln!(
            "--leg {proto}: {} steps before the kill (robot {before:.1} s), falls {falls:?}, steps from a terrain change to its gait {delays:?}; LegState {}; LegStatus at the command timeout {:?}, on the silent driver {:?}; first gains after the stop {gains:?}",
            steps.len(),
            ls,
            timeout.map(|t| t.1),
            silent.map(|t| t.1)
        );
        assert!(steps.len() >= 8, "{proto}: {} steps", steps.len());
        assert!(falls.is_empty(), "{proto}: fell at {falls:?}");
        assert!(!delays.is_empty(), "{proto}: no terrain change judged");
        assert!(
            delays.iter().all(|d| d.is_some_and(|d| d <= 3)),
            "{proto}: {delays:?}"
        );
        assert!(ls["frames"].as_u64().unwrap() > 1000, "{proto}: {ls}");
        // The 95th percentile: each LegState is matched to the nearest truth of the 50 ms
        // before it on the simulator's clock (the processes' clocks differ), and under TCG a
        // few arrive later than that (measured: largest 0.0097 rad and 3.1 mm, moteus). The
        // largest error is bounded on one clock, in-process (tests/demo.rs).
        assert!(
            ls["angle_err_rad"][1].as_f64().unwrap() < 0.01,
            "{proto}: {ls}"
        );
        assert!(
            ls["length_err_m"][1].as_f64().unwrap() < 0.002,
            "{proto}: {ls}"
        );
        let (_, st) = timeout.unwrap_or_else(|| panic!("{proto}: no CommandTimeout LegStatus"));
        // command_timeout_ms 50 plus one 2 ms period, and the bridge's process not run for a
        // while under emulation (measured: 63 ms in User-mode Linux at 0.5, with every other
        // check of the run passed). The bound of one period is asserted on one clock, in
        // process (leg/src/bridge.rs); here, that a controller gone leaves the leg stopped.
        assert!(st.command_age_ms <= 80, "{proto}: {st:?}");
        for (j, g) in gains.iter().enumerate() {
            let (kp, _) =
                g.unwrap_or_else(|| panic!("{proto}: joint {j} got no command after the stop"));
            assert_eq!(kp, 0.0, "{proto}: joint {j} still stiff after the stop");
        }
        let (_, st) = silent.unwrap_or_else(|| panic!("{proto}: the silent driver was not named"));
        assert_eq!(st.joint, 2, "{proto}: {st:?}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

fn ids_kind(f: &protocol::CanFrame) -> Option<MessageKind> {
    IdConfig::default()
        .lookup(f.raw_id(), f.is_extended())
        .map(|(k, _)| k)
}
