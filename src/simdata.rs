//! Labelled training sets for the classifier: from simulator samples (the glue between the `sim`
//! and `node` crates, which do not depend on each other) or from a dataset directory.

use node::classifier::dataset::Dataset;
use node::classifier::train::Labelled;
use node::classifier::{ClassInfo, PressureImage};
use sim::dataset::Sample;
use sim::terrain::Terrain;

/// Images, each one's class (an index into `classes`), and the classes in the order of the
/// terrains given: the name and the terrain id the model puts on the bus.
pub struct TrainingSet {
    pub classes: Vec<ClassInfo>,
    pub images: Vec<PressureImage>,
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

    /// A user's dataset (`DIR/<class>/<images>`), with terrain ids as `presrs train` gives
    /// them: the protocol's id for a known terrain name, 100 + the class index otherwise.
    pub fn from_dataset(ds: Dataset) -> Self {
        let classes = ds
            .classes
            .iter()
            .enumerate()
            .map(|(i, n)| ClassInfo {
                name: n.clone(),
                terrain_id: protocol::messages::terrain_id(n).unwrap_or(100 + i as u8),
            })
            .collect();
        let (images, labels) = ds.samples.into_iter().map(|s| (s.image, s.class)).unzip();
        Self {
            classes,
            images,
            labels,
        }
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
