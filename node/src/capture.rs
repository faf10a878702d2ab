//! A training set from the robot's own runs (`presrs capture`).
//!
//! [`Capture`] runs the node's own stance logic ([`StancePipeline::for_capture`]: debounce, the
//! stance, the image nearest the sample time) on a bus or a candump log, fills dead sensor lines
//! as the node's repair filter does ([`LineHealth`], learned over the stances), labels each step
//! with a terrain ([`Labelling`]) and hands out one [`CapturedStep`] per step. [`CaptureSet`]
//! writes them in the layout `presrs train` reads, `DIR/<terrain>/<name>.pgm`, with a
//! `DIR/manifest.csv` that also keeps a second capture of the same log from adding anything.

use std::collections::HashSet;
use std::io::Write;
use std::path::{Path, PathBuf};

use protocol::Stamped;
use protocol::candump::{format_seconds, parse_seconds};
use protocol::component::{Component, Outbox};
use protocol::terrain::{Terrain, TerrainCatalog};

use crate::classifier::PressureImage;
use crate::classifier::dataset::write_pgm;
use crate::config::{NodeConfig, RepairMode};
use crate::health::LineHealth;
use crate::stance::StancePipeline;

/// Errors of a capture: labels, the output folder, a write.
#[derive(Debug, thiserror::Error)]
pub enum CaptureError {
    /// A labels file line that cannot be used.
    #[error("{path} line {line}: {reason}")]
    Labels {
        /// The labels file.
        path: String,
        /// 1-based line.
        line: usize,
        /// What is wrong and the fix.
        reason: String,
    },
    /// `--label` names no terrain of the catalog.
    #[error("--label {name}: {reason}")]
    Label {
        /// The name given.
        name: String,
        /// What the catalog said.
        reason: String,
    },
    /// Neither `--label` nor `--labels` was given.
    #[error("give --label TERRAIN or --labels FILE.csv")]
    NoLabels,
    /// A file of the capture cannot be read or written.
    #[error("cannot {what} {}: {source}{hint}", path.display())]
    Io {
        /// What was being done.
        what: &'static str,
        /// The file or folder.
        path: PathBuf,
        /// What the OS said.
        source: std::io::Error,
        /// The likely fix.
        hint: &'static str,
    },
    /// The manifest of an earlier capture is not one this version wrote.
    #[error("{} line {line}: not a capture manifest line ({reason}); move it away or fix it", path.display())]
    Manifest {
        /// The manifest.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// What is wrong.
        reason: String,
    },
}

fn io(what: &'static str, path: &Path, source: std::io::Error) -> CaptureError {
    let hint = match source.raw_os_error() {
        Some(28) => " (the disk is full: free space; what was written before is kept)",
        Some(13) | Some(30) => " (not writable: pick another --out)",
        Some(2) => " (its folder does not exist)",
        _ => "",
    };
    CaptureError::Io {
        what,
        path: path.to_path_buf(),
        source,
        hint,
    }
}

/// One range of a labels file: steps whose touchdown and sample both fall in `[start, end)`
/// (the log's clock, µs) on `foot` (any foot when `None`) are `terrain`.
#[derive(Clone, Debug, PartialEq)]
pub struct LabelRange {
    /// Start, µs on the log's clock.
    pub start_us: u64,
    /// End (exclusive).
    pub end_us: u64,
    /// The terrain.
    pub terrain: Terrain,
    /// The foot it applies to; all feet when `None`.
    pub foot: Option<u8>,
}

/// How steps get their terrain.
#[derive(Clone, Debug)]
pub enum Labelling {
    /// Every step is this terrain (`--label`).
    All(Terrain),
    /// Time ranges (`--labels`), for a run that crosses terrains.
    Ranges(Vec<LabelRange>),
}

/// Why a step was not written.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Skip {
    /// No image was sampled inside the stance (lost, or none sent).
    NoImage,
    /// The sampled image reads zero everywhere: the array was not read.
    Blank,
    /// Outside every labelled range.
    Unlabelled,
    /// Touchdown and sample in different ranges (or one in none).
    SpansLabels,
}

/// What a capture did with the steps it saw.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct CaptureCounts {
    /// Steps decided (one per stance).
    pub steps: u64,
    /// Steps handed out as [`CapturedStep`]s.
    pub captured: u64,
    /// Skipped: no image inside the stance.
    pub no_image: u64,
    /// Skipped: blank image.
    pub blank: u64,
    /// Skipped: outside every labelled range.
    pub unlabelled: u64,
    /// Skipped: spanning two ranges.
    pub spans_labels: u64,
}

/// One step's image, labelled, ready to be written.
#[derive(Clone, Debug)]
pub struct CapturedStep {
    /// The foot.
    pub foot: u8,
    /// The step number (the node's TerrainClass `step`).
    pub step: u16,
    /// Its terrain.
    pub terrain: Terrain,
    /// Touchdown on the log's clock (µs): the image's receipt less its time in the stance.
    pub touchdown_us: u64,
    /// The image's receipt on the log's clock (µs).
    pub sample_us: u64,
    /// Sum of the image's pixels (after the repair).
    pub load_sum: u64,
    /// The foot's learned damage (eq. 6) when it was taken, percent.
    pub damage_pct: f64,
    /// Lines the repair filter filled in this image.
    pub repaired_lines: usize,
    /// The gait in force at touchdown (the controller's last GaitStatus before it: 1..=3 for
    /// G1..G3); `None` when the bus carried no GaitStatus (a lab's own controller).
    pub gait: Option<u8>,
    /// The image (repaired unless the config's `repair = "none"`).
    pub image: PressureImage,
}

/// Parses a labels CSV: `start_s,end_s,terrain[,foot]` per line, in the log's own timestamps
/// (seconds, as `candump -L` prints them). A header line, blank lines and `#` comments are
/// allowed. Terrains must be in `catalog`; ranges of one foot must not overlap.
pub fn parse_labels(
    text: &str,
    origin: &str,
    catalog: &TerrainCatalog,
) -> Result<Vec<LabelRange>, CaptureError> {
    let bad = |line: usize, reason: String| CaptureError::Labels {
        path: origin.to_string(),
        line,
        reason,
    };
    let mut out: Vec<(usize, LabelRange)> = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = i + 1;
        let l = raw.trim();
        if l.is_empty() || l.starts_with('#') || (line == 1 && l.starts_with("start")) {
            continue;
        }
        let f: Vec<&str> = l.split(',').map(str::trim).collect();
        if !(3..=4).contains(&f.len()) {
            return Err(bad(
                line,
                format!(
                    "`{l}` has {} fields; want start_s,end_s,terrain[,foot]",
                    f.len()
                ),
            ));
        }
        let secs = |s: &str, what: &str| {
            parse_seconds(s).ok_or_else(|| {
                bad(
                    line,
                    format!(
                        "{what} `{s}` is not a time in seconds (as candump -L prints it, e.g. 1700000000.250000)"
                    ),
                )
            })
        };
        let (start_us, end_us) = (secs(f[0], "start_s")?, secs(f[1], "end_s")?);
        if end_us <= start_us {
            return Err(bad(
                line,
                format!("end_s {} is not after start_s {}", f[1], f[0]),
            ));
        }
        let terrain = catalog.known(f[2]).map_err(|e| bad(line, e.to_string()))?;
        let foot = match f.get(3) {
            None | Some(&"") => None,
            Some(s) => Some(
                s.parse::<u8>()
                    .ok()
                    .filter(|&n| n < protocol::ids::MAX_FEET)
                    .ok_or_else(|| bad(line, format!("foot `{s}` is not 0..7")))?,
            ),
        };
        let r = LabelRange {
            start_us,
            end_us,
            terrain,
            foot,
        };
        if let Some((other, _)) = out.iter().find(|(_, o)| {
            (o.foot.is_none() || r.foot.is_none() || o.foot == r.foot)
                && o.start_us < r.end_us
                && r.start_us < o.end_us
        }) {
            return Err(bad(
                line,
                format!("overlaps the range of line {other}: a step there would have two terrains"),
            ));
        }
        out.push((line, r));
    }
    if out.is_empty() {
        return Err(bad(
            0,
            "no ranges: want lines start_s,end_s,terrain[,foot]".into(),
        ));
    }
    Ok(out.into_iter().map(|(_, r)| r).collect())
}

impl Labelling {
    /// A command's `--label NAME` (every step that terrain) or else `--labels FILE` (a CSV of
    /// time ranges, [`parse_labels`]); errors name the option and the fix.
    pub fn from_args(
        label: Option<&str>,
        labels: Option<&Path>,
        catalog: &TerrainCatalog,
    ) -> Result<Self, CaptureError> {
        match (label, labels) {
            (Some(name), _) => {
                catalog
                    .known(name)
                    .map(Labelling::All)
                    .map_err(|e| CaptureError::Label {
                        name: name.to_string(),
                        reason: e.to_string(),
                    })
            }
            (None, Some(p)) => {
                let text = std::fs::read_to_string(p).map_err(|e| io("read", p, e))?;
                Ok(Labelling::Ranges(parse_labels(
                    &text,
                    &p.display().to_string(),
                    catalog,
                )?))
            }
            (None, None) => Err(CaptureError::NoLabels),
        }
    }

    /// The terrain of a step on `foot` from `t0` (touchdown) to `t1` (sample), log clock.
    pub fn label(&self, foot: u8, t0: u64, t1: u64) -> Result<Terrain, Skip> {
        let ranges = match self {
            Labelling::All(t) => return Ok(*t),
            Labelling::Ranges(r) => r,
        };
        let find = |t: u64| {
            ranges
                .iter()
                .position(|r| r.foot.is_none_or(|f| f == foot) && r.start_us <= t && t < r.end_us)
        };
        match (find(t0), find(t1)) {
            (Some(a), Some(b)) if a == b => Ok(ranges[a].terrain),
            (None, None) => Err(Skip::Unlabelled),
            _ => Err(Skip::SpansLabels),
        }
    }
}

/// The node's stance logic and repair filter, turning frames into labelled step images.
pub struct Capture {
    pipeline: StancePipeline,
    repair: RepairMode,
    dead_after: u32,
    health: Vec<LineHealth>,
    labelling: Labelling,
    counts: CaptureCounts,
    decided: Vec<u8>,
    ids: protocol::ids::IdConfig,
    gaits: crate::gait::GaitTrack,
}

impl Capture {
    /// A capture with the node's config `cfg` (debounce, sample time, repair, feet, ids).
    pub fn new(cfg: NodeConfig, labelling: Labelling) -> Self {
        Self {
            health: (0..cfg.feet).map(|_| LineHealth::new(0, 0)).collect(),
            repair: cfg.repair,
            dead_after: cfg.dead_after_stances,
            ids: cfg.ids.clone(),
            pipeline: StancePipeline::for_capture(cfg),
            labelling,
            counts: CaptureCounts::default(),
            decided: Vec::new(),
            gaits: crate::gait::GaitTrack::default(),
        }
    }

    /// Counts so far.
    pub fn counts(&self) -> CaptureCounts {
        self.counts
    }

    /// The stance pipeline's counters (frames, images, steps).
    pub fn pipeline(&self) -> &StancePipeline {
        &self.pipeline
    }

    /// One frame with its time: the clock moves on to it first ([`Self::tick`]), then the
    /// frame is processed, as the node does live and on a replay.
    pub fn feed(&mut self, st: &Stamped, out: &mut impl FnMut(CapturedStep)) {
        self.tick(st.t_us, out);
        self.process(st, out);
    }

    /// One received (or logged) frame; a step it ends goes to `out`.
    pub fn process(&mut self, st: &Stamped, out: &mut impl FnMut(CapturedStep)) {
        self.gaits.on_frame(st, &self.ids);
        let decided = &mut self.decided;
        self.pipeline
            .on_frame(st, &mut |foot, _| decided.push(foot));
        self.take(out);
    }

    /// The receiver's clock moved on to `now_us` without a frame: decides steps whose nearer
    /// images can no longer come (as the node does).
    pub fn tick(&mut self, now_us: u64, out: &mut impl FnMut(CapturedStep)) {
        let decided = &mut self.decided;
        self.pipeline
            .tick(now_us, &mut |foot, _| decided.push(foot));
        self.take(out);
    }

    fn take(&mut self, out: &mut impl FnMut(CapturedStep)) {
        for i in 0..self.decided.len() {
            let foot = self.decided[i];
            self.counts.steps += 1;
            match self.step(foot) {
                Ok(c) => {
                    self.counts.captured += 1;
                    out(c);
                }
                Err(Skip::NoImage) => self.counts.no_image += 1,
                Err(Skip::Blank) => self.counts.blank += 1,
                Err(Skip::Unlabelled) => self.counts.unlabelled += 1,
                Err(Skip::SpansLabels) => self.counts.spans_labels += 1,
            }
        }
        self.decided.clear();
    }

    fn step(&mut self, foot: u8) -> Result<CapturedStep, Skip> {
        let s = self.pipeline.sample(foot).ok_or(Skip::NoImage)?;
        if s.pixels.iter().all(|&p| p == 0) {
            return Err(Skip::Blank);
        }
        let in_stance = s.sample_us.wrapping_sub(s.touchdown_us) as u64;
        let touchdown_us = s.rx_us.saturating_sub(in_stance);
        let terrain = self.labelling.label(foot, touchdown_us, s.rx_us)?;
        let mut image = PressureImage::new(s.rows, s.cols, s.bits, s.pixels.to_vec());
        let h = &mut self.health[foot as usize];
        if h.size() != (s.rows, s.cols) {
            *h = LineHealth::new(s.rows, s.cols);
        }
        let repaired_lines = match self.repair {
            RepairMode::None => 0,
            RepairMode::PerImage => {
                let (r, c) = crate::classifier::repair::repair(&mut image);
                r + c
            }
            RepairMode::History => {
                h.observe(&image.pixels, self.dead_after);
                h.repair(&mut image.pixels)
            }
        };
        Ok(CapturedStep {
            foot,
            step: s.step,
            terrain,
            touchdown_us,
            sample_us: s.rx_us,
            load_sum: image.pixels.iter().map(|&p| p as u64).sum(),
            damage_pct: h.damage_pct(),
            repaired_lines,
            gait: self.gaits.at(touchdown_us),
            image,
        })
    }
}

/// What the manifest says of one image besides its terrain folder.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ManifestEntry {
    /// Its run: the candump log or interface it was captured from (`source`).
    pub source: String,
    /// The gait in force at its touchdown (`gait`, empty when the bus carried no GaitStatus,
    /// and in manifests written before the column).
    pub gait: Option<u8>,
}

/// One manifest line, parsed: `Ok(None)` for a header or blank line; `Err` says what is wrong.
/// Lines have the 9 columns of [`MANIFEST_HEADER_V1`] or the 10 of [`MANIFEST_HEADER`]: a
/// capture appends 10 to a manifest that began with 9, and both stay readable.
struct ManifestLine<'a> {
    file: &'a str,
    foot: u8,
    step: u16,
    touchdown_us: u64,
    entry: ManifestEntry,
}

fn parse_manifest_line(l: &str) -> Result<Option<ManifestLine<'_>>, String> {
    // A manifest saved by a Windows editor ends its lines in CR LF.
    let l = l.strip_suffix('\r').unwrap_or(l);
    if l.is_empty() || l == MANIFEST_HEADER || l == MANIFEST_HEADER_V1 {
        return Ok(None);
    }
    let f: Vec<&str> = l.split(',').collect();
    if !(9..=10).contains(&f.len()) {
        return Err(format!(
            "{} fields; want the 10 of `{MANIFEST_HEADER}` (or 9, without gait)",
            f.len()
        ));
    }
    let gait = match f.get(9) {
        None | Some(&"") => None,
        Some(g) => Some(
            g.parse::<u8>()
                .ok()
                .filter(|&g| g != 0)
                .ok_or_else(|| format!("gait `{g}` is not 1..255 or empty"))?,
        ),
    };
    Ok(Some(ManifestLine {
        file: f[0],
        foot: f[2].parse().map_err(|_| format!("foot `{}`", f[2]))?,
        step: f[3].parse().map_err(|_| format!("step `{}`", f[3]))?,
        touchdown_us: parse_seconds(f[4]).ok_or_else(|| format!("touchdown_s `{}`", f[4]))?,
        entry: ManifestEntry {
            source: f[8].to_string(),
            gait,
        },
    }))
}

/// Each image's manifest entry (its run, its gait), by its path relative to the training-set
/// folder (`terrain/name.pgm`). `Ok(None)` when `dir` has no manifest (a folder not written by
/// `presrs capture`); a manifest line that is not one is an error naming it.
pub fn read_manifest(
    dir: &Path,
) -> Result<Option<std::collections::HashMap<PathBuf, ManifestEntry>>, CaptureError> {
    let path = dir.join("manifest.csv");
    let text = match std::fs::read_to_string(&path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(io("read", &path, e)),
    };
    let mut entries = std::collections::HashMap::new();
    for (i, l) in text.lines().enumerate() {
        match parse_manifest_line(l) {
            Ok(Some(m)) => {
                entries.insert(PathBuf::from(m.file), m.entry);
            }
            Ok(None) => {}
            Err(reason) => {
                return Err(CaptureError::Manifest {
                    path,
                    line: i + 1,
                    reason,
                });
            }
        }
    }
    Ok(Some(entries))
}

/// A capture filling a training set, as a part on the bus ([`Component`]): `presrs capture
/// --iface` runs it with the one runner; a log is fed to it frame by frame
/// ([`CaptureService::feed`]). The first write error stops it ([`Component::done`]);
/// everything written before stays written.
pub struct CaptureService {
    /// The stance logic and the labels.
    pub capture: Capture,
    /// Where captured steps go.
    pub set: CaptureSet,
    /// The name the manifest keys steps by.
    pub source: String,
    /// The write error that stopped it, if one did.
    pub failed: Option<CaptureError>,
    last_t: u64,
}

impl CaptureService {
    /// A capture into `set`, keying steps by `source`.
    pub fn new(capture: Capture, set: CaptureSet, source: String) -> Self {
        Self {
            capture,
            set,
            source,
            failed: None,
            last_t: 0,
        }
    }

    /// One frame with its time (a log's, or the bus's receive time).
    pub fn feed(&mut self, st: &Stamped) {
        self.last_t = st.t_us;
        let (set, source, failed) = (&mut self.set, &self.source, &mut self.failed);
        self.capture
            .feed(st, &mut |c| keep(set, source, failed, &c));
    }
}

impl CaptureService {
    /// Feeds a log's records until the capture is done (a `--replay`).
    pub fn replay<R: std::borrow::Borrow<protocol::candump::LogRecord>>(
        &mut self,
        records: impl IntoIterator<Item = R>,
    ) {
        for r in records {
            self.feed(&r.borrow().stamped);
            if self.failed.is_some() {
                break;
            }
        }
    }

    /// `presrs capture --json`'s object: what was read, written and skipped, and why it
    /// stopped if it did; `out` names the set's folder.
    pub fn report_json(&self, out: &Path) -> serde_json::Value {
        let (c, pc, set) = (
            self.capture.counts(),
            self.capture.pipeline().counters,
            &self.set,
        );
        serde_json::json!({
            "source": self.source, "out": out, "frames": pc.frames, "images": pc.images,
            "steps": c.steps, "written": set.written, "duplicates": set.duplicates,
            "no_image": c.no_image, "blank": c.blank, "unlabelled": c.unlabelled,
            "spans_labels": c.spans_labels, "per_terrain": set.written_per_terrain,
            "per_gait": set.written_per_gait.iter().map(|(g, n)| (crate::gait::gait_name(*g), *n))
                .collect::<std::collections::BTreeMap<_, _>>(),
            "set_total": set.len(), "error": self.failed.as_ref().map(|e| e.to_string()),
        })
    }

    /// The same as one line for a person.
    pub fn report_line(&self, out: &Path) -> String {
        let (c, set) = (self.capture.counts(), &self.set);
        let terrains: Vec<String> = set
            .written_per_terrain
            .iter()
            .map(|(t, n)| format!("{t} {n}"))
            .collect();
        let gaits: Vec<String> = set
            .written_per_gait
            .iter()
            .map(|(g, n)| format!("{} {n}", crate::gait::gait_name(*g)))
            .collect();
        format!(
            "capture of {}: {} steps, {} written ({}; by gait at touchdown: {}), {} already in the set; skipped: {} without an image in the stance, {} blank, {} outside every label, {} spanning two labels; {} holds {} steps",
            self.source,
            c.steps,
            set.written,
            if terrains.is_empty() {
                "none".into()
            } else {
                terrains.join(", ")
            },
            if gaits.is_empty() {
                "none".into()
            } else {
                gaits.join(", ")
            },
            set.duplicates,
            c.no_image,
            c.blank,
            c.unlabelled,
            c.spans_labels,
            out.display(),
            set.len()
        )
    }
}

fn keep(set: &mut CaptureSet, source: &str, failed: &mut Option<CaptureError>, c: &CapturedStep) {
    if failed.is_none()
        && let Err(e) = set.add(c, source)
    {
        *failed = Some(e);
    }
}

impl Component for CaptureService {
    fn name(&self) -> &'static str {
        "capture"
    }

    /// Every frame, as the node sees them: a lab's foot may send what the node reads under
    /// any ids its config gives.
    fn filters(&self) -> Vec<(u32, u32)> {
        Vec::new()
    }

    fn on_frame(&mut self, st: &Stamped, _: u64, _: &mut Outbox) {
        self.feed(st);
    }

    /// The bus went quiet: steps whose nearer images can no longer come are decided, on the
    /// clock of the last frame's receive time (the bus's, not this process's).
    fn tick(&mut self, _: u64, _: &mut Outbox) {
        let (set, source, failed) = (&mut self.set, &self.source, &mut self.failed);
        self.capture
            .tick(self.last_t, &mut |c| keep(set, source, failed, &c));
    }

    fn done(&self) -> bool {
        self.failed.is_some()
    }
}

/// The manifest's header line.
pub const MANIFEST_HEADER: &str =
    "file,terrain,foot,step,touchdown_s,sample_s,load_sum,damage_pct,source,gait";

/// The header of manifests written before the `gait` column; still read.
pub const MANIFEST_HEADER_V1: &str =
    "file,terrain,foot,step,touchdown_s,sample_s,load_sum,damage_pct,source";

/// A training-set folder being filled: `DIR/<terrain>/<name>.pgm` plus `DIR/manifest.csv`.
/// Steps already in the manifest (same source, foot, step and touchdown) are not added again.
pub struct CaptureSet {
    dir: PathBuf,
    manifest_path: PathBuf,
    manifest: std::fs::File,
    keys: HashSet<(String, u8, u16, u64)>,
    /// Images written by this set.
    pub written: u64,
    /// Of those, per terrain name.
    pub written_per_terrain: std::collections::BTreeMap<String, u64>,
    /// Of those, per gait in force at touchdown (`None`: no GaitStatus on the bus).
    pub written_per_gait: std::collections::BTreeMap<Option<u8>, u64>,
    /// Steps already in the manifest.
    pub duplicates: u64,
}

impl CaptureSet {
    /// Opens (creating) `dir` and its manifest; reads the steps it already holds.
    pub fn open(dir: &Path) -> Result<Self, CaptureError> {
        std::fs::create_dir_all(dir).map_err(|e| io("create the folder", dir, e))?;
        let manifest_path = dir.join("manifest.csv");
        let mut keys = HashSet::new();
        let existing = match std::fs::read_to_string(&manifest_path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => String::new(),
            Err(e) => return Err(io("read", &manifest_path, e)),
        };
        for (i, l) in existing.lines().enumerate() {
            match parse_manifest_line(l) {
                Ok(Some(m)) => {
                    keys.insert((m.entry.source, m.foot, m.step, m.touchdown_us));
                }
                Ok(None) => {}
                Err(reason) => {
                    return Err(CaptureError::Manifest {
                        path: manifest_path,
                        line: i + 1,
                        reason,
                    });
                }
            }
        }
        let mut manifest = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&manifest_path)
            .map_err(|e| io("open", &manifest_path, e))?;
        if existing.is_empty() {
            writeln!(manifest, "{MANIFEST_HEADER}").map_err(|e| io("write", &manifest_path, e))?;
        }
        Ok(Self {
            dir: dir.to_path_buf(),
            manifest_path,
            manifest,
            keys,
            written: 0,
            written_per_terrain: Default::default(),
            written_per_gait: Default::default(),
            duplicates: 0,
        })
    }

    /// Writes one step's image and its manifest line; `false` when the manifest has it already.
    /// The image is written to a temporary name and renamed, and the manifest line appended
    /// after it, so a failure (a full disk) leaves every earlier image and line intact.
    pub fn add(&mut self, c: &CapturedStep, source: &str) -> Result<bool, CaptureError> {
        // Commas would break the manifest's columns.
        let source = source.replace([',', '\n'], "_");
        let key = (source.clone(), c.foot, c.step, c.touchdown_us);
        if self.keys.contains(&key) {
            self.duplicates += 1;
            return Ok(false);
        }
        let class_dir = self.dir.join(c.terrain.name());
        std::fs::create_dir_all(&class_dir).map_err(|e| io("create the folder", &class_dir, e))?;
        let stem: String = Path::new(&source)
            .file_stem()
            .map(|s| s.to_string_lossy().to_string())
            .unwrap_or_else(|| "run".into())
            .chars()
            .map(|ch| {
                if ch.is_ascii_alphanumeric() || ch == '-' {
                    ch
                } else {
                    '_'
                }
            })
            .collect();
        let name = format!("{stem}_f{}_s{:05}_{}.pgm", c.foot, c.step, c.touchdown_us);
        let path = class_dir.join(&name);
        let tmp = class_dir.join(format!(".{name}.tmp"));
        if let Err(e) = write_pgm(&c.image, &tmp) {
            let _ = std::fs::remove_file(&tmp);
            return Err(io("write", &path, e));
        }
        std::fs::rename(&tmp, &path).map_err(|e| io("write", &path, e))?;
        let line = format!(
            "{}/{name},{},{},{},{},{},{},{:.1},{source},{}\n",
            c.terrain.name(),
            c.terrain.name(),
            c.foot,
            c.step,
            format_seconds(c.touchdown_us),
            format_seconds(c.sample_us),
            c.load_sum,
            c.damage_pct,
            c.gait.map(|g| g.to_string()).unwrap_or_default(),
        );
        self.manifest
            .write_all(line.as_bytes())
            .and_then(|_| self.manifest.flush())
            .map_err(|e| io("append to", &self.manifest_path, e))?;
        self.keys.insert(key);
        self.written += 1;
        *self
            .written_per_terrain
            .entry(c.terrain.name().to_string())
            .or_default() += 1;
        *self.written_per_gait.entry(c.gait).or_default() += 1;
        Ok(true)
    }

    /// Steps the folder's manifest holds (earlier captures included).
    pub fn len(&self) -> usize {
        self.keys.len()
    }

    /// The manifest holds no step.
    pub fn is_empty(&self) -> bool {
        self.keys.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_parse_and_name_the_bad_line() {
        let cat = TerrainCatalog::paper();
        let text = "start_s,end_s,terrain,foot\n# wood first\n10.0,20.5,wood\n20.5,30,clay,0\n";
        let r = parse_labels(text, "labels.csv", &cat).unwrap();
        assert_eq!(r.len(), 2);
        assert_eq!((r[0].start_us, r[0].end_us), (10_000_000, 20_500_000));
        assert_eq!((r[1].terrain, r[1].foot), (Terrain::CLAY, Some(0)));
        let l = Labelling::Ranges(r);
        assert_eq!(l.label(0, 11_000_000, 11_070_000), Ok(Terrain::WOOD));
        assert_eq!(l.label(0, 20_450_000, 20_520_000), Err(Skip::SpansLabels));
        assert_eq!(l.label(0, 31_000_000, 31_070_000), Err(Skip::Unlabelled));
        assert_eq!(l.label(1, 25_000_000, 25_070_000), Err(Skip::Unlabelled));
        for (text, want) in [
            ("1,2,moon\n", "line 1: `moon` is not a terrain"),
            ("1,2,wood\n3,2,clay\n", "line 2: end_s 2 is not after"),
            ("1,2\n", "line 1: `1,2` has 2 fields"),
            (
                "1,3,wood\n2,4,clay\n",
                "line 2: overlaps the range of line 1",
            ),
            ("x,3,wood\n", "start_s `x` is not a time"),
            ("1,3,wood,9\n", "foot `9` is not 0..7"),
        ] {
            let e = parse_labels(text, "labels.csv", &cat)
                .unwrap_err()
                .to_string();
            assert!(e.contains(want) && e.starts_with("labels.csv"), "{e}");
        }
    }

    #[test]
    fn label_options_name_what_is_wrong() {
        let cat = TerrainCatalog::paper();
        assert!(matches!(
            Labelling::from_args(Some("clay"), None, &cat),
            Ok(Labelling::All(t)) if t == Terrain::CLAY
        ));
        let e = Labelling::from_args(Some("moon"), None, &cat)
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("--label moon: "), "{e}");
        let e = Labelling::from_args(None, None, &cat)
            .unwrap_err()
            .to_string();
        assert!(e.contains("--label TERRAIN or --labels"), "{e}");
        let missing = Path::new("/nonexistent/labels.csv");
        let e = Labelling::from_args(None, Some(missing), &cat)
            .unwrap_err()
            .to_string();
        assert!(e.contains("cannot read /nonexistent/labels.csv"), "{e}");
    }

    #[test]
    fn the_manifest_reads_with_and_without_its_gait_column() {
        let dir = std::env::temp_dir().join(format!("presrs-manifest-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let read = |text: &str| {
            std::fs::write(dir.join("manifest.csv"), text).unwrap();
            read_manifest(&dir)
        };
        let v1 = format!("{MANIFEST_HEADER_V1}\nwood/a.pgm,wood,0,1,1.0,1.07,5,0.0,run1\n");
        let m = read(&v1).unwrap().unwrap();
        let want = |source: &str, gait| ManifestEntry {
            source: source.into(),
            gait,
        };
        assert_eq!(m[Path::new("wood/a.pgm")], want("run1", None));
        // A capture appends 10 columns to a manifest that began with 9.
        let mixed = format!(
            "{v1}wood/b.pgm,wood,0,2,2.0,2.07,5,0.0,run2,3\nwood/c.pgm,wood,0,3,3.0,3.07,5,0.0,run2,\n"
        );
        let m = read(&mixed.replace('\n', "\r\n")).unwrap().unwrap();
        assert_eq!(m[Path::new("wood/b.pgm")], want("run2", Some(3)));
        assert_eq!(m[Path::new("wood/c.pgm")], want("run2", None));
        for (line, why) in [
            ("wood/d.pgm,wood,0,4,4.0,4.07,5,0.0,run2,0", "gait `0`"),
            ("wood/d.pgm,wood,0,4,4.0,4.07,5,0.0,run2,G3", "gait `G3`"),
            ("wood/d.pgm,wood,0,4,4.0,4.07,5,0.0", "8 fields"),
            ("wood/d.pgm,wood,x,4,4.0,4.07,5,0.0,run2,1", "foot `x`"),
        ] {
            let e = read(&format!("{MANIFEST_HEADER}\n{line}\n"))
                .unwrap_err()
                .to_string();
            assert!(e.contains("manifest.csv line 2") && e.contains(why), "{e}");
        }
        std::fs::remove_file(dir.join("manifest.csv")).unwrap();
        assert!(read_manifest(&dir).unwrap().is_none());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
