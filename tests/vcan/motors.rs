//! The leg bridge driving each motor protocol's simulated motors, as processes.

use super::*;

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

/// On real SocketCAN, per motor protocol: `presrs lab sim --leg P` (the hopper's leg as two
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
                .args([
                    "lab",
                    "sim",
                    "--iface",
                    &iface,
                    "--duration",
                    &sim_s.to_string(),
                ])
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
        assert!(status.success(), "{proto}: presrs lab sim: {status}");
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
