//! The foot's own settings measured from a lab's stances, through the README's path (a
//! candump log, `capture`, `train`, `node --replay`): a foot whose footprint sits off the
//! array's centre and whose load builds up slowly (full at 150 ms, where the paper's hopper
//! had it at 70) gets a crop that keeps its load and a deciding frame that classifies at least
//! as well as the best fixed offset, and the node samples at the model's frame.

mod common;

use std::process::Command;

use protocol::messages::{FootContact, Message};
use protocol::tactile::Variant;
use protocol::{IdConfig, Stamped};
use rand::{Rng, SeedableRng};

/// The footprint: rows 12-43 and columns 9-38 of the 44x44 array.
const ROWS: (usize, usize) = (12, 44);
const COLS: (usize, usize) = (9, 39);
/// Full load this long after touchdown.
const FULL_LOAD_MS: f64 = 150.0;
const STANCE_MS: u64 = 220;

/// One frame of a stance on terrain `t` (a texture of period 5, 6 or 7 sensels), `ms` after
/// touchdown: the texture scaled by the load so far, plus the sensor's noise, inside the
/// footprint. Early in the stance the texture is still buried in the noise.
fn frame(rng: &mut impl Rng, t: usize, ms: u64, phase: (usize, usize)) -> Vec<u16> {
    let period = [5, 6, 7][t];
    // The load grows from 30 ms on to its full at 150 ms.
    let load = ((ms as f64 - 30.0) / (FULL_LOAD_MS - 30.0)).clamp(0.0, 1.0);
    (0..44 * 44)
        .map(|i| {
            let (r, c) = (i / 44, i % 44);
            if !(ROWS.0..ROWS.1).contains(&r) || !(COLS.0..COLS.1).contains(&c) {
                return 0;
            }
            let on = (r + phase.0) % period < period / 2 && (c + phase.1) % period < period / 2;
            let texture = if on { 120.0 } else { 40.0 };
            (texture * load + rng.random_range(0.0..180.0)).clamp(0.0, 255.0) as u16
        })
        .collect()
}

/// A candump log of `steps` stances per terrain, terrains in blocks of five steps, and the
/// labels CSV (`start_s,end_s,terrain`) of its terrains.
fn write_run(dir: &std::path::Path, name: &str, seed: u64, steps: usize) -> (String, String) {
    let ids = IdConfig::default();
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let base = 1_700_000_000_000_000u64;
    let mut frames: Vec<Stamped> = Vec::new();
    let mut labels = String::from("start_s,end_s,terrain\n");
    let names = ["wood", "carpet", "grass"];
    let (mut t_us, mut seq) = (base + 100_000, 0u8);
    for b in 0..steps * 3 / 5 {
        let terrain = b % 3;
        labels.push_str(&format!(
            "{},",
            protocol::candump::format_seconds(t_us - 50_000)
        ));
        for _ in 0..5 {
            let phase = (rng.random_range(0..9), rng.random_range(0..9));
            // The switch every 5 ms, a frame every 10 ms (5 ms into each period), then 120 ms
            // of flight.
            for ms in (0..STANCE_MS + 120).step_by(5) {
                let t = t_us + ms * 1000;
                seq = seq.wrapping_add(1);
                let stance = ms < STANCE_MS;
                let fc = Message::FootContact(FootContact {
                    stance,
                    seq,
                    timestamp_us: (t - base) as u32,
                });
                frames.push(Stamped {
                    t_us: t + 200,
                    frame: fc.to_frame(&ids, 0).unwrap(),
                });
                if stance && ms % 10 == 5 {
                    let px = frame(&mut rng, terrain, ms, phase);
                    for f in common::frames_44x44(&ids, Variant::Fd, 0, seq, (t - base) as u32, &px)
                    {
                        frames.push(Stamped {
                            t_us: t + 1000,
                            frame: f,
                        });
                    }
                }
            }
            t_us += (STANCE_MS + 120) * 1000;
        }
        labels.push_str(&format!(
            "{},{}\n",
            protocol::candump::format_seconds(t_us - 50_000),
            names[terrain]
        ));
    }
    frames.sort_by_key(|s| s.t_us);
    let log = dir.join(format!("{name}.log"));
    let mut w = std::io::BufWriter::new(std::fs::File::create(&log).unwrap());
    for st in &frames {
        protocol::candump::write_record(&mut w, "can0", st).unwrap();
    }
    drop(w);
    let csv = dir.join(format!("{name}.csv"));
    std::fs::write(&csv, labels).unwrap();
    (log.display().to_string(), csv.display().to_string())
}

fn presrs(dir: &std::path::Path, args: &[&str]) -> String {
    let out = common::output_ok(
        Command::new(env!("CARGO_BIN_EXE_presrs"))
            .args(args)
            .current_dir(dir),
    );
    format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

#[test]
fn an_offset_slowly_loading_foot_gets_its_own_crop_and_deciding_frame() {
    let dir = std::env::temp_dir().join(format!("presrs-foot-settings-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let (log, csv) = write_run(&dir, "run1", 1, 30);
    presrs(
        &dir,
        &[
            "capture", "--replay", &log, "--labels", &csv, "--out", "set",
        ],
    );
    let report = presrs(
        &dir,
        &["train", "--data", "set", "--out", "model.json", "--verbose"],
    );
    let model = node::classifier::Model::load(&dir.join("model.json")).unwrap();

    // The crop keeps every loaded row and column: the footprint's own box, nothing of it cut.
    let c = model.crop;
    assert!(c.top <= ROWS.0 && c.left <= COLS.0, "{c:?}\n{report}");
    assert!(
        44 - c.bottom >= ROWS.1 && 44 - c.right >= COLS.1,
        "{c:?}\n{report}"
    );
    assert!(
        c.top >= ROWS.0 - 1 && c.left >= COLS.0 - 1,
        "the unloaded border kept: {c:?}"
    );

    // The deciding frame: the one that classified best, or tied within noise with it; well
    // past the paper's 70 ms on a foot that loads until 150 ms.
    let line = report
        .lines()
        .find(|l| l.starts_with("deciding frame:"))
        .unwrap_or_else(|| panic!("{report}"));
    let per: Vec<(u32, f64)> = line
        .split("per offset: ")
        .nth(1)
        .unwrap()
        .split(", ")
        .filter_map(|e| {
            let mut w = e.split(' ');
            let ms = w.next()?.parse().ok()?;
            let acc = w.nth(1)?.trim_end_matches('%').parse().ok()?;
            Some((ms, acc))
        })
        .collect();
    let best = per.iter().map(|p| p.1).fold(0.0, f64::max);
    let chosen = model.sample_ms.expect("the model keeps its deciding frame");
    let at = |ms: u32| per.iter().find(|p| p.0 == ms).map(|p| p.1);
    let kept = at(chosen).unwrap();
    assert!(chosen >= 110, "{line}");
    assert!(kept >= best - 6.0, "{line}");
    assert!(
        kept > at(70).unwrap() + 5.0,
        "no better than the paper's 70 ms: {line}"
    );

    // The node samples each stance at the model's frame: its decision comes one frame after it.
    let (log2, csv2) = write_run(&dir, "run2", 2, 15);
    presrs(
        &dir,
        &[
            "node",
            "--replay",
            &log2,
            "--model",
            "model.json",
            "--csv",
            "steps.csv",
        ],
    );
    let text = std::fs::read_to_string(dir.join("steps.csv")).unwrap();
    let rows: Vec<Vec<&str>> = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect())
        .collect();
    assert!(rows.len() >= 40, "{} steps", rows.len());
    let secs = |s: &str| protocol::candump::parse_seconds(s).unwrap() as f64 * 1e-3;
    for r in &rows {
        let dt = secs(r[3]) - secs(r[2]);
        assert!(
            (dt - chosen as f64).abs() <= 12.0,
            "decided {dt:.1} ms after touchdown, the model's frame is {chosen} ms: {r:?}"
        );
    }
    let right = rows
        .iter()
        .zip(0..)
        .filter(|(r, i)| r[4] == ["wood", "carpet", "grass"][(i / 5) % 3])
        .count();
    assert!(
        right * 10 >= rows.len() * 8,
        "{right} of {} right:\n{text}",
        rows.len()
    );

    // `eval` on a capture of the next run judges each stance at the model's frame (its
    // `.stance/` frames), not at the capture's sample time, so it agrees with the node.
    presrs(
        &dir,
        &[
            "capture", "--replay", &log2, "--labels", &csv2, "--out", "set2",
        ],
    );
    let ev = presrs(&dir, &["eval", "--model", "model.json", "--data", "set2"]);
    assert!(
        ev.contains(&format!(
            "judged at the model's deciding frame, {chosen} ms after touchdown"
        )),
        "{ev}"
    );
    let acc: f64 = ev
        .split("overall accuracy ")
        .nth(1)
        .and_then(|t| t.split('%').next())
        .and_then(|t| t.parse().ok())
        .unwrap_or_else(|| panic!("{ev}"));
    assert!(acc >= 80.0, "eval at the model's frame: {acc}%\n{ev}");

    // A crop given that cuts loaded lines is warned about, with the load it cuts.
    let given = presrs(
        &dir,
        &[
            "train", "--data", "set", "--out", "m2.json", "--crop", "0,6,12,0",
        ],
    );
    assert!(
        given.contains("warning: crop 0,6,12,0 as given cuts")
            && given.contains("% of the stances' load"),
        "{given}"
    );

    // The lab's word: `--sample-ms` pins the frame to one the stances keep, and the node says
    // whose frame is in force; a time the set holds nothing at is refused by name.
    let pinned = presrs(
        &dir,
        &[
            "train",
            "--data",
            "set",
            "--out",
            "m3.json",
            "--sample-ms",
            "130",
        ],
    );
    assert!(
        pinned.contains("deciding frame 130 ms after touchdown (--sample-ms)"),
        "{pinned}"
    );
    let m3 = node::classifier::Model::load(&dir.join("m3.json")).unwrap();
    assert_eq!(m3.sample_ms, Some(130));
    let replay = presrs(&dir, &["node", "--replay", &log2, "--model", "m3.json"]);
    assert!(
        replay.contains("deciding frame 130 ms after touchdown (the model's)"),
        "{replay}"
    );
    std::fs::write(dir.join("pin.toml"), "sample_ms = 150\n").unwrap();
    let replay = presrs(
        &dir,
        &[
            "node", "--replay", &log2, "--model", "m3.json", "--config", "pin.toml",
        ],
    );
    assert!(
        replay.contains("deciding frame 150 ms after touchdown (the config's sample_ms"),
        "{replay}"
    );
    let out = Command::new(env!("CARGO_BIN_EXE_presrs"))
        .args([
            "train",
            "--data",
            "set",
            "--out",
            "m4.json",
            "--sample-ms",
            "200",
        ])
        .current_dir(&dir)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(
        err.contains("--sample-ms 200")
            && err.contains("30, 50, 70")
            && err.contains("sample_ms = 200"),
        "{err}"
    );
    assert!(!dir.join("m4.json").exists());
    let _ = std::fs::remove_dir_all(&dir);
}
