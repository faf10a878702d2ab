//! The node's stance pipeline on the simulated robot's traffic: one TerrainClass per step.

use node::{NodeConfig, StancePipeline};
use protocol::Stamped;
use protocol::messages::flags;
use sim::runner::{SimConfig, SimRobot};

#[test]
fn exactly_one_terrain_class_per_step_despite_switch_bounce() {
    let mut robot = SimRobot::new(SimConfig::default(), 3);
    let mut p = StancePipeline::new(NodeConfig::default(), None);
    let mut decided = Vec::new();
    let mut t = 0u64;
    while t < 5_000_000 {
        t += 1000;
        let mut frames = Vec::new();
        robot.advance_to(t, &mut |f| frames.push(f));
        for frame in frames {
            p.on_frame(&Stamped { t_us: t, frame }, &mut |foot, tc| {
                decided.push((foot, tc))
            });
        }
    }
    let steps = robot.steps.len();
    assert!(steps > 10, "the hopper made {steps} steps in 5 s");
    // The last touchdown may still be undecided at the cut.
    assert!(
        decided.len() == steps || decided.len() + 1 == steps,
        "{} decisions for {steps} steps",
        decided.len()
    );
    for (i, (_, tc)) in decided.iter().enumerate() {
        assert_eq!(tc.step as usize, i + 1, "step numbers run on");
        // Without a model every step reports "no sample" and unknown terrain.
        assert_ne!(tc.flags & flags::NO_SAMPLE, 0);
        assert_eq!(tc.terrain, protocol::messages::TERRAIN_UNKNOWN);
    }
    assert_eq!(
        p.counters.steps as usize,
        decided.len() + (steps - decided.len())
    );
}
