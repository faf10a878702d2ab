//! The load `presrs lab bench-node` puts on a node: feet at 100 Hz on a known schedule.
//!
//! [`Feet`] plays `n` feet on the foot clock: a step every 300 ms (150 ms stance), a CAN FD
//! tactile image every 10 ms per foot, the stance images being the simulator's skin images of
//! G2 stances on the four dynamic terrains ([`image_pool`]). The schedule is fixed (touchdowns
//! spread over the step period, 3.3 ms off the frame grid so that no frame ties two sample
//! times), so the benchmark knows which frame the node must pick for each step
//! ([`Sampled`]) and can time the decision from that frame's last segment. The simulated
//! hopper is not run: its physics would cost CPU in the benchmarking process and make the
//! step times differ between runs.
//!
//! [`measure`] plays the schedule in real time on one bus handle and matches the node's
//! TerrainClass on another; [`task_cpu_ns`] and [`memory_mb`] read a process's CPU time and
//! resident memory from `/proc`.

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use protocol::CanFrame;
use protocol::bus::CanBus;
use protocol::ids::IdConfig;
use protocol::messages::{self, FootContact, Message, TerrainClass, flags};
use protocol::tactile::{ImageRef, SegmentError, Segmenter, Variant};

mod beside;
mod feet;
mod measure;
mod proc_stats;
mod report;
mod run;

pub use beside::Beside;
pub use feet::{Feet, Sampled, image_pool};
pub use measure::{Tally, measure};
pub use proc_stats::{memory_mb, task_cpu_ns, task_slices};
pub use report::BenchReport;
pub use run::{BenchRun, NodeProcess, bench_inproc, bench_process};

/// Frame period of the PreSRS (100 Hz), µs.
pub const FRAME_US: u64 = 10_000;
/// Step period of the load, µs.
pub const STEP_US: u64 = 300_000;
/// Stance duration of the load, µs.
pub const STANCE_US: u64 = 150_000;
/// The paper's sample time after touchdown, µs.
pub const SAMPLE_US: u64 = 70_000;
/// Time played before measuring (the node's threads and caches settle), µs.
pub const WARMUP_US: u64 = 1_000_000;
/// Image side: the PreSRS's 44x44.
pub const SIDE: usize = 44;

/// Why the load could not be played.
#[derive(Debug, thiserror::Error)]
pub enum LoadError {
    /// No images to show.
    #[error("the load needs at least one 44x44 stance image")]
    NoImages,
    /// Feet outside 1..=MAX_FEET.
    #[error("{0} feet: allowed 1..={max}", max = protocol::ids::MAX_FEET)]
    Feet(u8),
    /// An image could not be segmented.
    #[error(transparent)]
    Segment(#[from] SegmentError),
    /// The listening bus handle failed.
    #[error("bus: {0}")]
    Bus(#[from] protocol::BusError),
    /// The listener thread panicked.
    #[error("the listener thread panicked")]
    Listener,
    /// The node process under test ended before the measurement.
    #[error("presrs node exited before the benchmark ({0})")]
    NodeExited(std::process::ExitStatus),
    /// The node process under test sent no NodeStatus.
    #[error("no NodeStatus from presrs node within {0:?} (is the interface up?)")]
    NoHeartbeat(std::time::Duration),
    /// Its state could not be read.
    #[error("the node process: {0}")]
    Process(#[from] std::io::Error),
    /// The node under test could not start in this process.
    #[error("the node: {0}")]
    Node(#[from] node::ServiceError),
    /// The model could not be handed to the node process.
    #[error("writing the model for presrs node: {0}")]
    Model(#[from] node::classifier::model::ModelError),
    /// A recording was asked for and could not start.
    #[error("--mcap {0}: the recording could not start (the log says why)")]
    Recording(String),
    /// The part beside the node could not start.
    #[error("the part beside the node: {0}")]
    Beside(#[from] record::RecordError),
    /// The kept unknown stances could not be written (`--keep-unknown`).
    #[error("--keep-unknown: {0}")]
    Keep(#[from] node::capture::CaptureError),
}

#[cfg(test)]
mod tests {
    use super::*;
    use measure::listen;
    use protocol::ids::MessageKind;
    use protocol::tactile::Reassembler;

    fn pool() -> Vec<(u8, Vec<u16>)> {
        (0..4u8)
            .map(|k| (k, vec![10 + k as u16; SIDE * SIDE]))
            .collect()
    }

    #[test]
    fn an_answer_heard_before_its_step_was_logged_still_counts() {
        let ids = IdConfig::default();
        let bus = protocol::bus::InProcBus::new();
        let (mut node, mut rx) = (bus.endpoint(), bus.endpoint());
        let (sent_tx, sent_rx) = mpsc::channel::<(Sampled, Instant, u64)>();
        let clock = bus.clock();
        let done = AtomicBool::new(false);
        let answer = |step: u16, terrain: u8| {
            let tc = TerrainClass {
                step,
                terrain,
                confidence_pct: 100.0,
                ..Default::default()
            };
            Message::TerrainClass(tc).to_frame(&ids, 0).unwrap()
        };
        let sampled = |step: u16| Sampled {
            foot: 0,
            step,
            t_us: WARMUP_US + SAMPLE_US + u64::from(step) * 300_000,
            terrain: 2,
        };
        let t = std::thread::scope(|s| {
            let (ids, done) = (&ids, &done);
            let listener = s.spawn(move || listen(&mut rx, ids, &sent_rx, done));
            // Step 1 logged first, as usual; step 2 answered before the player logged it.
            sent_tx
                .send((sampled(1), Instant::now(), clock.now_us()))
                .unwrap();
            std::thread::sleep(Duration::from_millis(20));
            node.send(&answer(1, 2)).unwrap();
            node.send(&answer(2, 3)).unwrap();
            std::thread::sleep(Duration::from_millis(30));
            sent_tx
                .send((sampled(2), Instant::now(), clock.now_us()))
                .unwrap();
            std::thread::sleep(Duration::from_millis(30));
            done.store(true, Ordering::Relaxed);
            listener.join().unwrap()
        })
        .unwrap();
        assert_eq!((t.decisions, t.classified), (2, 2));
        assert_eq!(t.heard_before_logged, 1);
        assert_eq!(t.correct, 1, "step 2 answered terrain 3 for a stance of 2");
        assert_eq!(t.latencies_us.len(), 1, "no latency for the early answer");
        // Answered 20 ms after it was logged, on the bus's clock too.
        assert_eq!(t.bus_latencies_us.len(), 1);
        assert!(
            (19_000.0..200_000.0).contains(&t.bus_latencies_us[0]),
            "{:?}",
            t.bus_latencies_us
        );
    }

    #[test]
    fn feet_play_100_hz_with_one_sampled_frame_per_stance_nearest_70_ms() {
        let ids = IdConfig::default();
        let mut feet = Feet::new(3, pool(), ids.clone()).unwrap();
        let mut frames = Vec::new();
        let mut sampled = Vec::new();
        let mut last = 0;
        while feet.next_us() < 2_000_000 {
            let t = feet.next_us();
            assert!(t >= last, "events in time order");
            last = t;
            if let Some(s) = feet.emit(&mut frames).unwrap() {
                sampled.push(s);
            }
        }
        let (mut contacts, mut images, mut touchdown) = ([0u32; 3], [0u32; 3], [None; 3]);
        let mut reasm = Reassembler::new(100_000);
        for f in &frames {
            match ids.lookup(f.raw_id(), f.is_extended()) {
                Some((MessageKind::FootContact, foot)) => {
                    let Ok(Some((_, Message::FootContact(c)))) = messages::decode(f, &ids) else {
                        panic!("a FootContact that does not decode");
                    };
                    contacts[foot as usize] += 1;
                    if c.stance {
                        touchdown[foot as usize] = Some(c.timestamp_us as u64);
                    }
                }
                Some((MessageKind::TactileFrame, foot)) => {
                    if let Some(img) = reasm.push(Variant::Fd, foot, f.data(), 0) {
                        assert_eq!((img.rows, img.cols), (SIDE as u8, SIDE as u8));
                        images[foot as usize] += 1;
                    }
                }
                other => panic!("unexpected frame {other:?}"),
            }
        }
        for foot in 0..3 {
            // 2 s at 100 Hz; touchdowns from 0.2 s every 0.3 s, each with a liftoff.
            assert!((199..=200).contains(&images[foot]), "{images:?}");
            let td0 = 200_000 + foot as u64 * STEP_US / 3 + 3_300;
            let tds: Vec<u64> = (0..)
                .map(|k| td0 + k * STEP_US)
                .take_while(|&t| t < 2_000_000)
                .collect();
            let lifts = tds.iter().filter(|&&t| t + STANCE_US < 2_000_000).count();
            assert_eq!(contacts[foot] as usize, tds.len() + lifts, "{contacts:?}");
            assert!(touchdown[foot].is_some());
            let steps: Vec<&Sampled> = sampled.iter().filter(|s| s.foot as usize == foot).collect();
            assert_eq!(steps.len(), tds.len());
            for (k, s) in steps.iter().enumerate() {
                assert_eq!(s.step as usize, k + 1);
                let td = 200_000 + foot as u64 * STEP_US / 3 + 3_300 + k as u64 * STEP_US;
                let off = (s.t_us as i64 - (td + SAMPLE_US) as i64).abs();
                assert!(
                    off <= FRAME_US as i64 / 2,
                    "foot {foot} step {k}: {off} µs off"
                );
                assert!(s.terrain < 4);
            }
        }
    }

    #[test]
    fn feet_refuse_no_images_and_too_many_feet() {
        let ids = IdConfig::default();
        assert!(matches!(
            Feet::new(3, Vec::new(), ids.clone()),
            Err(LoadError::NoImages)
        ));
        assert!(matches!(
            Feet::new(3, vec![(0, vec![0; 9])], ids.clone()),
            Err(LoadError::NoImages)
        ));
        assert!(matches!(
            Feet::new(0, pool(), ids.clone()),
            Err(LoadError::Feet(0))
        ));
        assert!(matches!(
            Feet::new(200, pool(), ids),
            Err(LoadError::Feet(200))
        ));
    }
}
