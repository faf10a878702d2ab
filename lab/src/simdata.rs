//! Labelled training sets for the classifier: from simulator samples (the glue between the `sim`
//! and `node` crates, which do not depend on each other) or from a dataset directory.

use node::classifier::{ClassInfo, PressureImage};
use protocol::terrain::Terrain;
use sim::dataset::Sample;

pub use node::training::{
    LoadError, NotInCatalog, RunSplit, TrainCalibratedError, Trained, TrainingSet,
    no_training_run_images_note,
};

/// A training set of simulator samples, classes in the order of `terrains`; samples of a
/// terrain not in `terrains` are left out.
pub fn training_set(samples: Vec<Sample>, terrains: &[Terrain]) -> TrainingSet {
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
    TrainingSet {
        classes,
        images,
        labels,
        runs,
        gaits,
        flights: Vec::new(),
        frames: Vec::new(),
        captured_ms: None,
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

/// A generated set at a glance, as `presrs lab dataset` prints it: a line per terrain with its
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
    use node::classifier::train::TrainOptions;

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
                }
                .into(),
                ..Default::default()
            };
            let t = train_run
                .train_calibrated(&opts, Some((&cal, &names)))
                .unwrap();
            let c = t
                .model
                .unknown
                .novelty
                .as_ref()
                .unwrap()
                .calibration
                .clone();
            (
                c,
                t.report(
                    opts.unknown_rate,
                    std::time::Duration::ZERO,
                    "m.json",
                    false,
                ),
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
            crop: crop.into(),
            check_texture: true,
            ..Default::default()
        };
        let t = train_run
            .train_calibrated(&opts, Some((&cal, &["run2.log".to_string()])))
            .unwrap();
        let bands = t.model.unknown.texture_bands.clone().unwrap();
        for set in [&train_run, &cal] {
            for (img, &l) in set.images.iter().zip(&set.labels) {
                let w = img.crop(&crop).unwrap();
                let r = node::classifier::texture::roughness(&w.pixels, w.rows, w.cols);
                let [lo, hi] = bands[l];
                assert!((lo..=hi).contains(&r), "{r} outside {lo}-{hi}");
            }
        }
        let report = t.report(
            opts.unknown_rate,
            std::time::Duration::ZERO,
            "m.json",
            false,
        );
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
                    crop: crop.into(),
                    unknown_checks: node::classifier::options::UnknownChecks::Fixed(
                        node::classifier::options::Candidate::PLAIN,
                    ),
                    ..Default::default()
                },
                None,
            )
            .unwrap();
        assert!(plain.model.unknown.texture_bands.is_none());
        assert!(
            !plain
                .report(0.02, std::time::Duration::ZERO, "m.json", false)
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
        assert_eq!(
            set.gait_note(false),
            None,
            "every terrain in each: nothing to act on"
        );
        let note = set.gait_note(true).unwrap();
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
        let short = set.gait_note(false).unwrap();
        let note = set.gait_note(true).unwrap();
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
        assert!(
            short.contains(&format!("; not captured: {first} in G3: ")) && short.len() < 300,
            "{short}"
        );
        set.gaits.iter_mut().for_each(|g| *g = None);
        assert_eq!(set.gait_note(true), None);
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
}
