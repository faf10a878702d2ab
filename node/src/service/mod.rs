//! The node as a service with a lifecycle: [`NodeService::new`] checks the config and the
//! model, then either the caller drives it in lock-step ([`NodeService::process`] per frame,
//! [`NodeService::tick`] on its clock), or [`NodeService::start`] runs it on a bus on its own
//! threads until [`RunningNode::stop`].
//!
//! Live on SocketCAN, a candump replay (the log's clock), the demo (lock-step on a simulated
//! clock) and the node benchmark all run this one type; only the frame source and the clock
//! differ. Everything driven by time rather than by frames is in [`NodeService::tick`]: a step
//! decided at its sample deadline when no nearer frame can come, and NodeStatus (the heartbeat)
//! at `status_hz`.
//!
//! The node is a [`Component`], the shape of every part on the bus. Started
//! ([`NodeService::start`]), it runs on one thread ([`component::spawn_one`]): the thread a
//! frame wakes reads it, decides and sends the answer, with no hand-off between threads
//! (measured against the three threads of [`component::spawn`], [`NodeThreads::Three`]:
//! docs/decisions/node-threads.md). Model reloads ([`RunningNode::reload_model`]) hand it a
//! model already loaded and checked, installed between two bursts of frames. Its kernel
//! filters keep the rest of the bus from waking it.
//!
//! The bus handle is opened with retry and backoff: a missing interface, or one that goes
//! down, shows as `Degraded` in NodeStatus and in the log, never as an exit.

mod counters;
mod running;

pub mod output;
use counters::Shared;
pub use counters::{NodeStats, StageTimes};
pub use output::Output;
pub use running::RunningNode;

use crate::unknown::{Reason, ReasonCounts};
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use protocol::bus::{BusSource, ControllerState, Tap};
use protocol::clock::Clock;
use protocol::component::{self, Component, Link, LinkStats, Outbox, RunOptions, Threaded};
use protocol::emit::Emit;
use protocol::messages::{NodeState, NodeStatus, TERRAIN_UNKNOWN};
use protocol::tactile::ReassemblyStats;
use protocol::terrain::CatalogError;
use protocol::{CanFrame, IdConfig, MessageKind, Stamped, TerrainCatalog};
use thiserror::Error;

use crate::classifier::Model;
use crate::classifier::model::{CatalogMismatch, ModelError};
use crate::config::NodeConfig;
use crate::gait_status::{GaitTally, GaitTrack, describe_counts};
use crate::stance::{Counters, Decided, StancePipeline};
use crate::step_table::StepSender;
use crate::unknown::energy::EnergyTally;
use crate::unknown::keep::UnknownKeeper;

/// Why the node cannot start, or cannot take a model.
#[derive(Debug, Error)]
pub enum ServiceError {
    /// The config's terrains file.
    #[error(transparent)]
    Catalog(#[from] CatalogError),
    /// The model file.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// The model's terrains differ from the node's catalog.
    #[error(transparent)]
    Mismatch(#[from] CatalogMismatch),
    /// The operating system refused a thread.
    #[error("starting the node's {thread} thread: {source}")]
    Spawn {
        /// Which thread.
        thread: &'static str,
        /// What the OS said.
        source: std::io::Error,
    },
    /// The node's threads have exited (stopped, or a thread panicked).
    #[error("the node has stopped; start it again")]
    Stopped,
}

/// Notes step `d` for the keeper when it is one to keep.
#[inline]
fn mark_keep(
    keep: Option<&UnknownKeeper>,
    due: &mut [Option<(Decided, Option<u8>)>],
    d: &Decided,
    gait: Option<u8>,
) {
    if keep.is_some_and(|k| k.wants(&d.class))
        && let Some(slot) = due.get_mut(d.foot as usize)
    {
        *slot = Some((*d, gait));
    }
}

/// Hands a decided step to the live step table, if there is one.
#[inline]
fn offer(steps: &Option<StepSender>, t_us: u64, o: &Output) {
    if let (Some(s), Some(row)) = (steps, crate::step_table::StepRow::of(t_us, o)) {
        s.offer(row);
    }
}

/// The terrain node: one per robot, any number of feet.
pub struct NodeService {
    pipeline: StancePipeline,
    catalog: TerrainCatalog,
    status_period_us: u64,
    next_status_us: Option<u64>,
    heartbeat: u8,
    shared: Arc<Shared>,
    /// What one call said, kept between calls ([`Component`]): no allocation per frame.
    said: Vec<Output>,
    last_log: Instant,
    last_logged: Counters,
    /// The controller's gait, followed from its GaitStatus frames.
    gait: GaitTrack,
    /// Decisions and unknowns per gait since the node began.
    tally: GaitTally,
    last_logged_unknown: u64,
    /// Where the pipeline's time went ([`NodeStats::stages`]).
    stages: StageTimes,
    /// Read every frame on the bus, not only the node's own kinds: a recorder tap keeps the
    /// whole bus.
    read_all: bool,
    /// Where each decided step also goes (`presrs node --csv`): a bounded queue, never waited on.
    steps: Option<StepSender>,
    /// Where unknown stances go (`presrs node --keep-unknown`): a pool of slots, never waited on.
    keep: Option<UnknownKeeper>,
    /// Per foot, the unknown step the last call decided, to keep once the pipeline is free.
    keep_due: [Option<(Decided, Option<u8>)>; protocol::ids::MAX_FEET as usize],
}

impl NodeService {
    /// A node for `config` with `model`. Fails when the config's terrains file is bad or the
    /// model's terrains differ from it (the error says which class and the fix).
    pub fn new(config: NodeConfig, model: Model) -> Result<Self, ServiceError> {
        let catalog = config.catalog()?;
        model.check_catalog(&catalog)?;
        let shared = Arc::new(Shared::default());
        shared.model_id.store(model.id(), Ordering::Relaxed);
        // Driven in lock-step, there is no bus to wait for: running at once.
        shared.link.set_link(Link::Open);
        let status_period_us = (1e6 / config.status_hz.max(0.1)) as u64;
        Ok(Self {
            pipeline: StancePipeline::new(config, Some(model)),
            catalog,
            status_period_us,
            next_status_us: None,
            heartbeat: 0,
            shared,
            said: Vec::with_capacity(16),
            stages: StageTimes::default(),
            read_all: false,
            last_log: Instant::now(),
            last_logged: Counters::default(),
            gait: GaitTrack::default(),
            tally: GaitTally::default(),
            last_logged_unknown: 0,
            steps: None,
            keep: None,
            keep_due: [None; protocol::ids::MAX_FEET as usize],
        })
    }

    /// Offers every step decided from now on to `steps` (a live step table,
    /// [`crate::step_table::StepLog`]), off the node's thread.
    pub fn set_step_log(&mut self, steps: StepSender) {
        self.steps = Some(steps);
    }

    /// Keeps every stance called unknown from now on ([`crate::unknown::keep`]), off the
    /// node's thread.
    pub fn set_keep_unknown(&mut self, keep: UnknownKeeper) {
        self.keep = Some(keep);
    }

    /// Hands the unknown stances the last call decided to the keeper: each foot's image stays
    /// valid until its next touchdown, so after the call is soon enough.
    fn keep_unknown(&mut self) {
        let Some(k) = &self.keep else { return };
        for due in self.keep_due.iter_mut() {
            if let Some((d, gait)) = due.take()
                && let Some(s) = self.pipeline.sample(d.foot)
                && s.step == d.class.step
            {
                k.offer(&d, gait, &s);
            }
        }
    }

    /// Measures decisions' latency (TerrainClass `latency_us`) on `clock`, read when each
    /// decision is made, instead of on the driver's time. [`NodeService::start`] sets the bus's
    /// clock; a caller driving the node itself sets one when frames may reach it late.
    pub fn set_clock(&mut self, clock: Arc<dyn Clock>) {
        self.pipeline.set_clock(clock);
    }

    /// One received frame; the decisions it completes go to `out`.
    pub fn process(&mut self, frame: &Stamped, out: &mut (impl Emit<Output> + ?Sized)) {
        self.gait.on_frame(frame, self.pipeline.ids());
        let (gait, tally, steps) = (self.gait.current(), &mut self.tally, &self.steps);
        let (keeping, due) = (self.keep.as_ref(), &mut self.keep_due);
        let t_us = frame.t_us;
        self.pipeline.on_frame(frame, &mut |d: Decided| {
            tally.add(gait, d.class.terrain == TERRAIN_UNKNOWN);
            mark_keep(keeping, due, &d, gait);
            let o = Output::class(d, gait);
            offer(steps, t_us, &o);
            out.emit(o)
        });
        self.keep_unknown();
    }

    /// A recorded run on its own clock: each frame's time ticks the node before the frame is
    /// processed, as a live node's clock would have, so a replay decides as the robot did.
    /// `out` hears each output with the time it came at.
    pub fn replay<'a>(
        &mut self,
        frames: impl IntoIterator<Item = &'a Stamped>,
        out: &mut (impl Emit<(u64, Output)> + ?Sized),
    ) {
        for f in frames {
            let t = f.t_us;
            self.tick(t, &mut |o| out.emit((t, o)));
            self.process(f, &mut |o| out.emit((t, o)));
        }
    }

    /// Everything due by `now_us` (the clock of [`Stamped::t_us`]): steps whose sample deadline
    /// has passed with no nearer frame possible, and NodeStatus when a status period is up.
    pub fn tick(&mut self, now_us: u64, out: &mut (impl Emit<Output> + ?Sized)) {
        let (gait, tally, steps) = (self.gait.current(), &mut self.tally, &self.steps);
        let (keeping, due) = (self.keep.as_ref(), &mut self.keep_due);
        self.pipeline.tick(now_us, &mut |d: Decided| {
            tally.add(gait, d.class.terrain == TERRAIN_UNKNOWN);
            mark_keep(keeping, due, &d, gait);
            let o = Output::class(d, gait);
            offer(steps, now_us, &o);
            out.emit(o)
        });
        self.keep_unknown();
        // A clock that jumped back (a new bus clock) must not silence the heartbeat.
        let due = self
            .next_status_us
            .is_none_or(|t| now_us >= t || t > now_us + self.status_period_us);
        if due {
            self.next_status_us = Some(now_us + self.status_period_us);
            out.emit(Output::Status(self.status(false)));
        }
    }

    fn send_said(&mut self, said: &mut Vec<Output>, out: &mut Outbox) {
        for o in said.drain(..) {
            if let Some(f) = self.frame(&o) {
                out.push(f);
            }
        }
        self.said = std::mem::take(said);
    }

    /// The NodeStatus the heartbeat carries now.
    pub fn status(&mut self, stopping: bool) -> NodeStatus {
        let r = self.pipeline.reassembly_stats();
        self.shared.publish(
            &self.pipeline.counters,
            &r,
            self.pipeline.damage_pct(),
            self.tally.unknown(),
            self.stages,
        );
        self.heartbeat = self.heartbeat.wrapping_add(1);
        // The low 8 bits of the running totals, as docs/protocol.md says: a monitor takes
        // differences mod 256. (Saturating at 255 hid every loss after the 255th: measured on
        // vcan, a 0x600 flood held IncompleteFrames at 255 for 131 s while the total grew to
        // 37,700.)
        let low8 = |v: u64| (v & 0xff) as u8;
        NodeStatus {
            heartbeat: self.heartbeat,
            state: match self.shared.state() {
                _ if stopping => NodeState::Stopping,
                NodeState::Running if self.pipeline.wrong_image_size() => NodeState::WrongImageSize,
                s => s,
            },
            model_id: self.shared.model_id.load(Ordering::Relaxed) as u16,
            crc_failures: low8(r.crc_failures),
            incomplete_frames: low8(r.incomplete),
            bus_errors: low8(self.shared.link.bus_errors.load(Ordering::Relaxed)),
            damage_pct: self.pipeline.damage_pct(),
        }
    }

    /// Loads, checks and installs the model at `path`; returns its id. A bad file leaves the
    /// model already loaded in place.
    pub fn reload_model(&mut self, path: &Path) -> Result<u64, ServiceError> {
        let model = Model::load(path)?;
        self.set_model(model)
    }

    /// [`Self::set_model`] with the terrains read again (see [`RunningNode::reload`]).
    pub fn set_model_in(
        &mut self,
        model: Model,
        catalog: TerrainCatalog,
    ) -> Result<u64, ServiceError> {
        model.check_catalog(&catalog)?;
        self.catalog = catalog;
        self.set_model(model)
    }

    /// Checks and installs `model`; returns its id. The step in progress keeps its decision.
    pub fn set_model(&mut self, model: Model) -> Result<u64, ServiceError> {
        model.check_catalog(&self.catalog)?;
        let id = model.id();
        self.pipeline.set_model(Some(model));
        self.shared.model_id.store(id, Ordering::Relaxed);
        Ok(id)
    }

    /// The deciding frame's time after touchdown in force, and whose it is (the config's, the
    /// model's or the paper's).
    pub fn sample_time(&self) -> crate::stance::SampleTime {
        self.pipeline.sample_time()
    }

    /// The frame that carries `out` on the node's ids.
    pub fn frame(&self, out: &Output) -> Option<CanFrame> {
        out.to_frame(self.ids())
    }

    /// The CAN ids the node listens and talks on.
    pub fn ids(&self) -> &IdConfig {
        self.pipeline.ids()
    }

    /// The terrains the node reports.
    pub fn catalog(&self) -> &TerrainCatalog {
        &self.catalog
    }

    /// The pipeline's counters per stage.
    pub fn counters(&self) -> Counters {
        self.pipeline.counters
    }

    /// Decisions and unknowns per gait since the node began: where its unknowns gather. Many
    /// in a gait the model was not trained in ([`Model::gaits`]) are that gait's, not new
    /// ground's (docs/real-robot.md, "A gait the model never saw").
    pub fn gait_tally(&self) -> &GaitTally {
        &self.tally
    }

    /// `G1 3/103, G2 0/67`: unknown of decided steps per gait, naming gaits the model was not
    /// trained in; empty when no GaitStatus came. For logs and summaries, not the hot path.
    pub fn describe_gaits(&self) -> String {
        let model_gaits = self.model().and_then(|m| m.gaits.as_deref());
        describe_counts(&self.tally.counts(), model_gaits)
    }

    /// Tactile reassembly counters.
    pub fn reassembly_stats(&self) -> ReassemblyStats {
        self.pipeline.reassembly_stats()
    }

    /// Largest learned sensor damage over the feet, percent.
    pub fn damage_pct(&self) -> f64 {
        self.pipeline.damage_pct()
    }

    /// The installed model.
    pub fn model(&self) -> Option<&Model> {
        self.pipeline.model()
    }

    /// Per terrain of the model that has a return map: its stances judged by the energy check
    /// and those outside the map, since the model's classes were installed.
    pub fn energy_tally(&self) -> Vec<EnergyTally> {
        let Some(m) = self.model() else {
            return Vec::new();
        };
        let maps = m.unknown.energy.as_deref().unwrap_or(&[]);
        m.classes
            .iter()
            .zip(self.pipeline.energy_tally())
            .enumerate()
            .filter(|&(k, _)| maps.get(k).is_some_and(Option::is_some))
            .map(|(_, (c, t))| EnergyTally {
                terrain: c.name.clone(),
                judged: t[0],
                outside: t[1],
            })
            .collect()
    }

    /// The counters of the runner it runs under, which NodeStatus reports (its state, bus
    /// errors): pass them as [`RunOptions::link`].
    pub fn link_stats(&self) -> Arc<LinkStats> {
        self.shared.link.clone()
    }

    /// Runs the node on `bus` on its own threads until [`RunningNode::stop`].
    pub fn start(self, bus: BusSource) -> Result<RunningNode, ServiceError> {
        self.start_with_tap(bus, None)
    }

    /// [`NodeService::start`], offering every frame the pipeline takes in and every frame it
    /// sends to `tap` (a recorder), in the pipeline's order, each once: TerrainClass and
    /// NodeStatus are taken as sent (the node is their one sender), not as they come back. The tap never makes the node
    /// wait: what it cannot take it drops and counts ([`NodeStats::record_dropped`]).
    pub fn start_with_tap(
        self,
        bus: BusSource,
        tap: Option<Arc<dyn Tap>>,
    ) -> Result<RunningNode, ServiceError> {
        self.start_on(bus, tap, NodeThreads::default())
    }

    /// [`NodeService::start_with_tap`] on `threads` (the default is the one measured faster:
    /// `presrs lab bench-node --node-threads` measures both).
    pub fn start_on(
        self,
        bus: BusSource,
        tap: Option<Arc<dyn Tap>>,
        threads: NodeThreads,
    ) -> Result<RunningNode, ServiceError> {
        let mut node = self;
        node.read_all = tap.is_some();
        let clock = bus.clock();
        node.set_clock(clock.clone());
        let shared = node.shared.clone();
        let catalog = node.catalog.clone();
        let label = bus.label().to_string();
        let opts = RunOptions {
            // The node's clock is the bus's (that of the receive timestamps), read directly:
            // anchored to the last frame's timestamp instead, a node that had been stopped
            // took the frames queued meanwhile for "now".
            clock: Some(clock),
            tap: tap.clone(),
            link: Some(shared.link.clone()),
            // Ticks after the frames, which come every 10 ms per foot; waking every 1 ms
            // besides cost the node three quarters of its CPU (docs/decisions/node-threads.md).
            idle_wait: Some(IDLE_WAIT),
            ..RunOptions::default()
        };
        let threads = match threads {
            NodeThreads::One => component::spawn_one(node, bus, opts),
            // About 0.4 s of one foot's FD tactile stream: room for the pipeline to fall
            // briefly behind.
            NodeThreads::Three => component::spawn(node, bus, opts, 16_384),
        }
        .map_err(|source| ServiceError::Spawn {
            thread: "node",
            source,
        })?;
        tracing::info!(iface = %label, "presrs node started");
        Ok(RunningNode {
            threads,
            catalog,
            shared,
            tap,
        })
    }
}

/// How long a started node waits without frames before it ticks anyway (the 20 ms the node's
/// pipeline thread waited before it ran on one thread).
const IDLE_WAIT: Duration = Duration::from_millis(20);

/// The threads a started node runs on. One thread reads a frame, decides and answers it;
/// three hand each frame from a receive thread to the pipeline and its answer to a send
/// thread, so that a slow decision never keeps the socket unread. Measured:
/// docs/decisions/node-threads.md.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum NodeThreads {
    /// Receive, decide and send on one thread (`component::spawn_one`).
    #[default]
    #[cfg_attr(feature = "clap", value(name = "1"))]
    One,
    /// Receive, pipeline and send threads (`component::spawn`).
    #[cfg_attr(feature = "clap", value(name = "3"))]
    Three,
}

impl NodeThreads {
    /// How many threads.
    pub fn count(self) -> u8 {
        match self {
            NodeThreads::One => 1,
            NodeThreads::Three => 3,
        }
    }
}

/// The node as a part on the bus. [`NodeService::start`] runs it on its own thread, which is
/// what `presrs node` does. [`component::run`] runs it on the caller's thread, with
/// [`RunOptions::clock`] set to the bus's clock (its deadlines compare with the frames'
/// receive times) and [`RunOptions::link`] to [`NodeService::link_stats`] (NodeStatus reports
/// the link).
impl Component for NodeService {
    fn name(&self) -> &'static str {
        "pipeline"
    }

    /// A foot's tactile stream and switch, and the controller's gait, under the ids the config
    /// gives: the kernel keeps the rest of the bus (the leg's 500 Hz state and commands) from
    /// waking the node. Every frame when a recorder taps it.
    fn filters(&self) -> Vec<(u32, u32)> {
        if self.read_all {
            return Vec::new();
        }
        self.ids().filters(&[
            MessageKind::FootContact,
            MessageKind::TactileFrame,
            MessageKind::TactileFrameClassic,
            MessageKind::GaitStatus,
        ])
    }

    fn on_frame(&mut self, st: &Stamped, now_us: u64, out: &mut Outbox) {
        let t0 = Instant::now();
        let mut said = std::mem::take(&mut self.said);
        self.process(st, &mut said);
        let decided = said.iter().any(|o| matches!(o, Output::Class { .. }));
        self.send_said(&mut said, out);
        let ns = t0.elapsed().as_nanos() as u64;
        let s = &mut self.stages;
        s.frames += 1;
        s.frame_ns += ns;
        if decided {
            s.decided += 1;
            s.decided_ns += ns;
            let wait = now_us.saturating_sub(st.t_us);
            s.decided_wait_us += wait;
            s.decided_max_us = s.decided_max_us.max(wait + ns / 1000);
        }
    }

    fn expected_frame_us(&self) -> Option<u64> {
        self.pipeline.next_decision().map(|(_, at)| at)
    }

    fn warm_up(&mut self) {
        if let Some((Some(foot), _)) = self.pipeline.next_decision() {
            self.pipeline.warm_up(foot);
        }
    }

    fn tick(&mut self, now_us: u64, out: &mut Outbox) {
        let mut said = std::mem::take(&mut self.said);
        NodeService::tick(self, now_us, &mut said);
        self.send_said(&mut said, out);
        // A log line every 10 s: never per frame.
        if self.last_log.elapsed() >= Duration::from_secs(10) {
            let c = self.counters();
            let r = self.reassembly_stats();
            let last = self.last_logged;
            let unknown = self.tally.unknown();
            tracing::info!(
                frames = c.frames - last.frames,
                steps = c.steps - last.steps,
                classified = c.classified - last.classified,
                unknown = unknown - self.last_logged_unknown,
                unknown_by_reason = %c.unknown_by_reason,
                unknown_by_gait = %self.describe_gaits(),
                no_sample = c.no_sample - last.no_sample,
                decode_errors = c.decode_errors - last.decode_errors,
                images = r.delivered,
                crc_failures = r.crc_failures,
                incomplete = r.incomplete,
                rx_dropped = self.shared.link.rx_dropped.load(Ordering::Relaxed),
                damage_pct = self.damage_pct(),
                "last 10 s"
            );
            self.last_logged = c;
            self.last_logged_unknown = unknown;
            self.last_log = Instant::now();
        }
    }

    fn stop(&mut self, _: u64, out: &mut Outbox) {
        let last = Output::Status(self.status(true));
        if let Some(f) = self.frame(&last) {
            out.push(f);
        }
    }

    /// TerrainClass and NodeStatus: the node is their one sender.
    fn is_own(&self, frame: &CanFrame) -> bool {
        matches!(
            self.ids().lookup(frame.raw_id(), frame.is_extended()),
            Some((MessageKind::TerrainClass | MessageKind::NodeStatus, _))
        )
    }
}
