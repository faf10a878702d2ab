//! Issue 5's per-gait target on a sample large enough to judge it: a model trained on G2 stances
//! only classifies the steps of G1, G2 and G3 (the paper's Table 5: one classifier across
//! gaits, 98.6-99.3%). The vcan suite runs the same model and gaits as processes on real
//! SocketCAN, but 35-46 steps a gait is all the VM's time allows, and one such run cannot tell 95%
//! from 97% (one wrong step more or less decides); the lock-step loop here is exact per seed and
//! runs 300 steps a gait in seconds.

use node::classifier::train::TrainOptions;
use presrs_lab::closed_loop::{LoopParams, run};
use sim::dataset::{Kind, Options, generate};
use sim::runner::Track;

/// The vcan suite's model (tests/vcan/run.sh): 60 G2 stances per terrain, 45 used and 30 of
/// them trained, load-normalised, the foot's crop; its rejection calibrated on another run of
/// the same foot (here a second dataset, seed 22, as run.sh's is a second `presrs lab sim`).
fn g2_model() -> node::classifier::Model {
    let set = |seed: u64, n: usize| {
        let samples = generate(&Options {
            kind: Kind::Dynamic,
            n: Some(n),
            gait: controller::Gait::g2(),
            damage_pct: 0.0,
            sensor: sim::DEFAULT_SENSOR,
            seed,
        });
        presrs_lab::simdata::training_set(samples, &Kind::Dynamic.terrains())
    };
    let opts = TrainOptions {
        per_class: 45,
        train: 30,
        normalize_load: true,
        crop: "0,3,6,0".parse().unwrap(),
        seed: 21,
        ..Default::default()
    };
    let cal = set(22, 20);
    let names = ["simulator run, seed 22".to_string()];
    match set(21, 60).train_calibrated(&opts, Some((&cal, &names))) {
        Ok(t) => t.model,
        Err(e) => panic!("training the G2 model: {e}"),
    }
}

#[test]
fn a_g2_model_classifies_95_percent_of_every_gaits_steps() {
    let model = g2_model();
    let mut report = Vec::new();
    for gait in 1..=3u8 {
        let p = LoopParams {
            fixed_gait: Some(gait),
            controller: None,
            ..LoopParams::with_controller(&Default::default(), 300, 5)
        };
        let r = match run(&Track::default(), model.clone(), &p, |_| {}) {
            Ok(r) => r,
            Err(e) => panic!("G{gait}: {e}"),
        };
        assert_eq!(r.falls(), 0, "G{gait} fell");
        let right = r.rows.iter().filter(|s| s.is_correct()).count();
        report.push((gait, right, r.rows.len()));
    }
    eprintln!("G2 model, (gait, right, steps), seed 5: {report:?}");
    for (gait, right, all) in report {
        assert!(all >= 300, "G{gait}: {all} steps");
        assert!(
            right as f64 >= 0.95 * all as f64,
            "G{gait}: {right}/{all} steps right"
        );
    }
}
