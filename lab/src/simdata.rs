//! Labelled training sets for the classifier: from simulator samples (the glue between the `sim`
//! and `node` crates, which do not depend on each other) or from a dataset directory.

use node::classifier::dataset::Dataset;
use node::classifier::train::Labelled;
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

/// Images, each one's class (an index into `classes`), and the classes in the order of the
/// terrains given: the name and the terrain id the model puts on the bus.
#[derive(Clone)]
pub struct TrainingSet {
    /// One entry per class: its name and the terrain id the model sends.
    pub classes: Vec<ClassInfo>,
    /// The images.
    pub images: Vec<PressureImage>,
    /// Each image's class, an index into `classes`.
    pub labels: Vec<usize>,
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
        let (images, labels) = samples
            .into_iter()
            .filter_map(|s| {
                let k = terrains.iter().position(|t| *t == s.terrain)?;
                Some((PressureImage::new(s.rows, s.cols, 8, s.pixels), k))
            })
            .unzip();
        Self {
            classes,
            images,
            labels,
        }
    }

    /// A user's dataset (`DIR/<class>/<images>`): every class folder must be named after a
    /// terrain in `catalog`, whose id the model then sends; no id is ever made up.
    pub fn from_dataset(ds: Dataset, catalog: &TerrainCatalog) -> Result<Self, NotInCatalog> {
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
        let (images, labels) = ds.samples.into_iter().map(|s| (s.image, s.class)).unzip();
        Ok(Self {
            classes,
            images,
            labels,
        })
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
