//! The leg bridge's motor frames against the drivers' own Python packages: mjbots'
//! `moteus`, cantools reading the CANSimple DBC shipped in `odrive-can`, and
//! `mini-cheetah-motor-driver-socketcan` (`tests/interop/drivers_check.py`). Each direction: their
//! decoder reads what our bridge and our simulated drivers send, and our decoders read what
//! their encoders make. Run with `--features interop` (the README's test command does).
#![cfg(feature = "interop")]

mod common;

use std::f64::consts::TAU;

use leg::driver::{JointCommand, Reply, mit, moteus, odrive};
use protocol::CanFrame;
use protocol::component::Outbox;
use serde_json::{Value, json};

fn hex(d: &[u8]) -> String {
    d.iter().map(|b| format!("{b:02x}")).collect()
}

fn unhex(s: &str) -> Vec<u8> {
    (0..s.len() / 2)
        .map(|i| u8::from_str_radix(&s[2 * i..2 * i + 2], 16).unwrap())
        .collect()
}

fn frame(id: u64, data: &[u8], fd: bool) -> CanFrame {
    let id = protocol::frame::make_id(id as u32, id > 0x7FF).unwrap();
    if fd {
        CanFrame::fd(id, data, true).unwrap()
    } else {
        CanFrame::classic(id, data).unwrap()
    }
}

/// `tests/interop/drivers_check.py ARGS`'s JSON; its failure fails the test (never a skip).
fn drivers_check(args: &[&std::ffi::OsStr]) -> Value {
    let o = std::process::Command::new("python3")
        .arg(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/interop/drivers_check.py"
        ))
        .args(args)
        .output()
        .expect("python3");
    assert!(
        o.status.success(),
        "drivers_check.py {args:?} failed (pip install -r tests/requirements.txt): {}",
        String::from_utf8_lossy(&o.stderr)
    );
    serde_json::from_slice(&o.stdout).unwrap()
}

fn close(a: f64, b: f64, tol: f64, what: &str) {
    assert!((a - b).abs() <= tol, "{what}: {a} vs {b} (tolerance {tol})");
}

fn commands() -> Vec<JointCommand> {
    let mut v = Vec::new();
    for i in 0..12 {
        let x = i as f64;
        v.push(JointCommand {
            position_rad: -5.0 + 0.9 * x,
            velocity_rad_s: 3.0 - 0.55 * x,
            kp: 0.5 + 1.7 * x,
            kd: 0.02 + 0.03 * x,
            torque_nm: -2.0 + 0.37 * x,
        });
    }
    v
}

#[test]
fn the_drivers_python_packages_read_our_frames_and_we_read_theirs() {
    let cmds = commands();
    // moteus: configured kp 400 N m/rev, kd 40 N m s/rev; the bridge sends scales.
    let (kp_full, kd_full) = (400.0, 40.0);
    let mut bridge = moteus::Moteus::new(1, 0, kp_full, kd_full, 0.05);
    let server = moteus::Server::new(1, kp_full, kd_full);
    let mut out = Outbox::default();
    for c in &cmds {
        bridge.command(c, &mut out);
    }
    bridge.damp(0.3, &mut out);
    let moteus_cmds: Vec<String> = out.drain().map(|f| hex(f.data())).collect();
    let replies: Vec<(f64, f64, f64, i8)> = (0..8)
        .map(|i| {
            (
                0.3 * i as f64 - 1.0,
                0.5 - 0.2 * i as f64,
                0.1 * i as f64,
                if i == 5 { 33 } else { 0 },
            )
        })
        .collect();
    for &(p, v, t, fault) in &replies {
        server.reply(
            0,
            &moteus::MotorState {
                position_rad: p,
                velocity_rad_s: v,
                torque_nm: t,
                running: true,
                fault,
            },
            &mut out,
        );
    }
    let moteus_replies: Vec<String> = out.drain().map(|f| hex(f.data())).collect();
    let make: Vec<Value> = cmds
        .iter()
        .map(|c| {
            json!({"id": 1, "position": c.position_rad / TAU, "velocity": c.velocity_rad_s / TAU,
                   "feedforward_torque": c.torque_nm, "kp_scale": c.kp * TAU / kp_full,
                   "kd_scale": c.kd * TAU / kd_full, "watchdog": 0.05})
        })
        .collect();

    // ODrive node 3.
    let mut od = odrive::Odrive::new(3);
    let ods = odrive::Server::new(3);
    od.enable(&mut out);
    for c in &cmds[..4] {
        od.command(c, &mut out);
    }
    od.stop(&mut out);
    ods.encoder_estimates(2.5, -1.25, &mut out);
    ods.heartbeat(0x40, 8, &mut out);
    let od_frames: Vec<CanFrame> = out.drain().collect();
    let od_json: Vec<Value> = od_frames
        .iter()
        .map(|f| json!({"id": f.raw_id(), "data": hex(f.data())}))
        .collect();
    let od_encode = json!([
        {"node": 3, "name": "Axis0_Get_Encoder_Estimates", "signals": {"Pos_Estimate": 0.75, "Vel_Estimate": -2.5}},
        {"node": 3, "name": "Axis0_Heartbeat", "signals": {"Axis_Error": 0x800, "Axis_State": 8}},
    ]);

    // MIT: AK80-9-V1.1.
    let model = "AK80-9-V1.1";
    let r = mit::Ranges::of_model(model).unwrap();
    let mit_server = mit::Server::new(1, 0, r);
    let mit_cmds: Vec<JointCommand> = cmds
        .iter()
        .map(|c| JointCommand {
            kp: c.kp * 20.0,
            kd: c.kd * 10.0,
            ..*c
        })
        .collect();
    for &(p, v, t, _) in &replies {
        mit_server.reply(p, v, t, 0, &mut out);
    }
    let mit_replies: Vec<String> = out.drain().map(|f| hex(f.data())).collect();

    let vectors = json!({
        "moteus": {"commands": moteus_cmds, "replies": moteus_replies, "make": make},
        "odrive": {"frames": od_json, "encode": od_encode},
        "mit": {"model": model, "replies": mit_replies, "commands": mit_cmds.iter().map(|c| json!({
            "position": c.position_rad, "velocity": c.velocity_rad_s, "kp": c.kp, "kd": c.kd, "torque": c.torque_nm})).collect::<Vec<_>>()},
    });
    let dir = std::env::temp_dir().join(format!("presrs-drivers-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let input = dir.join("vectors.json");
    std::fs::write(&input, vectors.to_string()).unwrap();
    let res = drivers_check(&[input.as_os_str()]);

    // moteus: mjbots' parser reads our commands.
    let got = res["moteus"]["commands"].as_array().unwrap();
    for (c, g) in cmds.iter().zip(got) {
        assert_eq!(g["mode"], 10, "{g}");
        close(
            g["position"].as_f64().unwrap(),
            c.position_rad / TAU,
            1e-6,
            "moteus position",
        );
        close(
            g["velocity"].as_f64().unwrap(),
            c.velocity_rad_s / TAU,
            1e-6,
            "moteus velocity",
        );
        close(
            g["feedforward_torque"].as_f64().unwrap(),
            c.torque_nm,
            1e-6,
            "moteus torque",
        );
        close(
            g["kp_scale"].as_f64().unwrap(),
            (c.kp * TAU / kp_full).min(1.0),
            1e-6,
            "kp_scale",
        );
        close(
            g["kd_scale"].as_f64().unwrap(),
            (c.kd * TAU / kd_full).min(1.0),
            1e-6,
            "kd_scale",
        );
        close(g["watchdog"].as_f64().unwrap(), 0.05, 1e-6, "watchdog");
        let q: Vec<u64> = g["queried"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_u64().unwrap())
            .collect();
        for reg in [0, 1, 2, 3, 0xF] {
            assert!(q.contains(&reg), "register {reg} not queried: {q:?}");
        }
    }
    let damp = &got[cmds.len()];
    assert!(
        damp["position"].is_null() || damp["position"].as_f64().is_none_or(f64::is_nan),
        "{damp}"
    );
    assert_eq!(damp["kp_scale"].as_f64(), Some(0.0));
    // ...and our simulated moteus's replies.
    for (&(p, v, t, fault), g) in replies
        .iter()
        .zip(res["moteus"]["replies"].as_array().unwrap())
    {
        close(
            g["position"].as_f64().unwrap(),
            p / TAU,
            1e-6,
            "moteus reply position",
        );
        close(
            g["velocity"].as_f64().unwrap(),
            v / TAU,
            1e-6,
            "moteus reply velocity",
        );
        close(
            g["torque"].as_f64().unwrap(),
            t,
            1e-6,
            "moteus reply torque",
        );
        assert_eq!(g["fault"].as_i64(), Some(fault as i64));
        assert_eq!(g["mode"].as_i64(), Some(if fault != 0 { 1 } else { 10 }));
    }
    // Our simulated moteus reads mjbots' own position commands.
    for (c, m) in cmds.iter().zip(res["moteus"]["made"].as_array().unwrap()) {
        let f = frame(
            m["id"].as_u64().unwrap(),
            &pad_fd(unhex(m["data"].as_str().unwrap())),
            true,
        );
        let Some(Ok((moteus::Order::Position(g), 0))) = server.on_frame(&f) else {
            panic!("{m}: {:?}", server.on_frame(&f));
        };
        close(
            g.position_rad,
            c.position_rad,
            1e-5,
            "position from moteus.make_position",
        );
        close(g.velocity_rad_s, c.velocity_rad_s, 1e-5, "velocity");
        close(g.torque_nm, c.torque_nm, 1e-5, "torque");
        close(g.kp, c.kp.min(kp_full / TAU), 1e-4, "kp");
        close(g.kd, c.kd.min(kd_full / TAU), 1e-5, "kd");
    }

    // ODrive: cantools with ODrive's DBC reads our frames.
    let dec = res["odrive"]["decoded"].as_array().unwrap();
    let names: Vec<&str> = dec.iter().map(|d| d["name"].as_str().unwrap()).collect();
    assert_eq!(
        &names[..2],
        ["Axis0_Set_Controller_Mode", "Axis0_Set_Axis_State"]
    );
    assert!(dec.iter().all(|d| d["node"] == 3));
    assert_eq!(dec[0]["signals"]["Control_Mode"], 3.0);
    assert_eq!(dec[0]["signals"]["Input_Mode"], 1.0);
    assert_eq!(dec[1]["signals"]["Axis_Requested_State"], 8.0);
    let c0 = &cmds[0];
    let pos_gain = dec
        .iter()
        .find(|d| d["name"] == "Axis0_Set_Pos_Gain")
        .unwrap();
    let vel_gains = dec
        .iter()
        .find(|d| d["name"] == "Axis0_Set_Vel_Gains")
        .unwrap();
    let pg = pos_gain["signals"]["Pos_Gain"].as_f64().unwrap();
    let vg = vel_gains["signals"]["Vel_Gain"].as_f64().unwrap();
    close(vg, c0.kd * TAU, 1e-5, "Vel_Gain");
    close(
        pg * vg,
        c0.kp * TAU,
        1e-4,
        "Pos_Gain * Vel_Gain (stiffness, N m/turn)",
    );
    let inputs: Vec<&Value> = dec
        .iter()
        .filter(|d| d["name"] == "Axis0_Set_Input_Pos")
        .collect();
    assert_eq!(inputs.len(), 4);
    for (c, d) in cmds.iter().zip(&inputs) {
        let s = &d["signals"];
        close(
            s["Input_Pos"].as_f64().unwrap(),
            c.position_rad / TAU,
            1e-5,
            "Input_Pos",
        );
        close(
            s["Vel_FF"].as_f64().unwrap(),
            c.velocity_rad_s / TAU,
            1e-3,
            "Vel_FF",
        );
        close(
            s["Torque_FF"].as_f64().unwrap(),
            c.torque_nm,
            1e-3,
            "Torque_FF",
        );
    }
    let last_state = dec
        .iter()
        .rev()
        .find(|d| d["name"] == "Axis0_Set_Axis_State")
        .unwrap();
    assert_eq!(
        last_state["signals"]["Axis_Requested_State"], 1.0,
        "stop is IDLE"
    );
    let est = dec
        .iter()
        .find(|d| d["name"] == "Axis0_Get_Encoder_Estimates")
        .unwrap();
    close(
        est["signals"]["Pos_Estimate"].as_f64().unwrap(),
        2.5 / TAU,
        1e-6,
        "Pos_Estimate",
    );
    close(
        est["signals"]["Vel_Estimate"].as_f64().unwrap(),
        -1.25 / TAU,
        1e-6,
        "Vel_Estimate",
    );
    let hb = dec.iter().find(|d| d["name"] == "Axis0_Heartbeat").unwrap();
    assert_eq!(hb["signals"]["Axis_Error"], 64.0);
    assert_eq!(hb["signals"]["Axis_State"], 8.0);
    // ...and our bridge reads frames cantools made from ODrive's DBC.
    let enc = res["odrive"]["encoded"].as_array().unwrap();
    let f = frame(
        enc[0]["id"].as_u64().unwrap(),
        &unhex(enc[0]["data"].as_str().unwrap()),
        false,
    );
    let Some(Ok(Reply::Reading {
        position_rad,
        velocity_rad_s,
        ..
    })) = od.decode(&f)
    else {
        panic!("{:?}", od.decode(&f));
    };
    close(position_rad, 0.75 * TAU, 1e-5, "Pos_Estimate read back");
    close(velocity_rad_s, -2.5 * TAU, 1e-5, "Vel_Estimate read back");
    let f = frame(
        enc[1]["id"].as_u64().unwrap(),
        &unhex(enc[1]["data"].as_str().unwrap()),
        false,
    );
    assert_eq!(od.decode(&f), Some(Ok(Reply::Status { fault: 0x800 })));

    // MIT: the mini-cheetah driver's encoding agrees with ours within its truncation (one
    // count), and our simulated motor reads it.
    let q = |span: f64, bits: u32| span / ((1u32 << bits) - 1) as f64;
    for (c, e) in mit_cmds
        .iter()
        .zip(res["mit"]["encoded"].as_array().unwrap())
    {
        let theirs: [u8; 8] = unhex(e.as_str().unwrap()).try_into().unwrap();
        let a = mit::unpack(&theirs, &r);
        let b = mit::unpack(&mit::pack(c, &r), &r);
        close(
            a.position_rad,
            b.position_rad,
            q(2.0 * r.p_max, 16) * 1.01,
            "MIT position",
        );
        close(
            a.velocity_rad_s,
            b.velocity_rad_s,
            q(2.0 * r.v_max, 12) * 1.01,
            "MIT velocity",
        );
        close(a.kp, b.kp, q(r.kp_max, 12) * 1.01, "MIT kp");
        close(a.kd, b.kd, q(r.kd_max, 12) * 1.01, "MIT kd");
        close(
            a.torque_nm,
            b.torque_nm,
            q(2.0 * r.t_max, 12) * 1.01,
            "MIT torque",
        );
        let f = frame(1, &theirs, false);
        let Some(Ok(mit::Order::Command(g))) = mit_server.on_frame(&f) else {
            panic!()
        };
        close(
            g.position_rad,
            c.position_rad,
            q(2.0 * r.p_max, 16),
            "MIT position read",
        );
        close(g.kp, c.kp.min(r.kp_max), q(r.kp_max, 12), "MIT kp read");
    }
    for (&(p, v, t, _), g) in replies
        .iter()
        .zip(res["mit"]["replies"].as_array().unwrap())
    {
        close(
            g["position"].as_f64().unwrap(),
            p,
            q(2.0 * r.p_max, 16),
            "MIT reply position",
        );
        close(
            g["velocity"].as_f64().unwrap(),
            v,
            q(2.0 * r.v_max, 12),
            "MIT reply velocity",
        );
        close(
            g["torque"].as_f64().unwrap(),
            t,
            q(2.0 * r.t_max, 12),
            "MIT reply torque",
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A CAN FD payload padded to the next valid length (moteus pads with NOP, 0x50).
fn pad_fd(mut d: Vec<u8>) -> Vec<u8> {
    while !protocol::frame::is_valid_fd_len(d.len()) {
        d.push(0x50);
    }
    d
}

/// One motor frame as a decoder read it: the joint's id, what it is, and its values (rad,
/// rad/s, N m/rad, N m s/rad, N m; the driver's own codes as numbers).
#[derive(Debug)]
struct Row {
    joint: u64,
    kind: String,
    v: std::collections::BTreeMap<&'static str, f64>,
}

/// Our decoders on one frame of the log: the motor's side for commands (the simulator's
/// servers), the bridge's for replies.
fn our_row(cfg: &leg::LegConfig, f: &CanFrame) -> Option<Row> {
    use std::collections::BTreeMap;
    for which in 0..2 {
        let j = if which == 0 { &cfg.hip } else { &cfg.length };
        let id = j.id.unwrap() as u64;
        let driver = cfg.driver(which);
        let mut v = BTreeMap::new();
        let command = |v: &mut BTreeMap<_, _>, c: &JointCommand| {
            v.insert("velocity", c.velocity_rad_s);
            v.insert("torque", c.torque_nm);
            v.insert("kp", c.kp);
            v.insert("kd", c.kd);
            // Without stiffness the position is moot (the damped stop's moteus command sends
            // NaN: none), so it is compared only where it acts.
            if c.kp != 0.0 {
                v.insert("position", c.position_rad);
            }
        };
        let kind = match cfg.hip.driver.unwrap() {
            leg::DriverKind::Moteus => {
                let s = moteus::Server::new(id as u8, j.moteus_kp.unwrap(), j.moteus_kd.unwrap());
                match s.on_frame(f) {
                    Some(Ok((moteus::Order::Position(c), _))) => {
                        v.insert("mode", 10.0);
                        command(&mut v, &c);
                        "command"
                    }
                    Some(Ok((moteus::Order::Stop, _))) => {
                        v.insert("mode", 0.0);
                        "command"
                    }
                    Some(Ok((moteus::Order::Query, _))) => "command",
                    Some(Err(e)) => panic!("our moteus server: {e}: {f:?}"),
                    None => "",
                }
            }
            leg::DriverKind::Odrive => match odrive::Server::new(id as u8).on_frame(f) {
                Some(Ok(odrive::Order::InputPos(p, vel, t))) => {
                    v.extend([("position", p), ("velocity", vel), ("torque", t)]);
                    "Set_Input_Pos"
                }
                Some(Ok(odrive::Order::PosGain(g))) => {
                    v.insert("Pos_Gain", g);
                    "Set_Pos_Gain"
                }
                Some(Ok(odrive::Order::VelGain(g))) => {
                    v.insert("Vel_Gain", g);
                    "Set_Vel_Gains"
                }
                Some(Ok(odrive::Order::State(s))) => {
                    v.insert("Axis_Requested_State", s as f64);
                    "Set_Axis_State"
                }
                Some(Ok(odrive::Order::ControllerMode(c, i))) => {
                    v.extend([("Control_Mode", c as f64), ("Input_Mode", i as f64)]);
                    "Set_Controller_Mode"
                }
                Some(Err(e)) => panic!("our ODrive server: {e}: {f:?}"),
                None => "",
            },
            leg::DriverKind::Mit => {
                let s = mit::Server::new(id as u8, j.mit_master_id, cfg.mit_ranges_of(which));
                match s.on_frame(f) {
                    Some(Ok(mit::Order::Command(c))) => {
                        command(&mut v, &c);
                        // MIT always carries a position (0 with no stiffness).
                        v.insert("position", c.position_rad);
                        "command"
                    }
                    Some(Ok(mit::Order::Enter)) => "enter",
                    Some(Ok(mit::Order::Exit)) => "exit",
                    Some(Ok(mit::Order::Zero)) => "zero",
                    Some(Err(e)) => panic!("our MIT server: {e}: {f:?}"),
                    None => "",
                }
            }
        };
        if !kind.is_empty() {
            return Some(Row {
                joint: id,
                kind: kind.into(),
                v,
            });
        }
        match driver.decode(f) {
            Some(Ok(Reply::Reading {
                position_rad,
                velocity_rad_s,
                torque_nm,
                fault,
            })) => {
                let odrive = matches!(driver, leg::driver::Driver::Odrive(_));
                v.extend([("position", position_rad), ("velocity", velocity_rad_s)]);
                if !odrive {
                    v.insert("torque", torque_nm);
                }
                if let Some(code) = fault {
                    v.insert("fault", code as f64);
                }
                let kind = if odrive {
                    "Get_Encoder_Estimates"
                } else {
                    "reply"
                };
                return Some(Row {
                    joint: id,
                    kind: kind.into(),
                    v,
                });
            }
            Some(Ok(Reply::Status { fault })) => {
                v.insert("Axis_Error", fault as f64);
                return Some(Row {
                    joint: id,
                    kind: "Heartbeat".into(),
                    v,
                });
            }
            Some(Err(e)) => panic!("our {} decoder: {e}: {f:?}", driver.name()),
            None => {}
        }
    }
    None
}

/// The vendor's row, in the same units as ours (ODrive's turns to rad).
fn their_row(r: &Value) -> Row {
    let mut v = std::collections::BTreeMap::new();
    let kind = r["kind"].as_str().unwrap().to_string();
    let turns = kind == "Set_Input_Pos" || kind == "Get_Encoder_Estimates";
    for (k, key) in [
        ("position", "position"),
        ("velocity", "velocity"),
        ("torque", "torque"),
        ("kp", "kp"),
        ("kd", "kd"),
        ("mode", "mode"),
        ("fault", "fault"),
        ("Input_Pos", "position"),
        ("Vel_FF", "velocity"),
        ("Torque_FF", "torque"),
        ("Pos_Estimate", "position"),
        ("Vel_Estimate", "velocity"),
        ("Pos_Gain", "Pos_Gain"),
        ("Vel_Gain", "Vel_Gain"),
        ("Axis_Requested_State", "Axis_Requested_State"),
        ("Control_Mode", "Control_Mode"),
        ("Input_Mode", "Input_Mode"),
        ("Axis_Error", "Axis_Error"),
    ] {
        if let Some(x) = r[k].as_f64() {
            let scale = if turns && (key == "position" || key == "velocity") {
                TAU
            } else {
                1.0
            };
            v.insert(key, x * scale);
        }
    }
    Row {
        joint: r["joint"].as_u64().unwrap(),
        kind,
        v,
    }
}

/// On a bus: the closed loop through each protocol's motors (`presrs demo --leg P
/// --candump LOG`); python-can reads the log and the protocol's own package decodes every motor
/// frame in it (mjbots' `moteus`; cantools with the CANSimple DBC shipped in `odrive-can`;
/// `mini-cheetah-motor-driver-socketcan`'s unpacking and model ranges). They read what our
/// decoders read, frame by frame, and what they read is the leg the config describes: each
/// joint commanded at rate_hz, the length joint's stiffness the config's leg spring, the hip's
/// its flight stiffness, no fault, and the length joint moving as the hopper hops.
#[test]
fn the_drivers_packages_decode_every_motor_frame_of_a_closed_loop_run() {
    let dir = std::env::temp_dir().join(format!("presrs-drivers-log-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let model = common::small_model(&dir);
    for kind in leg::DriverKind::ALL {
        let proto = kind.name();
        let log = dir.join(format!("{proto}.log"));
        let out = common::output_ok(
            std::process::Command::new(env!("CARGO_BIN_EXE_presrs"))
                .args(["demo", "--steps", "12", "--json", "--leg", proto, "--model"])
                .arg(&model)
                .arg("--csv")
                .arg(dir.join("steps.csv"))
                .arg("--candump")
                .arg(&log),
        );
        let summary: Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(summary["falls"], 0, "{proto}: {summary}");

        let cfg = leg::LegConfig::example(kind);
        let (hip, len) = (cfg.hip.id.unwrap() as u64, cfg.length.id.unwrap() as u64);
        let mut joints = serde_json::Map::new();
        for j in [&cfg.hip, &cfg.length] {
            joints.insert(
                j.id.unwrap().to_string(),
                json!([j.moteus_kp.unwrap_or(0.0), j.moteus_kd.unwrap_or(0.0)]),
            );
        }
        let spec = json!({
            "protocol": proto, "log": log, "joints": joints, "source": cfg.hip.moteus_source,
            "master": cfg.hip.mit_master_id, "model": cfg.hip.mit_model,
        });
        let spec_path = dir.join(format!("{proto}-spec.json"));
        std::fs::write(&spec_path, spec.to_string()).unwrap();
        let res = drivers_check(&["log".as_ref(), spec_path.as_os_str()]);
        let theirs: Vec<Row> = res["rows"]
            .as_array()
            .unwrap()
            .iter()
            .map(their_row)
            .collect();

        // Frame by frame: the same frames are motor frames, and read to the same values.
        let records = protocol::candump::read_log_file(&log).unwrap();
        assert_eq!(res["frames"].as_u64().unwrap() as usize, records.len());
        let ours: Vec<Row> = records
            .iter()
            .filter_map(|r| our_row(&cfg, &r.stamped.frame))
            .collect();
        assert_eq!(ours.len(), theirs.len(), "{proto}: motor frames");
        for (i, (a, b)) in ours.iter().zip(&theirs).enumerate() {
            assert_eq!(
                (a.joint, &a.kind),
                (b.joint, &b.kind),
                "{proto} frame {i}: {a:?} vs {b:?}"
            );
            for (k, x) in &a.v {
                let y = b.v.get(k).unwrap_or_else(|| {
                    panic!("{proto} frame {i}: {k} missing from theirs: {a:?} vs {b:?}")
                });
                // f32 registers and fields (moteus, ODrive), one count's rounding of the
                // vendors' own conversions (MIT).
                let tol = 1e-4 * x.abs().max(1.0);
                assert!(
                    (x - y).abs() <= tol,
                    "{proto} frame {i} {k}: ours {x}, theirs {y}"
                );
            }
        }

        // What their decoders read is the leg of the config.
        let t = |kind: &str, joint: u64| -> Vec<&Row> {
            theirs
                .iter()
                .filter(|r| r.kind == kind && r.joint == joint)
                .collect()
        };
        let command_kind = if proto == "odrive" {
            "Set_Input_Pos"
        } else {
            "command"
        };
        let times: Vec<f64> = res["rows"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|r| r["kind"] == command_kind && r["joint"] == len)
            .map(|r| r["t"].as_f64().unwrap())
            .collect();
        let rate = (times.len() - 1) as f64 / (times[times.len() - 1] - times[0]);
        let want_kp = |which: usize, k: f64| cfg.map(which).stiffness_to_driver(k);
        let (leg_kp, hip_kp) = (
            want_kp(1, cfg.impedance.stance_stiffness_n_per_m),
            want_kp(0, cfg.impedance.hip_stiffness_nm_per_rad),
        );
        let kps = |joint: u64| -> Vec<f64> {
            if proto == "odrive" {
                // Stiffness = pos_gain (turn/s per turn) x vel_gain (N m per turn/s), per
                // turn: over 2 pi per rad.
                let pg = t("Set_Pos_Gain", joint);
                let vg = t("Set_Vel_Gains", joint);
                pg.iter()
                    .zip(&vg)
                    .map(|(p, v)| p.v["Pos_Gain"] * v.v["Vel_Gain"] / TAU)
                    .collect()
            } else {
                t(command_kind, joint)
                    .iter()
                    .filter_map(|r| r.v.get("kp").copied())
                    .collect()
            }
        };
        let near = |v: &[f64], want: f64| v.iter().any(|k| (k - want).abs() <= 0.05 * want);
        let replies = if proto == "odrive" {
            "Get_Encoder_Estimates"
        } else {
            "reply"
        };
        let lengths: Vec<f64> = t(replies, len).iter().map(|r| r.v["position"]).collect();
        let span = lengths.iter().cloned().fold(f64::MIN, f64::max)
            - lengths.iter().cloned().fold(f64::MAX, f64::min);
        let faults = theirs
            .iter()
            .filter(|r| {
                r.v.get("fault").is_some_and(|&f| f != 0.0)
                    || r.v.get("Axis_Error").is_some_and(|&f| f != 0.0)
            })
            .count();
        eprintln!(
            "{proto}: {} frames, {} motor frames decoded by the package, {} commands to the length joint at {rate:.1} Hz, its stiffness {:?} N m/rad (config {leg_kp:.3}), hip's {:?} (config {hip_kp:.3}), length joint's encoder span {span:.3} rad, {faults} faults",
            records.len(),
            theirs.len(),
            times.len(),
            kps(len).iter().fold(f64::MIN, |a, &b| a.max(b)),
            kps(hip).iter().fold(f64::MIN, |a, &b| a.max(b)),
        );
        assert!(
            (rate - cfg.rate_hz).abs() <= 0.02 * cfg.rate_hz,
            "{proto}: {rate} Hz"
        );
        assert!(near(&kps(len), leg_kp), "{proto}: {:?}", kps(len));
        assert!(near(&kps(hip), hip_kp), "{proto}: {:?}", kps(hip));
        // Compressing the spring by 1 cm turns the length joint by 0.126 rad at 0.5 m/turn.
        assert!(span > 0.1, "{proto}: length joint span {span} rad");
        assert_eq!(faults, 0, "{proto}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
