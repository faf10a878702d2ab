//! Our encoders against Python `cantools` reading `protocol/presrs.dbc`, in both directions, and
//! our candump writer against python-can's reader. Run with `--features interop` (the README's
//! test command does); it needs `pip install -r tests/requirements.txt`.
#![cfg(feature = "interop")]

mod common;

use common::*;
use protocol::ids::IdConfig;
use protocol::messages::decode;
use protocol::tactile::{Reassembler, Variant};
use protocol::{CanFrame, Stamped};
use rand::{Rng, SeedableRng};

fn tmp(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("presrs-interop-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d.join(name)
}

#[test]
fn cantools_decodes_every_signal_we_encode() {
    let ids = IdConfig::default();
    let mut rng = rand::rngs::StdRng::seed_from_u64(7);
    let mut vectors = Vec::new();
    for foot in 0..8u8 {
        for _ in 0..10 {
            for m in random_messages(&mut rng, foot) {
                let f = m.to_frame(&ids, foot).unwrap();
                vectors.push(serde_json::json!({"id": f.raw_id(), "data": hex(f.data()), "expected": signals(&m)}));
            }
        }
        // Tactile: header and data signals of a real image.
        let px: Vec<u16> = (0..44 * 44).map(|_| rng.random_range(0..256)).collect();
        let frames = frames_44x44(&ids, Variant::Fd, foot, 3, 99, &px);
        let crc = protocol::tactile::pixel_crc(&px, 8);
        vectors.push(serde_json::json!({"id": frames[0].raw_id(), "data": hex(frames[0].data()), "expected": {
            "FrameSeq": 3, "SegmentIndex": 0, "Rows": 44, "Cols": 44, "BitsPerPixel": 8, "SegmentCount": 32,
            "Crc32": crc, "TimestampUs": 99}}));
        for (s, f) in frames.iter().enumerate().skip(1) {
            let mut exp = serde_json::Map::new();
            exp.insert("SegmentIndex".into(), s.into());
            for i in 0..62 {
                let k = (s - 1) * 62 + i;
                exp.insert(format!("Px{i:02}"), px.get(k).copied().unwrap_or(0).into());
            }
            vectors.push(
                serde_json::json!({"id": f.raw_id(), "data": hex(f.data()), "expected": exp}),
            );
        }
    }
    let path = tmp("vectors.json");
    std::fs::write(&path, serde_json::to_string(&vectors).unwrap()).unwrap();
    let dbc = root().join("protocol/presrs.dbc");
    let out = python(&["decode", dbc.to_str().unwrap(), path.to_str().unwrap()]);
    assert!(out.contains(" 0 mismatches"), "{out}");
    println!("{out}");
}

#[test]
fn we_decode_what_cantools_encodes() {
    let ids = IdConfig::default();
    let dbc = root().join("protocol/presrs.dbc");
    let path = tmp("encoded.json");
    python(&[
        "encode",
        dbc.to_str().unwrap(),
        path.to_str().unwrap(),
        "11",
    ]);
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    let mut n = 0;
    for vec in v["vectors"].as_array().unwrap() {
        let id = protocol::frame::make_id(
            vec["id"].as_u64().unwrap() as u32,
            vec["extended"].as_bool().unwrap(),
        )
        .unwrap();
        let f = CanFrame::classic(id, &unhex(vec["data"].as_str().unwrap())).unwrap();
        let (_, m) = decode(&f, &ids)
            .unwrap_or_else(|e| panic!("{}: {e}", vec["name"]))
            .unwrap_or_else(|| panic!("{}: not recognised", vec["name"]));
        let ours = signals(&m);
        for (name, want) in vec["signals"].as_object().unwrap() {
            let got = ours
                .get(name.as_str())
                .unwrap_or_else(|| panic!("{} lacks {name}", vec["name"]));
            assert!(
                (got - want.as_f64().unwrap()).abs() < 1e-6,
                "{} {name}: ours {got} cantools {want}",
                vec["name"]
            );
            n += 1;
        }
    }
    assert!(n > 1000, "only {n} signals compared");
    for img in v["images"].as_array().unwrap() {
        let variant = if img["name"].as_str().unwrap().contains("Classic") {
            Variant::Classic
        } else {
            Variant::Fd
        };
        let mut r = Reassembler::default();
        let mut got = None;
        for (i, fr) in img["frames"].as_array().unwrap().iter().enumerate() {
            if let Some(im) = r.push(variant, 2, &unhex(fr.as_str().unwrap()), i as u64) {
                got = Some(im.pixels().to_vec());
            }
        }
        let want: Vec<u16> = img["pixels"]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| p.as_u64().unwrap() as u16)
            .collect();
        assert_eq!(
            got.as_deref(),
            Some(&want[..]),
            "{}: {:?}",
            img["name"],
            r.stats()
        );
    }
}

#[test]
fn python_can_reads_our_candump_log() {
    let ids = IdConfig::default();
    let mut rng = rand::rngs::StdRng::seed_from_u64(3);
    let mut log = Vec::new();
    let mut t = 1_700_000_000_000_000u64;
    let mut n = 0;
    for foot in 0..2u8 {
        for m in random_messages(&mut rng, foot) {
            t += 137;
            protocol::candump::write_record(
                &mut log,
                "vcan0",
                &Stamped {
                    t_us: t,
                    frame: m.to_frame(&ids, foot).unwrap(),
                },
            )
            .unwrap();
            n += 1;
        }
        let px: Vec<u16> = (0..44 * 44).map(|_| rng.random_range(0..256)).collect();
        for f in frames_44x44(&ids, Variant::Fd, foot, 1, 5, &px) {
            t += 20;
            protocol::candump::write_record(&mut log, "vcan0", &Stamped { t_us: t, frame: f })
                .unwrap();
            n += 1;
        }
    }
    let path = tmp("ours.log");
    std::fs::write(&path, &log).unwrap();
    let dbc = root().join("protocol/presrs.dbc");
    let out = python(&["log", dbc.to_str().unwrap(), path.to_str().unwrap()]);
    let v: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
    assert_eq!(v["frames"].as_u64(), Some(n));
    assert_eq!(v["tactile_headers"].as_u64(), Some(2));
}
