//! A session as a lab records it: the bus's frames of some steps on known terrains, how each
//! step is labelled, and (for scoring) each step's true touchdown.

use node::capture::Labelling;
use protocol::Stamped;
use protocol::terrain::Terrain;
use sim::foot_model::FootModel;
use sim::runner::{SimConfig, Track};

/// One recording of a session: a candump log's frames and its labels.
#[derive(Clone, Debug)]
pub struct Recording {
    /// The frames, on the log's clock.
    pub frames: Vec<Stamped>,
    /// How `capture` labels its steps.
    pub labels: Labelling,
    /// Its name (the capture manifest's `source`).
    pub source: String,
    /// Each step's foot, true touchdown (the log's clock, µs) and terrain.
    pub truth: Vec<(u8, u64, Terrain)>,
}

/// A session: one or more recordings (the simulator records each terrain on its own track, as
/// a lab records a run per terrain).
#[derive(Clone, Debug, Default)]
pub struct Session {
    /// Its recordings.
    pub recordings: Vec<Recording>,
}

/// A session of the simulated hopper wearing `foot`: `steps` stances on each of `terrains`,
/// each terrain its own run at G2, named `{name}-{terrain}`.
pub fn simulated(
    foot: &FootModel,
    terrains: &[Terrain],
    steps: usize,
    seed: u64,
    name: &str,
) -> Result<Session, sim::terrain::CannotSimulate> {
    let mut s = Session::default();
    for (k, &terrain) in terrains.iter().enumerate() {
        let cfg = SimConfig {
            track: Track {
                segments: vec![sim::runner::Segment::new(terrain, 10.0)?],
                ..Track::default()
            },
            foot: foot.clone(),
            ..SimConfig::default()
        };
        let mut frames = Vec::new();
        let seed = seed.wrapping_mul(1_000).wrapping_add(k as u64);
        let truth = sim::runner::record_steps(cfg, seed, steps, &mut |st: Stamped| frames.push(st));
        s.recordings.push(Recording {
            frames,
            labels: Labelling::All(terrain),
            source: format!("{name}-{}", terrain.name()),
            truth: truth
                .iter()
                .map(|t| (t.foot, t.touchdown_us, t.terrain))
                .collect(),
        });
    }
    Ok(s)
}
