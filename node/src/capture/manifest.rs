//! A captured set on disk: `DIR/<terrain>/<name>.pgm` and `DIR/manifest.csv`, which names each
//! image's source and step so that a second capture of the same log adds nothing.

use super::{
    CaptureError, CapturedStep, HashSet, Path, PathBuf, PressureImage, format_seconds, io,
    parse_seconds, write_pgm,
};
use std::io::Write;

/// What the manifest says of one image besides its terrain folder.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ManifestEntry {
    /// Its run: the candump log or interface it was captured from (`source`).
    pub source: String,
    /// The gait in force at its touchdown (`gait`, empty when the bus carried no GaitStatus,
    /// and in manifests written before the column).
    pub gait: Option<u8>,
    /// The flights before and after its stance, µs (`flight_before_s`, `flight_after_s`; empty
    /// where an edge was not heard, and in manifests written before the columns).
    pub flights_us: [Option<u32>; 2],
    /// Its image's time after touchdown, µs (`sample_s` - `touchdown_s`): the capture's sample
    /// time, to the array's frame (`None` when the sample is not after the touchdown).
    pub sampled_after_us: Option<u32>,
}

/// One manifest line, parsed: `Ok(None)` for a header or blank line; `Err` says what is wrong.
/// Lines have the 9 columns of [`MANIFEST_HEADER_V1`], the 10 of [`MANIFEST_HEADER_V2`] or the
/// 12 of [`MANIFEST_HEADER`]: a capture appends 12 to a manifest that began with fewer, and
/// every line stays readable.
pub(super) struct ManifestLine<'a> {
    file: &'a str,
    foot: u8,
    step: u16,
    touchdown_us: u64,
    entry: ManifestEntry,
}

pub(super) fn parse_manifest_line(l: &str) -> Result<Option<ManifestLine<'_>>, String> {
    // A manifest saved by a Windows editor ends its lines in CR LF.
    let l = l.strip_suffix('\r').unwrap_or(l);
    if l.is_empty() || l == MANIFEST_HEADER || l == MANIFEST_HEADER_V2 || l == MANIFEST_HEADER_V1 {
        return Ok(None);
    }
    let f: Vec<&str> = l.split(',').collect();
    if ![9, 10, 12].contains(&f.len()) {
        return Err(format!(
            "{} fields; want the 12 of `{MANIFEST_HEADER}` (or 10 without the flights, 9 \
             without the gait)",
            f.len()
        ));
    }
    let flight = |i: usize| -> Result<Option<u32>, String> {
        match f.get(i) {
            None | Some(&"") => Ok(None),
            Some(s) => parse_seconds(s)
                .and_then(|us| u32::try_from(us).ok())
                .map(Some)
                .ok_or_else(|| format!("flight `{s}` is not seconds or empty")),
        }
    };
    let gait = match f.get(9) {
        None | Some(&"") => None,
        Some(g) => Some(
            g.parse::<u8>()
                .ok()
                .filter(|&g| g != 0)
                .ok_or_else(|| format!("gait `{g}` is not 1..255 or empty"))?,
        ),
    };
    let touchdown_us = parse_seconds(f[4]).ok_or_else(|| format!("touchdown_s `{}`", f[4]))?;
    let sample_us = parse_seconds(f[5]).ok_or_else(|| format!("sample_s `{}`", f[5]))?;
    Ok(Some(ManifestLine {
        file: f[0],
        foot: f[2].parse().map_err(|_| format!("foot `{}`", f[2]))?,
        step: f[3].parse().map_err(|_| format!("step `{}`", f[3]))?,
        touchdown_us,
        entry: ManifestEntry {
            source: f[8].to_string(),
            gait,
            flights_us: [flight(10)?, flight(11)?],
            sampled_after_us: sample_us
                .checked_sub(touchdown_us)
                .and_then(|d| u32::try_from(d).ok()),
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

/// Where a set keeps its stances' frames (`DIR/.stance/<terrain>/<image name>`).
pub const STANCE_DIR: &str = ".stance";

/// The stance frames a set at `root` keeps beside its image `image` (a path under `root`), at
/// [`crate::stance::FRAME_OFFSETS_MS`] (a blank image where the stance had ended); `None` when
/// it keeps none for it, or they cannot be read (the image itself is then what there is).
pub fn stance_frames(root: &Path, image: &Path) -> Option<Vec<PressureImage>> {
    let rel = image.strip_prefix(root).ok()?;
    crate::classifier::dataset::read_images(&root.join(STANCE_DIR).join(rel)).ok()
}

/// The manifest's header line.
pub const MANIFEST_HEADER: &str = "file,terrain,foot,step,touchdown_s,sample_s,load_sum,\
                                   damage_pct,source,gait,flight_before_s,flight_after_s";

/// The header of manifests written before the flight columns; still read.
pub const MANIFEST_HEADER_V2: &str =
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
    /// The image the last [`CaptureSet::add`] wrote, relative to the folder.
    pub last_written: Option<String>,
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
            last_written: None,
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
        self.write_frames(c, &name)?;
        let flight = |f: Option<u32>| f.map(|us| format_seconds(us.into())).unwrap_or_default();
        let line = format!(
            "{}/{name},{},{},{},{},{},{},{:.1},{source},{},{},{}\n",
            c.terrain.name(),
            c.terrain.name(),
            c.foot,
            c.step,
            format_seconds(c.touchdown_us),
            format_seconds(c.sample_us),
            c.load_sum,
            c.damage_pct,
            c.gait.map(|g| g.to_string()).unwrap_or_default(),
            flight(c.flights_us[0]),
            flight(c.flights_us[1]),
        );
        self.manifest
            .write_all(line.as_bytes())
            .and_then(|_| self.manifest.flush())
            .map_err(|e| io("append to", &self.manifest_path, e))?;
        self.keys.insert(key);
        self.last_written = Some(format!("{}/{name}", c.terrain.name()));
        self.written += 1;
        *self
            .written_per_terrain
            .entry(c.terrain.name().to_string())
            .or_default() += 1;
        *self.written_per_gait.entry(c.gait).or_default() += 1;
        Ok(true)
    }

    /// The step's stance frames beside its image: `DIR/.stance/<terrain>/<name>` (hidden, so
    /// not a class folder), one image per offset of [`crate::stance::FRAME_OFFSETS_MS`] in
    /// one PGM file, blank where the stance had no frame.
    fn write_frames(&self, c: &CapturedStep, name: &str) -> Result<(), CaptureError> {
        if c.frames.iter().all(Option::is_none) {
            return Ok(());
        }
        let dir = self.dir.join(STANCE_DIR).join(c.terrain.name());
        std::fs::create_dir_all(&dir).map_err(|e| io("create the folder", &dir, e))?;
        let blank = PressureImage::new(
            c.image.rows,
            c.image.cols,
            c.image.bits,
            vec![0; c.image.pixels.len()],
        );
        let path = dir.join(name);
        let tmp = dir.join(format!(".{name}.tmp"));
        let mut bytes = Vec::new();
        for f in &c.frames {
            crate::classifier::dataset::pgm_bytes(f.as_ref().unwrap_or(&blank), &mut bytes);
        }
        if let Err(e) = std::fs::write(&tmp, &bytes) {
            let _ = std::fs::remove_file(&tmp);
            return Err(io("write", &path, e));
        }
        std::fs::rename(&tmp, &path).map_err(|e| io("write", &path, e))
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
