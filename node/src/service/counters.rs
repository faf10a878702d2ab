//! The node's counters: shared by its threads as atomics, read as one [`NodeStats`].

use super::{
    Arc, AtomicU64, ControllerState, Counters, Link, LinkStats, NodeState, Ordering, Reason,
    ReasonCounts, ReassemblyStats,
};

/// The counters a running node shares between its threads, written without locks: the
/// runner's (frames in and out, bus errors, the link's state) and the pipeline's.
#[derive(Debug, Default)]
pub(super) struct Shared {
    pub(super) link: Arc<LinkStats>,
    pub(super) model_id: AtomicU64,
    pub(super) damage_bits: AtomicU64,
    pub(super) steps: AtomicU64,
    pub(super) classified: AtomicU64,
    pub(super) no_sample: AtomicU64,
    pub(super) images: AtomicU64,
    pub(super) crc_failures: AtomicU64,
    pub(super) incomplete: AtomicU64,
    pub(super) decode_errors: AtomicU64,
    pub(super) unknown: AtomicU64,
    pub(super) unknown_by_reason: [AtomicU64; Reason::ALL.len()],
    /// [`StageTimes`], each field an atomic.
    pub(super) stages: [AtomicU64; 6],
}

/// Where the node's time goes, summed since it started: every frame's work, and of the frames
/// that ended a step with its TerrainClass, their work and how long they waited between the
/// bus's receive stamp and the pipeline. Kept per frame in plain integers, published with each
/// NodeStatus; `presrs lab bench-node --json` reports the means.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StageTimes {
    /// Frames the pipeline took.
    pub frames: u64,
    /// Their work (decode, reassembly, stance, and the decision where one was due), ns.
    pub frame_ns: u64,
    /// Frames whose work ended in a TerrainClass.
    pub decided: u64,
    /// Their work, ns.
    pub decided_ns: u64,
    /// Their wait from the bus's receive stamp to the pipeline (wake-ups and hand-offs), µs.
    pub decided_wait_us: u64,
    /// The longest wait and work of one of them, µs: the node's share of a latency tail.
    pub decided_max_us: u64,
}

impl StageTimes {
    fn to_array(self) -> [u64; 6] {
        [
            self.frames,
            self.frame_ns,
            self.decided,
            self.decided_ns,
            self.decided_wait_us,
            self.decided_max_us,
        ]
    }

    fn from_array(a: [u64; 6]) -> Self {
        Self {
            frames: a[0],
            frame_ns: a[1],
            decided: a[2],
            decided_ns: a[3],
            decided_wait_us: a[4],
            decided_max_us: a[5],
        }
    }
}

/// A node's counters at one moment.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct NodeStats {
    /// As NodeStatus reports it.
    pub state: NodeState,
    /// The loaded model's content hash ([`Model::id`]).
    pub model_id: u64,
    /// Largest learned sensor damage over the feet, percent.
    pub damage_pct: f64,
    /// Frames read from the bus.
    pub rx_frames: u64,
    /// Frames the receive thread dropped because the pipeline was behind.
    pub rx_dropped: u64,
    /// Frames written to the bus.
    pub tx_frames: u64,
    /// Frames not sent (send queue full, or a bus error).
    pub tx_dropped: u64,
    /// Bus errors on receive or send.
    pub bus_errors: u64,
    /// Touchdowns.
    pub steps: u64,
    /// Steps decided from an image.
    pub classified: u64,
    /// Steps decided unknown (TerrainClass 0xFF): not like any trained terrain, or outside
    /// its return map ([`NodeService::gait_tally`] counts them per gait).
    pub unknown: u64,
    /// Unknown steps per reason: the image's check (novelty, load, texture), the energy
    /// check, no contact or no sample, as each TerrainClass says.
    pub unknown_by_reason: ReasonCounts,
    /// Steps that ended without an image.
    pub no_sample: u64,
    /// Tactile images reassembled.
    pub images: u64,
    /// Tactile transfers that failed their CRC.
    pub crc_failures: u64,
    /// Tactile transfers never completed.
    pub incomplete: u64,
    /// Frames with our ids that did not decode.
    pub decode_errors: u64,
    /// Frames a recorder tap dropped because it was behind (0 without one).
    pub record_dropped: u64,
    /// Where the pipeline's time went.
    pub stages: StageTimes,
}

impl Shared {
    pub(super) fn publish(
        &self,
        c: &Counters,
        r: &ReassemblyStats,
        damage_pct: f64,
        unknown: u64,
        stages: StageTimes,
    ) {
        let r_ = Ordering::Relaxed;
        for (a, v) in self.stages.iter().zip(stages.to_array()) {
            a.store(v, r_);
        }
        self.unknown.store(unknown, r_);
        for (a, &v) in self.unknown_by_reason.iter().zip(&c.unknown_by_reason.0) {
            a.store(v, r_);
        }
        self.steps.store(c.steps, r_);
        self.classified.store(c.classified, r_);
        self.no_sample.store(c.no_sample, r_);
        self.decode_errors.store(c.decode_errors, r_);
        self.images.store(r.delivered, r_);
        self.crc_failures.store(r.crc_failures, r_);
        self.incomplete.store(r.incomplete, r_);
        self.damage_bits.store(damage_pct.to_bits(), r_);
    }

    pub(super) fn snapshot(&self) -> NodeStats {
        let l = |a: &AtomicU64| a.load(Ordering::Relaxed);
        NodeStats {
            state: self.state(),
            model_id: l(&self.model_id),
            damage_pct: f64::from_bits(l(&self.damage_bits)),
            rx_frames: l(&self.link.rx_frames),
            rx_dropped: l(&self.link.rx_dropped),
            tx_frames: l(&self.link.tx_frames),
            tx_dropped: l(&self.link.tx_dropped),
            bus_errors: l(&self.link.bus_errors),
            steps: l(&self.steps),
            classified: l(&self.classified),
            unknown: l(&self.unknown),
            unknown_by_reason: ReasonCounts(std::array::from_fn(|i| l(&self.unknown_by_reason[i]))),
            no_sample: l(&self.no_sample),
            images: l(&self.images),
            crc_failures: l(&self.crc_failures),
            incomplete: l(&self.incomplete),
            decode_errors: l(&self.decode_errors),
            record_dropped: 0,
            stages: StageTimes::from_array(std::array::from_fn(|i| l(&self.stages[i]))),
        }
    }

    /// The node's state, the CAN controller's error state first: a bus-off or error-passive
    /// controller explains whatever else the node sees.
    pub(super) fn state(&self) -> NodeState {
        match (self.link.controller(), self.link.link()) {
            (ControllerState::BusOff, _) => NodeState::BusOff,
            (ControllerState::Passive, _) => NodeState::ErrorPassive,
            (_, Link::Starting) => NodeState::Starting,
            (_, Link::Open) => NodeState::Running,
            (_, Link::Failing) => NodeState::Degraded,
        }
    }
}
