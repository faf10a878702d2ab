//! The simulated hopper under the controller crate's `Controller`, with a perfect classifier in
//! place of the node: what the controller and the simulator promise each other when things go
//! wrong (a fall, a node outage), judged in simulated time only.

use controller::{Controller, ControllerConfig};
use presrs_sim::runner::{Segment, SimConfig, SimRobot, Track};
use protocol::messages::{self, LegCommand, Message, NodeStatus, TerrainClass};
use protocol::terrain::TerrainCatalog;

/// What the harness does besides passing frames between robot and controller.
#[derive(Default)]
struct Script {
    /// The node is silent (no heartbeat, no TerrainClass) in these intervals, µs.
    outages: Vec<(u64, u64)>,
    /// LegCommands carry this touchdown angle (rad) in this interval, µs: a forced fall.
    bad_angle: Option<(u64, u64, f64)>,
}

struct Run {
    falls: Vec<u64>,
    touchdowns: Vec<u64>,
}

/// Runs robot and controller in lock-step (1 ms) for `until_us` of simulated time; after every
/// touchdown the "node" names the step's true terrain.
fn run(track: Track, script: &Script, until_us: u64) -> Run {
    let cfg = SimConfig {
        track,
        ..Default::default()
    };
    let ids = cfg.ids.clone();
    let mut robot = SimRobot::new(cfg, 1);
    let ccfg = ControllerConfig::default();
    let mut ctrl = Controller::new(ccfg.clone(), &ccfg.catalog().unwrap());
    let (mut sent, mut out) = (Vec::new(), Vec::new());
    let mut steps = 0;
    let mut t_us = 0;
    while t_us < until_us {
        t_us += 1000;
        robot.advance_to(t_us, &mut sent);
        for f in sent.drain(..) {
            if let Ok(Some((foot, m))) = messages::decode(&f, &ids) {
                ctrl.on_message(foot, &m, t_us, &mut out);
            }
        }
        let node_up = !script.outages.iter().any(|&(a, b)| (a..b).contains(&t_us));
        if node_up && t_us % 100_000 == 0 {
            let hb = Message::NodeStatus(NodeStatus::default());
            ctrl.on_message(0, &hb, t_us, &mut out);
        }
        if robot.steps.len() > steps {
            steps = robot.steps.len();
            if node_up {
                let tc = Message::TerrainClass(TerrainClass {
                    step: steps as u16,
                    terrain: robot.steps[steps - 1].terrain.id(),
                    confidence_pct: 95.0,
                    ..Default::default()
                });
                ctrl.on_message(0, &tc, t_us, &mut out);
            }
        }
        ctrl.tick(t_us, &mut out);
        for m in out.drain(..) {
            let m = match (m, script.bad_angle) {
                (Message::LegCommand(lc), Some((a, b, angle))) if (a..b).contains(&t_us) => {
                    Message::LegCommand(LegCommand {
                        touchdown_angle_rad: angle,
                        ..lc
                    })
                }
                (m, _) => m,
            };
            if let Some(f) = m.to_frame(&ids, 0) {
                robot.on_frame(&f);
            }
        }
    }
    Run {
        falls: robot.falls.clone(),
        touchdowns: robot.steps.iter().map(|s| s.touchdown_us).collect(),
    }
}

fn one_terrain(name: &str) -> Track {
    let t = TerrainCatalog::paper().by_name(name).unwrap();
    Track {
        diameter_m: 30.0,
        segments: vec![Segment::new(t, 100.0).unwrap()],
    }
}

/// Relaunched after a fall, the hopper runs the controller's gait again. It used to be
/// relaunched at the speed of the simulator's start gait (G2): under G3 (wood) or G1 (clay) it
/// then fell every 0.35-0.48 s for the rest of the run.
#[test]
fn after_a_forced_fall_the_hopper_steps_on_in_the_controllers_gait() {
    for terrain in ["wood", "clay"] {
        let script = Script {
            bad_angle: Some((3_000_000, 3_300_000, 1.2)),
            ..Default::default()
        };
        let r = run(one_terrain(terrain), &script, 8_000_000);
        assert!(
            r.falls.first().is_some_and(|&t| t >= 3_000_000),
            "{terrain}: the forced fall did not happen: {:?}",
            r.falls
        );
        // A relaunch inside the bad commands' window may fall once more; after it, none.
        assert!(
            r.falls.iter().all(|&t| t < 4_000_000),
            "{terrain}: falls at {:?} µs",
            r.falls
        );
        let after = r.touchdowns.iter().filter(|&&t| t > 4_000_000).count();
        assert!(after >= 10, "{terrain}: {after} steps in the 4 s after");
    }
}

/// A node that stops for 2 s sends the controller to the safe gait (the config's) and, when it is back,
/// to each terrain's gait again: both switches keep the hopper on its feet. Before eq. (5)
/// walked beta_des to a new gait's in steps, 2 of 40 outages in-process were followed by a
/// fall (the new gait's touchdown angle at the old gait's speed).
#[test]
fn node_outages_switch_gaits_without_a_fall() {
    for kill_s in [6.0, 12.42, 16.13, 21.0] {
        let kill = (kill_s * 1e6) as u64;
        let script = Script {
            outages: vec![(kill, kill + 2_000_000)],
            ..Default::default()
        };
        let r = run(Track::default(), &script, kill + 6_000_000);
        assert!(r.touchdowns.len() > 20, "{} steps", r.touchdowns.len());
        assert_eq!(
            r.falls,
            Vec::<u64>::new(),
            "node lost at {kill_s} s: falls (µs)"
        );
    }
}
