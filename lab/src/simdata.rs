//! Labelled training sets for the classifier: from simulator samples (the glue between the `sim`
//! and `node` crates, which do not depend on each other) or from a dataset directory.

use node::classifier::dataset::Dataset;
use node::classifier::train::{CalibrateError, Labelled, Split, TrainOptions, train};
use node::classifier::{ClassInfo, PressureImage};
use protocol::terrain::{Terrain, TerrainCatalog};
use sim::dataset::Sample;

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
    Read(#[from] node::classifier::dataset::ImageError),
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
    Manifest(#[from] node::capture::CaptureError),
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
}

/// A model from [`TrainingSet::train_calibrated`].
pub struct Trained {
    /// The model.
    pub model: node::classifier::Model,
    /// Which of the training images went where (indices into the images trained on).
    pub split: Split,
    /// Images trained on (the set less any run held out for calibration).
    pub train_images: usize,
    /// Calibration images not used: beyond `MAX_CALIBRATION_PER_CLASS` of a terrain.
    pub unused_calibration: usize,
    /// How the unknown-ground checks were chosen, and the table.
    pub choice: node::training::choice::Choice,
}

impl Trained {
    /// `presrs train`'s account: unused calibration images, how the unknown-terrain check was
    /// calibrated (or why there is none: `unknown_rate` as asked), and what was trained, in
    /// `took`, written to `out`.
    pub fn report(&self, unknown_rate: f64, took: std::time::Duration, out: &str) -> String {
        use std::fmt::Write;
        let (model, split) = (&self.model, &self.split);
        let mut o = String::new();
        // Writing to a String cannot fail.
        if unknown_rate > 0.0 {
            let _ = write!(o, "{}", self.choice);
        }
        if self.unused_calibration > 0 {
            let _ = writeln!(
                o,
                "calibration run: {} images not used (at most {} per terrain, the first ones)",
                self.unused_calibration,
                node::classifier::train::MAX_CALIBRATION_PER_CLASS
            );
        }
        let _ = match &model.novelty {
            Some(nv) => {
                let c = &nv.calibration;
                writeln!(
                    o,
                    "unknown terrain: calibrated on {} ({} images{}) to --unknown-rate {}{}: \
                     the check calls {:.1}% of them unknown ({:.1}% were taken for another \
                     terrain){}",
                    c.source.describe(),
                    c.images,
                    if c.runs.is_empty() {
                        String::new()
                    } else {
                        format!(" of {}", c.runs.join(", "))
                    },
                    unknown_rate,
                    if nv.reference_classes.is_empty() {
                        String::new()
                    } else {
                        format!(
                            " (the held-out run's {} images classified right are now the \
                             model's references for the next run; scored without them, the \
                             calibration set its thresholds at {:.3})",
                            nv.reference_classes.len(),
                            c.rate
                        )
                    },
                    100.0 * c.called_unknown,
                    100.0 * c.misclassified,
                    if c.margin > 1.0 {
                        format!(
                            " before the margin (x{}); with one run only, calibrate on a second \
                             one (--calibrate DIR) for thresholds that fit the robot's next run",
                            c.margin
                        )
                    } else {
                        String::new()
                    }
                )
            }
            None if unknown_rate > 0.0 => writeln!(
                o,
                "unknown terrain: no calibration image showed contact; the density rule decides"
            ),
            None => writeln!(o, "unknown terrain: rejection off (--unknown-rate 0)"),
        };
        if let Some(bands) = &model.texture_ranges {
            let each: Vec<String> = model
                .classes
                .iter()
                .zip(bands)
                .map(|(c, [lo, hi])| format!("{} {lo:.3}-{hi:.3}", c.name))
                .collect();
            let _ = writeln!(
                o,
                "texture check: an image whose roughness lies outside its terrain's band is \
                 unknown; bands over the images trained and calibrated on: {} (terrains whose \
                 bands overlap it cannot tell apart)",
                each.join(", ")
            );
        }
        if let Some(c) = model.novelty.as_ref().map(|nv| &nv.calibration)
            && c.source == node::unknown::novelty::CalibrationSource::HeldOutRuns
            && c.training_run_images() == 0
        {
            let _ = writeln!(o, "{}", no_training_run_images_note());
        }
        let _ = writeln!(
            o,
            "trained on {} + {} images ({} classes), h = {}, kernel width {:.4}, {:.1} ms; {} \
             images left for testing; wrote {out}",
            split.train.len(),
            split.validation.len(),
            model.classes.len(),
            model.h,
            model.kernel_width,
            took.as_secs_f64() * 1e3,
            split.test.len(),
        );
        o
    }
}

/// What `presrs train` adds when a calibration on held-out runs holds none of the training
/// run's images (fewer than `MIN_SAME_RUN_PER_CLASS` per terrain were left out of the model):
/// the calibration's own check then says less than the next run will do. Measured: see
/// `node::classifier::novelty`, "How many images to store".
pub fn no_training_run_images_note() -> String {
    format!(
        "unknown terrain: the calibration holds none of the training run's images (fewer than \
         {} per terrain were left out of the model by --per-class), only the held-out run's, \
         and its check understates the next run: on the real SpeedPP2D maps (presrs experiment \
         open-set --per-class 30 --train 20, seeds 1-10) the next run's known images were \
         called unknown 5.9% (median; 5.1-6.4%) against 2.4% (1.9-3.6%) at the default \
         --per-class 20, which leaves 10 of each person's 30 out. Draw fewer images per terrain \
         than the training run holds, or expect more unknowns than --unknown-rate on the next \
         run.",
        node::classifier::train::MIN_SAME_RUN_PER_CLASS
    )
}

/// Why [`TrainingSet::train_calibrated`] failed: training or the calibration, as they say it.
#[derive(Debug, thiserror::Error)]
pub enum TrainCalibratedError {
    /// Training.
    #[error(transparent)]
    Train(#[from] node::classifier::train::TrainError),
    /// Calibrating on the other run.
    #[error(transparent)]
    Calibrate(#[from] node::classifier::train::CalibrateError),
    /// Choosing the unknown-ground checks.
    #[error(transparent)]
    Choice(#[from] node::training::choice::ChoiceError),
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
    /// Samples of a terrain not in `terrains` are left out.
    pub fn from_samples(samples: Vec<Sample>, terrains: &[Terrain]) -> Self {
        let classes = terrains
            .iter()
            .map(|t| ClassInfo {
                name: t.name().to_string(),
                terrain_id: t.id(),
            })
            .collect();
        let (images, labels): (Vec<PressureImage>, Vec<usize>) = samples
            .into_iter()
            .filter_map(|s| {
                let k = terrains.iter().position(|t| *t == s.terrain)?;
                Some((PressureImage::new(s.rows, s.cols, 8, s.pixels), k))
            })
            .unzip();
        let runs = vec![None; labels.len()];
        let gaits = vec![None; labels.len()];
        Self {
            classes,
            images,
            labels,
            runs,
            gaits,
        }
    }

    /// Reads `DIR/<class>/<images>` ([`node::classifier::dataset::load_dataset`]) and names
    /// its classes from `catalog` ([`TrainingSet::from_dataset`]). With `skip_bad`, unreadable
    /// files are skipped, each logged as a warning, and returned; without it the first is an
    /// error. A folder without a single image is an error either way.
    pub fn load(
        dir: &std::path::Path,
        catalog: &TerrainCatalog,
        skip_bad: bool,
    ) -> Result<(Self, Vec<node::classifier::dataset::ImageError>), LoadError> {
        let mut ds = node::classifier::dataset::load_dataset(dir, skip_bad)?;
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
        let manifest = node::capture::read_manifest(&ds.root)?;
        let entries: Vec<Option<&node::capture::ManifestEntry>> = ds
            .samples
            .iter()
            .map(|s| manifest.as_ref()?.get(s.path.strip_prefix(&ds.root).ok()?))
            .collect();
        let runs = entries
            .iter()
            .map(|e| e.map(|e| e.source.clone()))
            .collect();
        let gaits = entries.iter().map(|e| e.and_then(|e| e.gait)).collect();
        let (images, labels) = ds.samples.into_iter().map(|s| (s.image, s.class)).unzip();
        Ok(Self {
            classes,
            images,
            labels,
            runs,
            gaits,
        })
    }

    /// `presrs train`'s account of the gaits the set's stances touched down in (the capture
    /// manifest's `gait`), and the terrains that lack one of them; `None` when no image has a
    /// gait (a folder not captured from a bus that carried GaitStatus).
    ///
    /// Why it matters, measured (docs/real-robot.md, "A gait the model never saw"): a gait
    /// between trained ones is known ground (real SpeedPP2D, a speed between two trained ones,
    /// 2.5% unknown), one beyond them is not (a faster speed 34.5% unknown, a slower 19.5%).
    pub fn gait_note(&self) -> Option<String> {
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
        let name = |g: u8| node::gait::gait_name(Some(g));
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
        } else {
            let _ = write!(o, "; not captured: {}", lacking.join(", "));
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
        }
    }

    /// Per class, its runs sorted by name; `roles` runs at the end are set aside, the last for
    /// `fresh` (when `roles` is 2) and the one before it for `calibration`, as far as the class
    /// has runs to spare (the first run always trains). Images without a run are one run.
    ///
    /// `presrs train` sets one run aside (`roles` 1: calibration on the next recording);
    /// `presrs experiment open-set` two (calibrate on one, judge on a run nobody saw).
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
        model: &mut node::classifier::Model,
        runs: &[String],
    ) -> Result<f64, node::classifier::train::CalibrateError> {
        let images: Vec<(&PressureImage, &str)> = self
            .images
            .iter()
            .zip(&self.labels)
            .map(|(im, &k)| (im, self.classes[k].name.as_str()))
            .collect();
        node::classifier::train::calibrate_on_runs(model, &images, runs)
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
        // Which unknown-ground checks this lab's ground needs, measured on its runs.
        let cal_labelled: Vec<Labelled<'_>> = match calibration {
            Some((cal, names)) => cal
                .images
                .iter()
                .zip(&cal.labels)
                .map(|(image, &l)| {
                    let name = &cal.classes[l].name;
                    let class = train_set
                        .classes
                        .iter()
                        .position(|c| &c.name == name)
                        .ok_or_else(|| CalibrateError::UnknownClass {
                            run: names.join(", "),
                            class: name.clone(),
                        })?;
                    Ok(Labelled { image, class })
                })
                .collect::<Result<_, CalibrateError>>()?,
            None => Vec::new(),
        };
        let choice = node::training::choice::choose(
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
            let cap = node::classifier::train::MAX_CALIBRATION_PER_CLASS;
            unused_calibration = (0..cal.classes.len())
                .map(|k| {
                    cal.labels
                        .iter()
                        .filter(|&&l| l == k)
                        .count()
                        .saturating_sub(cap)
                })
                .sum();
        }
        // The load and texture bands over the calibration run too: the next run's spread, not
        // only the training run's.
        if (opts.check_texture || opts.check_load)
            && let Some((cal, _)) = calibration
        {
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
                node::classifier::train::add_texture_check(&mut model, images.iter().copied());
            }
            if opts.check_load {
                node::classifier::train::add_load_check_on(&mut model, images);
            }
        }
        // The gaits the model has seen: its stored samples' and its calibration run's.
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
        model.gaits = (!gaits.is_empty()).then_some(gaits);
        model.unknown_choice = (opts.unknown_rate > 0.0).then(|| choice.record());
        Ok(Trained {
            model,
            split,
            train_images: train_set.images.len(),
            unused_calibration,
            choice,
        })
    }

    /// The distinct runs of the set's images (named ones only), sorted.
    pub fn run_names(&self) -> Vec<String> {
        let mut v: Vec<String> = self.runs.iter().flatten().cloned().collect();
        v.sort();
        v.dedup();
        v
    }

    /// The images with their classes, as `node::classifier::train::train` takes them.
    pub fn labelled(&self) -> Vec<Labelled<'_>> {
        self.images
            .iter()
            .zip(&self.labels)
            .map(|(image, &class)| Labelled { image, class })
            .collect()
    }
}

/// Writes `samples` as `out/<terrain>/<NNNN>.pgm` (numbered per terrain, in order), the layout
/// `presrs train` reads.
pub fn write_images(samples: &[Sample], out: &std::path::Path) -> Result<(), WriteError> {
    let mut counts = std::collections::BTreeMap::new();
    for s in samples {
        let dir = out.join(s.terrain.name());
        std::fs::create_dir_all(&dir).map_err(|e| WriteError(dir.display().to_string(), e))?;
        let k = counts.entry(s.terrain.name()).or_insert(0usize);
        let img = PressureImage::new(s.rows, s.cols, 8, s.pixels.clone());
        let path = dir.join(format!("{:04}.pgm", *k));
        node::classifier::dataset::write_pgm(&img, &path)
            .map_err(|e| WriteError(path.display().to_string(), e))?;
        *k += 1;
    }
    Ok(())
}

/// A file or folder [`write_images`] could not write.
#[derive(Debug, thiserror::Error)]
#[error("writing {0}: {1}")]
pub struct WriteError(pub String, #[source] pub std::io::Error);

/// Per terrain of `samples` (in the order given): its samples' count and mean load (N), stance
/// (s) and forward speed (m/s).
pub fn means(samples: &[Sample], terrains: &[Terrain]) -> Vec<(Terrain, usize, [f64; 3])> {
    terrains
        .iter()
        .filter_map(|&t| {
            let of: Vec<&Sample> = samples.iter().filter(|s| s.terrain == t).collect();
            let n = of.len() as f64;
            let mean = |f: fn(&Sample) -> f64| of.iter().map(|s| f(s)).sum::<f64>() / n;
            (!of.is_empty()).then(|| {
                let m = [
                    mean(|s| s.load_n),
                    mean(|s| s.stance_s),
                    mean(|s| s.speed_m_s),
                ];
                (t, of.len(), m)
            })
        })
        .collect()
}

/// A generated set at a glance, as `presrs dataset` prints it: a line per terrain with its
/// count and mean load (dynamic sets: also stance time and speed).
pub fn describe(samples: &[Sample], kind: sim::dataset::Kind) -> String {
    let mut out = String::new();
    for (t, n, [load, stance_s, speed]) in means(samples, &kind.terrains()) {
        let name = t.name();
        out += &if kind == sim::dataset::Kind::Dynamic {
            format!(
                "{name}: {n} images; load at the sample {load:.1} N, stance {:.0} ms, speed \
                 {speed:.2} m/s (means)\n",
                stance_s * 1e3
            )
        } else {
            format!("{name}: {n} images, load {load:.1} N\n")
        };
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use node::classifier::dataset::write_pgm;

    /// Calibrated on another run, a model keeps the training run's unused images in its
    /// calibration; one that stores them all has none, and `presrs train` says what that does.
    #[test]
    fn a_model_storing_its_whole_training_run_is_told_its_check_understates_the_next_run() {
        let kind = sim::dataset::Kind::Static;
        let train_run = crate::study::dataset_on(kind, 20, controller::Gait::g2(), 41, 1);
        let cal = crate::study::dataset_on(kind, 10, controller::Gait::g2(), 42, 2);
        let names = ["run2.log".to_string()];
        let trained = |per_class: usize, train: usize| {
            let opts = TrainOptions {
                per_class,
                train,
                crop: node::classifier::image::Crop {
                    top: 2,
                    bottom: 2,
                    left: 2,
                    right: 2,
                },
                ..Default::default()
            };
            let t = train_run
                .train_calibrated(&opts, Some((&cal, &names)))
                .unwrap();
            let c = t.model.novelty.as_ref().unwrap().calibration.clone();
            (
                c,
                t.report(opts.unknown_rate, std::time::Duration::ZERO, "m.json"),
            )
        };
        let note = no_training_run_images_note();
        // 20 of 20 per terrain stored: the calibration is the held-out run's 40 images alone.
        let (c, report) = trained(20, 13);
        assert_eq!((c.held_out_images, c.training_run_images()), (40, 0));
        assert!(report.contains(&note), "{report}");
        // 6 of 20 left out of the model: they calibrate beside the held-out run.
        let (c, report) = trained(14, 9);
        assert_eq!((c.held_out_images, c.training_run_images()), (40, 24));
        assert!(!report.contains(&note), "{report}");
    }

    /// `--check-texture`: the bands cover the training run's and the calibration run's images
    /// (a robot's next run scatters like the calibration run), and `train` prints them.
    #[test]
    fn the_texture_bands_cover_both_runs_and_train_prints_them() {
        let kind = sim::dataset::Kind::Static;
        let train_run = crate::study::dataset_on(kind, 20, controller::Gait::g2(), 41, 1);
        let cal = crate::study::dataset_on(kind, 10, controller::Gait::g2(), 42, 2);
        let crop = node::classifier::image::Crop {
            top: 2,
            bottom: 2,
            left: 2,
            right: 2,
        };
        let opts = TrainOptions {
            crop,
            check_texture: true,
            ..Default::default()
        };
        let t = train_run
            .train_calibrated(&opts, Some((&cal, &["run2.log".to_string()])))
            .unwrap();
        let bands = t.model.texture_ranges.clone().unwrap();
        for set in [&train_run, &cal] {
            for (img, &l) in set.images.iter().zip(&set.labels) {
                let w = img.crop(&crop).unwrap();
                let r = node::classifier::texture::roughness(&w.pixels, w.rows, w.cols);
                let [lo, hi] = bands[l];
                assert!((lo..=hi).contains(&r), "{r} outside {lo}-{hi}");
            }
        }
        let report = t.report(opts.unknown_rate, std::time::Duration::ZERO, "m.json");
        let line = report
            .lines()
            .find(|l| l.starts_with("texture check:"))
            .unwrap_or_default();
        for c in &t.model.classes {
            assert!(line.contains(&format!("{} ", c.name)), "{report}");
        }
        // Without the flag, and the choice fixed to the plain checks: no bands, no line.
        let plain = train_run
            .train_calibrated(
                &TrainOptions {
                    crop,
                    unknown_checks: node::classifier::options::UnknownChecks::Fixed(
                        node::classifier::options::Candidate::PLAIN,
                    ),
                    ..Default::default()
                },
                None,
            )
            .unwrap();
        assert!(plain.model.texture_ranges.is_none());
        assert!(
            !plain
                .report(0.02, std::time::Duration::ZERO, "m.json")
                .lines()
                .any(|l| l.starts_with("texture check:"))
        );
    }

    /// `train` lists the gaits a set's stances touched down in and the terrains lacking one;
    /// a set without gaits (no manifest, or a bus without GaitStatus) gets no note.
    #[test]
    fn the_gait_note_names_each_gait_and_the_terrains_that_lack_one() {
        let kind = sim::dataset::Kind::Static;
        let mut set = crate::study::dataset_on(kind, 4, controller::Gait::g2(), 41, 1);
        let g3 = crate::study::dataset_on(kind, 4, controller::Gait::g3(), 42, 1);
        let n = set.images.len();
        assert_eq!(
            set.gaits,
            vec![Some(2); n],
            "a simulated set knows its gait"
        );
        let note = set.gait_note().unwrap();
        assert!(
            note.starts_with(&format!(
                "gaits at touchdown (capture manifest): G2 {n}; every"
            )),
            "{note}"
        );
        // G3 on every terrain but the first, and one stance of unknown gait.
        let keep: Vec<usize> = (0..g3.images.len())
            .filter(|&i| g3.labels[i] != 0)
            .collect();
        let g3 = g3.subset(&keep);
        set.images.extend(g3.images);
        set.labels.extend(g3.labels);
        set.runs.extend(g3.runs);
        set.gaits.extend(g3.gaits);
        set.gaits[0] = None;
        let note = set.gait_note().unwrap();
        let first = &set.classes[0].name;
        assert!(
            note.contains(&format!(
                "G2 {}, G3 {}, 1 without a GaitStatus",
                n - 1,
                keep.len()
            )),
            "{note}"
        );
        assert!(
            note.contains(&format!("; not captured: {first} in G3. ")),
            "{note}"
        );
        set.gaits.iter_mut().for_each(|g| *g = None);
        assert_eq!(set.gait_note(), None);
    }

    #[test]
    fn a_generated_set_is_described_per_terrain_in_means() {
        let kind = sim::dataset::Kind::Dynamic;
        let t = kind.terrains();
        let sample = |terrain: Terrain, load_n: f64| Sample {
            terrain,
            rows: 1,
            cols: 1,
            pixels: vec![0],
            load_n,
            stance_s: 0.15,
            speed_m_s: 0.5,
        };
        let samples = [sample(t[0], 20.0), sample(t[0], 30.0), sample(t[1], 10.0)];
        let text = describe(&samples, kind);
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 2, "{text}");
        assert_eq!(
            lines[0],
            format!(
                "{}: 2 images; load at the sample 25.0 N, stance 150 ms, speed 0.50 m/s (means)",
                t[0].name()
            )
        );
        // Terrains of another set are not this one's.
        let kind = sim::dataset::Kind::Static;
        assert_eq!(describe(&samples, kind), "");
        let s = kind.terrains()[0];
        let text = describe(&[sample(s, 20.0), sample(s, 30.0)], kind);
        assert_eq!(text, format!("{}: 2 images, load 25.0 N\n", s.name()));
    }

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
