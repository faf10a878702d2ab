//! Classifies every pressure image in a folder (PGM, or a TekScan ASCII export) with a model.
//!
//! ```text
//! cargo run --release -p presrs-node --example classify_folder -- model.json images/
//! ```
//!
//! The same pipeline as the node's, one image at a time: crop, repair filter, FFT magnitude,
//! PCA, Parzen window; an image unlike every terrain the model knows is `unknown`.

use presrs_node::classifier::dataset::read_images;
use presrs_node::classifier::{Classifier, Model};
use protocol::TerrainCatalog;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let (Some(model), Some(dir)) = (args.next(), args.next()) else {
        return Err("usage: classify_folder MODEL.json DIR".into());
    };
    let mut classifier = Classifier::new(Model::load(model.as_ref())?);
    let catalog = TerrainCatalog::paper();
    let mut files: Vec<_> = std::fs::read_dir(&dir)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file())
        .collect();
    files.sort();
    for path in files {
        // One file may hold several frames (a TekScan movie); a bad file is named, not fatal.
        let images = match read_images(&path) {
            Ok(i) => i,
            Err(e) => {
                eprintln!("{e}");
                continue;
            }
        };
        for (i, img) in images.iter().enumerate() {
            match classifier.classify_image(img, true) {
                Ok(d) => println!(
                    "{} #{i}: {} ({:.0}%)",
                    path.display(),
                    catalog.describe(d.terrain_id),
                    d.confidence * 100.0
                ),
                Err(e) => eprintln!("{} #{i}: {e}", path.display()),
            }
        }
    }
    Ok(())
}
