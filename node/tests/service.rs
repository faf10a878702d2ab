//! The node service with a small fake foot (no simulator): one decision per step from the image
//! nearest the sample time, a lost frame decided by `tick` at the deadline, "no sample" at
//! liftoff, the heartbeat at `status_hz`, model checks, and the threaded node on a bus.

use std::time::{Duration, Instant};

use presrs_node::classifier::train::{Labelled, TrainOptions, train};
use presrs_node::classifier::{ClassInfo, Crop, Model, PressureImage};
use presrs_node::{NodeConfig, NodeService, Output, ServiceError};
use protocol::bus::{BusSource, CanBus, InProcBus};
use protocol::messages::{self, FootContact, Message, NodeState, TerrainClass, flags};
use protocol::tactile::{ImageRef, Segmenter, Variant};
use protocol::{CanFrame, IdConfig, Stamped, TerrainCatalog};
use rand::{Rng, SeedableRng};

/// 44x44 texture: `period` sets the contact-patch spacing (the terrain), with random offset,
/// load and noise.
fn texture(rng: &mut impl Rng, period: usize) -> Vec<u16> {
    let (dy, dx) = (rng.random_range(0..period), rng.random_range(0..period));
    let load = rng.random_range(0.8..1.2);
    (0..44 * 44)
        .map(|i| {
            let (r, c) = (i / 44 + dy, i % 44 + dx);
            let on = r % period < period / 2 && c % period < period / 2;
            let v: f64 = if on { 150.0 * load } else { 10.0 * load } + rng.random_range(-8.0..8.0);
            v.clamp(0.0, 255.0) as u16
        })
        .collect()
}

const PERIODS: [usize; 3] = [4, 7, 11];
const NAMES: [&str; 3] = ["wood", "carpet", "grass"];

fn model() -> Model {
    model_of(&[0, 1, 2])
}

/// One foot that steps on a terrain: FootContact every 5 ms, a tactile image every 10 ms
/// (captured 5 ms into each period, received 1 ms later), on the foot's own clock.
struct FakeFoot {
    ids: IdConfig,
    seg: Segmenter,
    rng: rand::rngs::StdRng,
    seq: u8,
    /// Rows and columns of its images.
    size: usize,
    /// Bits per pixel of its images.
    bits: u8,
}

impl FakeFoot {
    fn new() -> Self {
        let ids = IdConfig::default();
        Self {
            seg: Segmenter::new(Variant::Fd, ids.clone()),
            ids,
            rng: rand::rngs::StdRng::seed_from_u64(7),
            seq: 0,
            size: 44,
            bits: 8,
        }
    }

    /// The frames of a stance from `touchdown_us` lasting `stance_ms`, as (receive time,
    /// frame); `keep_image(dt_ms)` drops images by their time after touchdown.
    fn stance(
        &mut self,
        terrain: usize,
        touchdown_us: u64,
        stance_ms: u64,
        keep_image: impl Fn(u64) -> bool,
    ) -> Vec<Stamped> {
        self.step(touchdown_us, stance_ms, |ms, rng| {
            (ms < stance_ms && keep_image(ms)).then(|| texture(rng, PERIODS[terrain]))
        })
    }

    /// A stance from `touchdown_us` lasting `stance_ms` and 60 ms of flight after it, with
    /// the image `image(ms after touchdown)` gives (none: no image then).
    fn step(
        &mut self,
        touchdown_us: u64,
        stance_ms: u64,
        image: impl Fn(u64, &mut rand::rngs::StdRng) -> Option<Vec<u16>>,
    ) -> Vec<Stamped> {
        let mut out = Vec::new();
        let contact = |stance: bool, t: u64, seq: u8| {
            let m = Message::FootContact(FootContact {
                stance,
                seq,
                timestamp_us: t as u32,
            });
            Stamped {
                t_us: t + 200,
                frame: m.to_frame(&self.ids, 0).unwrap(),
            }
        };
        for ms in (0..stance_ms + 60).step_by(5) {
            let t = touchdown_us + ms * 1000;
            self.seq = self.seq.wrapping_add(1);
            out.push(contact(ms < stance_ms, t, self.seq));
            if ms % 10 == 5
                && let Some(px) = image(ms, &mut self.rng)
            {
                let img = ImageRef {
                    rows: self.size,
                    cols: self.size,
                    bits: self.bits,
                    timestamp_us: t as u32,
                    pixels: &px,
                };
                self.seg
                    .frames(0, self.seq, &img, &mut |f: CanFrame| {
                        out.push(Stamped {
                            t_us: t + 1000,
                            frame: f,
                        })
                    })
                    .unwrap();
            }
        }
        out.sort_by_key(|s| s.t_us);
        out
    }
}

/// Drives the node in lock-step over `frames`, ticking every millisecond; returns each
/// output with the time it came.
fn lock_step(node: &mut NodeService, frames: &[Stamped], end_us: u64) -> Vec<(u64, Output)> {
    let mut said = Vec::new();
    let mut i = 0;
    let start = frames.first().map_or(0, |f| f.t_us);
    for t in (start..end_us).step_by(1000) {
        while i < frames.len() && frames[i].t_us <= t {
            node.process(&frames[i], &mut |o| said.push((t, o)));
            i += 1;
        }
        node.tick(t, &mut |o| said.push((t, o)));
    }
    said
}

/// `frames` as a candump log's records (interface can0).
fn as_log(frames: &[Stamped]) -> Vec<protocol::candump::LogRecord> {
    frames
        .iter()
        .map(|st| protocol::candump::LogRecord {
            iface: "can0".into(),
            stamped: *st,
        })
        .collect()
}

fn classes(said: &[(u64, Output)]) -> Vec<(u64, TerrainClass)> {
    said.iter()
        .filter_map(|&(t, o)| match o {
            Output::Class { class, .. } => Some((t, class)),
            Output::Status(_) => None,
        })
        .collect()
}

#[test]
fn one_decision_per_step_from_the_image_nearest_the_sample_time() {
    let mut node = NodeService::new(NodeConfig::default(), model()).unwrap();
    // The live step table (`presrs node --csv`) gets every decision, off the node's thread.
    let dir = std::env::temp_dir().join(format!("presrs-service-steps-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let table =
        presrs_node::step_table::StepLog::create(&dir.join("s.csv"), TerrainCatalog::paper())
            .unwrap();
    node.set_step_log(table.sender().unwrap());
    let mut foot = FakeFoot::new();
    let mut frames = Vec::new();
    let terrains = [0, 1, 2, 2, 0, 1];
    for (k, &terrain) in terrains.iter().enumerate() {
        frames.extend(foot.stance(terrain, 1_000_000 + k as u64 * 400_000, 200, |_| true));
    }
    let said = lock_step(&mut node, &frames, 1_000_000 + 7 * 400_000);
    drop(node);
    assert_eq!(table.finish().unwrap(), (terrains.len() as u64, 0));
    let csv = std::fs::read_to_string(dir.join("s.csv")).unwrap();
    for (k, line) in csv.lines().skip(1).enumerate() {
        let f: Vec<&str> = line.split(',').collect();
        let td = protocol::candump::parse_seconds(f[2]).unwrap();
        let want = 1_000_000 + k as u64 * 400_000;
        // The touchdown on the receiver's clock, within the switch's 5 ms report period.
        assert!(
            td.abs_diff(want) <= 5_000,
            "step {k}: touchdown {td} for {want}: {line}"
        );
        assert_eq!(f[4], NAMES[terrains[k]], "{line}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
    let got = classes(&said);
    assert_eq!(got.len(), terrains.len(), "{got:?}");
    let catalog = TerrainCatalog::paper();
    for (k, (&(t, tc), &terrain)) in got.iter().zip(&terrains).enumerate() {
        assert_eq!(tc.step as usize, k + 1);
        assert_eq!(
            catalog.describe(tc.terrain),
            NAMES[terrain],
            "step {k}: {tc:?}"
        );
        assert_eq!(tc.flags & flags::NO_SAMPLE, 0);
        // Images at 65 and 75 ms are equally near 70 ms: the first decides, on the frame
        // that completes it (received 1 ms after capture).
        let td = 1_000_000 + k as u64 * 400_000;
        assert_eq!(t - td, 66_200, "step {k} decided at {} µs", t - td);
    }
}

#[test]
fn the_deciding_frame_is_announced_and_warming_up_for_it_changes_no_decision() {
    use protocol::component::Component;
    // Robot time at the receiver's rate, and at a third of it (emulation): the receipt that
    // is announced follows the receiver's clock, not the foot's.
    for (multi_frame, slow) in [(false, 1), (true, 1), (false, 3), (true, 3)] {
        let rx = |t: u64| 1_000_000 + (t - 1_000_000) * slow;
        let cfg = NodeConfig {
            multi_frame,
            ..NodeConfig::default()
        };
        let mut foot = FakeFoot::new();
        let mut frames = Vec::new();
        let terrains = [0, 1, 2, 2, 0, 1];
        for (k, &terrain) in terrains.iter().enumerate() {
            frames.extend(foot.stance(terrain, 1_000_000 + k as u64 * 400_000, 200, |_| true));
        }
        for st in &mut frames {
            st.t_us = rx(st.t_us);
        }
        let end = rx(1_000_000 + 7 * 400_000);
        let plain = classes(&lock_step(
            &mut NodeService::new(cfg.clone(), model()).unwrap(),
            &frames,
            end,
        ));
        // The same stream, warming up whenever a deciding frame is announced, and noting what
        // was announced when each frame came.
        let mut node = NodeService::new(cfg, model()).unwrap();
        let (mut said, mut announced) = (Vec::new(), Vec::new());
        for st in &frames {
            if let Some(at) = node.expected_frame_us() {
                node.warm_up();
                announced.push((st.t_us, at));
            }
            node.process(st, &mut |o| said.push((st.t_us, o)));
            node.tick(st.t_us, &mut |o| said.push((st.t_us, o)));
        }
        let warmed = classes(&said);
        assert_eq!(warmed.len(), terrains.len(), "{multi_frame}: {warmed:?}");
        for (a, b) in warmed.iter().zip(&plain) {
            assert_eq!(a.1, b.1, "multi_frame {multi_frame}");
        }
        // Each step's deciding image was announced (its receive time, one frame period after
        // the image before it) before it came: 66 ms after touchdown single-frame, the image
        // at the window's end (received 106 ms after it) multi-frame.
        let dt = if multi_frame { 106_000 } else { 66_000 };
        for k in 0..terrains.len() as u64 {
            let at = rx(1_000_000 + k * 400_000 + dt);
            assert!(
                announced.iter().any(|&(t, a)| a == at && t < at),
                "multi_frame {multi_frame}, step {k}: {at} not announced before it came"
            );
        }
    }
}

#[test]
fn between_steps_no_frame_is_due_and_in_stance_the_deciding_image_is_announced_early() {
    use protocol::component::Component;
    let mut node = NodeService::new(NodeConfig::default(), model()).unwrap();
    let mut foot = FakeFoot::new();
    let (first, second) = (1_000_000, 1_400_000);
    let mut frames = foot.stance(1, first, 200, |_| true);
    frames.extend(foot.stance(2, second, 200, |_| true));
    let (mut between, mut early) = (Vec::new(), Vec::new());
    for st in &frames {
        let next = node.expected_frame_us();
        // After the first step's decision, nothing is due until the next touchdown.
        if st.t_us > first + 100_000 && st.t_us < second {
            between.push(next);
        }
        // The image that decides the second step (66 ms after its touchdown) is known from
        // the stance's first image on: the runner batches the frames before it.
        if st.t_us > second + 6_000 && st.t_us < second + 30_000 {
            early.push(next);
        }
        node.process(st, &mut |_| {});
        node.tick(st.t_us, &mut |_| {});
    }
    assert!(
        !between.is_empty() && between.iter().all(|n| *n == Some(u64::MAX)),
        "{between:?}"
    );
    assert!(
        !early.is_empty() && early.iter().all(|n| *n == Some(second + 66_000)),
        "{early:?}"
    );
}

#[test]
fn a_frame_lost_after_the_best_one_is_decided_at_the_deadline_not_at_liftoff() {
    let mut node = NodeService::new(NodeConfig::default(), model()).unwrap();
    let mut foot = FakeFoot::new();
    // Images up to 45 ms only: 45 is the nearest to 70 that came. On the array's 10 ms grid
    // the last image that could be nearer is the one at 85; it would be here by 95 (one
    // period for its transfer). (Without the grid: 70 + 25 + 10 = 105.)
    let frames = foot.stance(1, 1_000_000, 250, |ms| ms <= 45);
    let said = lock_step(&mut node, &frames, 1_500_000);
    let got = classes(&said);
    assert_eq!(got.len(), 1, "{got:?}");
    let (t, tc) = got[0];
    assert_eq!(TerrainCatalog::paper().describe(tc.terrain), "carpet");
    let after_touchdown_ms = (t - 1_000_000) as f64 / 1000.0;
    assert!(
        (95.0..=97.0).contains(&after_touchdown_ms),
        "decided {after_touchdown_ms} ms after touchdown; liftoff is at 250"
    );
}

/// Images stop after 55 ms (the 65 and 75 ms ones and all after lost), FootContact goes on at
/// its 100 Hz (5 ms here): decided once the foot's clock shows that no nearer image can come
/// (the 75 ms one, nearer than 55, would have been here by 85), not at liftoff (200 ms).
#[test]
fn the_nearest_image_before_the_sample_time_is_decided_within_a_frame_period() {
    let mut node = NodeService::new(NodeConfig::default(), model()).unwrap();
    let mut foot = FakeFoot::new();
    let frames = foot.stance(2, 1_000_000, 200, |ms| ms <= 55);
    let got = classes(&lock_step(&mut node, &frames, 1_400_000));
    assert_eq!(got.len(), 1, "{got:?}");
    let (t, tc) = got[0];
    assert_eq!(TerrainCatalog::paper().describe(tc.terrain), "grass");
    let after_ms = (t - 1_000_000) as f64 / 1000.0;
    assert!(
        (85.0..=87.0).contains(&after_ms),
        "decided {after_ms} ms after touchdown"
    );
}

#[test]
fn a_stance_without_an_image_is_no_sample_at_liftoff() {
    let mut node = NodeService::new(NodeConfig::default(), model()).unwrap();
    let mut foot = FakeFoot::new();
    let frames = foot.stance(0, 1_000_000, 200, |_| false);
    let got = classes(&lock_step(&mut node, &frames, 1_400_000));
    assert_eq!(got.len(), 1, "{got:?}");
    let (_, tc) = got[0];
    assert_ne!(tc.flags & flags::NO_SAMPLE, 0);
    assert_eq!(tc.terrain, messages::TERRAIN_UNKNOWN);
    assert_eq!(
        tc.latency_us, 0,
        "no sampled frame: latency 0, as documented"
    );
    assert_eq!(node.counters().no_sample, 1);
}

/// A foot that sends no image in the stance but streams in flight: the frame sampled with the
/// liftoff edge (inside the 5 ms debounce, so the node is still in stance) is not the stance's
/// (it was classified before).
#[test]
fn an_image_sampled_after_the_liftoff_edge_is_not_the_stances() {
    let mut node = NodeService::new(NodeConfig::default(), model()).unwrap();
    let mut foot = FakeFoot::new();
    // FootContact every 5 ms: the one at 205 ms is the first to say flight.
    let frames = foot.step(1_000_000, 203, |ms, rng| {
        (ms >= 205).then(|| texture(rng, PERIODS[1]))
    });
    let got = classes(&lock_step(&mut node, &frames, 1_400_000));
    assert_eq!(got.len(), 1, "{got:?}");
    let tc = got[0].1;
    assert_ne!(tc.flags & flags::NO_SAMPLE, 0, "{tc:?}");
    assert_eq!(tc.terrain, messages::TERRAIN_UNKNOWN);
}

/// A 32x32 foot on a 44x44 model: every step unclassified, and the node says why once (log)
/// and in every NodeStatus while it lasts (state 5), not "running" with silent no-samples.
#[test]
fn a_foot_of_another_image_size_is_reported_not_silently_unclassified() {
    let mut node = NodeService::new(NodeConfig::default(), model()).unwrap();
    assert_eq!(node.status(false).state, NodeState::Running);
    let mut foot = FakeFoot::new();
    foot.size = 32;
    let frames = foot.step(1_000_000, 200, |ms, _| {
        (ms < 200).then(|| vec![90u16; 32 * 32])
    });
    let got = classes(&lock_step(&mut node, &frames, 1_400_000));
    assert_eq!(got.len(), 1, "{got:?}");
    assert_ne!(got[0].1.flags & flags::NO_SAMPLE, 0);
    assert!(node.counters().wrong_size >= 19, "{:?}", node.counters());
    assert_eq!(node.status(false).state, NodeState::WrongImageSize);
    // The foot's images fit again: running.
    foot.size = 44;
    let frames = foot.stance(0, 2_000_000, 200, |_| true);
    let got = classes(&lock_step(&mut node, &frames, 2_400_000));
    assert_eq!(got.len(), 1);
    assert_eq!(node.status(false).state, NodeState::Running);
    // 16-bit images of the right size on a model trained on 8-bit ones: the same.
    foot.bits = 16;
    let frames = foot.stance(0, 3_000_000, 200, |_| true);
    let got = classes(&lock_step(&mut node, &frames, 3_400_000));
    assert_ne!(got[0].1.flags & flags::NO_SAMPLE, 0, "{got:?}");
    assert_eq!(node.status(false).state, NodeState::WrongImageSize);
}

/// A stance whose images show no foot on the ground (a blank array, or a few noisy sensels):
/// flagged NO_CONTACT, terrain unknown, and counted apart from "no sample".
#[test]
fn a_stance_image_without_contact_is_no_contact_not_a_terrain() {
    for multi_frame in [false, true] {
        let cfg = NodeConfig {
            multi_frame,
            ..NodeConfig::default()
        };
        let mut node = NodeService::new(cfg, model()).unwrap();
        let mut foot = FakeFoot::new();
        let frames = foot.step(1_000_000, 200, |ms, _| {
            let mut px = vec![0u16; 44 * 44];
            px[(ms as usize * 7) % (44 * 44)] = 9;
            (ms < 200).then_some(px)
        });
        let got = classes(&lock_step(&mut node, &frames, 1_400_000));
        assert_eq!(got.len(), 1, "{got:?}");
        let tc = got[0].1;
        assert_eq!(tc.flags & flags::NO_SAMPLE, 0, "{tc:?}");
        assert_ne!(tc.flags & flags::NO_CONTACT, 0, "{tc:?}");
        assert_eq!(
            (tc.terrain, tc.confidence_pct),
            (messages::TERRAIN_UNKNOWN, 0.0)
        );
        let c = node.counters();
        assert_eq!(
            (c.no_contact, c.no_sample, c.classified),
            (1, 0, 0),
            "multi {multi_frame}"
        );
    }
}

#[test]
fn the_heartbeat_comes_at_status_hz_with_the_model_id() {
    let cfg = NodeConfig {
        status_hz: 20.0,
        ..NodeConfig::default()
    };
    let m = model();
    let id = m.id();
    let mut node = NodeService::new(cfg, m).unwrap();
    let said = lock_step(&mut node, &[], 1_000_000);
    let status: Vec<_> = said
        .iter()
        .filter_map(|&(t, o)| match o {
            Output::Status(s) => Some((t, s)),
            _ => None,
        })
        .collect();
    assert_eq!(status.len(), 20);
    for (k, (t, s)) in status.iter().enumerate() {
        assert_eq!(*t, k as u64 * 50_000);
        assert_eq!(s.heartbeat as usize, k + 1);
        assert_eq!(s.state, NodeState::Running);
        assert_eq!(s.model_id, id as u16);
    }
    // The heartbeat survives a clock that jumps back (another bus clock).
    let mut again = Vec::new();
    node.tick(10_000, &mut again);
    assert!(matches!(again[..], [Output::Status(_)]), "{again:?}");
}

#[test]
fn a_model_outside_the_catalog_is_refused_and_a_bad_reload_keeps_the_model() {
    let mut m = model();
    m.classes[2].terrain_id = 20;
    let err = NodeService::new(NodeConfig::default(), m).err().unwrap();
    assert!(matches!(err, ServiceError::Mismatch(_)), "{err}");
    assert!(err.to_string().contains("terrains file"), "{err}");

    let m = model();
    let id = m.id();
    let mut node = NodeService::new(NodeConfig::default(), m).unwrap();
    let dir = std::env::temp_dir().join(format!("presrs-service-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bad = dir.join("bad.json");
    std::fs::write(&bad, "{ not a model").unwrap();
    let err = node.reload_model(&bad).err().unwrap();
    assert!(err.to_string().contains("bad.json"), "{err}");
    assert_eq!(node.model().map(Model::id), Some(id));
}

/// The same node on its own threads on a bus: a step's frames in, its TerrainClass out; a
/// reload through the handle; a last NodeStatus that says Stopping.
#[test]
fn started_on_a_bus_it_answers_each_step_and_says_when_it_stops() {
    for threads in [
        presrs_node::NodeThreads::One,
        presrs_node::NodeThreads::Three,
    ] {
        started_on(threads);
    }
}

fn started_on(threads: presrs_node::NodeThreads) {
    let m = model();
    let dir = std::env::temp_dir().join(format!(
        "presrs-service-bus-{}-{threads:?}",
        std::process::id()
    ));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("model.json");
    m.save(&path).unwrap();
    let bus = InProcBus::new();
    let mut robot = bus.endpoint();
    let running = NodeService::new(NodeConfig::default(), m)
        .unwrap()
        .start_on(BusSource::InProc(bus.clone()), None, threads)
        .unwrap();
    let ids = IdConfig::default();
    let mut foot = FakeFoot::new();
    // Waits (in wall time, generously: this checks function, not speed) for a message.
    let wait_for = |robot: &mut dyn CanBus, want: &dyn Fn(&Message) -> bool| {
        let end = Instant::now() + Duration::from_secs(20);
        while Instant::now() < end {
            if let Ok(Some(st)) = robot.recv(Duration::from_millis(10))
                && let Ok(Some((_, m))) = messages::decode(&st.frame, &ids)
                && want(&m)
            {
                return Some(m);
            }
        }
        None
    };
    let is_status = |m: &Message| matches!(m, Message::NodeStatus(_));
    assert!(wait_for(&mut robot, &is_status).is_some(), "no heartbeat");
    for st in foot.stance(2, 1_000_000, 200, |_| true) {
        robot.send(&st.frame).unwrap();
    }
    let class = wait_for(&mut robot, &|m| matches!(m, Message::TerrainClass(_)));
    let Some(Message::TerrainClass(tc)) = class else {
        panic!("no TerrainClass for the step");
    };
    assert_eq!(TerrainCatalog::paper().describe(tc.terrain), "grass");
    // A texture the model was not trained on: unknown, and counted so.
    let novel = foot.step(1_400_000, 200, |ms, rng| {
        (ms < 200).then(|| texture(rng, 2))
    });
    for st in novel {
        robot.send(&st.frame).unwrap();
    }
    let class = wait_for(&mut robot, &|m| matches!(m, Message::TerrainClass(_)));
    let Some(Message::TerrainClass(tc)) = class else {
        panic!("no TerrainClass for the second step");
    };
    assert_eq!(tc.terrain, messages::TERRAIN_UNKNOWN, "{tc:?}");
    assert!(running.reload_model(&dir.join("missing.json")).is_err());
    assert_eq!(running.reload_model(&path).unwrap(), model().id());
    assert!(running.is_running());
    let stats = running.stop();
    assert_eq!(
        (stats.steps, stats.classified, stats.unknown),
        (2, 2, 1),
        "{threads:?}: {stats:?}"
    );
    assert!(stats.tx_frames >= 2);
    // Every frame the pipeline took is timed; the two steps' last frames are the decided ones.
    let st = stats.stages;
    assert!(
        st.frames > 0 && st.frames <= stats.rx_frames,
        "{threads:?}: {st:?}, {} frames read",
        stats.rx_frames
    );
    assert_eq!(st.decided, 2, "{threads:?}: {st:?}");
    assert!(st.decided_ns > 0 && st.frame_ns >= st.decided_ns, "{st:?}");
    let mut last = None;
    while let Ok(Some(st)) = robot.recv(Duration::from_millis(50)) {
        if let Ok(Some((_, Message::NodeStatus(s)))) = messages::decode(&st.frame, &ids) {
            last = Some(s.state);
        }
    }
    assert_eq!(last, Some(NodeState::Stopping));
}

/// The same node as a bus component on the one runner, on one thread: a step in, its
/// TerrainClass out, heartbeats on the bus's clock, a last NodeStatus that says Stopping.
#[test]
fn as_a_component_on_the_one_runner_it_answers_each_step() {
    use protocol::component::{self, RunOptions};
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};
    let bus = InProcBus::new();
    let mut robot = bus.endpoint();
    let stop = Arc::new(AtomicBool::new(false));
    let (b, s) = (bus.clone(), stop.clone());
    let runner = std::thread::spawn(move || {
        let mut node = NodeService::new(NodeConfig::default(), model()).unwrap();
        let source = BusSource::InProc(b);
        let opts = RunOptions {
            clock: Some(source.clock()),
            ..RunOptions::default()
        };
        let stats = component::run(&mut node, &source, &opts, &s);
        (stats, node.counters())
    });
    let ids = IdConfig::default();
    let mut said = Vec::new();
    let mut listen = |robot: &mut dyn CanBus, until: &dyn Fn(&[Message]) -> bool| {
        let end = Instant::now() + Duration::from_secs(20);
        while Instant::now() < end && !until(&said) {
            if let Ok(Some(st)) = robot.recv(Duration::from_millis(10))
                && let Ok(Some((_, m))) = messages::decode(&st.frame, &ids)
            {
                said.push(m);
            }
        }
        said.clone()
    };
    let heard = listen(&mut robot, &|m| {
        m.iter().any(|m| matches!(m, Message::NodeStatus(_)))
    });
    assert!(!heard.is_empty(), "no heartbeat");
    let mut foot = FakeFoot::new();
    for st in foot.stance(2, 1_000_000, 200, |_| true) {
        robot.send(&st.frame).unwrap();
    }
    let heard = listen(&mut robot, &|m| {
        m.iter().any(|m| matches!(m, Message::TerrainClass(_)))
    });
    let tc = heard.iter().find_map(|m| match m {
        Message::TerrainClass(tc) => Some(*tc),
        _ => None,
    });
    let tc = tc.expect("no TerrainClass for the step");
    assert_eq!(TerrainCatalog::paper().describe(tc.terrain), "grass");
    stop.store(true, Ordering::Relaxed);
    let (stats, counters) = runner.join().unwrap();
    assert_eq!((counters.steps, counters.classified), (1, 1));
    assert!(stats.sent >= 2, "{stats:?}");
    let mut last = None;
    while let Ok(Some(st)) = robot.recv(Duration::from_millis(50)) {
        if let Ok(Some((_, Message::NodeStatus(s)))) = messages::decode(&st.frame, &ids) {
            last = Some(s.state);
        }
    }
    assert_eq!(last, Some(NodeState::Stopping));
}

#[test]
fn a_replay_decides_each_step_as_the_log_clock_says() {
    let mut foot = FakeFoot::new();
    let mut frames = Vec::new();
    let terrains = [2, 0, 1];
    for (k, &terrain) in terrains.iter().enumerate() {
        frames.extend(foot.stance(terrain, 1_000_000 + k as u64 * 400_000, 200, |_| true));
    }
    let mut node = NodeService::new(NodeConfig::default(), model()).unwrap();
    let mut said = Vec::new();
    node.replay(&frames, &mut said);
    let got = classes(&said);
    assert_eq!(got.len(), terrains.len(), "{got:?}");
    let catalog = TerrainCatalog::paper();
    for (k, (&(t, tc), &terrain)) in got.iter().zip(&terrains).enumerate() {
        assert_eq!(
            catalog.describe(tc.terrain),
            NAMES[terrain],
            "step {k}: {tc:?}"
        );
        // Only frame times tick a replay: the step is decided at the very frame that completes
        // the nearest image (captured at 65 ms, received 1 ms later), not on a tick grid.
        assert_eq!(t - (1_000_000 + k as u64 * 400_000), 66_000, "step {k}");
    }
    // The same frames as a candump log: the same decisions, and a summary that counts them.
    let records = as_log(&frames);
    let mut node = NodeService::new(NodeConfig::default(), model()).unwrap();
    let mut lines = Vec::new();
    let sum = presrs_node::replay::replay_log(&mut node, &records, &mut |(t, o)| {
        if let Output::Class { foot, class, .. } = o {
            lines.push(presrs_node::replay::class_line(t, foot, &class, &catalog))
        }
    });
    assert_eq!(lines.len(), terrains.len(), "{lines:?}");
    for (line, &terrain) in lines.iter().zip(&terrains) {
        assert!(line.contains(NAMES[terrain]), "{line}");
    }
    assert_eq!(sum.frames, frames.len());
    assert_eq!(sum.span_us, frames[frames.len() - 1].t_us - frames[0].t_us);
    assert_eq!((sum.counters.steps, sum.counters.classified), (3, 3));
    assert_eq!(sum.reassembly.crc_failures, 0);
    let text = sum.to_string();
    assert!(
        text.starts_with(&format!("replayed {} frames", frames.len()))
            && text.contains("3 steps, 3 classified"),
        "{text}"
    );
}

/// A classic-CAN foot at the spec's worst case (docs/protocol.md): one image per step, the
/// sampled one, its 391 frames 135 µs apart (a 1 Mbit/s bus at full load, worst stuffing).
fn classic_worst_case_steps(cfg: NodeConfig) -> Vec<(u64, TerrainClass)> {
    let ids = IdConfig::default();
    let seg = Segmenter::new(Variant::Classic, ids.clone());
    let mut rng = rand::rngs::StdRng::seed_from_u64(3);
    let mut frames = Vec::new();
    for (k, &terrain) in [0usize, 1, 2, 1].iter().enumerate() {
        let td = 1_000_000 + k as u64 * 400_000;
        // FootContact at 100 Hz, as the spec has it (edges fall on the 10 ms grid here).
        for ms in (0..400u64).step_by(10) {
            let t = td + ms * 1000;
            let m = Message::FootContact(FootContact {
                stance: ms < 200,
                seq: (k * 40 + ms as usize / 10) as u8,
                timestamp_us: t as u32,
            });
            frames.push(Stamped {
                t_us: t + 200,
                frame: m.to_frame(&ids, 0).unwrap(),
            });
        }
        let px = texture(&mut rng, PERIODS[terrain]);
        let capture = td + 70_000;
        let img = ImageRef {
            rows: 44,
            cols: 44,
            bits: 8,
            timestamp_us: capture as u32,
            pixels: &px,
        };
        let mut n = 0u64;
        seg.frames(0, k as u8, &img, &mut |f: CanFrame| {
            n += 1;
            frames.push(Stamped {
                t_us: capture + n * 135,
                frame: f,
            })
        })
        .unwrap();
        assert_eq!(n, 391);
    }
    frames.sort_by_key(|s| s.t_us);
    let mut node = NodeService::new(cfg, model()).unwrap();
    let mut said = Vec::new();
    node.replay(&frames, &mut said);
    classes(&said)
}

#[test]
fn a_classic_foot_at_the_spec_worst_case_is_classified_with_the_default_timeout() {
    let got = classic_worst_case_steps(NodeConfig::default());
    let catalog = TerrainCatalog::paper();
    let names: Vec<String> = got
        .iter()
        .map(|(_, tc)| catalog.describe(tc.terrain))
        .collect();
    assert_eq!(names, [NAMES[0], NAMES[1], NAMES[2], NAMES[1]], "{got:?}");
    // The old 50 ms default dropped every such image: the test can tell the two apart.
    let short = classic_worst_case_steps(NodeConfig {
        reassembly_timeout_us: 50_000,
        ..NodeConfig::default()
    });
    assert!(
        short.iter().all(|(_, tc)| tc.flags & flags::NO_SAMPLE != 0),
        "{short:?}"
    );
}

/// Property test of stance tracking: random feet — steps of random length, switch
/// bounce at both edges, images on a 10 ms grid with random loss, a sender clock that wraps
/// mid-run, malformed frames on our identifiers mixed in — replayed through the node. Images
/// inside each stance show wood; images in flight, including those sampled right after the
/// liftoff edge while the debounce is pending, show grass. Feet report the switch at 100 Hz or
/// only on its edges, with or without images in flight. Whatever the sequence: one TerrainClass
/// per stance, each with its own step number, and never grass.
#[test]
fn stance_tracking_properties_hold_for_random_feet_and_malformed_traffic() {
    use protocol::MessageKind;
    let ids = IdConfig::default();
    let seg = Segmenter::new(Variant::Fd, ids.clone());
    let model = model();
    let (wood, grass) = (0usize, 2usize);
    let grass_id = TerrainCatalog::paper().by_name(NAMES[grass]).unwrap().id();
    let mut totals = (0usize, 0usize, 0usize);
    for run in 0..60u64 {
        // Half the feet report the switch at 100 Hz as the spec has it, half only its edges;
        // a third send no images in flight.
        let periodic = run % 2 == 0;
        let flight_images = run % 3 != 0;
        let mut rng = rand::rngs::StdRng::seed_from_u64(1000 + run);
        // The sender's clock starts up to 1.5 s before it wraps.
        let t0 = u32::MAX as u64 - rng.random_range(0..1_500_000u64);
        let mut frames: Vec<Stamped> = Vec::new();
        let mut seq = 0u8;
        let mut contact = |frames: &mut Vec<Stamped>, stance: bool, t: u64| {
            seq = seq.wrapping_add(1);
            let m = Message::FootContact(FootContact {
                stance,
                seq,
                timestamp_us: t as u32,
            });
            frames.push(Stamped {
                t_us: t + 150,
                frame: m.to_frame(&ids, 0).unwrap(),
            });
        };
        // Stances [touchdown, liftoff) on the foot's clock.
        let mut stances = Vec::new();
        let mut t = t0 + rng.random_range(20_000..200_000u64);
        for _ in 0..rng.random_range(2..6) {
            let len = rng.random_range(60_000..250_000u64);
            stances.push((t, t + len));
            t += len + rng.random_range(60_000..250_000u64);
        }
        let end = t;
        let in_stance = |x: u64| stances.iter().any(|&(a, b)| (a..b).contains(&x));
        // The switch: a report every 10 ms, and every edge with up to 3 ms of bounce.
        for ms in (t0..end).step_by(10_000).filter(|_| periodic) {
            contact(&mut frames, in_stance(ms), ms);
        }
        for &(a, b) in &stances {
            for (edge, state) in [(a, true), (b, false)] {
                let mut x = edge;
                if rng.random_bool(0.5) {
                    contact(&mut frames, state, x);
                    contact(&mut frames, !state, x + 1_000);
                    x += rng.random_range(2_000..3_000u64);
                }
                contact(&mut frames, state, x);
            }
        }
        // Images on a 10 ms grid, 20% lost.
        let phase = rng.random_range(0..10_000u64);
        for (k, ts) in (t0 + phase..end).step_by(10_000).enumerate() {
            if rng.random_bool(0.2) || !(flight_images || in_stance(ts)) {
                continue;
            }
            let terrain = if in_stance(ts) { wood } else { grass };
            let px = texture(&mut rng, PERIODS[terrain]);
            let img = ImageRef {
                rows: 44,
                cols: 44,
                bits: 8,
                timestamp_us: ts as u32,
                pixels: &px,
            };
            let mut n = 0;
            seg.frames(0, k as u8, &img, &mut |f: CanFrame| {
                n += 1;
                frames.push(Stamped {
                    t_us: ts + 500 + n * 150,
                    frame: f,
                });
            })
            .unwrap();
        }
        // Malformed traffic on our identifiers: wrong lengths, FD on fixed-layout ids, garbage
        // tactile segments, a stance value of 7.
        for _ in 0..rng.random_range(20..80) {
            let at = rng.random_range(t0..end) + 150;
            let kind = MessageKind::ALL[rng.random_range(0..MessageKind::ALL.len())];
            let Some(id) = protocol::frame::make_id(ids.id(kind, 0), false) else {
                continue;
            };
            let len = rng.random_range(0..9);
            let mut data = vec![0u8; if rng.random_bool(0.5) { 64 } else { len }];
            rng.fill(&mut data[..]);
            if kind == MessageKind::FootContact && data.len() == 8 {
                data[0] = 7;
            }
            let frame = if data.len() > 8 || rng.random_bool(0.3) {
                CanFrame::fd(id, &data, true)
            } else {
                CanFrame::classic(id, &data)
            };
            if let Some(frame) = frame {
                frames.push(Stamped { t_us: at, frame });
            }
        }
        frames.sort_by_key(|s| s.t_us);
        let mut node = NodeService::new(NodeConfig::default(), model.clone()).unwrap();
        let mut said = Vec::new();
        node.replay(&frames, &mut said);
        node.tick(end + 1_000_000, &mut |o| said.push((end + 1_000_000, o)));
        let got = classes(&said);
        let steps: std::collections::BTreeSet<u16> = got.iter().map(|(_, tc)| tc.step).collect();
        // Exactly one: every stance here lasts longer than the debounce and gets images.
        assert!(
            got.len() == stances.len() && steps.len() == got.len(),
            "run {run}: {} TerrainClass for {} stances: {got:?}",
            got.len(),
            stances.len()
        );
        assert!(
            got.iter().all(|(_, tc)| tc.terrain != grass_id),
            "run {run}: an image from outside a stance was classified: {got:?}"
        );
        totals.0 += stances.len();
        totals.1 += got.len();
        totals.2 += got
            .iter()
            .filter(|(_, tc)| tc.flags & flags::NO_SAMPLE == 0)
            .count();
    }
    // The properties are not met by saying nothing: most stances are decided from an image.
    let (stances, decided, classified) = totals;
    assert!(
        decided * 10 >= stances * 9 && classified * 10 >= stances * 7,
        "{stances} stances, {decided} decided, {classified} from an image"
    );
}

/// Keeps every frame offered, and refuses (drops and counts) after `room` frames.
struct Keep {
    frames: std::sync::Mutex<Vec<Stamped>>,
    room: usize,
    dropped: std::sync::atomic::AtomicU64,
}

impl protocol::bus::Tap for Keep {
    fn offer(&self, frame: &Stamped) {
        let mut f = self.frames.lock().unwrap();
        if f.len() < self.room {
            f.push(*frame);
        } else {
            self.dropped
                .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        }
    }
    fn dropped(&self) -> u64 {
        self.dropped.load(std::sync::atomic::Ordering::Relaxed)
    }
}

#[test]
fn a_tap_gets_each_frame_in_and_out_once_and_its_drops_are_counted() {
    use std::sync::Arc;
    for room in [usize::MAX, 5] {
        let bus = InProcBus::new();
        let mut robot = bus.endpoint();
        let tap = Arc::new(Keep {
            frames: Default::default(),
            room,
            dropped: Default::default(),
        });
        let running = NodeService::new(NodeConfig::default(), model())
            .unwrap()
            .start_with_tap(
                BusSource::InProc(bus.clone()),
                Some(tap.clone() as Arc<dyn protocol::bus::Tap>),
            )
            .unwrap();
        let sent = FakeFoot::new().stance(2, 1_000_000, 200, |_| true);
        std::thread::sleep(Duration::from_millis(200));
        for st in &sent {
            robot.send(&st.frame).unwrap();
        }
        let ids = IdConfig::default();
        // Until the step is decided and every frame in or out has been offered to the tap (kept
        // or dropped): the step is decided on its 70 ms frame, and a slow machine still had the
        // stance's later frames queued when it stopped the node at the decision (qemu-aarch64:
        // 693 of 712 foot frames tapped). A frame offered twice or lost fails below.
        let offered = || {
            tap.frames.lock().unwrap().len() as u64
                + tap.dropped.load(std::sync::atomic::Ordering::Relaxed)
        };
        let end = Instant::now() + Duration::from_secs(20);
        while Instant::now() < end {
            let s = running.stats();
            if s.classified > 0 && offered() >= sent.len() as u64 + s.tx_frames {
                break;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        let stats = running.stop();
        let got = tap.frames.lock().unwrap().clone();
        let kind = |st: &Stamped| {
            ids.lookup(st.frame.raw_id(), st.frame.is_extended())
                .map(|k| k.0)
        };
        let count = |k: protocol::MessageKind| got.iter().filter(|s| kind(s) == Some(k)).count();
        if room == usize::MAX {
            assert_eq!(stats.record_dropped, 0);
            // The foot's frames once each, the node's TerrainClass once (not again as it
            // comes back through the node's receive handle).
            let foot_frames = got
                .iter()
                .filter(|s| sent.iter().any(|x| x.frame == s.frame))
                .count();
            assert_eq!(foot_frames, sent.len());
            assert_eq!(count(protocol::MessageKind::TerrainClass), 1);
            assert_eq!(
                count(protocol::MessageKind::NodeStatus) as u64,
                stats.tx_frames - 1,
                "every status sent, once"
            );
        } else {
            assert_eq!(got.len(), 5);
            assert_eq!(
                stats.record_dropped,
                (sent.len() + stats.tx_frames as usize - 5) as u64,
                "what the tap could not take is counted"
            );
        }
    }
}

/// NodeStatus carries the low 8 bits of each running total (docs/protocol.md), so a
/// monitor that takes differences mod 256 sees every loss; saturating at 255 hid them all.
#[test]
fn status_counters_wrap_mod_256_instead_of_pinning_at_255() {
    let mut node = NodeService::new(NodeConfig::default(), model()).unwrap();
    let mut foot = FakeFoot::new();
    let seg = Segmenter::new(Variant::Fd, IdConfig::default());
    let px: Vec<u16> = texture(&mut foot.rng, 7);
    let n = 300u64;
    for k in 0..n {
        let img = ImageRef {
            rows: 44,
            cols: 44,
            bits: 8,
            timestamp_us: (k * 10_000) as u32,
            pixels: &px,
        };
        let mut frames = Vec::new();
        seg.frames(0, k as u8, &img, &mut frames).unwrap();
        // A flipped pixel byte in the last data segment: the transfer fails its CRC.
        let last = frames.last_mut().unwrap();
        let mut data = last.data().to_vec();
        data[4] ^= 0x55;
        *last = CanFrame::fd(last.id(), &data, last.is_brs()).unwrap();
        for f in frames {
            node.process(
                &Stamped {
                    t_us: k * 10_000,
                    frame: f,
                },
                &mut |_| {},
            );
        }
    }
    assert_eq!(node.reassembly_stats().crc_failures, n);
    let s = node.status(false);
    assert_eq!(s.crc_failures, (n % 256) as u8, "{s:?}");
}

/// LatencyUs runs from the sampled frame's receipt to the decision on the node's
/// clock, so a node that takes its frames late (stopped, behind) says how late, saturating at
/// the field's 65535 µs; in lock-step without a clock it is the driver's time (0 here: the
/// frame that completes the image decides it).
#[test]
fn latency_shows_how_late_the_node_decided() {
    use protocol::clock::ManualClock;
    let run = |delay_us: Option<u64>| {
        let mut node = NodeService::new(NodeConfig::default(), model()).unwrap();
        let clock = ManualClock::new(0);
        if delay_us.is_some() {
            node.set_clock(std::sync::Arc::new(clock.clone()));
        }
        let frames = FakeFoot::new().stance(0, 1_000_000, 200, |_| true);
        let mut said = Vec::new();
        for f in &frames {
            // The node takes each frame `delay` after the kernel stamped it.
            clock.set_us(f.t_us + delay_us.unwrap_or(0));
            node.process(f, &mut said);
        }
        let got: Vec<TerrainClass> = said
            .iter()
            .filter_map(|o| match *o {
                Output::Class { class, .. } => Some(class),
                _ => None,
            })
            .collect();
        assert_eq!(got.len(), 1, "{got:?}");
        assert_eq!(got[0].flags & flags::NO_SAMPLE, 0);
        got[0].latency_us
    };
    assert_eq!(run(None), 0);
    assert_eq!(run(Some(0)), 0);
    assert_eq!(run(Some(20_000)), 20_000);
    assert_eq!(run(Some(3_000_000)), messages::LATENCY_MAX_US);
}

/// Error frames reach the node's NodeStatus: bus-off and error-passive are its state
/// until the controller restarts, and each error frame counts in BusErrors.
#[test]
fn error_frames_set_the_node_state_until_the_controller_restarts() {
    use protocol::bus::ErrorClasses;
    let bus = InProcBus::new();
    let mut robot = bus.endpoint();
    let running = NodeService::new(NodeConfig::default(), model())
        .unwrap()
        .start(BusSource::InProc(bus.clone()))
        .unwrap();
    let ids = IdConfig::default();
    // The next heartbeat whose state passes `want` (generous wall time: function, not speed).
    let status = |robot: &mut dyn CanBus, want: &dyn Fn(NodeState) -> bool| {
        let end = Instant::now() + Duration::from_secs(20);
        while Instant::now() < end {
            if let Ok(Some(st)) = robot.recv(Duration::from_millis(10))
                && let Ok(Some((_, Message::NodeStatus(s)))) = messages::decode(&st.frame, &ids)
                && want(s.state)
            {
                return Some(s);
            }
        }
        None
    };
    let s = status(&mut robot, &|s| s == NodeState::Running).expect("running");
    let errors_before = s.bus_errors;
    bus.report_error(ErrorClasses {
        passive: true,
        ..Default::default()
    });
    status(&mut robot, &|s| s == NodeState::ErrorPassive).expect("error-passive reported");
    bus.report_error(ErrorClasses {
        bus_off: true,
        ..Default::default()
    });
    let s = status(&mut robot, &|s| s == NodeState::BusOff).expect("bus-off reported");
    assert_eq!(s.bus_errors.wrapping_sub(errors_before), 2, "{s:?}");
    bus.report_error(ErrorClasses {
        restarted: true,
        ..Default::default()
    });
    status(&mut robot, &|s| s == NodeState::Running).expect("running after the restart");
    let stats = running.stop();
    assert_eq!(stats.bus_errors, 3, "{stats:?}");
}

/// The energy check. A stance whose flight after is not what its class's return
/// map gives for its flight before makes the next stance of that class unknown (flag ENERGY);
/// a stance of another class, or one after a stance the map allows, is the texture's.
#[test]
fn a_stance_that_took_energy_its_terrain_does_not_makes_the_next_of_its_kind_unknown() {
    use presrs_node::unknown::energy::ReturnMap;
    let mut m = model();
    // Wood: the flight after a stance as long as the one before, within 10 ms.
    let wood = ReturnMap {
        intercept_s: 0.0,
        slope: 1.0,
        residual_s: [-0.010, 0.010],
        stances: 50,
    };
    m.unknown.energy = Some(vec![Some(wood), None, None]);
    let run = |m: Model| {
        let mut node = NodeService::new(NodeConfig::default(), m).unwrap();
        let mut foot = FakeFoot::new();
        let mut frames = Vec::new();
        // Stances of 200 ms; flights (liftoff to the next touchdown) 200, 200, 150, 150, 200 ms.
        let touchdowns = [
            1_000_000u64,
            1_400_000,
            1_800_000,
            2_150_000,
            2_500_000,
            2_900_000,
        ];
        let terrains = [0, 0, 0, 0, 0, 1];
        for (&td, &k) in touchdowns.iter().zip(&terrains) {
            frames.extend(foot.stance(k, td, 200, |_| true));
        }
        let said = lock_step(&mut node, &frames, 3_400_000);
        let catalog = TerrainCatalog::paper();
        let got = classes(&said)
            .into_iter()
            .map(|(_, tc)| (catalog.describe(tc.terrain), tc.flags & flags::ENERGY != 0))
            .collect::<Vec<_>>();
        let flagged = got.iter().filter(|(_, e)| *e).count() as u64;
        assert_eq!(node.counters().energy_unknown, flagged, "counted as sent");
        got
    };
    let got = run(m.clone());
    let want = [
        ("wood", false),
        ("wood", false),
        ("wood", false),
        // Stance 3 flew 150 ms after a 200 ms flight: wood does not take that much.
        ("unknown", true),
        // Stance 4: 150 ms after 150 ms, as wood does.
        ("wood", false),
        // Stance 5 flew 200 after 150 (outside wood's map), but stance 6 is carpet.
        ("carpet", false),
    ];
    let got_s: Vec<(String, bool)> = got.iter().map(|(n, e)| (n.clone(), *e)).collect();
    let want_s: Vec<(String, bool)> = want.iter().map(|(n, e)| (n.to_string(), *e)).collect();
    assert_eq!(got_s, want_s);
    // Without the energy check the texture decides every stance.
    m.unknown.energy = None;
    let plain = run(m);
    assert!(plain.iter().all(|(n, e)| n != "unknown" && !e), "{plain:?}");
    // A model file whose map list does not match its classes is refused, naming the key.
    let mut bad = model();
    bad.unknown.energy = Some(vec![Some(wood)]);
    let e = bad.validate().err().map(|e| e.to_string());
    assert!(e.as_deref().is_some_and(|e| e.contains("energy")), "{e:?}");
}

/// The node counts its unknowns per gait in force when each step is decided (the controller's
/// GaitStatus), live as in a replay: where a run's unknowns gather.
#[test]
fn unknowns_are_counted_in_the_gait_each_step_was_decided_in() {
    use presrs_node::unknown::energy::ReturnMap;
    use protocol::messages::{GaitReason, GaitStatus};
    let mut m = model();
    // Wood's return map makes the fourth stance unknown (as the test above shows).
    m.unknown.energy = Some(vec![
        Some(ReturnMap {
            intercept_s: 0.0,
            slope: 1.0,
            residual_s: [-0.010, 0.010],
            stances: 50,
        }),
        None,
        None,
    ]);
    m.gaits = Some(vec![1]);
    let ids = IdConfig::default();
    let gait_status = |t_us: u64, gait: u8| Stamped {
        t_us,
        frame: Message::GaitStatus(GaitStatus {
            gait,
            terrain: 0,
            omega_rad_s: 6.0,
            beta_des_rad: 0.27,
            reason: GaitReason::Terrain,
            foot: 0,
        })
        .to_frame(&ids, 0)
        .unwrap(),
    };
    let mut foot = FakeFoot::new();
    let mut frames = Vec::new();
    let touchdowns = [1_000_000u64, 1_400_000, 1_800_000, 2_150_000, 2_500_000];
    for &td in &touchdowns {
        frames.extend(foot.stance(0, td, 200, |_| true));
    }
    // The first step before any GaitStatus; G1 from 1.3 s; G2 from 2.1 s (10 Hz repeats).
    for t in (1_300_000..2_100_000).step_by(100_000) {
        frames.push(gait_status(t, 1));
    }
    for t in (2_100_000..3_000_000).step_by(100_000) {
        frames.push(gait_status(t, 2));
    }
    frames.sort_by_key(|s| s.t_us);
    let mut node = NodeService::new(NodeConfig::default(), m).unwrap();
    let said = lock_step(&mut node, &frames, 3_000_000);
    let decided: Vec<(Option<u8>, bool)> = said
        .iter()
        .filter_map(|(_, o)| match o {
            Output::Class { class, gait, .. } => {
                Some((*gait, class.terrain == messages::TERRAIN_UNKNOWN))
            }
            Output::Status(_) => None,
        })
        .collect();
    assert_eq!(
        decided,
        [
            (None, false),
            (Some(1), false),
            (Some(1), false),
            (Some(2), true),
            (Some(2), false)
        ]
    );
    assert_eq!(node.gait_tally().unknown(), 1);
    assert_eq!(
        node.describe_gaits(),
        "G1 0/2, G2 1/2 (the model was not trained in it), no GaitStatus 0/1"
    );
    // The same frames replayed from a log count the same.
    let records = as_log(&frames);
    let model = node.model().unwrap().clone();
    let mut replayed = NodeService::new(NodeConfig::default(), model).unwrap();
    let sum = presrs_node::replay::replay_log(&mut replayed, &records, &mut Vec::new());
    assert_eq!(sum.gaits, node.gait_tally().counts());
    assert!(
        sum.to_string().ends_with(
            "unknown by gait: G1 0/2, G2 1/2 (the model was not trained in it), no GaitStatus 0/1"
        ),
        "{sum}"
    );
}

/// The gaits a model file says it was trained in: gait numbers, sorted, each once; a file
/// without them loads as before.
#[test]
fn a_model_files_gaits_are_checked() {
    let mut m = model();
    assert!(m.gaits.is_none() && m.validate().is_ok());
    m.gaits = Some(vec![1, 3]);
    assert!(m.validate().is_ok());
    for bad in [vec![0, 1], vec![3, 1], vec![2, 2]] {
        m.gaits = Some(bad.clone());
        let e = m.validate().err().map(|e| e.to_string());
        assert!(
            e.as_deref().is_some_and(|e| e.contains("gaits")),
            "{bad:?}: {e:?}"
        );
    }
}

/// A model of the terrains `known` (indices into [`PERIODS`]) only.
fn model_of(known: &[usize]) -> Model {
    let mut rng = rand::rngs::StdRng::seed_from_u64(1);
    let imgs: Vec<(PressureImage, usize)> = known
        .iter()
        .enumerate()
        .flat_map(|(k, &t)| (0..30).map(move |_| (k, t)))
        .map(|(k, t)| {
            (
                PressureImage::new(44, 44, 8, texture(&mut rng, PERIODS[t])),
                k,
            )
        })
        .collect();
    let data: Vec<Labelled> = imgs
        .iter()
        .map(|(image, class)| Labelled::new(image, *class))
        .collect();
    let classes: Vec<ClassInfo> = known
        .iter()
        .map(|&t| ClassInfo {
            name: NAMES[t].to_string(),
            terrain_id: TerrainCatalog::paper().by_name(NAMES[t]).unwrap().id(),
        })
        .collect();
    let opts = TrainOptions {
        crop: "2,2,2,2".parse::<Crop>().unwrap().into(),
        ..TrainOptions::default()
    };
    train(&data, &classes, &opts).unwrap().0
}

/// The multi-frame path calls a terrain the model never saw unknown as often as the
/// single-frame path (it used to take the summed posterior's terrain, never unknown), and
/// says why on the bus; known ground stays known in both.
#[test]
fn multi_frame_calls_ground_the_model_never_saw_unknown_as_single_frame_does() {
    for (left_out, name) in NAMES.iter().enumerate() {
        let known: Vec<usize> = (0..NAMES.len()).filter(|&t| t != left_out).collect();
        let model = model_of(&known);
        let mut foot = FakeFoot::new();
        let mut frames = Vec::new();
        let mut truth = Vec::new();
        for i in 0..30u64 {
            let t = (i % 3) as usize;
            frames.extend(foot.stance(t, 1_000_000 + i * 400_000, 200, |_| true));
            truth.push(t);
        }
        let end = 1_000_000 + 31 * 400_000;
        let unknown_share = |multi_frame: bool| {
            let cfg = NodeConfig {
                multi_frame,
                ..NodeConfig::default()
            };
            let mut node = NodeService::new(cfg, model.clone()).unwrap();
            let said = classes(&lock_step(&mut node, &frames, end));
            assert_eq!(said.len(), truth.len(), "one decision per step");
            let (mut novel, mut novel_unknown, mut known_unknown) = (0, 0, 0);
            for ((_, tc), &t) in said.iter().zip(&truth) {
                let unknown = tc.terrain == messages::TERRAIN_UNKNOWN;
                if unknown {
                    assert_eq!(
                        tc.unknown_reason(),
                        Some(messages::UnknownReason::Novelty),
                        "flags {:#x}",
                        tc.flags
                    );
                }
                assert_eq!(tc.flags & flags::MULTI_FRAME != 0, multi_frame);
                if t == left_out {
                    novel += 1;
                    novel_unknown += unknown as usize;
                } else {
                    known_unknown += unknown as usize;
                }
            }
            let stats = node.counters().unknown_by_reason;
            assert_eq!(
                stats.get(messages::UnknownReason::Novelty) as usize,
                novel_unknown + known_unknown
            );
            (novel_unknown as f64 / novel as f64, known_unknown)
        };
        let (single, single_known) = unknown_share(false);
        let (multi, multi_known) = unknown_share(true);
        assert!(
            single >= 0.9 && multi >= single - 0.1,
            "left out {name}: single-frame {single:.2}, multi-frame {multi:.2}"
        );
        assert!(
            single_known <= 2 && multi_known <= 2,
            "left out {name}: known steps called unknown {single_known} / {multi_known} of 20"
        );
    }
}

/// The multi-frame rule reports the class its frames' summed posterior decides, and judges that
/// class at the sample-time frame: a stance whose frames are wood but whose 65 ms frame is
/// grass is not called wood on grass's verdict (its reason and its terrain agree).
#[test]
fn multi_frame_judges_the_class_its_frames_decided() {
    let cfg = NodeConfig {
        multi_frame: true,
        ..NodeConfig::default()
    };
    let mut node = NodeService::new(cfg, model()).unwrap();
    let mut foot = FakeFoot::new();
    let mut frames = Vec::new();
    for i in 0..6u64 {
        // Stances 1, 3, 5: every frame wood but the one nearest 70 ms (65 ms), grass.
        let odd = i % 2 == 1;
        frames.extend(foot.step(1_000_000 + i * 400_000, 200, |ms, rng| {
            let t = if odd && ms == 65 { 2 } else { 0 };
            (ms < 200).then(|| texture(rng, PERIODS[t]))
        }));
    }
    let said = classes(&lock_step(&mut node, &frames, 1_000_000 + 7 * 400_000));
    assert_eq!(said.len(), 6);
    let catalog = TerrainCatalog::paper();
    for (i, (_, tc)) in said.iter().enumerate() {
        assert_ne!(tc.flags & flags::MULTI_FRAME, 0);
        if i % 2 == 0 {
            assert_eq!(catalog.describe(tc.terrain), "wood", "stance {i}: {tc:?}");
        } else {
            // Five wood frames decide wood; judged as wood, the grass frame is new ground.
            assert_eq!(tc.terrain, messages::TERRAIN_UNKNOWN, "stance {i}: {tc:?}");
            assert_eq!(tc.unknown_reason(), Some(messages::UnknownReason::Novelty));
        }
    }
}

/// The node reads its feet's switch and tactile frames and the controller's gait; the kernel
/// (or the in-process bus) keeps the leg's traffic and the node's own answers from waking it.
#[test]
fn the_node_asks_the_bus_only_for_the_frames_it_reads() {
    use protocol::bus::passes;
    use protocol::component::Component;
    use protocol::messages::{GaitReason, GaitStatus, LegState};
    let node = NodeService::new(NodeConfig::default(), model()).unwrap();
    let filters = node.filters();
    assert!(!filters.is_empty());
    let ids = IdConfig::default();
    let frame = |m: Message| m.to_frame(&ids, 1).unwrap();
    let contact = FootContact {
        stance: true,
        timestamp_us: 5,
        seq: 0,
    };
    assert!(passes(&filters, &frame(Message::FootContact(contact))));
    let tactile = FakeFoot::new().stance(1, 1_000_000, 30, |_| true);
    assert!(tactile.iter().all(|st| passes(&filters, &st.frame)));
    let gait = GaitStatus {
        gait: 1,
        terrain: 0,
        omega_rad_s: 10.0,
        beta_des_rad: 0.3,
        reason: GaitReason::Terrain,
        foot: 0,
    };
    assert!(passes(&filters, &frame(Message::GaitStatus(gait))));
    let leg = LegState {
        leg_angle_rad: 0.1,
        leg_length_m: 0.15,
        ..LegState::default()
    };
    assert!(!passes(&filters, &frame(Message::LegState(leg))));
    let own = TerrainClass::default();
    assert!(!passes(&filters, &frame(Message::TerrainClass(own))));
}
