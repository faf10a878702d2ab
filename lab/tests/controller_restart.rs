//! Issue 28: a controller killed in mid-hop and restarted takes the leg over from what the bus
//! says (bumpless), on every gait, without a fall; the lock-step loop makes it exact per seed.

use controller::ControllerConfig;
use presrs_lab::closed_loop::{LoopParams, run};
use protocol::TerrainCatalog;
use sim::runner::Track;

fn track(terrain: &str) -> Track {
    let text = format!("diameter_m = 2.8\n[[segments]]\nterrain = \"{terrain}\"\nlength_m = 9.0\n");
    Track::from_toml(&text, "restart.toml", &TerrainCatalog::paper()).unwrap()
}

/// Runs 60 steps on `terrain` with the controller dead from 6 s to 7 s; returns the falls and
/// the gaits of the last ten steps.
fn restart(terrain: &str, cfg: &ControllerConfig, seed: u64) -> (u64, Vec<u8>) {
    let model = presrs_lab::model::sim_model(1).unwrap();
    let p = LoopParams {
        controller_restart: Some((6_000_000, 1_000_000)),
        ..LoopParams::with_controller(cfg, 60, seed)
    };
    let r = run(&track(terrain), model, &p, |_| {}).unwrap();
    assert_eq!(r.rows.len(), 60);
    let gaits = r.rows[50..].iter().map(|s| s.gait).collect();
    (r.falls, gaits)
}

#[test]
fn a_restarted_controller_takes_over_every_gait_without_a_fall() {
    let cfg = ControllerConfig::default();
    // clay runs G1, grass G2, carpet G3 (the default terrain -> gait table).
    for (terrain, gait) in [("clay", 1u8), ("grass", 2), ("carpet", 3)] {
        for seed in 1..=2 {
            let (falls, gaits) = restart(terrain, &cfg, seed);
            assert_eq!(falls, 0, "{terrain} seed {seed}: fell after the restart");
            assert!(
                gaits.iter().all(|&g| g == gait),
                "{terrain} seed {seed}: gaits after the restart {gaits:?}"
            );
        }
    }
}
