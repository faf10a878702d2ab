//! Keeping the stances the node calls unknown, where a lab can reach them
//! (`presrs node --keep-unknown DIR`, live or over `--replay`).
//!
//! Unknown ground is the robot's news: the stances it could not place are what a lab looks at
//! to decide whether the robot met new ground. Only stances with a real stance image are kept
//! (unknown by novelty, load, texture or energy); a step without an image or without contact
//! carries no ground to look at.
//!
//! The node's thread only copies: [`UnknownKeeper::offer`] takes a free slot from a pool made
//! at start (each slot holds the largest image a foot can send), fills it and hands it to a
//! writer thread, never waiting; with no free slot the stance is dropped and counted. The
//! writer writes what `presrs capture` writes, `DIR/unknown/<name>.pgm` with its line in
//! `DIR/manifest.csv` (so a second keep of the same log adds nothing), plus `DIR/kept.csv`
//! with each stance's reason, best class and confidence.
//!
//! Beside them, the run's first [`SESSION_PER_TERRAIN`] stances of each known terrain decided
//! at [`SESSION_CONFIDENCE_PCT`] or more go to `DIR/session/<terrain>/` (reason `known` in
//! `kept.csv`): how known ground looked in the same run, which `presrs discover --add`
//! calibrates the new model on, so that what the run shares with the new ground (its load,
//! its sensor, its day) is not taken for the new terrain's signature.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU8, AtomicU64, Ordering};

use crossbeam_channel::{Receiver, Sender, TrySendError};
use protocol::messages::{TerrainClass, UnknownReason};
use protocol::tactile::MAX_PIXELS;
use protocol::terrain::{Terrain, TerrainCatalog};

use crate::capture::{CaptureError, CaptureSet, CapturedStep};
use crate::classifier::PressureImage;
use crate::stance::{Decided, StanceSample};

/// Stances the pool holds in flight: about 20 s of one foot that meets only new ground.
pub const SLOTS: usize = 64;

/// Known stances kept per terrain and run, as the session's references.
pub const SESSION_PER_TERRAIN: u8 = 40;

/// The confidence a known stance needs to be kept as a reference (the node's own label).
pub const SESSION_CONFIDENCE_PCT: f64 = 90.0;

/// The folder of a keep that holds the session's known stances.
pub const SESSION_DIR: &str = "session";

/// The header of `DIR/kept.csv`.
pub const KEPT_HEADER: &str = "file,foot,step,reason,flags,confidence_pct,damage_pct,gait,source";

/// One kept stance, in a slot of the pool.
struct Slot {
    decided: Decided,
    gait: Option<u8>,
    sample_rx_us: u64,
    rows: usize,
    cols: usize,
    bits: u8,
    pixels: Box<[u16; MAX_PIXELS]>,
}

/// What a keep wrote.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct KeptCounts {
    /// Stances written.
    pub written: u64,
    /// Stances the manifest had already (the same log kept twice).
    pub duplicates: u64,
    /// Stances dropped for want of a free slot (the writer fell behind).
    pub dropped: u64,
    /// Known stances kept as the session's references.
    pub session: u64,
}

impl std::fmt::Display for KeptCounts {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} unknown stances ({} already there, {} dropped: the writer fell behind) and {} \
             known ones as the session's references",
            self.written, self.duplicates, self.dropped, self.session
        )
    }
}

/// The node's side: offers unknown stances, never blocks.
#[derive(Clone)]
pub struct UnknownKeeper {
    free: Receiver<Box<Slot>>,
    full: Sender<Box<Slot>>,
    dropped: Arc<AtomicU64>,
    wait: bool,
    /// Known stances kept so far, per terrain id.
    known: Arc<[AtomicU8; 256]>,
}

/// The writer's side: joins the thread and says what it wrote.
pub struct KeepWriter {
    thread: std::thread::JoinHandle<Result<KeptCounts, CaptureError>>,
    dropped: Arc<AtomicU64>,
}

/// Whether a step's verdict rests on a real stance image (and so is worth keeping).
pub fn keepable(class: &TerrainClass) -> bool {
    // Exhaustive: a new reason must say whether it rests on the image.
    match class.unknown_reason() {
        Some(UnknownReason::Novelty | UnknownReason::Load | UnknownReason::Texture) => true,
        Some(UnknownReason::Energy) => true,
        Some(UnknownReason::NoSample | UnknownReason::NoContact) | None => false,
    }
}

impl UnknownKeeper {
    /// Opens `dir` (created if missing; an existing keep is added to, nothing overwritten) and
    /// starts the writer. `source` names the run in the manifest (the log's file, or the
    /// interface); `catalog` names the known terrains' folders.
    pub fn create(
        dir: &Path,
        source: &str,
        catalog: &TerrainCatalog,
    ) -> Result<(Self, KeepWriter), CaptureError> {
        let set = CaptureSet::open(dir)?;
        let session = CaptureSet::open(&dir.join(SESSION_DIR))?;
        let kept_path = dir.join("kept.csv");
        let new = !kept_path.exists();
        let io = |e| crate::capture::io("append to", &kept_path, e);
        let mut kept = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&kept_path)
            .map_err(io)?;
        if new {
            writeln!(kept, "{KEPT_HEADER}").map_err(io)?;
        }
        let (free_tx, free) = crossbeam_channel::bounded(SLOTS);
        let (full, full_rx) = crossbeam_channel::bounded(SLOTS);
        for _ in 0..SLOTS {
            let _ = free_tx.send(Box::new(Slot {
                decided: Decided {
                    foot: 0,
                    class: TerrainClass::default(),
                    touchdown_us: 0,
                },
                gait: None,
                sample_rx_us: 0,
                rows: 0,
                cols: 0,
                bits: 8,
                pixels: Box::new([0; MAX_PIXELS]),
            }));
        }
        let dropped = Arc::new(AtomicU64::new(0));
        let w = Writer {
            set,
            session,
            catalog: catalog.clone(),
            kept,
            kept_path,
            source: source.replace([',', '\n'], "_"),
        };
        let thread = std::thread::Builder::new()
            .name("keep-unknown".into())
            .spawn(move || w.run(full_rx, free_tx))
            .map_err(|e| crate::capture::io("start the writer for", dir, e))?;
        Ok((
            Self {
                free,
                full,
                dropped: dropped.clone(),
                wait: false,
                known: Arc::new(std::array::from_fn(|_| AtomicU8::new(0))),
            },
            KeepWriter { thread, dropped },
        ))
    }

    /// For a replay, which has no deadline and must keep every stance: [`Self::offer`] waits
    /// for a free slot instead of dropping the stance.
    pub fn waiting(mut self) -> Self {
        self.wait = true;
        self
    }

    /// Whether step `class` is one to keep: unknown on its image ([`keepable`]), or a
    /// confident known stance of a terrain that has fewer than [`SESSION_PER_TERRAIN`] kept.
    #[inline]
    pub fn wants(&self, class: &TerrainClass) -> bool {
        keepable(class) || self.wants_known(class)
    }

    #[inline]
    fn wants_known(&self, class: &TerrainClass) -> bool {
        class.terrain != protocol::messages::TERRAIN_UNKNOWN
            && class.confidence_pct >= SESSION_CONFIDENCE_PCT
            && self.known[class.terrain as usize].load(Ordering::Relaxed) < SESSION_PER_TERRAIN
    }

    /// Offers step `d` (decided with `gait` in force) and its image `s`: kept when
    /// [`Self::wants`] it. Copies into a free slot; no allocation, no wait.
    pub fn offer(&self, d: &Decided, gait: Option<u8>, s: &StanceSample<'_>) {
        if !self.wants(&d.class) || s.pixels.len() > MAX_PIXELS || s.pixels.len() != s.rows * s.cols
        {
            return;
        }
        let known = !keepable(&d.class);
        let slot = if self.wait {
            self.free.recv().ok()
        } else {
            self.free.try_recv().ok()
        };
        let Some(mut slot) = slot else {
            self.dropped.fetch_add(1, Ordering::Relaxed);
            return;
        };
        slot.decided = *d;
        slot.gait = gait;
        slot.sample_rx_us = s.rx_us;
        (slot.rows, slot.cols, slot.bits) = (s.rows, s.cols, s.bits);
        slot.pixels[..s.pixels.len()].copy_from_slice(s.pixels);
        // The pool holds as many slots as the queue: a slot taken always fits.
        match self.full.try_send(slot) {
            Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) => {
                self.dropped.fetch_add(1, Ordering::Relaxed);
            }
            Ok(()) if known => {
                self.known[d.class.terrain as usize].fetch_add(1, Ordering::Relaxed);
            }
            Ok(()) => {}
        }
    }
}

impl KeepWriter {
    /// Waits for the writer once every [`UnknownKeeper`] is dropped; what it wrote.
    pub fn finish(self) -> Result<KeptCounts, CaptureError> {
        let mut counts = match self.thread.join() {
            Ok(r) => r?,
            Err(_) => {
                let e = std::io::Error::other("the writer thread panicked");
                return Err(crate::capture::io(
                    "write",
                    Path::new("the kept stances"),
                    e,
                ));
            }
        };
        counts.dropped = self.dropped.load(Ordering::Relaxed);
        Ok(counts)
    }
}

struct Writer {
    set: CaptureSet,
    session: CaptureSet,
    catalog: TerrainCatalog,
    kept: std::fs::File,
    kept_path: PathBuf,
    source: String,
}

impl Writer {
    fn run(
        mut self,
        full: Receiver<Box<Slot>>,
        free: Sender<Box<Slot>>,
    ) -> Result<KeptCounts, CaptureError> {
        let mut counts = KeptCounts::default();
        for slot in full {
            let r = self.write(&slot, &mut counts);
            let _ = free.send(slot);
            r?;
        }
        Ok(counts)
    }

    fn write(&mut self, s: &Slot, counts: &mut KeptCounts) -> Result<(), CaptureError> {
        let n = s.rows * s.cols;
        let image = PressureImage::new(s.rows, s.cols, s.bits, s.pixels[..n].to_vec());
        let c = &s.decided.class;
        let known = (!keepable(c))
            .then(|| self.catalog.by_id(c.terrain))
            .flatten();
        let step = CapturedStep {
            foot: s.decided.foot,
            step: c.step,
            terrain: known.unwrap_or(Terrain::UNKNOWN),
            touchdown_us: s.decided.touchdown_us,
            sample_us: s.sample_rx_us,
            load_sum: image.pixels.iter().map(|&p| p as u64).sum(),
            damage_pct: c.damage_pct,
            repaired_lines: 0,
            gait: s.gait,
            image,
            flights_us: [None, None],
            frames: Vec::new(),
        };
        let set = if known.is_some() {
            &mut self.session
        } else {
            &mut self.set
        };
        if !set.add(&step, &self.source)? {
            if known.is_none() {
                counts.duplicates += 1;
            }
            return Ok(());
        }
        let file = match (known, set.last_written.as_deref()) {
            (Some(_), Some(f)) => format!("{SESSION_DIR}/{f}"),
            (_, f) => f.unwrap_or_default().to_string(),
        };
        let reason = match known {
            Some(_) => "known",
            None => c.unknown_reason().map_or("", UnknownReason::name),
        };
        // An unknown step chose no terrain: no confidence (the frame's is the rejected
        // class's), as the step table and the replay print it.
        let confidence =
            crate::replay::known_confidence(c).map_or(String::new(), |p| format!("{p:.1}"));
        let line = format!(
            "{file},{},{},{reason},{},{confidence},{:.1},{},{}\n",
            step.foot,
            step.step,
            c.flags,
            c.damage_pct,
            s.gait.map(|g| g.to_string()).unwrap_or_default(),
            self.source,
        );
        self.kept
            .write_all(line.as_bytes())
            .and_then(|_| self.kept.flush())
            .map_err(|e| crate::capture::io("append to", &self.kept_path, e))?;
        if known.is_some() {
            counts.session += 1;
        } else {
            counts.written += 1;
        }
        Ok(())
    }
}
