//! A lab's own terrain end to end through one terrains file: `presrs train` on a class folder
//! named after it, the node (`presrs node --replay`) sending its id, the controller choosing its
//! gait, and the DBC naming it. Without the file, each of them refuses and says why.

mod common;

use std::path::Path;
use std::process::Command;

use controller::{Controller, ControllerConfig};
use protocol::messages::{FootContact, Message, NodeStatus, TerrainClass};
use protocol::tactile::Variant;
use protocol::{IdConfig, Stamped, TerrainCatalog};
use rand::{Rng, SeedableRng};

const TERRAINS: &str = "# our lab's floor\n[[terrain]]\nid = 20\nname = \"asphalt\"\n";

/// A 44x44 texture: contact patches every `period` sensels, `fill` of each, random placement.
fn texture(rng: &mut impl Rng, period: usize, fill: f64) -> Vec<u16> {
    let (dy, dx) = (rng.random_range(0..period), rng.random_range(0..period));
    (0..44 * 44)
        .map(|p| {
            let (r, c) = (p / 44 + dy, p % 44 + dx);
            let on = ((r % period) as f64) < fill * period as f64
                && ((c % period) as f64) < fill * period as f64;
            let v: f64 = if on { 150.0 } else { 10.0 } + rng.random_range(-8.0..8.0);
            v.clamp(0.0, 255.0) as u16
        })
        .collect()
}

const CLASSES: [(&str, usize, f64); 3] =
    [("wood", 4, 0.5), ("asphalt", 7, 0.5), ("grass", 11, 0.35)];

fn write_dataset(dir: &Path) {
    let mut rng = rand::rngs::StdRng::seed_from_u64(20);
    for (name, period, fill) in CLASSES {
        let d = dir.join(name);
        std::fs::create_dir_all(&d).unwrap();
        for i in 0..30 {
            let px = texture(&mut rng, period, fill);
            let mut b = b"P2\n44 44\n255\n".to_vec();
            for v in px {
                b.extend_from_slice(format!("{v} ").as_bytes());
            }
            std::fs::write(d.join(format!("{i:03}.pgm")), b).unwrap();
        }
    }
}

/// Four steps on asphalt as a foot sends them: switch edges, and images at 100 Hz throughout
/// (blank in flight).
fn write_asphalt_log(path: &Path) {
    let ids = IdConfig::default();
    let mut rng = rand::rngs::StdRng::seed_from_u64(21);
    let mut records = Vec::new();
    let base = 1_800_000_000_000_000u64;
    let mut push = |t_us: u64, frame| {
        records.push(Stamped {
            t_us: base + t_us,
            frame,
        })
    };
    let mut seq = 0u8;
    let stances: Vec<u64> = (0..4).map(|step| 100_000 + step * 400_000).collect();
    for &td in &stances {
        for (dt, stance) in [(0, true), (150_000, false)] {
            seq = seq.wrapping_add(1);
            let m = Message::FootContact(FootContact {
                stance,
                seq,
                timestamp_us: (td + dt) as u32,
            });
            push(td + dt, m.to_frame(&ids, 0).unwrap());
        }
    }
    for k in 0..170u64 {
        let t = 5_000 + k * 10_000;
        let in_stance = stances.iter().any(|&td| (td..td + 150_000).contains(&t));
        let px = if in_stance {
            texture(&mut rng, 7, 0.5)
        } else {
            vec![0; 44 * 44]
        };
        for f in common::frames_44x44(&ids, Variant::Fd, 0, k as u8, t as u32, &px) {
            push(t + 500, f);
        }
    }
    records.sort_by_key(|r| r.t_us);
    let mut w = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    for r in &records {
        protocol::candump::write_record(&mut w, "can0", r).unwrap();
    }
}

fn presrs(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_presrs"))
        .args(args)
        .output()
        .unwrap()
}

#[test]
fn a_lab_terrain_from_a_terrains_file_trains_classifies_switches_and_decodes() {
    let dir = std::env::temp_dir().join(format!("presrs-terrains-{}", std::process::id()));
    let data = dir.join("data");
    write_dataset(&data);
    let terrains = dir.join("terrains.toml");
    std::fs::write(&terrains, TERRAINS).unwrap();
    let (data_s, terrains_s) = (data.to_str().unwrap(), terrains.to_str().unwrap());
    let model = dir.join("model.json");
    let model_s = model.to_str().unwrap();

    // Without the file, training refuses the folder, names it and the fix; no id is invented.
    let out = presrs(&[
        "train", "--data", data_s, "--out", model_s, "--crop", "2,2,2,2",
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "trained on an unknown terrain");
    assert!(
        err.contains("asphalt") && err.contains("--terrains") && err.contains("[[terrain]]"),
        "{err}"
    );
    assert!(!model.exists());

    let train = [
        "train", "--data", data_s, "--out", model_s, "--crop", "2,2,2,2",
    ];
    common::output_ok(
        Command::new(env!("CARGO_BIN_EXE_presrs"))
            .args(train)
            .args(["--terrains", terrains_s]),
    );
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&model).unwrap()).unwrap();
    let asphalt = m["classes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["name"] == "asphalt")
        .unwrap_or_else(|| panic!("no asphalt class in {}", m["classes"]));
    assert_eq!(asphalt["terrain_id"], 20);

    // The node: its id on every step of an asphalt run, and its name in the output.
    let log = dir.join("asphalt.log");
    write_asphalt_log(&log);
    let replay = [
        "node",
        "--replay",
        log.to_str().unwrap(),
        "--model",
        model_s,
        "--json",
    ];
    let out = presrs(&replay);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success(),
        "the node ran a model whose ids it cannot name"
    );
    assert!(err.contains("asphalt") && err.contains("20"), "{err}");
    let out = common::output_ok(
        Command::new(env!("CARGO_BIN_EXE_presrs"))
            .args(replay)
            .args(["--terrains", terrains_s]),
    );
    let steps: Vec<serde_json::Value> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(
        steps.len(),
        4,
        "one TerrainClass per step: {steps:?}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for s in &steps {
        assert_eq!(
            (&s["terrain_id"], &s["terrain"]),
            (&20.into(), &"asphalt".into()),
            "{s}"
        );
    }

    // The controller: `asphalt = 3` needs the catalog; with it, asphalt steps switch to G3.
    let cfg_text = format!(
        "terrains = \"{}\"\ninitial_gait = 1\n[terrain_gaits]\nasphalt = 3\n",
        terrains_s
    );
    let bare =
        ControllerConfig::parse("initial_gait = 1\n[terrain_gaits]\nasphalt = 3\n", "c.toml");
    let e = bare.unwrap_err().to_string();
    assert!(
        e.contains("terrain_gaits.asphalt") && e.contains("terrains"),
        "{e}"
    );
    let cfg = ControllerConfig::parse(&cfg_text, "c.toml").unwrap();
    let catalog = cfg.catalog().unwrap();
    let mut ctrl = Controller::new(cfg, &catalog);
    let mut sink = |_: Message| {};
    let hb = Message::NodeStatus(NodeStatus::default());
    let mut t = 0u64;
    for s in &steps {
        t += 400_000;
        ctrl.on_message(0, &hb, t, &mut sink);
        let edge = |stance, at: u64| {
            Message::FootContact(FootContact {
                stance,
                seq: 0,
                timestamp_us: at as u32,
            })
        };
        ctrl.on_message(0, &edge(true, t), t, &mut sink);
        let tc = TerrainClass {
            terrain: s["terrain_id"].as_u64().unwrap() as u8,
            confidence_pct: s["confidence_pct"].as_f64().unwrap(),
            ..Default::default()
        };
        ctrl.on_message(0, &Message::TerrainClass(tc), t + 70_000, &mut sink);
        ctrl.on_message(0, &edge(false, t + 150_000), t + 150_000, &mut sink);
        t += 150_000;
    }
    assert_eq!(ctrl.gait().id, 3, "asphalt's gait");

    // The DBC names id 20; with `--features interop`, cantools (an independent decoder) reads
    // a TerrainClass frame of id 20 back as "asphalt".
    let dbc_path = dir.join("presrs.dbc");
    common::output_ok(Command::new(env!("CARGO_BIN_EXE_presrs")).args([
        "lab",
        "dbc",
        "--terrains",
        terrains_s,
        "--out",
        dbc_path.to_str().unwrap(),
    ]));
    let dbc = std::fs::read_to_string(&dbc_path).unwrap();
    let table = dbc
        .lines()
        .find(|l| l.starts_with("VAL_TABLE_ Terrain"))
        .unwrap_or_default();
    assert!(table.contains(" 20 \"asphalt\""), "{table}");
    #[cfg(feature = "interop")]
    {
        let tc = TerrainClass {
            terrain: 20,
            confidence_pct: 90.0,
            ..Default::default()
        };
        let f = Message::TerrainClass(tc)
            .to_frame(&IdConfig::default(), 0)
            .unwrap();
        let named = common::python(&[
            "choice",
            dbc_path.to_str().unwrap(),
            &f.raw_id().to_string(),
            &common::hex(f.data()),
            "TerrainId",
        ]);
        assert_eq!(named.trim(), "asphalt");
    }

    // A catalog that clashes with a default names both entries.
    std::fs::write(&terrains, "[[terrain]]\nid = 8\nname = \"asphalt\"\n").unwrap();
    let out = presrs(&["lab", "dbc", "--terrains", terrains_s]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains("`asphalt` (id 8)") && err.contains("`wood` (id 8)"),
        "{err}"
    );
    assert_eq!(TerrainCatalog::paper().by_id(20), None);
    let _ = std::fs::remove_dir_all(&dir);
}
