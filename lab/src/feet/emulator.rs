//! The independent foot board (`../shared/foot-emulator/foot.py`, written from the spec by
//! someone else) as a source of sessions: image folders in, a candump log and a truth file
//! out. It is run as a process (`python3`, with numpy), never linked: it stays someone else's.

use std::path::{Path, PathBuf};
use std::process::Command;

use node::capture::{LabelRange, Labelling};
use protocol::terrain::TerrainCatalog;

use super::FeetError;
use super::session::{Recording, Session};

/// The emulator's feet `presrs lab feet` walks: the paper's, and those the issue found wanting
/// (its flags as the emulator's README gives them).
pub const EMULATOR_FEET: [(&str, &[&str]); 5] = [
    ("paper's", &[]),
    ("rolls on, full at 120 ms", &["--roll", "--ramp", "0.12"]),
    ("loads slowly, full at 150 ms", &["--ramp", "0.15"]),
    (
        "off-centre 10,8, full at 80 ms",
        &["--shift", "10,8", "--ramp", "0.08"],
    ),
    ("weak (gain 0.5)", &["--gain", "0.5"]),
];

/// The emulator's script and the Python that runs it.
#[derive(Clone, Debug)]
pub struct Emulator {
    /// `foot.py`.
    pub script: PathBuf,
    /// The interpreter (`python3`).
    pub python: PathBuf,
}

impl Emulator {
    /// The emulator at `script` (default: `../shared/foot-emulator/foot.py` from the working
    /// folder, the repository's root), if it and a Python with numpy are there; `Err` says
    /// what is missing when a script was named.
    pub fn find(script: Option<&Path>) -> Result<Option<Emulator>, String> {
        let default = Path::new("../shared/foot-emulator/foot.py");
        let path = script.unwrap_or(default);
        if !path.is_file() {
            return match script {
                Some(p) => Err(format!("{}: no such file", p.display())),
                None => Ok(None),
            };
        }
        let python = PathBuf::from("python3");
        let numpy = Command::new(&python)
            .args(["-c", "import numpy"])
            .output()
            .is_ok_and(|o| o.status.success());
        if !numpy {
            let why = "python3 with numpy is needed to run the foot emulator (pip install numpy)";
            return match script {
                Some(_) => Err(why.into()),
                None => {
                    tracing::warn!("{why}: its feet are left out");
                    Ok(None)
                }
            };
        }
        Ok(Some(Emulator {
            script: path.to_path_buf(),
            python,
        }))
    }

    /// A session of the emulated foot with `flags` pressing the images of `images`
    /// (`DIR/<terrain>/*.pgm`): `per_class` steps of each terrain in a shuffled order, one
    /// log, labelled from the emulator's truth.
    pub fn session(
        &self,
        images: &Path,
        flags: &[&str],
        per_class: usize,
        seed: u64,
        name: &str,
        catalog: &TerrainCatalog,
    ) -> Result<Session, FeetError> {
        let dir = images.parent().unwrap_or(images);
        let log = dir.join(format!("{name}.log"));
        let truth_path = dir.join(format!("{name}.json"));
        let out = Command::new(&self.python)
            .arg(&self.script)
            .arg(images)
            .arg("--out")
            .arg(&log)
            .arg("--truth")
            .arg(&truth_path)
            .args(["--per-class", &per_class.to_string()])
            .args(["--seed", &seed.to_string()])
            .args(flags)
            .output()
            .map_err(|e| FeetError::Emulator(format!("{}: {e}", self.python.display())))?;
        if !out.status.success() {
            return Err(FeetError::Emulator(format!(
                "{} {}: {}",
                self.script.display(),
                flags.join(" "),
                String::from_utf8_lossy(&out.stderr).trim()
            )));
        }
        let records = protocol::candump::read_log_file(&log)
            .map_err(|e| FeetError::Emulator(format!("its log: {e}")))?;
        let text = std::fs::read_to_string(&truth_path)
            .map_err(|e| FeetError::Io(truth_path.display().to_string(), e))?;
        let truth = parse_truth(&text, catalog)?;
        let labels = truth
            .iter()
            .map(|t| LabelRange {
                // The step's stance, a little either side (the emulator's own times).
                start_us: t.touchdown_us.saturating_sub(20_000),
                end_us: t.liftoff_us + 50_000,
                terrain: t.terrain,
                foot: Some(t.foot),
            })
            .collect();
        Ok(Session {
            recordings: vec![Recording {
                frames: records.into_iter().map(|r| r.stamped).collect(),
                labels: Labelling::Ranges(labels),
                source: name.to_string(),
                truth: truth
                    .iter()
                    .map(|t| (t.foot, t.touchdown_us, t.terrain))
                    .collect(),
            }],
        })
    }
}

/// One step of the emulator's truth file.
struct TruthStep {
    foot: u8,
    touchdown_us: u64,
    liftoff_us: u64,
    terrain: protocol::terrain::Terrain,
}

/// The emulator's truth JSON: `[{foot, terrain, td, lo, ...}]`, times in the log's seconds.
fn parse_truth(text: &str, catalog: &TerrainCatalog) -> Result<Vec<TruthStep>, FeetError> {
    let bad = |why: String| FeetError::Emulator(format!("its truth file: {why}"));
    let v: serde_json::Value = serde_json::from_str(text).map_err(|e| bad(e.to_string()))?;
    let steps = v.as_array().ok_or_else(|| bad("not a list".into()))?;
    steps
        .iter()
        .map(|s| {
            let us = |k: &str| {
                s[k].as_f64()
                    .filter(|t| t.is_finite() && *t >= 0.0)
                    .map(|t| (t * 1e6).round() as u64)
                    .ok_or_else(|| bad(format!("a step without `{k}`")))
            };
            let name = s["terrain"].as_str().unwrap_or_default();
            Ok(TruthStep {
                foot: s["foot"]
                    .as_u64()
                    .and_then(|f| u8::try_from(f).ok())
                    .unwrap_or(0),
                touchdown_us: us("td")?,
                liftoff_us: us("lo")?,
                terrain: catalog
                    .by_name(name)
                    .ok_or_else(|| bad(format!("terrain `{name}` is not in the catalog")))?,
            })
        })
        .collect()
}
