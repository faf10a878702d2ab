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
//! Started, three threads joined by bounded channels:
//! - `receive` reads the bus and never blocks on the others: a full queue drops the frame and
//!   counts it (`rx_dropped`);
//! - `pipeline` owns the service: reassembly, stance tracking, classification, ticks and model
//!   reloads ([`RunningNode::reload_model`] hands it a model already loaded and checked);
//! - `send` writes TerrainClass and NodeStatus frames.
//!
//! Receive and send each open their own handle with retry and backoff: a missing interface, or
//! one that goes down, shows as `Degraded` in NodeStatus and in the log, never as an exit.

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU8, AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crossbeam_channel::{Receiver, RecvTimeoutError, Sender, TrySendError, bounded};
use protocol::bus::{
    Backoff, BusHealth, BusSource, ControllerState, HealthWatch, Tap, after_bus_error,
    open_with_retry,
};
use protocol::clock::Clock;
use protocol::component::{Component, Outbox};
use protocol::messages::{Message, NodeState, NodeStatus, TerrainClass};
use protocol::tactile::ReassemblyStats;
use protocol::terrain::CatalogError;
use protocol::{CanFrame, IdConfig, MessageKind, Stamped, TerrainCatalog};
use thiserror::Error;

use crate::classifier::Model;
use crate::classifier::model::{CatalogMismatch, ModelError};
use crate::config::NodeConfig;
use crate::stance::{Counters, StancePipeline};

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

/// What the node says: frames for the bus, as messages.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Output {
    /// One step's decision (exactly one per step).
    Class {
        /// The foot that stepped.
        foot: u8,
        /// The decision.
        class: TerrainClass,
    },
    /// The heartbeat, at `status_hz`.
    Status(NodeStatus),
}

impl Output {
    /// The frame that carries this on `ids`: TerrainClass on its foot's id, NodeStatus on
    /// the node's.
    pub fn to_frame(&self, ids: &IdConfig) -> Option<CanFrame> {
        match *self {
            Output::Class { foot, class } => Message::TerrainClass(class).to_frame(ids, foot),
            Output::Status(s) => Message::NodeStatus(s).to_frame(ids, 0),
        }
    }
}

/// The counters a running node shares between its threads, written without locks.
#[derive(Debug, Default)]
struct Shared {
    state: AtomicU8,
    /// The CAN controller's state ([`ControllerState`] as u8) from the receive handle's error
    /// frames.
    controller: AtomicU8,
    model_id: AtomicU64,
    damage_bits: AtomicU64,
    bus_errors: AtomicU64,
    rx_frames: AtomicU64,
    rx_dropped: AtomicU64,
    tx_frames: AtomicU64,
    tx_dropped: AtomicU64,
    steps: AtomicU64,
    classified: AtomicU64,
    no_sample: AtomicU64,
    images: AtomicU64,
    crc_failures: AtomicU64,
    incomplete: AtomicU64,
    decode_errors: AtomicU64,
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
}

impl Shared {
    fn publish(&self, c: &Counters, r: &ReassemblyStats, damage_pct: f64) {
        let r_ = Ordering::Relaxed;
        self.steps.store(c.steps, r_);
        self.classified.store(c.classified, r_);
        self.no_sample.store(c.no_sample, r_);
        self.decode_errors.store(c.decode_errors, r_);
        self.images.store(r.delivered, r_);
        self.crc_failures.store(r.crc_failures, r_);
        self.incomplete.store(r.incomplete, r_);
        self.damage_bits.store(damage_pct.to_bits(), r_);
    }

    fn snapshot(&self) -> NodeStats {
        let l = |a: &AtomicU64| a.load(Ordering::Relaxed);
        NodeStats {
            state: self.state(),
            model_id: l(&self.model_id),
            damage_pct: f64::from_bits(l(&self.damage_bits)),
            rx_frames: l(&self.rx_frames),
            rx_dropped: l(&self.rx_dropped),
            tx_frames: l(&self.tx_frames),
            tx_dropped: l(&self.tx_dropped),
            bus_errors: l(&self.bus_errors),
            steps: l(&self.steps),
            classified: l(&self.classified),
            no_sample: l(&self.no_sample),
            images: l(&self.images),
            crc_failures: l(&self.crc_failures),
            incomplete: l(&self.incomplete),
            decode_errors: l(&self.decode_errors),
            record_dropped: 0,
        }
    }

    /// The node's state, the CAN controller's error state first: a bus-off or error-passive
    /// controller explains whatever else the node sees.
    fn state(&self) -> NodeState {
        match self.controller.load(Ordering::Relaxed) {
            c if c == ControllerState::BusOff as u8 => NodeState::BusOff,
            c if c == ControllerState::Passive as u8 => NodeState::ErrorPassive,
            _ => NodeState::from_u8(self.state.load(Ordering::Relaxed)).unwrap_or_default(),
        }
    }

    fn set_state(&self, s: NodeState) {
        self.state.store(s as u8, Ordering::Relaxed);
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
        shared.set_state(NodeState::Running);
        let status_period_us = (1e6 / config.status_hz.max(0.1)) as u64;
        Ok(Self {
            pipeline: StancePipeline::new(config, Some(model)),
            catalog,
            status_period_us,
            next_status_us: None,
            heartbeat: 0,
            shared,
            said: Vec::with_capacity(16),
        })
    }

    /// Measures decisions' latency (TerrainClass `latency_us`) on `clock`, read when each
    /// decision is made, instead of on the driver's time. [`NodeService::start`] sets the bus's
    /// clock; a caller driving the node itself sets one when frames may reach it late.
    pub fn set_clock(&mut self, clock: Arc<dyn Clock>) {
        self.pipeline.set_clock(clock);
    }

    /// One received frame; the decisions it completes go to `out`.
    pub fn process(&mut self, frame: &Stamped, out: &mut impl FnMut(Output)) {
        self.pipeline
            .on_frame(frame, &mut |foot, class| out(Output::Class { foot, class }));
    }

    /// A recorded run on its own clock: each frame's time ticks the node before the frame is
    /// processed, as a live node's clock would have, so a replay decides as the robot did.
    /// `out` hears each output with the time it came at.
    pub fn replay<'a>(
        &mut self,
        frames: impl IntoIterator<Item = &'a Stamped>,
        out: &mut impl FnMut(u64, Output),
    ) {
        for f in frames {
            let t = f.t_us;
            self.tick(t, &mut |o| out(t, o));
            self.process(f, &mut |o| out(t, o));
        }
    }

    /// Everything due by `now_us` (the clock of [`Stamped::t_us`]): steps whose sample deadline
    /// has passed with no nearer frame possible, and NodeStatus when a status period is up.
    pub fn tick(&mut self, now_us: u64, out: &mut impl FnMut(Output)) {
        self.pipeline.tick(now_us, &mut |foot, class| {
            out(Output::Class { foot, class })
        });
        // A clock that jumped back (a new bus clock) must not silence the heartbeat.
        let due = self
            .next_status_us
            .is_none_or(|t| now_us >= t || t > now_us + self.status_period_us);
        if due {
            self.next_status_us = Some(now_us + self.status_period_us);
            out(Output::Status(self.status(false)));
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
        self.shared
            .publish(&self.pipeline.counters, &r, self.pipeline.damage_pct());
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
            bus_errors: low8(self.shared.bus_errors.load(Ordering::Relaxed)),
            damage_pct: self.pipeline.damage_pct(),
        }
    }

    /// Loads, checks and installs the model at `path`; returns its id. A bad file leaves the
    /// model already loaded in place.
    pub fn reload_model(&mut self, path: &Path) -> Result<u64, ServiceError> {
        let model = Model::load(path)?;
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
        let mut node = self;
        let clock = bus.clock();
        node.set_clock(clock.clone());
        let shared = node.shared.clone();
        shared.set_state(NodeState::Starting);
        let stop = Arc::new(AtomicBool::new(false));
        // About 0.4 s of one foot's FD tactile stream: room for the pipeline to fall briefly behind.
        let (rx_tx, rx_rx) = bounded::<Stamped>(16_384);
        let (out_tx, out_rx) = bounded::<CanFrame>(256);
        let (model_tx, model_rx) = bounded::<Model>(2);
        let spawn = |name: &'static str, f: Box<dyn FnOnce() + Send>| {
            std::thread::Builder::new()
                .name(name.into())
                .spawn(f)
                .map_err(|source| ServiceError::Spawn {
                    thread: name,
                    source,
                })
        };
        let label = bus.label().to_string();
        let catalog = node.catalog.clone();
        let mut threads = Vec::new();
        {
            let (bus, stop, sh) = (bus.clone(), stop.clone(), shared.clone());
            let h = spawn(
                "receive",
                Box::new(move || receive_loop(&bus, &stop, &sh, rx_tx)),
            )?;
            threads.push(("receive", h));
        }
        {
            let (st, sh, tap) = (stop.clone(), shared.clone(), tap.clone());
            let h = spawn(
                "pipeline",
                Box::new(move || {
                    pipeline_loop(
                        node,
                        &*clock,
                        &st,
                        &sh,
                        tap.as_deref(),
                        rx_rx,
                        model_rx,
                        out_tx,
                    )
                }),
            );
            match h {
                Ok(h) => threads.push(("pipeline", h)),
                Err(e) => {
                    stop.store(true, Ordering::Relaxed);
                    join(threads);
                    return Err(e);
                }
            }
        }
        {
            let (st, sh) = (stop.clone(), shared.clone());
            let h = spawn("send", Box::new(move || send_loop(&bus, &st, &sh, out_rx)));
            match h {
                Ok(h) => threads.push(("send", h)),
                Err(e) => {
                    stop.store(true, Ordering::Relaxed);
                    join(threads);
                    return Err(e);
                }
            }
        }
        tracing::info!(iface = %label, "presrs node started");
        Ok(RunningNode {
            stop,
            catalog,
            models: model_tx,
            shared,
            tap,
            threads,
        })
    }
}

/// A node running on its threads (from [`NodeService::start`]).
pub struct RunningNode {
    stop: Arc<AtomicBool>,
    catalog: TerrainCatalog,
    models: Sender<Model>,
    shared: Arc<Shared>,
    tap: Option<Arc<dyn Tap>>,
    threads: Vec<(&'static str, JoinHandle<()>)>,
}

impl RunningNode {
    /// Loads and checks the model at `path` on the caller's thread, then hands it to the
    /// pipeline, which installs it between two frames; returns its id. A bad file is an error
    /// here and the running model stays.
    pub fn reload_model(&self, path: &Path) -> Result<u64, ServiceError> {
        let model = Model::load(path)?;
        model.check_catalog(&self.catalog)?;
        let id = model.id();
        self.models.send(model).map_err(|_| ServiceError::Stopped)?;
        Ok(id)
    }

    /// The terrains the node reports.
    pub fn catalog(&self) -> &TerrainCatalog {
        &self.catalog
    }

    /// The counters now.
    pub fn stats(&self) -> NodeStats {
        NodeStats {
            record_dropped: self.tap.as_ref().map_or(0, |t| t.dropped()),
            ..self.shared.snapshot()
        }
    }

    /// True while every thread runs.
    pub fn is_running(&self) -> bool {
        self.threads.iter().all(|(_, h)| !h.is_finished())
    }

    /// Stops the threads (a last NodeStatus says `Stopping`), joins them and returns the final
    /// counters.
    pub fn stop(self) -> NodeStats {
        self.stop.store(true, Ordering::Relaxed);
        join(self.threads);
        let s = NodeStats {
            record_dropped: self.tap.as_ref().map_or(0, |t| t.dropped()),
            ..self.shared.snapshot()
        };
        tracing::info!(
            rx_frames = s.rx_frames,
            rx_dropped = s.rx_dropped,
            tx_frames = s.tx_frames,
            tx_dropped = s.tx_dropped,
            bus_errors = s.bus_errors,
            steps = s.steps,
            classified = s.classified,
            record_dropped = s.record_dropped,
            "presrs node stopped"
        );
        s
    }
}

fn join(threads: Vec<(&'static str, JoinHandle<()>)>) {
    for (name, h) in threads {
        if h.join().is_err() {
            tracing::error!("the node's {name} thread panicked");
        }
    }
}

/// The node as a part on the bus, on one thread: [`protocol::component::run`] runs it with
/// [`RunOptions::clock`](protocol::component::RunOptions) set to the bus's clock (its deadlines
/// compare with the frames' receive times). [`NodeService::start`] runs the same node on three
/// threads (receive, pipeline, send), which is what `presrs node` does: measured with
/// `presrs bench-node`, the receive thread keeps a burst of six feet's images from waiting
/// behind a classification.
impl Component for NodeService {
    fn name(&self) -> &'static str {
        "node"
    }

    /// Every frame: a foot's tactile stream and switch, under the ids the config gives.
    fn filters(&self) -> Vec<(u32, u32)> {
        Vec::new()
    }

    fn start(&mut self, _: u64, _: &mut Outbox) {
        self.shared.set_state(NodeState::Running);
    }

    fn on_frame(&mut self, st: &Stamped, _: u64, out: &mut Outbox) {
        let mut said = std::mem::take(&mut self.said);
        self.process(st, &mut |o| said.push(o));
        self.send_said(&mut said, out);
    }

    fn tick(&mut self, now_us: u64, out: &mut Outbox) {
        let mut said = std::mem::take(&mut self.said);
        NodeService::tick(self, now_us, &mut |o| said.push(o));
        self.send_said(&mut said, out);
    }

    fn on_health(&mut self, health: &BusHealth, _: u64) {
        self.shared
            .controller
            .store(health.state as u8, Ordering::Relaxed);
    }

    fn stop(&mut self, _: u64, out: &mut Outbox) {
        let last = Output::Status(self.status(true));
        if let Some(f) = self.frame(&last) {
            out.push(f);
        }
    }
}

fn receive_loop(bus: &BusSource, stop: &AtomicBool, sh: &Shared, to_pipeline: Sender<Stamped>) {
    let mut backoff = Backoff::default();
    let degrade = &mut || sh.set_state(NodeState::Degraded);
    let mut watch = HealthWatch::default();
    while !stop.load(Ordering::Relaxed) {
        let Some(mut rx) = open_with_retry(bus, stop, "receive", degrade) else {
            break;
        };
        backoff.reset();
        sh.set_state(NodeState::Running);
        // Error frames of this handle already in `bus_errors`.
        let mut counted = 0u64;
        while !stop.load(Ordering::Relaxed) {
            let got = rx.recv(Duration::from_millis(20));
            let h = rx.health();
            if h.error_frames != counted {
                sh.bus_errors
                    .fetch_add(h.error_frames.saturating_sub(counted), Ordering::Relaxed);
                counted = h.error_frames;
            }
            if let Some(state) = watch.update("node receive", bus.label(), &h) {
                sh.controller.store(state as u8, Ordering::Relaxed);
            }
            match got {
                Ok(Some(st)) => {
                    sh.rx_frames.fetch_add(1, Ordering::Relaxed);
                    match to_pipeline.try_send(st) {
                        Ok(()) => {}
                        Err(TrySendError::Full(_)) => {
                            sh.rx_dropped.fetch_add(1, Ordering::Relaxed);
                        }
                        Err(TrySendError::Disconnected(_)) => return,
                    }
                }
                Ok(None) => {}
                Err(e) => {
                    sh.bus_errors.fetch_add(1, Ordering::Relaxed);
                    sh.set_state(NodeState::Degraded);
                    if !after_bus_error("receive", &e, &mut backoff, stop) {
                        return;
                    }
                    break;
                }
            }
        }
    }
}

#[allow(clippy::too_many_arguments)]
fn pipeline_loop(
    mut node: NodeService,
    clock: &dyn Clock,
    stop: &AtomicBool,
    sh: &Shared,
    tap: Option<&dyn Tap>,
    from_receive: Receiver<Stamped>,
    models: Receiver<Model>,
    to_send: Sender<CanFrame>,
) {
    // The node's clock is the bus's (that of the receive timestamps), read directly: anchored
    // to the last frame's timestamp instead, a node that had been stopped took the frames
    // queued meanwhile for "now".
    let mut next_tick_us = 0u64;
    let mut last_log = Instant::now();
    let mut last_counters = node.counters();
    let ids = node.ids().clone();
    // Sent frames reach the tap stamped with the node's clock at the decision.
    let mut t_out = 0u64;
    let emit = |t_us: u64, o: Output| {
        let Some(f) = o.to_frame(&ids) else {
            return;
        };
        if let Some(tap) = tap {
            tap.offer(&Stamped { t_us, frame: f });
        }
        if to_send.try_send(f).is_err() {
            sh.tx_dropped.fetch_add(1, Ordering::Relaxed);
        }
    };
    loop {
        if let Ok(m) = models.try_recv() {
            match node.set_model(m) {
                Ok(id) => tracing::info!(model_id = id, "model reloaded"),
                Err(e) => tracing::error!("{e}; keeping the model already loaded"),
            }
        }
        match from_receive.recv_timeout(Duration::from_millis(20)) {
            Ok(st) => {
                // The node's own frames come back through its receive handle (SocketCAN
                // loops them to the node's other socket): the tap has them from `emit`.
                if let Some(tap) = tap
                    && !matches!(
                        ids.lookup(st.frame.raw_id(), st.frame.is_extended()),
                        Some((MessageKind::TerrainClass | MessageKind::NodeStatus, _))
                    )
                {
                    tap.offer(&st);
                }
                node.process(&st, &mut |o| emit(st.t_us, o));
                t_out = st.t_us;
            }
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => {
                if !stop.load(Ordering::Relaxed) {
                    // The receive thread ended by itself: say so, then stop like a signal.
                    tracing::error!("the receive thread has exited; stopping the node");
                }
                break;
            }
        }
        if stop.load(Ordering::Relaxed) {
            break;
        }
        // Ticks at most once per millisecond of bus time, not per frame (about 20,000 frames/s
        // for six feet): deadlines and the heartbeat need no finer grain.
        let now = clock.now_us();
        if now >= next_tick_us || now + 1_000_000 < next_tick_us {
            next_tick_us = now + 1000;
            node.tick(now, &mut |o| emit(now, o));
            t_out = now;
        }
        // A log line every 10 s: never per frame.
        if last_log.elapsed() >= Duration::from_secs(10) {
            let c = node.counters();
            let r = node.reassembly_stats();
            tracing::info!(
                frames = c.frames - last_counters.frames,
                steps = c.steps - last_counters.steps,
                classified = c.classified - last_counters.classified,
                no_sample = c.no_sample - last_counters.no_sample,
                decode_errors = c.decode_errors - last_counters.decode_errors,
                images = r.delivered,
                crc_failures = r.crc_failures,
                incomplete = r.incomplete,
                rx_dropped = sh.rx_dropped.load(Ordering::Relaxed),
                record_dropped = tap.map_or(0, |t| t.dropped()),
                damage_pct = node.damage_pct(),
                "last 10 s"
            );
            last_counters = c;
            last_log = Instant::now();
        }
    }
    let last = node.status(true);
    emit(t_out, Output::Status(last));
}

fn send_loop(bus: &BusSource, stop: &AtomicBool, sh: &Shared, from_pipeline: Receiver<CanFrame>) {
    let mut backoff = Backoff::default();
    let degrade = &mut || sh.set_state(NodeState::Degraded);
    // Runs until the pipeline has stopped and its last frames (the final NodeStatus) are out.
    'open: loop {
        let Some(mut tx) = open_with_retry(bus, stop, "send", degrade) else {
            break;
        };
        backoff.reset();
        loop {
            let f = match from_pipeline.recv_timeout(Duration::from_millis(50)) {
                Ok(f) => f,
                Err(RecvTimeoutError::Timeout) => continue,
                Err(RecvTimeoutError::Disconnected) => break 'open,
            };
            match tx.send(&f) {
                Ok(()) => {
                    sh.tx_frames.fetch_add(1, Ordering::Relaxed);
                }
                Err(e) => {
                    sh.bus_errors.fetch_add(1, Ordering::Relaxed);
                    sh.tx_dropped.fetch_add(1, Ordering::Relaxed);
                    sh.set_state(NodeState::Degraded);
                    if !after_bus_error("send", &e, &mut backoff, stop) {
                        break 'open;
                    }
                    continue 'open;
                }
            }
        }
    }
}
