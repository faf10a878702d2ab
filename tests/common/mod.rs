//! Helpers shared by the system tests.
#![allow(dead_code)]

use std::collections::BTreeMap;

use protocol::messages::*;

/// The DBC signal values of a message, from our own decoder (for comparison with cantools).
pub fn signals(m: &Message) -> BTreeMap<&'static str, f64> {
    let mut s = BTreeMap::new();
    match m {
        Message::LegCommand(c) => {
            s.insert("LegLengthSetpoint", c.leg_length_m);
            s.insert("TouchdownAngleSetpoint", c.touchdown_angle_rad);
            s.insert("GaitId", c.gait as f64);
            s.insert("Phase", c.phase as u8 as f64);
            s.insert("Sequence", c.seq as f64);
        }
        Message::FootContact(c) => {
            s.insert("Contact", c.stance as u8 as f64);
            s.insert("Sequence", c.seq as f64);
            s.insert("TimestampUs", c.timestamp_us as f64);
        }
        Message::LegState(c) => {
            s.insert("LegAngle", c.leg_angle_rad);
            s.insert("LegLength", c.leg_length_m);
            s.insert("TimestampUs", c.timestamp_us as f64);
        }
        Message::LegStatus(c) => {
            s.insert("Mode", c.mode as u8 as f64);
            s.insert("Joint", c.joint as f64);
            s.insert("CommandAgeMs", c.command_age_ms as f64);
            s.insert("FaultCode", c.fault_code as f64);
        }
        Message::TerrainClass(c) => {
            s.insert("Step", c.step as f64);
            s.insert("TerrainId", c.terrain as f64);
            s.insert("Confidence", c.confidence_pct);
            s.insert("DamagePercent", c.damage_pct);
            for (name, bit) in [
                ("FlagRepaired", flags::REPAIRED),
                ("FlagLowConfidence", flags::LOW_CONFIDENCE),
                ("FlagNoSample", flags::NO_SAMPLE),
                ("FlagMultiFrame", flags::MULTI_FRAME),
                ("FlagNoContact", flags::NO_CONTACT),
                ("FlagEnergy", flags::ENERGY),
            ] {
                s.insert(name, (c.flags & bit != 0) as u8 as f64);
            }
            s.insert(
                "UnknownReason",
                ((c.flags & flags::REASON_MASK) >> flags::REASON_SHIFT) as f64,
            );
            s.insert("LatencyUs", c.latency_us as f64);
        }
        Message::NodeStatus(c) => {
            s.insert("Heartbeat", c.heartbeat as f64);
            s.insert("State", c.state as u8 as f64);
            s.insert("ModelId", c.model_id as f64);
            s.insert("CrcFailures", c.crc_failures as f64);
            s.insert("IncompleteFrames", c.incomplete_frames as f64);
            s.insert("BusErrors", c.bus_errors as f64);
            s.insert("DamagePercent", c.damage_pct);
        }
        Message::GaitStatus(c) => {
            s.insert("ActiveGait", c.gait as f64);
            s.insert("TerrainId", c.terrain as f64);
            s.insert("Omega", c.omega_rad_s);
            s.insert("BetaDes", c.beta_des_rad);
            s.insert("Reason", c.reason as u8 as f64);
            s.insert("Foot", c.foot as f64);
        }
        Message::StepState(c) => {
            s.insert("Speed", c.speed_m_s);
            s.insert("StanceTime", c.stance_s);
            s.insert("FlightTime", c.flight_s);
            s.insert("TouchdownAngle", c.touchdown_angle_rad);
            s.insert("LiftoffAngle", c.liftoff_angle_rad);
            s.insert("EnergyRatio", c.energy_ratio);
        }
        Message::TactileSegment(_) => {}
    }
    s
}

/// One random message of every kind for a foot, already quantised as the wire carries it.
pub fn random_messages(rng: &mut impl rand::Rng, foot: u8) -> Vec<Message> {
    let ms = vec![
        Message::LegCommand(LegCommand {
            leg_length_m: rng.random_range(0.0..0.6),
            touchdown_angle_rad: rng.random_range(-1.0..1.0),
            gait: rng.random_range(0..4),
            phase: if rng.random_bool(0.5) {
                Phase::Stance
            } else {
                Phase::Flight
            },
            seq: rng.random(),
        }),
        Message::FootContact(FootContact {
            stance: rng.random_bool(0.5),
            seq: rng.random(),
            timestamp_us: rng.random(),
        }),
        Message::LegState(LegState {
            leg_angle_rad: rng.random_range(-1.0..1.0),
            leg_length_m: rng.random_range(0.0..0.6),
            timestamp_us: rng.random(),
        }),
        Message::LegStatus(LegStatus {
            mode: LegMode::from_u8(rng.random_range(0..7)).unwrap_or_default(),
            joint: rng.random_range(0..3),
            command_age_ms: rng.random(),
            fault_code: rng.random(),
        }),
        Message::TerrainClass(TerrainClass {
            step: rng.random(),
            terrain: rng.random_range(0..12),
            confidence_pct: rng.random_range(0.0..100.0),
            damage_pct: rng.random_range(0.0..100.0),
            flags: rng.random_range(0..16),
            latency_us: rng.random_range(0..70000),
        }),
        Message::NodeStatus(NodeStatus {
            heartbeat: rng.random(),
            state: NodeState::from_u8(rng.random_range(0..5)).unwrap_or_default(),
            model_id: rng.random(),
            crc_failures: rng.random(),
            incomplete_frames: rng.random(),
            bus_errors: rng.random(),
            damage_pct: rng.random_range(0.0..100.0),
        }),
        Message::GaitStatus(GaitStatus {
            gait: rng.random_range(1..4),
            terrain: rng.random_range(0..12),
            omega_rad_s: rng.random_range(0.0..20.0),
            beta_des_rad: rng.random_range(-1.0..1.0),
            reason: GaitReason::from_u8(rng.random_range(0..4)).unwrap_or_default(),
            foot,
        }),
        Message::StepState(protocol::messages::StepState {
            speed_m_s: rng.random_range(-3.0..3.0),
            stance_s: rng.random_range(0.0..0.5),
            flight_s: rng.random_range(0.0..0.5),
            touchdown_angle_rad: rng.random_range(-1.0..1.0),
            liftoff_angle_rad: rng.random_range(-1.0..1.0),
            energy_ratio: rng.random_range(0.0..1.9),
        }),
    ];
    // Quantise through the wire so expected values are exactly what the frame carries.
    let ids = protocol::IdConfig::default();
    ms.into_iter()
        .filter_map(|m| m.to_frame(&ids, foot))
        .filter_map(|f| {
            protocol::messages::decode(&f, &ids)
                .ok()
                .flatten()
                .map(|(_, m)| m)
        })
        .collect()
}

/// The frames of one 44x44 8-bit image, as the foot sends them.
pub fn frames_44x44(
    ids: &protocol::IdConfig,
    v: protocol::tactile::Variant,
    foot: u8,
    seq: u8,
    ts: u32,
    px: &[u16],
) -> Vec<protocol::CanFrame> {
    let img = protocol::tactile::ImageRef {
        rows: 44,
        cols: 44,
        bits: 8,
        timestamp_us: ts,
        pixels: px,
    };
    let mut out = Vec::new();
    protocol::tactile::Segmenter::new(v, ids.clone())
        .frames(foot, seq, &img, &mut out)
        .unwrap_or_else(|e| panic!("{e}"));
    out
}

/// Hex of bytes.
pub fn hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02x}")).collect()
}

pub fn unhex(s: &str) -> Vec<u8> {
    (0..s.len() / 2)
        .filter_map(|i| u8::from_str_radix(&s[2 * i..2 * i + 2], 16).ok())
        .collect()
}

/// The repository root (the root package's manifest directory).
pub fn root() -> std::path::PathBuf {
    std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Runs `scripts/<script>` (one that reads the `jiku-data` package) with `args` and `--out
/// out`; its failure fails the test (never a skip).
pub fn jiku_script(script: &str, args: &[&str], out: &std::path::Path) {
    let o = std::process::Command::new("python3")
        .arg(root().join("scripts").join(script))
        .args(args)
        .arg("--out")
        .arg(out)
        .output()
        .unwrap_or_else(|e| panic!("cannot run python3 scripts/{script}: {e}"));
    assert!(
        o.status.success(),
        "scripts/{script} failed (run scripts/install-deps.sh, which installs jiku-data): {}",
        String::from_utf8_lossy(&o.stderr)
    );
}

/// Runs the Python interop client; its failure fails the test (never a skip).
pub fn python(args: &[&str]) -> String {
    let script = root().join("tests/interop/cantools_check.py");
    let out = std::process::Command::new("python3")
        .arg(&script)
        .args(args)
        .output()
        .unwrap_or_else(|e| {
            panic!(
                "cannot run python3 {}: {e}. Install: pip install -r tests/requirements.txt",
                script.display()
            )
        });
    let stdout = String::from_utf8_lossy(&out.stdout).to_string();
    assert!(
        out.status.success(),
        "python3 cantools_check.py {args:?} failed:\n{stdout}\n{}\n(needs: pip install -r tests/requirements.txt)",
        String::from_utf8_lossy(&out.stderr)
    );
    stdout
}

/// The command that runs the protocol crate's example `name` (`args` after it): the binary
/// `cargo test --workspace` built beside this test's when it is newer than every source it is
/// built from (the protocol crate's `src/`, the example, its manifest, the lock file), else
/// `cargo run`. Why: `cargo run -p presrs-protocol` resolves the crate's features alone, not as
/// the workspace's test build did, and so compiled it and its dependencies again (49 s of the
/// test command's 8 min on a 2-core machine).
pub fn protocol_example(name: &str, args: &[&str]) -> std::process::Command {
    let modified = |p: &std::path::Path| std::fs::metadata(p).and_then(|m| m.modified()).ok();
    let built = std::env::current_exe()
        .ok()
        .and_then(|t| Some(t.parent()?.parent()?.join("examples").join(name)));
    let newest_source = {
        let p = root().join("protocol");
        let mut files = vec![
            p.join("Cargo.toml"),
            root().join("Cargo.lock"),
            p.join("examples").join(format!("{name}.rs")),
        ];
        let mut dirs = vec![p.join("src")];
        while let Some(d) = dirs.pop() {
            for e in std::fs::read_dir(&d).into_iter().flatten().flatten() {
                let path = e.path();
                if path.is_dir() {
                    dirs.push(path);
                } else {
                    files.push(path);
                }
            }
        }
        files.iter().filter_map(|f| modified(f)).max()
    };
    let mut c = match (built, newest_source) {
        (Some(bin), Some(src)) if modified(&bin).is_some_and(|b| b > src) => {
            std::process::Command::new(bin)
        }
        _ => {
            let mut c = std::process::Command::new(env!("CARGO"));
            c.current_dir(root()).args([
                "run",
                "-q",
                "-p",
                "presrs-protocol",
                "--example",
                name,
                "--",
            ]);
            c
        }
    };
    c.args(args);
    c
}

/// Runs `cmd` to the end; unless it succeeded, panics with its status and stderr.
pub fn output_ok(cmd: &mut std::process::Command) -> std::process::Output {
    let out = cmd
        .output()
        .unwrap_or_else(|e| panic!("starting {cmd:?}: {e}"));
    assert!(
        out.status.success(),
        "{cmd:?}: {}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// A small model (20 dynamic G2 images per terrain, the paper's crop), saved in `dir`.
pub fn small_model(dir: &std::path::Path) -> std::path::PathBuf {
    let samples = sim::dataset::generate(&sim::dataset::Options {
        kind: sim::dataset::Kind::Dynamic,
        n: Some(20),
        gait: controller::Gait::g2(),
        damage_pct: 0.0,
        sensor: sim::DEFAULT_SENSOR,
        seed: 4,
    });
    let set = presrs::simdata::training_set(samples, &sim::dataset::Kind::Dynamic.terrains());
    let opts = node::classifier::train::TrainOptions {
        crop: node::classifier::Crop {
            top: 0,
            bottom: 3,
            left: 6,
            right: 0,
        }
        .into(),
        ..Default::default()
    };
    let (model, _) = node::classifier::train::train(&set.labelled(), &set.classes, &opts).unwrap();
    let path = dir.join("model.json");
    model.save(&path).unwrap();
    path
}

/// A model of the simulator's dynamic terrains but `left_out` (30 G2 images each, seed 4, the
/// defaults' crop and checks): the left-out terrain is new ground to it.
pub fn model_without(left_out: &str) -> node::classifier::Model {
    let samples: Vec<_> = sim::dataset::generate(&sim::dataset::Options {
        kind: sim::dataset::Kind::Dynamic,
        n: Some(30),
        gait: controller::Gait::g2(),
        damage_pct: 0.0,
        sensor: sim::DEFAULT_SENSOR,
        seed: 4,
    })
    .into_iter()
    .filter(|s| s.terrain.name() != left_out)
    .collect();
    let terrains: Vec<_> = sim::dataset::Kind::Dynamic
        .terrains()
        .into_iter()
        .filter(|t| t.name() != left_out)
        .collect();
    let set = presrs::simdata::training_set(samples, &terrains);
    let opts = node::classifier::train::TrainOptions::default();
    node::classifier::train::train(&set.labelled(), &set.classes, &opts)
        .unwrap()
        .0
}
