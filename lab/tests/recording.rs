//! `presrs demo --candump`'s path: a lock-step run recorded to a candump log
//! (`closed_loop::run_to`), stamped as `presrs lab sim --log` stamps its own when no live recording
//! sets the wall clock, and ended by its stop flag.

use std::sync::atomic::AtomicBool;

use controller::ControllerConfig;
use presrs_lab::closed_loop::{DemoOutputs, LoopParams, run_to};
use protocol::MessageKind;
use sim::runner::{LOG_EPOCH_US, Track};

#[test]
fn a_recorded_run_logs_every_part_on_the_log_clock_and_stops_on_its_flag() {
    let model = presrs_lab::model::sim_model(1).unwrap();
    let cfg = ControllerConfig::default();
    let p = LoopParams::with_controller(&cfg, 8, 1);
    let ids = p.node.ids.clone();
    let mut log = Vec::new();
    let stop = AtomicBool::new(false);
    let out = DemoOutputs {
        live: None,
        log: Some(&mut log),
        paced: false,
        stop: &stop,
    };
    let r = run_to(&Track::default(), model.clone(), &p, |_| {}, out).unwrap();
    assert_eq!(r.rows.len(), 8);
    let records = protocol::candump::read_log(log.as_slice()).unwrap();
    assert!(records[0].stamped.t_us >= LOG_EPOCH_US, "the log clock");
    let kinds: Vec<MessageKind> = records
        .iter()
        .filter_map(|r| {
            let f = &r.stamped.frame;
            ids.lookup(f.raw_id(), f.is_extended()).map(|(k, _)| k)
        })
        .collect();
    // The simulator's, the node's and the controller's frames: every part on the bus.
    for k in [
        MessageKind::TactileFrame,
        MessageKind::TerrainClass,
        MessageKind::LegCommand,
    ] {
        assert!(kinds.contains(&k), "no {k:?} in the log");
    }
    assert_eq!(
        kinds
            .iter()
            .filter(|&&k| k == MessageKind::TerrainClass)
            .count(),
        8,
        "one TerrainClass per step"
    );

    // A stop flag set (SIGINT) ends the run before its steps.
    let stop = AtomicBool::new(true);
    let mut log = Vec::new();
    let out = DemoOutputs {
        live: None,
        log: Some(&mut log),
        paced: false,
        stop: &stop,
    };
    let r = run_to(&Track::default(), model, &p, |_| {}, out).unwrap();
    assert!(r.rows.len() < 8, "{} steps after the stop", r.rows.len());
}
