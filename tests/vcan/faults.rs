//! The simulator, node and controller as processes, through bus and process faults.

use super::*;

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
        "lab",
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
            assert!(status.success(), "presrs lab sim exited with {status}");
            sim_done = true;
        }
        assert!(
            t0.elapsed() < wall(sim_s) * 3,
            "presrs lab sim did not finish"
        );
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
    // No fall, through the faults and the controller's restart included.
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
