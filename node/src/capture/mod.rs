//! A training set from the robot's own runs (`presrs capture`).
//!
//! [`Capture`] runs the node's own stance logic ([`StancePipeline::for_capture`]: debounce, the
//! stance, the image nearest the sample time) on a bus or a candump log, fills dead sensor lines
//! as the node's repair filter does ([`LineHealth`], learned over the stances), labels each step
//! with a terrain ([`Labelling`]) and hands out one [`CapturedStep`] per step. [`CaptureSet`]
//! writes them in the layout `presrs train` reads, `DIR/<terrain>/<name>.pgm`, with a
//! `DIR/manifest.csv` that also keeps a second capture of the same log from adding anything.

use std::collections::HashSet;
use std::path::{Path, PathBuf};

use protocol::Stamped;
use protocol::candump::{format_seconds, parse_seconds};
use protocol::component::{Component, Outbox};
use protocol::emit::Emit;
use protocol::terrain::{Terrain, TerrainCatalog};

use crate::classifier::PressureImage;
use crate::classifier::dataset::write_pgm;
use crate::config::{NodeConfig, RepairMode};
use crate::health::LineHealth;
use crate::stance::{Decided, StancePipeline};

mod labels;
mod manifest;
mod service;

pub use labels::{LabelRange, Labelling, parse_labels};
pub use manifest::{
    CaptureSet, MANIFEST_HEADER, MANIFEST_HEADER_V1, MANIFEST_HEADER_V2, ManifestEntry, STANCE_DIR,
    read_manifest, stance_frames,
};
pub use service::CaptureService;

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

pub(crate) fn io(what: &'static str, path: &Path, source: std::io::Error) -> CaptureError {
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
    /// The flights before and after the stance (µs, the foot's clock; `None` where its edge
    /// was not heard): what the stance did to the hop, for the energy check `train` weighs.
    pub flights_us: [Option<u32>; 2],
    /// The stance's frame nearest each of [`crate::stance::FRAME_OFFSETS_MS`] (`None` where
    /// the stance had none), repaired as the image is: the candidates for the deciding frame
    /// `train` measures.
    pub frames: Vec<Option<PressureImage>>,
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
    /// Per foot: its last step, held until the next touchdown gives the flight after it.
    pending: Vec<Option<CapturedStep>>,
    ids: protocol::ids::IdConfig,
    gaits: crate::gait_status::GaitTrack,
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
            pending: Vec::new(),
            gaits: crate::gait_status::GaitTrack::default(),
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
    pub fn feed(&mut self, st: &Stamped, out: &mut (impl Emit<CapturedStep> + ?Sized)) {
        self.tick(st.t_us, out);
        self.process(st, out);
    }

    /// One received (or logged) frame; a step it ends goes to `out`.
    pub fn process(&mut self, st: &Stamped, out: &mut (impl Emit<CapturedStep> + ?Sized)) {
        self.gaits.on_frame(st, &self.ids);
        let decided = &mut self.decided;
        self.pipeline
            .on_frame(st, &mut |d: Decided| decided.push(d.foot));
        self.take(out);
    }

    /// The receiver's clock moved on to `now_us` without a frame: decides steps whose nearer
    /// images can no longer come (as the node does).
    pub fn tick(&mut self, now_us: u64, out: &mut (impl Emit<CapturedStep> + ?Sized)) {
        let decided = &mut self.decided;
        self.pipeline
            .tick(now_us, &mut |d: Decided| decided.push(d.foot));
        self.take(out);
    }

    /// The steps decided since the last call, each held until the flight after it is known; a
    /// held step whose flights came is handed out.
    fn take(&mut self, out: &mut (impl Emit<CapturedStep> + ?Sized)) {
        for foot in 0..self.pending.len() {
            let o = self.pipeline.energy_observation(foot as u8);
            if let (Some(c), Some(o)) = (&mut self.pending[foot], o)
                && o.step == c.step
            {
                c.flights_us = [o.flight_before_us, o.flight_after_us];
                if let Some(c) = self.pending[foot].take() {
                    out.emit(c);
                }
            }
        }
        for i in 0..self.decided.len() {
            let foot = self.decided[i];
            self.counts.steps += 1;
            match self.step(foot) {
                Ok(c) => {
                    self.counts.captured += 1;
                    let f = foot as usize;
                    if self.pending.len() <= f {
                        self.pending.resize_with(f + 1, || None);
                    }
                    // A step held still (its next touchdown never heard) goes as it is.
                    if let Some(old) = self.pending[f].replace(c) {
                        out.emit(old);
                    }
                }
                Err(Skip::NoImage) => self.counts.no_image += 1,
                Err(Skip::Blank) => self.counts.blank += 1,
                Err(Skip::Unlabelled) => self.counts.unlabelled += 1,
                Err(Skip::SpansLabels) => self.counts.spans_labels += 1,
            }
        }
        self.decided.clear();
    }

    /// Hands out the steps still held (the run ended before their next touchdown: no flight
    /// after them). Call it at the end of a log or a live capture.
    pub fn finish(&mut self, out: &mut (impl Emit<CapturedStep> + ?Sized)) {
        let decided = &mut self.decided;
        self.pipeline
            .decide_open(&mut |d: Decided| decided.push(d.foot));
        self.take(out);
        for c in self.pending.iter_mut().filter_map(Option::take) {
            out.emit(c);
        }
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
        // The stance's other frames, repaired as its image (the history learns from one).
        let repair = self.repair;
        let frames = self
            .pipeline
            .stance_frames(foot)
            .map(|px| {
                px.map(|px| {
                    let mut f = PressureImage::new(s.rows, s.cols, s.bits, px.to_vec());
                    match repair {
                        RepairMode::None => {}
                        RepairMode::PerImage => {
                            crate::classifier::repair::repair(&mut f);
                        }
                        RepairMode::History => {
                            h.repair(&mut f.pixels);
                        }
                    }
                    f
                })
            })
            .collect();
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
            flights_us: [None, None],
            frames,
        })
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
            flights_us: [None, None],
            // Every line samples 70 ms after its touchdown.
            sampled_after_us: Some(70_000),
        };
        assert_eq!(m[Path::new("wood/a.pgm")], want("run1", None));
        // A capture appends 10 columns to a manifest that began with 9.
        let mixed = format!(
            "{v1}wood/b.pgm,wood,0,2,2.0,2.07,5,0.0,run2,3\nwood/c.pgm,wood,0,3,3.0,3.07,5,0.0,run2,\n"
        );
        let m = read(&mixed.replace('\n', "\r\n")).unwrap().unwrap();
        assert_eq!(m[Path::new("wood/b.pgm")], want("run2", Some(3)));
        assert_eq!(m[Path::new("wood/c.pgm")], want("run2", None));
        // And 12, with the flights before and after the stance (one edge not heard).
        let v3 = format!("{mixed}wood/e.pgm,wood,0,5,5.0,5.07,5,0.0,run3,2,0.210000,\n");
        let m = read(&v3).unwrap().unwrap();
        assert_eq!(
            m[Path::new("wood/e.pgm")],
            ManifestEntry {
                flights_us: [Some(210_000), None],
                ..want("run3", Some(2))
            }
        );
        for (line, why) in [
            (
                "wood/d.pgm,wood,0,4,4.0,4.07,5,0.0,run2,1,-1,",
                "flight `-1`",
            ),
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
