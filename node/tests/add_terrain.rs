//! A terrain added to a trained model (`classifier::train::add_class`, what `presrs discover
//! --add` fits): on synthetic textures, a model of two surfaces learns a third from a few
//! dozen of its stances, keeps the two, and refuses what it cannot add.

use presrs_node::classifier::model::{ClassInfo, Model};
use presrs_node::classifier::train::{
    Basis, ExtendError, Labelled, TrainOptions, add_class, told_apart, train,
};
use presrs_node::classifier::{Classifier, Crop, PressureImage};
use rand::SeedableRng;

mod common;
use common::texture;

const KINDS: [(usize, f64); 3] = [(4, 0.5), (7, 0.5), (11, 0.35)];

fn info(name: &str, id: u8) -> ClassInfo {
    ClassInfo {
        name: name.into(),
        terrain_id: id,
    }
}

fn two_terrain_model() -> Model {
    let mut rng = rand::rngs::StdRng::seed_from_u64(1);
    let imgs: Vec<(PressureImage, usize)> = (0..2)
        .flat_map(|k| (0..40).map(move |_| k))
        .map(|k| (texture(&mut rng, KINDS[k].0, KINDS[k].1), k))
        .collect();
    let data: Vec<Labelled<'_>> = imgs.iter().map(|(i, k)| Labelled::new(i, *k)).collect();
    let opts = TrainOptions {
        crop: "2,2,2,2".parse::<Crop>().unwrap().into(),
        ..TrainOptions::default()
    };
    train(&data, &[info("wood", 8), info("carpet", 9)], &opts)
        .unwrap()
        .0
}

/// The share of fresh images of kind `k` decided as class `class`.
fn right(m: &Model, k: usize, class: usize, seed: u64) -> f64 {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let mut c = Classifier::new(m.clone());
    let n = 40;
    let hits = (0..n)
        .filter(|_| {
            let img = texture(&mut rng, KINDS[k].0, KINDS[k].1);
            c.classify_image(&img, false).unwrap().class == Some(class)
        })
        .count();
    hits as f64 / n as f64
}

#[test]
fn a_third_terrain_is_learned_from_its_stances_and_the_two_are_kept() {
    let model = two_terrain_model();
    let mut rng = rand::rngs::StdRng::seed_from_u64(2);
    let new: Vec<PressureImage> = (0..30).map(|_| texture(&mut rng, 11, 0.35)).collect();
    // Before: the third texture is unknown ground, not either terrain.
    assert!(right(&model, 2, 0, 9) + right(&model, 2, 1, 9) < 0.2);
    for basis in [Basis::Extend, Basis::Refit] {
        let m = add_class(&model, info("grass", 11), &new, &[], basis).unwrap();
        assert_eq!(m.classes.len(), 3);
        assert_eq!(m.classes[2].name, "grass");
        let (grass, wood, carpet) = (right(&m, 2, 2, 3), right(&m, 0, 0, 4), right(&m, 1, 1, 5));
        eprintln!("{basis:?}: grass {grass}, wood {wood}, carpet {carpet}");
        assert!(grass >= 0.9, "{basis:?}: grass {grass}");
        assert!(
            wood >= right(&model, 0, 0, 4) - 0.05,
            "{basis:?}: wood {wood}"
        );
        assert!(
            carpet >= right(&model, 1, 1, 5) - 0.05,
            "{basis:?}: carpet {carpet}"
        );
        // Its own stored stances, each left out: the new terrain told apart.
        let t = told_apart(&m);
        assert_eq!(t[2].stances, 30);
        assert!(t[2].right >= 27, "{:?}", t[2]);
        // The file it writes is one every command loads.
        let path =
            std::env::temp_dir().join(format!("presrs-add-{}-{basis:?}.json", std::process::id()));
        m.save(&path).unwrap();
        let back = Model::load(&path).unwrap();
        assert_eq!(back.classes, m.classes);
        let _ = std::fs::remove_file(&path);
    }
    // Extending keeps every known stored stance's projection as it was.
    let m = add_class(&model, info("grass", 11), &new, &[], Basis::Extend).unwrap();
    assert!(m.h > model.h);
    let n_known = model.sample_classes.len();
    let mut c = Classifier::new(model.clone());
    let mut e = Classifier::new(m.clone());
    for work in model.images.as_ref().unwrap().pixels.iter().take(n_known) {
        c.classify_work(work);
        e.classify_work(work);
        for (a, b) in c.projection().iter().zip(e.projection()) {
            assert!((a - b).abs() <= 1e-3 * a.abs().max(1.0), "{a} vs {b}");
        }
    }
}

#[test]
fn what_cannot_be_added_is_refused_by_name() {
    let model = two_terrain_model();
    let mut rng = rand::rngs::StdRng::seed_from_u64(2);
    let new: Vec<PressureImage> = (0..10).map(|_| texture(&mut rng, 11, 0.35)).collect();
    let err = |r: Result<Model, ExtendError>| r.err().map(|e| e.to_string()).unwrap_or_default();
    // A name or an id the model has.
    let e = err(add_class(
        &model,
        info("wood", 30),
        &new,
        &[],
        Basis::Extend,
    ));
    assert!(e.contains("`wood`"), "{e}");
    let e = err(add_class(&model, info("mud", 9), &new, &[], Basis::Extend));
    assert!(e.contains("`carpet`"), "{e}");
    // Too few stances.
    let e = err(add_class(
        &model,
        info("mud", 20),
        &new[..3],
        &[],
        Basis::Extend,
    ));
    assert!(e.contains("3 stances of `mud`"), "{e}");
    // A stance of another sensor size.
    let mut odd = new.clone();
    odd[4] = PressureImage::new(32, 32, 8, vec![10; 32 * 32]);
    let e = err(add_class(&model, info("mud", 20), &odd, &[], Basis::Refit));
    assert!(e.contains("stance 4") && e.contains("32x32"), "{e}");
    // A session stance of a class the model does not have.
    let e = err(add_class(
        &model,
        info("mud", 20),
        &new,
        &[(&new[0], 5)],
        Basis::Extend,
    ));
    assert!(e.contains("class 5"), "{e}");
    // A model without stored images (an older file).
    let mut old = model.clone();
    old.images = None;
    let e = err(add_class(&old, info("mud", 20), &new, &[], Basis::Extend));
    assert!(e.contains("retrain"), "{e}");
}
