//! The leg bridge's motor frames against the drivers' own Python packages (issue 27): mjbots'
//! `moteus`, cantools reading the CANSimple DBC shipped in `odrive-can`, and
//! `mini-cheetah-motor-driver-socketcan` (`tests/interop/drivers_check.py`). Each direction: their
//! decoder reads what our bridge and our simulated drivers send, and our decoders read what
//! their encoders make. Run with `--features interop` (the README's test command does).
#![cfg(feature = "interop")]

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
    let o = std::process::Command::new("python3")
        .arg(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/interop/drivers_check.py"
        ))
        .arg(&input)
        .output()
        .expect("python3");
    assert!(
        o.status.success(),
        "drivers_check.py failed (pip install -r tests/requirements.txt): {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let res: Value = serde_json::from_slice(&o.stdout).unwrap();

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
