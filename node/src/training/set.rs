//! A labelled training set: images, their terrains, runs and gaits, from a dataset folder
//! (`presrs capture`'s layout) or built by a caller, and the model trained on it with its
//! rejection calibrated on another run ([`TrainingSet::train_calibrated`]).

use protocol::terrain::TerrainCatalog;

use super::report::Trained;
use crate::classifier::dataset::Dataset;
use crate::classifier::train::{CalibrateError, Labelled, Split, TrainOptions, train};
use crate::classifier::{ClassInfo, Crop, CropSpec, Model, PressureImage};

/// A dataset's class folder whose name is no terrain of the catalog.
#[derive(Debug, thiserror::Error)]
#[error(
    "class folder {folder}: `{name}` is not a terrain in the catalog; add it to a terrains file \
     ([[terrain]] id = N, name = \"{name}\", with N from 12 to 254 and unused) and pass \
     --terrains FILE, or rename the folder after a known terrain"
)]
pub struct NotInCatalog {
    /// The folder.
    pub folder: String,
    /// Its name.
    pub name: String,
}

/// A dataset folder that could not become a training set ([`TrainingSet::load`]).
#[derive(Debug, thiserror::Error)]
pub enum LoadError {
    /// A file or folder could not be read (the error names it).
    #[error(transparent)]
    Read(#[from] crate::classifier::dataset::ImageError),
    /// A class folder names no terrain.
    #[error(transparent)]
    NotInCatalog(#[from] NotInCatalog),
    /// No image at all.
    #[error(
        "{0}: no images found; want DIR/<terrain>/<images> (PGM, CSV or TekScan ASCII), as \
         `presrs capture` writes them"
    )]
    Empty(String),
    /// The folder's capture manifest cannot be read: its runs would be lost, and with them the
    /// calibration on the next run.
    #[error("{0} (or delete the manifest to train without its runs and gaits)")]
    Manifest(#[from] crate::capture::CaptureError),
}

/// Images, each one's class (an index into `classes`), and the classes in the order of the
/// terrains given: the name and the terrain id the model puts on the bus.
#[derive(Clone, Debug)]
pub struct TrainingSet {
    /// One entry per class: its name and the terrain id the model sends.
    pub classes: Vec<ClassInfo>,
    /// The images.
    pub images: Vec<PressureImage>,
    /// Each image's class, an index into `classes`.
    pub labels: Vec<usize>,
    /// Each image's run (the recording it came from: the capture manifest's `source`), or
    /// `None` when not known (no manifest; simulated sets are one run each).
    pub runs: Vec<Option<String>>,
    /// Each image's gait at touchdown (the capture manifest's `gait`; a simulated set's gait),
    /// or `None` when not known.
    pub gaits: Vec<Option<u8>>,
    /// Each image's flights before and after its stance, µs (the capture manifest's; read
    /// with [`TrainingSet::flights_of`], which gives none past the end: a set built without
    /// them may leave it empty).
    pub flights: Vec<[Option<u32>; 2]>,
    /// Each image's stance frames at [`crate::stance::FRAME_OFFSETS_MS`] (a blank image where
    /// the stance had none), as `presrs capture` keeps them in `DIR/.stance`; empty for an
    /// image without them, and past the end for a set built without any.
    pub frames: Vec<Vec<PressureImage>>,
    /// The time after touchdown the capture took `images` at, ms: the median of the capture
    /// manifest's sample times (`None` without one).
    pub captured_ms: Option<u32>,
}

/// Why [`TrainingSet::train_calibrated`] failed: training or the calibration, as they say it.
#[derive(Debug, thiserror::Error)]
pub enum TrainCalibratedError {
    /// Training.
    #[error(transparent)]
    Train(#[from] crate::classifier::train::TrainError),
    /// Calibrating on the other run.
    #[error(transparent)]
    Calibrate(#[from] crate::classifier::train::CalibrateError),
    /// Choosing the unknown-ground checks.
    #[error(transparent)]
    Choice(#[from] crate::training::choice::ChoiceError),
    /// `--sample-ms` names a time the set holds no stances at (the message says which it holds).
    #[error("{0}")]
    SampleMs(String),
}

/// What each run of a set is used for, per class: see [`TrainingSet::split_runs`].
#[derive(Clone)]
pub struct RunSplit {
    /// The images the model is trained on.
    pub train: TrainingSet,
    /// Images of other runs than `train`'s, to calibrate the rejection on (may be empty).
    pub calibration: TrainingSet,
    /// Images of a run seen by neither (may be empty): the robot's next run.
    pub fresh: TrainingSet,
}

impl TrainingSet {
    /// Reads `DIR/<class>/<images>` ([`crate::classifier::dataset::load_dataset`]) and names
    /// its classes from `catalog` ([`TrainingSet::from_dataset`]). With `skip_bad`, unreadable
    /// files are skipped, each logged as a warning, and returned; without it the first is an
    /// error. A folder without a single image is an error either way.
    pub fn load(
        dir: &std::path::Path,
        catalog: &TerrainCatalog,
        skip_bad: bool,
    ) -> Result<(Self, Vec<crate::classifier::dataset::ImageError>), LoadError> {
        let mut ds = crate::classifier::dataset::load_dataset(dir, skip_bad)?;
        let bad = std::mem::take(&mut ds.bad);
        for e in &bad {
            tracing::warn!("skipped (--skip-bad): {e}");
        }
        let set = Self::from_dataset(ds, catalog)?;
        if set.images.is_empty() {
            return Err(LoadError::Empty(dir.display().to_string()));
        }
        Ok((set, bad))
    }

    /// A user's dataset (`DIR/<class>/<images>`): every class folder must be named after a
    /// terrain in `catalog`, whose id the model then sends; no id is ever made up.
    pub fn from_dataset(ds: Dataset, catalog: &TerrainCatalog) -> Result<Self, LoadError> {
        let classes = ds
            .classes
            .iter()
            .map(|n| match catalog.by_name(n).filter(|t| !t.is_unknown()) {
                Some(t) => Ok(ClassInfo {
                    name: t.name().to_string(),
                    terrain_id: t.id(),
                }),
                None => Err(NotInCatalog {
                    folder: ds.root.join(n).display().to_string(),
                    name: n.clone(),
                }),
            })
            .collect::<Result<_, _>>()?;
        let manifest = crate::capture::read_manifest(&ds.root)?;
        let entries: Vec<Option<&crate::capture::ManifestEntry>> = ds
            .samples
            .iter()
            .map(|s| manifest.as_ref()?.get(s.path.strip_prefix(&ds.root).ok()?))
            .collect();
        let runs = entries
            .iter()
            .map(|e| e.map(|e| e.source.clone()))
            .collect();
        let gaits = entries.iter().map(|e| e.and_then(|e| e.gait)).collect();
        let flights = entries
            .iter()
            .map(|e| e.map_or([None, None], |e| e.flights_us))
            .collect();
        // The stances' frames a capture keeps beside each image; an unreadable file is as
        // none (the image itself is what trains).
        let frames = ds
            .samples
            .iter()
            .map(|s| crate::capture::stance_frames(&ds.root, &s.path).unwrap_or_default())
            .collect();
        let mut after: Vec<u32> = entries
            .iter()
            .filter_map(|e| e.and_then(|e| e.sampled_after_us))
            .collect();
        after.sort_unstable();
        let captured_ms = after.get(after.len() / 2).map(|us| (us + 500) / 1000);
        let (images, labels) = ds.samples.into_iter().map(|s| (s.image, s.class)).unzip();
        Ok(Self {
            classes,
            images,
            labels,
            runs,
            gaits,
            flights,
            frames,
            captured_ms,
        })
    }

    /// The set with each image replaced by its stance's frame `j` (of
    /// [`crate::stance::FRAME_OFFSETS_MS`]); images whose stance has no such frame are left
    /// out. `None` when some image has no frames at all.
    pub fn at_frame(&self, j: usize) -> Option<TrainingSet> {
        let n = crate::stance::FRAME_OFFSETS_MS.len();
        if self.frames.len() != self.images.len() || self.frames.iter().any(|f| f.len() != n) {
            return None;
        }
        let keep: Vec<usize> = (0..self.images.len())
            .filter(|&i| self.frames[i][j].pixels.iter().any(|&p| p > 0))
            .collect();
        let mut s = self.subset(&keep);
        s.images = keep.iter().map(|&i| self.frames[i][j].clone()).collect();
        s.frames = Vec::new();
        Some(s)
    }

    /// Image `i`'s flights before and after its stance, µs (none where the set has none).
    pub fn flights_of(&self, i: usize) -> [Option<u32>; 2] {
        self.flights.get(i).copied().unwrap_or([None, None])
    }

    /// `presrs train`'s account of the gaits the set's stances touched down in (the capture
    /// manifest's `gait`), and the terrains that lack one of them; `None` when no image has a
    /// gait (a folder not captured from a bus that carried GaitStatus). With `why`, what a
    /// missing gait costs, measured; without, a short note only when a terrain lacks one.
    ///
    /// Why it matters: a gait between trained ones is known ground, one beyond them is not
    /// (docs/decisions/figures-behind-comments.md, gait-coverage).
    pub fn gait_note(&self, why: bool) -> Option<String> {
        use std::collections::{BTreeMap, BTreeSet};
        use std::fmt::Write;
        if self.gaits.iter().all(Option::is_none) {
            return None;
        }
        let mut all: BTreeMap<u8, usize> = BTreeMap::new();
        let mut per_class: Vec<BTreeSet<u8>> = vec![BTreeSet::new(); self.classes.len()];
        for (g, &k) in self.gaits.iter().zip(&self.labels) {
            if let Some(g) = *g {
                *all.entry(g).or_default() += 1;
                if let Some(c) = per_class.get_mut(k) {
                    c.insert(g);
                }
            }
        }
        let mut o = String::from("gaits at touchdown (capture manifest): ");
        let name = |g: u8| crate::gait_status::gait_name(Some(g));
        let counts: Vec<String> = all
            .iter()
            .map(|(&g, n)| format!("{} {n}", name(g)))
            .collect();
        o.push_str(&counts.join(", "));
        let without = self.gaits.iter().filter(|g| g.is_none()).count();
        if without > 0 {
            let _ = write!(o, ", {without} without a GaitStatus");
        }
        let lacking: Vec<String> = self
            .classes
            .iter()
            .zip(&per_class)
            .flat_map(|(c, have)| {
                all.keys()
                    .filter(|g| !have.contains(g))
                    .map(move |&g| format!("{} in {}", c.name, name(g)))
            })
            .collect();
        if lacking.is_empty() {
            o.push_str("; every terrain in each");
            return why.then_some(o);
        }
        let _ = write!(o, "; not captured: {}", lacking.join(", "));
        if !why {
            o.push_str(
                ": a gait a terrain was not captured in can make it look new; capture each \
                 terrain in the slowest and the fastest gait the robot will run (on the \
                 simulator: `presrs demo --sweep N`)",
            );
            return Some(o);
        }
        // The controller runs a terrain in its own gait, so a set captured from the robot's
        // runs lacks gaits per terrain; the robot still meets them (the last terrain's gait at
        // a crossing, the safe gait after an unknown step).
        o.push_str(
            ". A stance meets its terrain in the gait the robot is running (the last terrain's \
             at a crossing, the safe gait after an unknown step), and a gait beyond those a \
             terrain was captured in makes it look new: on real walking, a speed beyond the \
             trained ones was 19.5-34.5% unknown, one between them 2.5% (docs/real-robot.md, \
             \"A gait the model never saw\"). Capture each terrain in the slowest and the \
             fastest gait the robot will run.",
        );
        Some(o)
    }

    /// The images at `idx`, with the same classes.
    pub fn subset(&self, idx: &[usize]) -> TrainingSet {
        TrainingSet {
            classes: self.classes.clone(),
            images: idx.iter().map(|&i| self.images[i].clone()).collect(),
            labels: idx.iter().map(|&i| self.labels[i]).collect(),
            runs: idx.iter().map(|&i| self.runs[i].clone()).collect(),
            gaits: idx.iter().map(|&i| self.gaits[i]).collect(),
            flights: idx.iter().map(|&i| self.flights_of(i)).collect(),
            frames: idx
                .iter()
                .map(|&i| self.frames.get(i).cloned().unwrap_or_default())
                .collect(),
            captured_ms: self.captured_ms,
        }
    }

    /// Per class, its runs sorted by name; `roles` runs at the end are set aside, the last for
    /// `fresh` (when `roles` is 2) and the one before it for `calibration`, as far as the class
    /// has runs to spare (the first run always trains). Images without a run are one run.
    ///
    /// `presrs train` sets one run aside (`roles` 1: calibration on the next recording);
    /// `presrs lab experiment open-set` two (calibrate on one, judge on a run nobody saw).
    pub fn split_runs(&self, roles: usize) -> RunSplit {
        let (mut t, mut c, mut f) = (Vec::new(), Vec::new(), Vec::new());
        for k in 0..self.classes.len() {
            let idx: Vec<usize> = (0..self.labels.len())
                .filter(|&i| self.labels[i] == k)
                .collect();
            let mut names: Vec<Option<&String>> =
                idx.iter().map(|&i| self.runs[i].as_ref()).collect();
            names.sort();
            names.dedup();
            let spare = roles.min(names.len().saturating_sub(1));
            let kept = names.len() - spare;
            for &i in &idx {
                let r = names
                    .iter()
                    .position(|n| *n == self.runs[i].as_ref())
                    .unwrap_or(0);
                if r < kept {
                    t.push(i);
                } else if roles == 2 && r == names.len() - 1 {
                    f.push(i);
                } else {
                    c.push(i);
                }
            }
        }
        RunSplit {
            train: self.subset(&t),
            calibration: self.subset(&c),
            fresh: self.subset(&f),
        }
    }

    /// Calibrates `model`'s unknown-terrain rejection on this set, a run (or runs) the model's
    /// stored samples did not come from; `runs` names them (in the model and in errors).
    /// Returns the calibration's check (the share of these images called unknown).
    pub fn calibrate(
        &self,
        model: &mut crate::classifier::Model,
        runs: &[String],
    ) -> Result<f64, crate::classifier::train::CalibrateError> {
        let images: Vec<(&PressureImage, &str)> = self
            .images
            .iter()
            .zip(&self.labels)
            .map(|(im, &k)| (im, self.classes[k].name.as_str()))
            .collect();
        crate::classifier::train::calibrate_on_runs(model, &images, runs)
    }

    /// A model trained on this set (`train` with `opts`), its unknown-terrain rejection
    /// calibrated on another run where there is one: `calibration` (a set and its runs'
    /// names), else, with rejection on, this set's own last run per terrain
    /// ([`TrainingSet::split_runs`]), else the training run's unused images (`train`'s own).
    pub fn train_calibrated(
        &self,
        opts: &TrainOptions,
        calibration: Option<(&TrainingSet, &[String])>,
    ) -> Result<Trained, TrainCalibratedError> {
        let own;
        let (train_set, calibration) = match calibration {
            Some(c) => (self, Some(c)),
            None if opts.unknown_rate > 0.0 => {
                let s = self.split_runs(1);
                let names = s.calibration.run_names();
                own = (s.train, s.calibration, names);
                let cal = (!own.1.images.is_empty()).then_some((&own.1, own.2.as_slice()));
                (&own.0, cal)
            }
            None => (self, None),
        };
        // The foot's deciding frame: the lab's, or measured where the sessions keep their
        // stances' frames; the sets at that frame train.
        use super::frame::{DecidingFrame, choose_frame, pinned};
        let pin = pinned(train_set, opts).map_err(TrainCalibratedError::SampleMs)?;
        // A calibration session without frames would be judged at another time than the
        // training one: then the node's sample time for both.
        let cal_ok = calibration.is_none_or(|(c, _)| c.at_frame(0).is_some());
        let (frame, j) = match pin {
            Some((ms, by, j)) => (DecidingFrame::Pinned { ms, by }, j),
            None => match cal_ok.then(|| choose_frame(train_set, opts)).flatten() {
                Some(fc) => {
                    let j = fc.chosen;
                    (DecidingFrame::Measured(fc), Some(j))
                }
                None => (DecidingFrame::NotMeasured, None),
            },
        };
        let Some(j) = j else {
            let mut trained = train_sets(train_set, calibration, opts, frame)?;
            trained.model.sample_ms = trained.frame.ms();
            return Ok(trained);
        };
        let at = |s: &TrainingSet| s.at_frame(j).unwrap_or_else(|| s.clone());
        let t = at(train_set);
        let c = calibration.map(|(c, n)| (at(c), n));
        let mut trained = train_sets(&t, c.as_ref().map(|(c, n)| (c, *n)), opts, frame)?;
        trained.model.sample_ms = trained.frame.ms();
        Ok(trained)
    }

    /// Per terrain and run, its images, with `role` (for `train`'s report).
    pub fn session_counts(&self, role: &'static str) -> Vec<super::SessionCount> {
        let mut out: Vec<super::SessionCount> = Vec::new();
        for (k, c) in self.classes.iter().enumerate() {
            let mut runs: Vec<Option<&String>> = (0..self.labels.len())
                .filter(|&i| self.labels[i] == k)
                .map(|i| self.runs[i].as_ref())
                .collect();
            runs.sort();
            for r in runs.chunk_by(|a, b| a == b) {
                out.push(super::SessionCount {
                    terrain: c.name.clone(),
                    run: r[0].cloned(),
                    images: r.len(),
                    role,
                });
            }
        }
        out
    }

    /// The distinct runs of the set's images (named ones only), sorted.
    pub fn run_names(&self) -> Vec<String> {
        let mut v: Vec<String> = self.runs.iter().flatten().cloned().collect();
        v.sort();
        v.dedup();
        v
    }

    /// The images with their classes, as `crate::classifier::train::train` takes them.
    pub fn labelled(&self) -> Vec<Labelled<'_>> {
        self.images
            .iter()
            .zip(&self.labels)
            .enumerate()
            .map(|(i, (image, &class))| Labelled {
                image,
                class,
                flights: self.flights_of(i),
            })
            .collect()
    }
}

/// [`TrainingSet::train_calibrated`] once the sets are chosen: the crop, the unknown-ground
/// choice, the fit, the calibration, the bands and the energy maps.
fn train_sets(
    train_set: &TrainingSet,
    calibration: Option<(&TrainingSet, &[String])>,
    opts: &TrainOptions,
    frame: super::frame::DecidingFrame,
) -> Result<Trained, TrainCalibratedError> {
    // The foot's own crop, measured once on every stance at the deciding frame (a given one is
    // checked), and kept only where it classifies the held-out stances at least as well as
    // none.
    let footprint = super::footprint::Footprint::of(
        train_set
            .images
            .iter()
            .chain(calibration.iter().flat_map(|(c, _)| &c.images)),
    );
    let crop_check = match (opts.crop, &footprint) {
        (CropSpec::Fixed(_), _) | (CropSpec::Auto, None) => None,
        (CropSpec::Auto, Some(f)) => Some(super::frame::check_crop(train_set, opts, f.crop())),
    };
    let crop = match (opts.crop, &crop_check) {
        (CropSpec::Fixed(c), _) => c,
        (CropSpec::Auto, Some(c)) => c.crop(),
        (CropSpec::Auto, None) => Crop::default(),
    };
    let crop_given = matches!(opts.crop, CropSpec::Fixed(_));
    let opts = &TrainOptions {
        crop: crop.into(),
        ..opts.clone()
    };
    // Which unknown-ground checks this lab's ground needs, measured on its runs.
    let cal_labelled = calibration_labelled(train_set, calibration)?;
    let choice = crate::training::choice::choose(
        &train_set.labelled(),
        &cal_labelled,
        &train_set.classes,
        opts,
    )?;
    let opts = &opts.with_candidate(&choice.candidate);
    let (mut model, split) = train(&train_set.labelled(), &train_set.classes, opts)?;
    let mut unused_calibration = 0;
    if let Some((cal, names)) = calibration {
        cal.calibrate(&mut model, names)?;
        let cap = crate::classifier::train::MAX_CALIBRATION_PER_CLASS;
        unused_calibration = (0..cal.classes.len())
            .map(|k| {
                let n = cal.labels.iter().filter(|&&l| l == k).count();
                n.saturating_sub(cap)
            })
            .sum();
    }
    if let Some((cal, _)) = calibration {
        add_bands(&mut model, train_set, cal, opts);
    }
    // The energy check, when chosen: a return map per terrain over every stance's flights.
    if choice.candidate.energy {
        let stances: Vec<(usize, f64, f64)> = train_set
            .labelled()
            .iter()
            .chain(&cal_labelled)
            .filter_map(|l| {
                let (before, after) = crate::unknown::energy::plausible_flights_s(l.flights)?;
                Some((l.class, before, after))
            })
            .collect();
        let maps = crate::unknown::energy::fit(&stances, model.classes.len(), model.unknown.rate);
        model.unknown.energy = maps.iter().any(Option::is_some).then_some(maps);
    }
    // The decision's confidence as its measured chance of being right.
    if let (Some((_, names)), crate::classifier::options::Confidence::Measure) =
        (calibration, opts.confidence)
    {
        model.confidence = super::confidence_fit::fit(
            &train_set.labelled(),
            &cal_labelled,
            names,
            &train_set.classes,
            opts,
        );
    }
    model.gaits = seen_gaits(train_set, &split, calibration);
    model.unknown.choice = (opts.unknown_rate > 0.0).then(|| choice.record());
    let mut sessions = train_set.session_counts("trained");
    if let Some((cal, _)) = calibration {
        sessions.extend(cal.session_counts("calibration"));
    }
    Ok(Trained {
        model,
        footprint,
        crop_given,
        crop_check,
        sessions,
        frame,
        split,
        train_images: train_set.images.len(),
        unused_calibration,
        choice,
    })
}

/// The calibration run's images with the training set's class indices (a class the training
/// set lacks is refused by name).
fn calibration_labelled<'a>(
    train_set: &TrainingSet,
    calibration: Option<(&'a TrainingSet, &[String])>,
) -> Result<Vec<Labelled<'a>>, CalibrateError> {
    let Some((cal, names)) = calibration else {
        return Ok(Vec::new());
    };
    cal.images
        .iter()
        .zip(&cal.labels)
        .enumerate()
        .map(|(i, (image, &l))| {
            let name = &cal.classes[l].name;
            let class = train_set
                .classes
                .iter()
                .position(|c| &c.name == name)
                .ok_or_else(|| CalibrateError::UnknownClass {
                    run: names.join(", "),
                    class: name.clone(),
                })?;
            Ok(Labelled {
                image,
                class,
                flights: cal.flights_of(i),
            })
        })
        .collect()
}

/// The load and texture bands, when chosen, over the calibration run too: the next run's
/// spread, not only the training run's.
fn add_bands(model: &mut Model, train_set: &TrainingSet, cal: &TrainingSet, opts: &TrainOptions) {
    if !(opts.check_texture || opts.check_load) {
        return;
    }
    let index = |set: &TrainingSet, l: usize| {
        let name = &set.classes[l].name;
        model.classes.iter().position(|c| &c.name == name)
    };
    let images: Vec<(&PressureImage, usize)> = [train_set, cal]
        .into_iter()
        .flat_map(|set| {
            set.images
                .iter()
                .zip(&set.labels)
                .filter_map(move |(img, &l)| index(set, l).map(|k| (img, k)))
        })
        .collect();
    if opts.check_texture {
        crate::classifier::train::add_texture_check(model, images.iter().copied());
    }
    if opts.check_load {
        crate::classifier::train::add_load_check_on(model, images);
    }
}

/// The gaits the model has seen: its stored samples' and its calibration run's.
fn seen_gaits(
    train_set: &TrainingSet,
    split: &Split,
    calibration: Option<(&TrainingSet, &[String])>,
) -> Option<Vec<u8>> {
    let mut gaits: Vec<u8> = split
        .train
        .iter()
        .chain(&split.validation)
        .filter_map(|&i| train_set.gaits.get(i).copied().flatten())
        .chain(
            calibration
                .iter()
                .flat_map(|(c, _)| c.gaits.iter().flatten().copied()),
        )
        .collect();
    gaits.sort_unstable();
    gaits.dedup();
    (!gaits.is_empty()).then_some(gaits)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::classifier::dataset::write_pgm;

    #[test]
    fn a_dataset_folder_loads_with_its_catalog_and_says_what_is_wrong() {
        let dir = std::env::temp_dir().join(format!("presrs-lab-load-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let catalog = TerrainCatalog::paper();
        std::fs::create_dir_all(dir.join("sand")).unwrap();
        // A class folder without an image: refused, naming the folder.
        let e = TrainingSet::load(&dir, &catalog, true).unwrap_err();
        assert!(matches!(e, LoadError::Empty(_)), "{e}");
        assert!(e.to_string().contains(&dir.display().to_string()), "{e}");
        for (class, v) in [("sand", 10u16), ("clay", 200)] {
            std::fs::create_dir_all(dir.join(class)).unwrap();
            let img = PressureImage::new(4, 4, 8, vec![v; 16]);
            write_pgm(&img, &dir.join(class).join("0.pgm")).unwrap();
        }
        std::fs::write(dir.join("sand").join("1.pgm"), b"not an image").unwrap();
        // A bad file stops the load unless skipped; skipped, it is returned, not lost.
        assert!(TrainingSet::load(&dir, &catalog, false).is_err());
        let (set, bad) = TrainingSet::load(&dir, &catalog, true).unwrap();
        assert_eq!(bad.len(), 1);
        assert!(bad[0].path.ends_with("1.pgm"), "{:?}", bad[0]);
        let names: Vec<&str> = set.classes.iter().map(|c| c.name.as_str()).collect();
        assert_eq!(names, ["clay", "sand"]);
        assert_eq!(set.labels, [0, 1]);
        assert_eq!(set.images[1].pixels[0], 10);
        // A folder named after no terrain: refused with the fix.
        std::fs::create_dir_all(dir.join("asphalt")).unwrap();
        write_pgm(
            &PressureImage::new(4, 4, 8, vec![1; 16]),
            &dir.join("asphalt").join("0.pgm"),
        )
        .unwrap();
        let e = TrainingSet::load(&dir, &catalog, true).unwrap_err();
        assert!(e.to_string().contains("--terrains FILE"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
