//! Recording while the robot runs, off the hot path. The threads that see frames offer them to
//! a [`LiveTap`]: a copy into a bounded queue, which never waits and never allocates; a full
//! queue drops the frame and counts it. One writer thread decodes, reassembles and writes to
//! every sink. A sink that fails (disk full, path gone) is logged by name and dropped; the
//! process and the other sinks go on. Outputs with an encoding of their own (ROS 2's CDR) are
//! [`FrameConsumer`]s on the same thread: they see every frame the tap kept.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crossbeam_channel::{Receiver, Sender, TryRecvError, TrySendError, bounded};
use protocol::Stamped;
use protocol::bus::{BusSource, Tap, open_with_retry};
use protocol::component::{self, Component, Outbox, RunOptions};

use crate::RecordError;
use crate::recorder::{Channel, RecordStats, Recorder, SimTruth, Sink};

/// Chunks are closed (and so readable after a SIGKILL) at least this often.
const FLUSH_PERIOD: Duration = Duration::from_secs(1);

/// The writer drains the queue this often: 200 frames of six feet's traffic, far below its
/// capacity.
const POLL: Duration = Duration::from_millis(10);

enum Entry {
    Frame(Stamped),
    Truth {
        t_us: u64,
        foot: u8,
        truth: SimTruth,
    },
}

/// The recorder's end that the process's threads hold. Cloning the `Arc` is how several
/// threads share it.
pub struct LiveTap {
    tx: Sender<Entry>,
    dropped: AtomicU64,
}

impl Tap for LiveTap {
    fn offer(&self, frame: &Stamped) {
        self.push(Entry::Frame(*frame));
    }
    fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }
    fn backlog(&self) -> f64 {
        self.tx.len() as f64 / self.tx.capacity().unwrap_or(usize::MAX).max(1) as f64
    }
}

impl LiveTap {
    fn push(&self, e: Entry) {
        match self.tx.try_send(e) {
            Ok(()) => {}
            Err(TrySendError::Full(_)) | Err(TrySendError::Disconnected(_)) => {
                self.dropped.fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    /// The simulator's truth for leg `foot` at `t_us` (same clock as the frames).
    pub fn offer_truth(&self, t_us: u64, foot: u8, truth: SimTruth) {
        self.push(Entry::Truth { t_us, foot, truth });
    }
}

/// An output that decodes frames itself (the ROS 2 bridge: CDR on Zenoh, rosbag2), fed by
/// the writer thread beside the JSON sinks. An error drops it (logged by name); the rest go on.
pub trait FrameConsumer: Send {
    /// A frame the tap kept; `dropped`: frames the tap has dropped so far (the queue was full).
    fn frame(&mut self, frame: &Stamped, dropped: u64) -> Result<(), RecordError>;
    /// About once a second: make what was written readable, check the network.
    fn flush(&mut self) -> Result<(), RecordError> {
        Ok(())
    }
    /// The recording ends: deliver or write what is left. Called once.
    fn finish(&mut self) -> Result<(), RecordError>;
}

/// How a live recording ended.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct LiveSummary {
    /// What was recorded.
    pub stats: RecordStats,
    /// Frames dropped because the writer was behind (or all sinks had failed).
    pub dropped: u64,
    /// Sinks that failed, with their error.
    pub failed: Vec<String>,
}

/// A writer thread and its tap.
pub struct LiveRecorder {
    tap: Arc<LiveTap>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<LiveSummary>>,
}

impl LiveRecorder {
    /// Starts the writer thread for `sinks` (each with a name for the log: its path or
    /// address). `capacity`: frames the queue holds while the writer is busy.
    pub fn start(
        recorder: Recorder,
        sinks: Vec<(String, Box<dyn Sink>)>,
        capacity: usize,
    ) -> Result<Self, RecordError> {
        Self::start_with(recorder, sinks, Vec::new(), capacity)
    }

    /// [`LiveRecorder::start`] with [`FrameConsumer`]s beside the sinks.
    pub fn start_with(
        recorder: Recorder,
        sinks: Vec<(String, Box<dyn Sink>)>,
        consumers: Vec<(String, Box<dyn FrameConsumer>)>,
        capacity: usize,
    ) -> Result<Self, RecordError> {
        let (tx, rx) = bounded(capacity.max(1));
        let tap = Arc::new(LiveTap {
            tx,
            dropped: AtomicU64::new(0),
        });
        let stop = Arc::new(AtomicBool::new(false));
        let (t, s) = (tap.clone(), stop.clone());
        let thread = std::thread::Builder::new()
            .name("record".into())
            .spawn(move || writer_loop(recorder, sinks, consumers, rx, &t, &s))
            .map_err(RecordError::Spawn)?;
        Ok(Self {
            tap,
            stop,
            thread: Some(thread),
        })
    }

    /// The tap to offer frames to.
    pub fn tap(&self) -> Arc<LiveTap> {
        self.tap.clone()
    }

    /// Writes what is queued, completes every sink (an MCAP file's summary and indexes) and
    /// returns the counts.
    pub fn finish(mut self) -> LiveSummary {
        self.stop.store(true, Ordering::Relaxed);
        let mut s = self
            .thread
            .take()
            .and_then(|t| t.join().ok())
            .unwrap_or_default();
        s.dropped = self.tap.dropped();
        s
    }
}

/// A recorder beside a process that does not record itself, as a part on the bus: it reads
/// every frame (no filter) and sends none; the runner's tap keeps each one.
struct Listener;

impl Component for Listener {
    fn name(&self) -> &'static str {
        "record"
    }
    fn filters(&self) -> Vec<(u32, u32)> {
        Vec::new()
    }
    fn on_frame(&mut self, _: &Stamped, _: u64, _: &mut Outbox) {}
    fn tick(&mut self, _: u64, _: &mut Outbox) {}
}

/// Reads every frame on `source` into `tap` on a thread of its own until `stop`: a recorder
/// beside a process that does not record itself (SocketCAN delivers that process's frames to
/// this second socket too). Opened before it returns, so no early frame is missed; reopened
/// after a bus error.
pub fn listen(
    source: BusSource,
    tap: Arc<LiveTap>,
    stop: Arc<AtomicBool>,
) -> Result<JoinHandle<()>, RecordError> {
    let bus = open_with_retry(&source, &stop, "record", &mut || {});
    std::thread::Builder::new()
        .name("record-listen".into())
        .spawn(move || {
            if bus.is_none() {
                return;
            }
            let opts = RunOptions {
                tick: Duration::from_millis(50),
                tap: Some(tap),
                // The process stops this listener when it is done: its last frames are in
                // the socket by then, not yet read.
                drain_on_stop: Some(Duration::from_millis(500)),
                ..RunOptions::default()
            };
            component::run_opened(&mut Listener, bus, &source, &opts, &stop);
        })
        .map_err(RecordError::Spawn)
}

impl Drop for LiveRecorder {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Several sinks as one: a failing sink is logged and dropped, the others go on.
struct Fanout {
    sinks: Vec<(String, Box<dyn Sink>)>,
    failed: Vec<String>,
}

impl Fanout {
    fn each(&mut self, f: &mut dyn FnMut(&mut dyn Sink) -> Result<(), RecordError>) {
        let mut i = 0;
        while i < self.sinks.len() {
            match f(self.sinks[i].1.as_mut()) {
                Ok(()) => i += 1,
                Err(e) => {
                    let (name, _) = self.sinks.remove(i);
                    tracing::error!(
                        "recording to {name} stopped: {e}; the process goes on without it"
                    );
                    self.failed.push(e.to_string());
                }
            }
        }
    }
}

/// Calls `f` on each consumer; one that fails is logged, dropped and its error kept.
fn each_consumer(
    consumers: &mut Vec<(String, Box<dyn FrameConsumer>)>,
    failed: &mut Vec<String>,
    f: &mut dyn FnMut(&mut dyn FrameConsumer) -> Result<(), RecordError>,
) {
    let mut i = 0;
    while i < consumers.len() {
        match f(consumers[i].1.as_mut()) {
            Ok(()) => i += 1,
            Err(e) => {
                let (name, _) = consumers.remove(i);
                tracing::error!("{name} stopped: {e}; the process goes on without it");
                failed.push(e.to_string());
            }
        }
    }
}

impl Sink for Fanout {
    fn add_channel(&mut self, index: usize, channel: &Channel) -> Result<(), RecordError> {
        self.each(&mut |s| s.add_channel(index, channel));
        Ok(())
    }
    fn write(&mut self, index: usize, t: u64, data: &[u8]) -> Result<(), RecordError> {
        self.each(&mut |s| s.write(index, t, data));
        Ok(())
    }
    fn flush(&mut self) -> Result<(), RecordError> {
        self.each(&mut |s| s.flush());
        Ok(())
    }
    fn finish(&mut self) -> Result<(), RecordError> {
        self.each(&mut |s| s.finish());
        Ok(())
    }
}

fn writer_loop(
    mut rec: Recorder,
    sinks: Vec<(String, Box<dyn Sink>)>,
    mut consumers: Vec<(String, Box<dyn FrameConsumer>)>,
    rx: Receiver<Entry>,
    tap: &LiveTap,
    stop: &AtomicBool,
) -> LiveSummary {
    let mut out = Fanout {
        sinks,
        failed: Vec::new(),
    };
    let mut last_flush = Instant::now();
    let mut dropped_logged = 0;
    loop {
        // Drains, then sleeps: a writer blocked in `recv` would make every `offer` wake it
        // (docs/decisions/figures-behind-comments.md, recorder-polling). Polling keeps
        // `offer` a plain store.
        // Read before draining: whatever was offered before the stop is drained below.
        let stopping = stop.load(Ordering::Relaxed);
        let mut disconnected = false;
        loop {
            match rx.try_recv() {
                Ok(e) => {
                    rec.set_recording_dropped(tap.dropped());
                    // The fan-out never fails as a whole: its sinks fail one by one.
                    let _ = match e {
                        Entry::Frame(st) => {
                            let dropped = tap.dropped();
                            each_consumer(&mut consumers, &mut out.failed, &mut |c| {
                                c.frame(&st, dropped)
                            });
                            // JSON only where a sink takes it (a ROS 2-only run skips it).
                            if out.sinks.is_empty() {
                                Ok(())
                            } else {
                                rec.frame(&st, &mut out)
                            }
                        }
                        Entry::Truth { t_us, foot, truth } if !out.sinks.is_empty() => {
                            rec.sim_truth(t_us, foot, &truth, &mut out)
                        }
                        Entry::Truth { .. } => Ok(()),
                    };
                }
                Err(TryRecvError::Empty) => break,
                Err(TryRecvError::Disconnected) => {
                    disconnected = true;
                    break;
                }
            }
        }
        let none_left = out.sinks.is_empty() && consumers.is_empty();
        if disconnected || stopping || none_left {
            if none_left {
                tracing::error!("every recording sink has failed: recording stopped");
            }
            break;
        }
        if last_flush.elapsed() >= FLUSH_PERIOD {
            last_flush = Instant::now();
            let _ = out.flush();
            each_consumer(&mut consumers, &mut out.failed, &mut |c| c.flush());
            let dropped = tap.dropped();
            if dropped > dropped_logged {
                tracing::warn!(
                    dropped_total = dropped,
                    "recorder behind: {} frames dropped in the last second (not recorded)",
                    dropped - dropped_logged
                );
                dropped_logged = dropped;
            }
        }
        std::thread::sleep(POLL);
    }
    let _ = out.finish();
    each_consumer(&mut consumers, &mut out.failed, &mut |c| c.finish());
    LiveSummary {
        stats: rec.stats(),
        dropped: tap.dropped(),
        failed: out.failed,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use protocol::messages::{FootContact, Message};
    use protocol::{IdConfig, TerrainCatalog};
    use std::sync::Mutex;

    #[derive(Clone, Default)]
    struct Counting(Arc<Mutex<(u64, bool)>>, Option<u64>);
    impl Sink for Counting {
        fn add_channel(&mut self, _: usize, _: &Channel) -> Result<(), RecordError> {
            Ok(())
        }
        fn write(&mut self, _: usize, _: u64, _: &[u8]) -> Result<(), RecordError> {
            let mut g = self.0.lock().unwrap();
            g.0 += 1;
            if self.1.is_some_and(|n| g.0 >= n) {
                return Err(RecordError::Internal("full"));
            }
            Ok(())
        }
        fn flush(&mut self) -> Result<(), RecordError> {
            Ok(())
        }
        fn finish(&mut self) -> Result<(), RecordError> {
            self.0.lock().unwrap().1 = true;
            Ok(())
        }
    }

    fn contact(t_us: u64) -> Stamped {
        Stamped {
            t_us,
            frame: Message::FootContact(FootContact::default())
                .to_frame(&IdConfig::default(), 0)
                .unwrap(),
        }
    }

    #[test]
    fn a_full_queue_drops_and_counts_and_what_was_queued_is_written() {
        let good = Counting::default();
        let rec = Recorder::new(IdConfig::default(), TerrainCatalog::paper());
        let live =
            LiveRecorder::start(rec, vec![("mem".into(), Box::new(good.clone()))], 4).unwrap();
        let tap = live.tap();
        for t in 0..10_000 {
            tap.offer(&contact(t));
        }
        let s = live.finish();
        let written = good.0.lock().unwrap().0;
        assert_eq!(written + s.dropped, 10_000, "each frame written or counted");
        assert!(
            s.dropped > 0,
            "a queue of 4 cannot take 10,000 frames at once"
        );
        assert!(good.0.lock().unwrap().1, "finished");
    }

    #[test]
    fn a_failing_sink_is_dropped_and_the_other_goes_on() {
        let (bad, good) = (Counting(Default::default(), Some(3)), Counting::default());
        let rec = Recorder::new(IdConfig::default(), TerrainCatalog::paper());
        let live = LiveRecorder::start(
            rec,
            vec![
                ("bad".into(), Box::new(bad.clone())),
                ("good".into(), Box::new(good.clone())),
            ],
            1024,
        )
        .unwrap();
        let tap = live.tap();
        for t in 0..100 {
            tap.offer(&contact(t));
        }
        let s = live.finish();
        assert_eq!(good.0.lock().unwrap().0, 100);
        assert_eq!(bad.0.lock().unwrap().0, 3);
        assert_eq!(s.failed.len(), 1);
    }
}

/// What to record live, as a process's `--mcap FILE` and `--foxglove [ADDR]` options give it
/// (with the `clap` feature, those options themselves: `#[command(flatten)]`).
#[derive(Clone, Debug, Default)]
#[cfg_attr(feature = "clap", derive(clap::Args))]
pub struct LiveOptions {
    /// Record every frame seen and sent to this MCAP file, off the hot path (frames are
    /// dropped and counted, never waited for, when the disk is slower than the bus).
    #[cfg_attr(feature = "clap", arg(long, value_name = "FILE"))]
    pub mcap: Option<std::path::PathBuf>,
    /// Serve the same channels live to the Foxglove app (Open connection -> Foxglove
    /// WebSocket, ws://HOST:PORT; port 0 picks one and the log names it).
    #[cfg_attr(
        feature = "clap",
        arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = "127.0.0.1:8765")
    )]
    pub foxglove: Option<String>,
}

/// About 1.5 s of six feet's traffic (20,000 frames/s): the writer may stall that long (a
/// slow disk, a chunk being written) before frames are dropped. 88 bytes each: 2.9 MB.
pub const LIVE_QUEUE: usize = 32_768;

impl LiveOptions {
    /// The recorder for these options, or `None` when none is asked for or none could start.
    /// A sink that cannot start is an error in the log, naming its path or address; the
    /// caller runs on without it.
    pub fn start(
        &self,
        ids: &protocol::IdConfig,
        catalog: &protocol::TerrainCatalog,
    ) -> Option<LiveRecorder> {
        self.start_with(ids, catalog, Vec::new())
    }

    /// [`LiveOptions::start`] with outputs of other encodings beside (the ROS 2 bridge); a
    /// recorder starts when any sink or consumer is asked for.
    pub fn start_with(
        &self,
        ids: &protocol::IdConfig,
        catalog: &protocol::TerrainCatalog,
        consumers: Vec<(String, Box<dyn FrameConsumer>)>,
    ) -> Option<LiveRecorder> {
        let mut sinks: Vec<(String, Box<dyn Sink>)> = Vec::new();
        if let Some(p) = &self.mcap {
            match crate::McapFile::create(p) {
                Ok(f) => {
                    tracing::info!(file = %p.display(), "recording to MCAP");
                    sinks.push((p.display().to_string(), Box::new(f)));
                }
                Err(e) => tracing::error!("--mcap: {e}; running without the recording"),
            }
        }
        if let Some(addr) = &self.foxglove {
            foxglove_sink(addr, &mut sinks);
        }
        if sinks.is_empty() && consumers.is_empty() {
            return None;
        }
        match LiveRecorder::start_with(
            Recorder::new(ids.clone(), catalog.clone()),
            sinks,
            consumers,
            LIVE_QUEUE,
        ) {
            Ok(r) => Some(r),
            Err(e) => {
                tracing::error!("{e}; running without the recording");
                None
            }
        }
    }
}

#[cfg(feature = "foxglove")]
fn foxglove_sink(addr: &str, sinks: &mut Vec<(String, Box<dyn Sink>)>) {
    match crate::FoxgloveServer::start(addr) {
        Ok(s) => {
            tracing::info!(
                "Foxglove view on ws://{}:{} (Foxglove app: Open connection -> Foxglove WebSocket)",
                addr.rsplit_once(':').map_or(addr, |(h, _)| h),
                s.port()
            );
            sinks.push((format!("ws://{addr}"), Box::new(s)));
        }
        Err(e) => tracing::error!("--foxglove: {e}; running without the live view"),
    }
}

#[cfg(not(feature = "foxglove"))]
fn foxglove_sink(addr: &str, _: &mut Vec<(String, Box<dyn Sink>)>) {
    tracing::error!(
        "--foxglove {addr}: this presrs was built without the `foxglove` feature; running without the live view"
    );
}

impl LiveRecorder {
    /// [`LiveRecorder::finish`], saying in the log what the recording holds.
    pub fn finish_logged(self) -> LiveSummary {
        let s = self.finish();
        tracing::info!(
            messages = s.stats.messages,
            images = s.stats.images,
            dropped = s.dropped,
            failed_sinks = s.failed.len(),
            "recording finished"
        );
        s
    }

    /// The tap as a process's bus loops take it.
    pub fn bus_tap(&self) -> Arc<dyn Tap> {
        self.tap()
    }
}
