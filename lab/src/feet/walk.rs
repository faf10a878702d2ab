//! One trial: one foot, one source of terrain images, one seed, through the README's path.

use std::path::{Path, PathBuf};

use node::capture::{Capture, CaptureService, CaptureSet};
use node::classifier::PressureImage;
use node::classifier::train::TrainOptions;
use node::training::TrainingSet;
use node::{NodeConfig, NodeService, Output};
use protocol::messages::TERRAIN_UNKNOWN;
use protocol::terrain::{Terrain, TerrainCatalog};

use super::session::{self, Session};
use super::{Emulator, FeetError, FeetOptions, Foot, Source};

/// What one trial measured.
#[derive(Clone, Debug, PartialEq)]
pub struct Trial {
    /// The foot's name.
    pub foot: String,
    /// The source of terrain images.
    pub source: &'static str,
    /// The seed.
    pub seed: u64,
    /// The deciding frame `train` chose, ms (`None`: the node's own).
    pub frame_ms: Option<u32>,
    /// Why, as `train` says it.
    pub frame_why: String,
    /// The crop `train` kept (`T,B,L,R`).
    pub crop: String,
    /// Why, as `train --verbose` says it.
    pub crop_why: String,
    /// The third session's known ground: steps, right, unknown.
    pub known: (usize, usize, usize),
    /// Its new ground: steps, called unknown.
    pub new: (usize, usize),
    /// Where `train` kept a crop: the known ground right had it kept none (the same path with
    /// `--crop 0,0,0,0`), steps and right.
    pub uncropped: Option<(usize, usize)>,
    /// New ground steps taken for a known terrain at a confidence of 90% or more.
    pub new_confident: usize,
    /// The third session's known ground decided known: each decision's confidence (0..=1) and
    /// whether it was right, for the calibration error.
    pub confidences: Vec<(f64, bool)>,
    /// The largest distance of a decided step's touchdown from the truth, ms.
    pub touchdown_err_ms: Option<f64>,
    /// New ground grouped, added and met again (`None`: the trial did not get that far).
    pub learned: Option<super::new_ground::Learned>,
    /// Why the trial could not finish.
    pub error: Option<String>,
}

impl Trial {
    /// Known ground decided right, a share.
    pub fn known_right(&self) -> f64 {
        self.known.1 as f64 / self.known.0.max(1) as f64
    }

    /// Known ground called unknown (the safe gait), a share.
    pub fn known_unknown(&self) -> f64 {
        self.known.2 as f64 / self.known.0.max(1) as f64
    }

    /// New ground called unknown (found), a share.
    pub fn new_found(&self) -> f64 {
        self.new.1 as f64 / self.new.0.max(1) as f64
    }

    /// Expected calibration error of the known ground's decisions (the confidence bands of
    /// `node::classifier::confidence`): `None` without decisions.
    pub fn calibration_error(&self) -> Option<f64> {
        use node::classifier::confidence::{BANDS, ConfidenceMap, ReliabilityBin};
        if self.confidences.is_empty() {
            return None;
        }
        let table: Vec<ReliabilityBin> = BANDS
            .iter()
            .map(|&(lo, hi)| {
                let inside: Vec<&(f64, bool)> = self
                    .confidences
                    .iter()
                    .filter(|c| c.0 >= lo && (c.0 < hi || hi >= 1.0))
                    .collect();
                let n = inside.len();
                ReliabilityBin {
                    lo,
                    hi,
                    n,
                    right: inside.iter().filter(|c| c.1).count(),
                    mean: inside.iter().map(|c| c.0).sum::<f64>() / n.max(1) as f64,
                }
            })
            .collect();
        Some(ConfidenceMap::calibration_error(&table))
    }

    /// The trial as JSON.
    pub fn to_json(&self) -> serde_json::Value {
        serde_json::json!({
            "foot": self.foot,
            "source": self.source,
            "seed": self.seed,
            "frame_ms": self.frame_ms,
            "frame_why": self.frame_why,
            "crop": self.crop,
            "known_steps": self.known.0,
            "known_right": self.known.1,
            "known_unknown": self.known.2,
            "new_steps": self.new.0,
            "new_found": self.new.1,
            "uncropped_known_right": self.uncropped.map(|u| u.1),
            "new_confident": self.new_confident,
            "known_calibration_error": self.calibration_error(),
            "touchdown_err_ms": self.touchdown_err_ms,
            "learned": self.learned.as_ref().map(|l| serde_json::json!({
                "kept_new": l.kept_new,
                "group": l.group,
                "added_by": l.added_by,
                "fresh_new": l.fresh_new,
                "fresh_known": l.fresh_known,
            })),
            "error": self.error,
        })
    }
}

/// Walks the path on `foot` with images from `source` and `seed` (see the module docs); a
/// trial that cannot finish says why in its `error`.
pub fn walk(
    foot: &Foot,
    source: &Source,
    emulator: Option<&Emulator>,
    seed: u64,
    opts: &FeetOptions,
) -> Trial {
    let mut t = Trial {
        foot: foot.name(),
        source: source.name(),
        seed,
        frame_ms: None,
        frame_why: String::new(),
        crop: String::new(),
        crop_why: String::new(),
        known: (0, 0, 0),
        new: (0, 0),
        uncropped: None,
        new_confident: 0,
        confidences: Vec::new(),
        touchdown_err_ms: None,
        learned: None,
        error: None,
    };
    let slug: String = format!("{}-{}-{seed}", t.foot, t.source)
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    let dir = opts.scratch.join(slug);
    let _ = std::fs::remove_dir_all(&dir);
    if let Err(e) = try_walk(foot, source, emulator, seed, opts, &dir, &mut t) {
        t.error = Some(e.to_string());
    }
    if !opts.keep {
        let _ = std::fs::remove_dir_all(&dir);
    }
    t
}

fn try_walk(
    foot: &Foot,
    source: &Source,
    emulator: Option<&Emulator>,
    seed: u64,
    opts: &FeetOptions,
    dir: &Path,
    t: &mut Trial,
) -> Result<(), FeetError> {
    let io = |p: &Path| {
        let p = p.display().to_string();
        move |e| FeetError::Io(p, e)
    };
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    let catalog = TerrainCatalog::paper();
    let (known, new) = terrains(source, &catalog)?;
    let mut all = known.clone();
    all.push(new);
    let make = |k: usize, terrains: &[Terrain], steps: usize| -> Result<Session, FeetError> {
        let name = format!("s{}", k + 1);
        let s_seed = seed * 10 + k as u64 + 1;
        Ok(match foot {
            Foot::Sim(m) => session::simulated(m, terrains, steps, s_seed, &name)
                .map_err(|e| FeetError::Emulator(e.to_string()))?,
            Foot::Emulator { flags, .. } => {
                let em = emulator
                    .ok_or_else(|| FeetError::Emulator("not found: pass --emulator".into()))?;
                let images = dir.join(format!("img{}", k + 1));
                // As many steps as there are images (no image pressed twice).
                let n = write_images(source, terrains, steps, s_seed, k, &images)?;
                let flags: Vec<&str> = flags.iter().map(String::as_str).collect();
                em.session(&images, &flags, n, s_seed, &name, &catalog)?
            }
        })
    };
    let sessions = vec![
        make(0, &known, opts.steps)?,
        make(1, &known, opts.steps)?,
        make(2, &all, opts.third_steps)?,
    ];
    let set = dir.join("set");
    for s in &sessions[..2] {
        capture(s, &set)?;
    }
    let (training, _) = TrainingSet::load(&set, &catalog, false)?;
    let trained = training.train_calibrated(&TrainOptions::default(), None)?;
    t.frame_ms = trained.model.sample_ms;
    t.frame_why = trained.frame.summary();
    t.crop = trained.model.crop.to_string();
    t.crop_why = trained.crop_line();
    if opts.keep {
        let m = dir.join("model.json");
        trained
            .model
            .save(&m)
            .map_err(|e| FeetError::Emulator(format!("{}: {e}", m.display())))?;
        write_logs(&sessions, dir)?;
    }
    let model = trained.model;
    if model.crop != node::classifier::Crop::default() {
        let none = TrainOptions {
            crop: node::classifier::Crop::default().into(),
            ..TrainOptions::default()
        };
        let mut u = t.clone();
        u.known = (0, 0, 0);
        u.new = (0, 0);
        replay(
            &sessions[2],
            &training.train_calibrated(&none, None)?.model,
            &mut u,
            None,
        )?;
        t.uncropped = Some((u.known.0, u.known.1));
    }
    let kept = dir.join("kept");
    replay(&sessions[2], &model, t, Some(&kept))?;
    // New ground: the kept stances grouped and added, then a fresh session.
    let (mut learned, added) =
        super::new_ground::learn(&kept, &sessions[2], &model, new, opts.grouping)?;
    if let Some(added) = added {
        let fourth = make(3, &all, opts.third_steps)?;
        fresh(&fourth, &model, &added, new, &mut learned)?;
        if opts.keep {
            let m = dir.join("added.json");
            added
                .save(&m)
                .map_err(|e| FeetError::Emulator(format!("{}: {e}", m.display())))?;
            write_logs(std::slice::from_ref(&fourth), dir)?;
        }
    }
    t.learned = Some(learned);
    Ok(())
}

/// Each session's recordings as candump logs (`DIR/<source>.log`), for a trial kept.
fn write_logs(sessions: &[Session], dir: &Path) -> Result<(), FeetError> {
    for r in sessions.iter().flat_map(|s| &s.recordings) {
        let path = dir.join(format!("{}.log", r.source));
        let io = |e| FeetError::Io(path.display().to_string(), e);
        let mut w = std::io::BufWriter::new(std::fs::File::create(&path).map_err(io)?);
        for f in &r.frames {
            protocol::candump::write_record(&mut w, "can0", f).map_err(io)?;
        }
        std::io::Write::flush(&mut w).map_err(io)?;
    }
    Ok(())
}

/// The known terrains and the new one of `source`.
fn terrains(
    source: &Source,
    catalog: &TerrainCatalog,
) -> Result<(Vec<Terrain>, Terrain), FeetError> {
    let names: &[&str] = match source {
        Source::Simulator => &["wood", "carpet", "clay", "grass"],
        // SpeedPP2D's people, each as a terrain name the spec's catalog has.
        Source::SpeedPp2d(_) => &["aluminum", "sand", "gravel", "pine_needles"],
    };
    let t: Vec<Terrain> = names.iter().filter_map(|n| catalog.by_name(n)).collect();
    match t.as_slice() {
        [a, b, c, d] => Ok((vec![*a, *b, *c], *d)),
        _ => Err(FeetError::Emulator(
            "the paper's catalog lacks a terrain".into(),
        )),
    }
}

/// Up to `steps` images of each of `terrains` from `source` for session `k`, as
/// `out/<terrain>/*.pgm`; returns how many of each (the fewest of any terrain).
fn write_images(
    source: &Source,
    terrains: &[Terrain],
    steps: usize,
    seed: u64,
    k: usize,
    out: &Path,
) -> Result<usize, FeetError> {
    match source {
        Source::Simulator => {
            let samples = sim::dataset::generate(&sim::dataset::Options {
                kind: sim::dataset::Kind::Dynamic,
                n: Some(steps),
                gait: controller::Gait::g2(),
                damage_pct: 0.0,
                sensor: sim::DEFAULT_SENSOR,
                seed,
            });
            let mine: Vec<_> = samples
                .into_iter()
                .filter(|s| terrains.contains(&s.terrain))
                .collect();
            crate::simdata::write_images(&mine, out)
                .map_err(|e| FeetError::Io(e.0.clone(), e.1))?;
            Ok(steps)
        }
        Source::SpeedPp2d(dir) => speedpp2d_images(dir, terrains, steps, k, out),
    }
}

/// SpeedPP2D's first four people (`DIR/subj00`..`subj03`, as `scripts/speedpp2d.py` writes
/// them) as the terrains: session `k` takes its own share of each person's 60 maps (at most
/// `steps`), scaled to 8 bits by the largest count of all (an
/// array's full scale is one for the whole foot). Returns the fewest maps of any person.
fn speedpp2d_images(
    dir: &Path,
    terrains: &[Terrain],
    steps: usize,
    k: usize,
    out: &Path,
) -> Result<usize, FeetError> {
    let people = ["subj00", "subj01", "subj02", "subj03"];
    // Each session its own maps, every speed in each: of every 12 in recording order, the
    // first session takes 5, the second 5, the third 2 (25, 25 and 10 of a person's 60).
    let share = |i: usize| match i % 12 {
        0..5 => 0,
        5..10 => 1,
        _ => 2,
    };
    let mut chosen: Vec<(Terrain, Vec<PressureImage>)> = Vec::new();
    for (p, &t) in people
        .iter()
        .zip(terrains.iter().chain(std::iter::repeat(&terrains[0])))
    {
        let folder = dir.join(p);
        let mut files: Vec<PathBuf> = std::fs::read_dir(&folder)
            .map_err(|e| FeetError::Io(folder.display().to_string(), e))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|e| e == "pgm"))
            .collect();
        files.sort();
        let imgs = files
            .iter()
            .enumerate()
            .filter(|(i, _)| share(*i) == k.min(2))
            .map(|(_, f)| f)
            .take(steps)
            .map(|f| node::classifier::dataset::read_image(f))
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| FeetError::Emulator(e.to_string()))?;
        chosen.push((t, imgs));
    }
    let chosen = &chosen[..terrains.len().min(chosen.len())];
    let max = chosen
        .iter()
        .flat_map(|(_, v)| v.iter().flat_map(|i| i.pixels.iter()))
        .copied()
        .max()
        .unwrap_or(1)
        .max(1) as f64;
    for (t, imgs) in chosen {
        let d = out.join(t.name());
        std::fs::create_dir_all(&d).map_err(|e| FeetError::Io(d.display().to_string(), e))?;
        for (i, img) in imgs.iter().enumerate() {
            let px = img
                .pixels
                .iter()
                .map(|&p| (p as f64 / max * 255.0).round() as u16)
                .collect();
            let path = d.join(format!("{i:04}.pgm"));
            node::classifier::dataset::write_pgm(
                &PressureImage::new(img.rows, img.cols, 8, px),
                &path,
            )
            .map_err(|e| FeetError::Io(path.display().to_string(), e))?;
        }
    }
    Ok(chosen.iter().map(|(_, v)| v.len()).min().unwrap_or(0))
}

/// Captures every recording of `s` into the set at `set`, as `presrs capture` does.
fn capture(s: &Session, set: &Path) -> Result<(), FeetError> {
    for r in &s.recordings {
        let mut svc = CaptureService::new(
            Capture::new(NodeConfig::default(), r.labels.clone()),
            CaptureSet::open(set)?,
            r.source.clone(),
        );
        for f in &r.frames {
            svc.feed(f);
        }
        svc.finish();
        if let Some(e) = svc.failed.take() {
            return Err(e.into());
        }
    }
    Ok(())
}

/// One true step of a session and what the node made of it.
struct Decided {
    /// Its true terrain.
    terrain: Terrain,
    /// The decision whose touchdown lies nearest the truth's, within 50 ms: its terrain id
    /// and confidence (0..=1), and how far its touchdown lies from the truth, ms.
    got: Option<(u8, f64, f64)>,
}

/// Every true step of `s` with the node's decision under `model`; the unknown stances kept in
/// `keep` when given (as `node --replay --keep-unknown`).
fn decide(
    s: &Session,
    model: &node::classifier::Model,
    keep: Option<&Path>,
) -> Result<Vec<Decided>, FeetError> {
    let mut out = Vec::new();
    for r in &s.recordings {
        let mut node = NodeService::new(NodeConfig::default(), model.clone())?;
        let writer = match keep {
            Some(dir) => {
                let (keeper, writer) =
                    node::unknown::keep::UnknownKeeper::create(dir, &r.source, node.catalog())?;
                node.set_keep_unknown(keeper.waiting());
                Some(writer)
            }
            None => None,
        };
        let mut said: Vec<(u8, u64, u8, f64)> = Vec::new();
        let mut hear = |o: Output| {
            if let Output::Class {
                foot,
                class,
                touchdown_us,
                ..
            } = o
            {
                said.push((
                    foot,
                    touchdown_us,
                    class.terrain,
                    class.confidence_pct / 100.0,
                ));
            }
        };
        node.replay(&r.frames, &mut |(_, o): (u64, Output)| hear(o));
        let end = r.frames.last().map_or(0, |f| f.t_us) + 2_000_000;
        node.tick(end, &mut hear);
        drop(node);
        if let Some(w) = writer {
            w.finish()?;
        }
        for &(foot, td, terrain) in &r.truth {
            let d = said
                .iter()
                .filter(|d| d.0 == foot)
                .min_by_key(|d| d.1.abs_diff(td))
                .filter(|d| d.1.abs_diff(td) <= 50_000);
            out.push(Decided {
                terrain,
                got: d.map(|d| (d.2, d.3, d.1.abs_diff(td) as f64 / 1000.0)),
            });
        }
    }
    Ok(out)
}

/// The third session through the node with `model` (its unknown stances kept in `keep`),
/// each decided step held against its true terrain and touchdown; a step the node never
/// decided counts against it.
fn replay(
    s: &Session,
    model: &node::classifier::Model,
    t: &mut Trial,
    keep: Option<&Path>,
) -> Result<(), FeetError> {
    let ids: Vec<u8> = model.classes.iter().map(|c| c.terrain_id).collect();
    for d in decide(s, model, keep)? {
        if let Some((_, _, e)) = d.got {
            t.touchdown_err_ms = Some(t.touchdown_err_ms.map_or(e, |w| w.max(e)));
        }
        let got = d.got.map(|g| g.0);
        let known_call = d.got.filter(|g| g.0 != TERRAIN_UNKNOWN);
        let id = d.terrain.id();
        if ids.contains(&id) {
            t.known.0 += 1;
            t.known.1 += usize::from(got == Some(id));
            t.known.2 += usize::from(got == Some(TERRAIN_UNKNOWN));
            if let Some(g) = known_call {
                t.confidences.push((g.1, g.0 == id));
            }
        } else {
            t.new.0 += 1;
            t.new.1 += usize::from(got == Some(TERRAIN_UNKNOWN));
            t.new_confident += usize::from(known_call.is_some_and(|g| g.1 >= 0.9));
        }
    }
    Ok(())
}

/// A fresh session's steps decided by the model before the add and after, into `l`: the new
/// terrain's steps and those decided as it; known steps, right before, right after.
fn fresh(
    s: &Session,
    before: &node::classifier::Model,
    after: &node::classifier::Model,
    new: Terrain,
    l: &mut super::new_ground::Learned,
) -> Result<(), FeetError> {
    let (b, a) = (decide(s, before, None)?, decide(s, after, None)?);
    let (mut n, mut k) = ((0, 0), (0, 0, 0));
    for (db, da) in b.iter().zip(&a) {
        let right = |d: &Decided| d.got.is_some_and(|g| g.0 == d.terrain.id());
        if db.terrain == new {
            n.0 += 1;
            n.1 += usize::from(right(da));
        } else {
            k.0 += 1;
            k.1 += usize::from(right(db));
            k.2 += usize::from(right(da));
        }
    }
    (l.fresh_new, l.fresh_known) = (n, k);
    Ok(())
}
