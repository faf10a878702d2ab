//! Faults in the closed loop cost no fall. A controller killed in mid-hop and
//! restarted takes the leg over from what the bus says (bumpless), on every gait; a node killed
//! and restarted; the bus silent for 0.3-2 s while the leg's own laws run it. A leg of motors,
//! which has no laws of its own: its bridge stalled, the bus silent briefly, the controller
//! restarted. The lock-step loop makes each run exact per seed.

use controller::ControllerConfig;
use presrs_lab::closed_loop::{LoopParams, run};
use protocol::TerrainCatalog;
use sim::runner::Track;

/// The dynamic terrains' model, trained once per test binary: every run here uses the same one
/// (training it per run was most of this file's time).
fn sim_model() -> node::classifier::Model {
    static MODEL: std::sync::OnceLock<node::classifier::Model> = std::sync::OnceLock::new();
    MODEL
        .get_or_init(|| presrs_lab::model::sim_model(1).unwrap())
        .clone()
}

fn track(terrain: &str) -> Track {
    let text = format!("diameter_m = 2.8\n[[segments]]\nterrain = \"{terrain}\"\nlength_m = 9.0\n");
    Track::from_toml(&text, "restart.toml", &TerrainCatalog::paper()).unwrap()
}

/// Runs 60 steps on `terrain` with the controller (or the node) dead from 6 s to 7 s; returns
/// the falls and the gaits of the last ten steps.
fn restart(terrain: &str, cfg: &ControllerConfig, seed: u64, node: bool) -> (u64, Vec<u8>) {
    let model = sim_model();
    let outage = Some((6_000_000, 1_000_000));
    let p = LoopParams {
        controller_restart: if node { None } else { outage },
        node_restart: if node { outage } else { None },
        ..LoopParams::with_controller(cfg, 60, seed)
    };
    let r = run(&track(terrain), model, &p, |_| {}).unwrap();
    assert_eq!(r.rows.len(), 60);
    let gaits = r.rows[50..].iter().map(|s| s.gait).collect();
    (r.falls(), gaits)
}

#[test]
fn a_restarted_controller_takes_over_every_gait_without_a_fall() {
    let cfg = ControllerConfig::default();
    // clay runs G1, grass G2, carpet G3 (the default terrain -> gait table).
    for (terrain, gait) in [("clay", 1u8), ("grass", 2), ("carpet", 3)] {
        for seed in 1..=2 {
            let (falls, gaits) = restart(terrain, &cfg, seed, false);
            assert_eq!(falls, 0, "{terrain} seed {seed}: fell after the restart");
            assert!(
                gaits.iter().all(|&g| g == gait),
                "{terrain} seed {seed}: gaits after the restart {gaits:?}"
            );
        }
    }
}

#[test]
fn a_restarted_node_costs_no_fall_on_any_gait() {
    let cfg = ControllerConfig::default();
    for (terrain, gait) in [("clay", 1u8), ("grass", 2), ("carpet", 3)] {
        let (falls, gaits) = restart(terrain, &cfg, 1, true);
        assert_eq!(falls, 0, "{terrain}: fell around the node's restart");
        // The safe gait while the node was away, the terrain's gait again after it.
        assert!(
            gaits.iter().all(|&g| g == gait),
            "{terrain}: gaits after the node's restart {gaits:?}"
        );
    }
}

/// The bus carries nothing for a while (an interface down): commands and reports are lost, the
/// simulated leg runs on its own laws. Measured before the controller re-listened after a gap
/// in the leg's reports: 21 of 45 such runs fell (1-5 times each; these four among them).
#[test]
fn a_silent_bus_costs_no_fall() {
    let model = sim_model();
    let cfg = ControllerConfig::default();
    for (at, len) in [
        (9_000_000, 2_000_000),
        (10_000_000, 1_000_000),
        (11_000_000, 1_000_000),
        (12_000_000, 300_000),
    ] {
        let p = LoopParams {
            link_down: Some((at, len)),
            ..LoopParams::with_controller(&cfg, 80, 1)
        };
        let r = run(&Track::default(), model.clone(), &p, |_| {}).unwrap();
        assert_eq!(
            r.falls(),
            0,
            "bus silent {len} us from {at} us: falls at {:?}",
            r.fall_times_us
        );
    }
}

/// A leg of motors behind its bridge (`presrs leg`) has no laws of its own: without commands
/// it is in its damped stop. Its bridge stalled for 100 ms (not run: what the vcan tests'
/// emulated kernel does to a process) or the bus silent for 30 ms, the controller must not
/// go quiet to take the leg over as it does for a leg that runs itself. Measured before it
/// knew the difference (40 steps, seed 1, five starting times): a 60-200 ms stall or silence
/// felled the MIT and moteus legs 6-10 times per run, ODrive 1-2; after, 0-2 per run
/// (the stall's own disturbance: the motors hold the last set point through it).
#[test]
fn a_stalled_bridge_or_a_short_silence_costs_a_leg_of_motors_no_cascade_of_falls() {
    let model = sim_model();
    let cfg = ControllerConfig::default();
    let mut total = 0;
    for kind in leg::DriverKind::ALL {
        for at in [5_000_000, 5_270_000, 6_050_000] {
            let stall = LoopParams {
                leg_stall: Some((at, 100_000)),
                leg: Some(leg::LegConfig::example(kind)),
                ..LoopParams::with_controller(&cfg, 40, 1)
            };
            let r = run(&Track::default(), model.clone(), &stall, |_| {}).unwrap();
            assert!(
                r.falls() <= 2,
                "{kind:?}, bridge stalled 100 ms from {at} us: falls at {:?}",
                r.fall_times_us
            );
            total += r.falls();
            let silent = LoopParams {
                link_down: Some((at, 30_000)),
                leg_stall: None,
                ..stall
            };
            let r = run(&Track::default(), model.clone(), &silent, |_| {}).unwrap();
            assert_eq!(
                r.falls(),
                0,
                "{kind:?}, bus silent 30 ms from {at} us: falls at {:?}",
                r.fall_times_us
            );
        }
    }
    // Measured: 4 (MIT 1, moteus 1, ODrive 2).
    assert!(total <= 6, "{total} falls after 9 stalls");
}

/// A controller killed beside a leg of motors: the leg is limp from its bridge's command
/// timeout until a controller commands it (the simulator sets the fallen hopper back on its
/// feet every 0.2 s meanwhile, and each counts as a fall). The restarted controller hears the
/// bridge's damped stop in LegStatus and commands at once. Measured before it did (it
/// listened for a step of a leg nobody ran; 40 steps, seed 1, the outages below): 1-10 falls
/// after the controller was back (MIT 6-10, moteus 6-10, ODrive 1-3); after, 0-1 per run.
#[test]
fn a_restarted_controller_takes_a_limp_leg_of_motors_back_at_once() {
    let model = sim_model();
    let cfg = ControllerConfig::default();
    let mut after_total = 0;
    for kind in leg::DriverKind::ALL {
        for (at, len) in [
            (6_000_000, 1_000_000),
            (6_000_000, 200_000),
            (7_300_000, 1_000_000),
            (8_100_000, 500_000),
        ] {
            let p = LoopParams {
                controller_restart: Some((at, len)),
                leg: Some(leg::LegConfig::example(kind)),
                ..LoopParams::with_controller(&cfg, 40, 1)
            };
            let r = run(&Track::default(), model.clone(), &p, |_| {}).unwrap();
            let after = r.fall_times_us.iter().filter(|&&t| t >= at + len).count();
            assert!(
                after <= 1,
                "{kind:?}, controller dead {len} us from {at} us: falls at {:?}",
                r.fall_times_us
            );
            after_total += after;
        }
    }
    // Measured: 9 of 12 runs fell once, 40-390 ms after the restart (9 in all).
    assert!(after_total <= 10, "{after_total} falls after 12 restarts");
}
