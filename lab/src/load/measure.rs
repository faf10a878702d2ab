//! Playing the schedule in real time and matching the node's TerrainClass per step.

use super::{
    AtomicBool, CanBus, Duration, Feet, HashMap, IdConfig, Instant, LoadError, Message, Ordering,
    SAMPLE_US, Sampled, TerrainClass, WARMUP_US, flags, messages, mpsc,
};

/// What a measured run saw.
#[derive(Clone, Debug, Default)]
pub struct Tally {
    /// Steps whose sampled frame was sent in the measured window.
    pub steps: u64,
    /// TerrainClass messages matched to those steps.
    pub decisions: u64,
    /// Of those, classified (not "no sample").
    pub classified: u64,
    /// Of those, the true terrain.
    pub correct: u64,
    /// Per classified step: the sampled frame's last segment sent -> TerrainClass received, µs.
    pub latencies_us: Vec<f64>,
    /// The same steps on the bus's clock: the last segment sent -> the TerrainClass's receive
    /// stamp (as a candump shows it), µs. Without the listener's own wake-up.
    pub bus_latencies_us: Vec<f64>,
    /// Of the decisions, those heard before the player had logged their step (see `listen`):
    /// counted, without a latency.
    pub heard_before_logged: u64,
    /// The node's last NodeStatus heard: its counts of failed and incomplete transfers say
    /// whether it lost frames (a step it never saw gets no TerrainClass).
    pub node_status: Option<messages::NodeStatus>,
    /// Frames the load could not send after retrying (a full socket buffer).
    pub send_errors: u64,
    /// The node's CPU time over the measured window, ns (when `cpu_ns` could read it).
    pub cpu_ns: Option<u64>,
}

/// Plays `feet` in real time for `total_us` on `tx` and matches each step's TerrainClass heard
/// on `rx`; `cpu_ns` reads the node's CPU time (at the start and end of the measured window),
/// `bus_us` the clock the bus stamps its frames with ([`protocol::bus::BusSource::clock`]).
pub fn measure(
    tx: &mut dyn CanBus,
    rx: &mut dyn CanBus,
    ids: &IdConfig,
    mut feet: Feet,
    total_us: u64,
    cpu_ns: &dyn Fn() -> Option<u64>,
    bus_us: &dyn Fn() -> u64,
) -> Result<Tally, LoadError> {
    let (sent_tx, sent_rx) = mpsc::channel::<(Sampled, Instant, u64)>();
    let done = AtomicBool::new(false);
    std::thread::scope(|s| {
        let stop = &done;
        let listener = s.spawn(move || listen(rx, ids, &sent_rx, stop));
        let start = Instant::now();
        let (mut steps, mut send_errors, mut cpu_start) = (0u64, 0u64, None);
        let mut played = Ok(());
        loop {
            let t = feet.next_us();
            if t >= total_us {
                break;
            }
            if cpu_start.is_none() && t >= WARMUP_US {
                cpu_start = Some(cpu_ns());
            }
            let due = start + Duration::from_micros(t);
            let now = Instant::now();
            if due > now {
                std::thread::sleep(due - now);
            }
            let sampled = feet.emit(&mut |f| {
                // A full socket buffer (ENOBUFS) is retried briefly rather than lost.
                for _ in 0..50 {
                    if tx.send(&f).is_ok() {
                        return;
                    }
                    std::thread::sleep(Duration::from_micros(100));
                }
                send_errors += 1;
            });
            match sampled {
                Ok(Some(sm)) => {
                    steps += u64::from(measured(&sm));
                    let _ = sent_tx.send((sm, Instant::now(), bus_us()));
                }
                Ok(None) => {}
                Err(e) => {
                    played = Err(e);
                    break;
                }
            }
        }
        let cpu = match (cpu_start.flatten(), cpu_ns()) {
            (Some(a), Some(b)) => Some(b.saturating_sub(a)),
            _ => None,
        };
        // The last decisions arrive within a few ms; then stop listening.
        std::thread::sleep(Duration::from_millis(300));
        done.store(true, Ordering::Relaxed);
        let heard = listener.join().map_err(|_| LoadError::Listener)?;
        played?;
        Ok(Tally {
            steps,
            send_errors,
            cpu_ns: cpu,
            ..heard?
        })
    })
}

/// A step counts when its sampled frame comes after the warm-up.
pub(super) fn measured(s: &Sampled) -> bool {
    s.t_us >= WARMUP_US + SAMPLE_US
}

/// Receives TerrainClass and matches each to its sampled frame.
///
/// The player logs a step after sending its frames; on one CPU (a vcan kernel under User-mode
/// Linux) it can be preempted in between, and the node's answer heard first. Such an answer is
/// kept until its step is logged, counted then, and left out of the latencies: its latency is
/// not known. (Before, it was dropped: a CI run's vcan bench matched 13 of 17 steps. Whether
/// this race or lost frames cost those four, that report could not say; it now counts the
/// one and shows the node's own counts of the other.)
pub(super) fn listen(
    bus: &mut dyn CanBus,
    ids: &IdConfig,
    sent: &mpsc::Receiver<(Sampled, Instant, u64)>,
    done: &AtomicBool,
) -> Result<Tally, LoadError> {
    let mut t = Tally::default();
    let mut pending: HashMap<(u8, u16), (Instant, u64, u8, bool)> = HashMap::new();
    let mut early: HashMap<(u8, u16), TerrainClass> = HashMap::new();
    while !done.load(Ordering::Relaxed) {
        let got = bus.recv(Duration::from_millis(5))?;
        let now = Instant::now();
        for (s, at, at_bus) in sent.try_iter() {
            match early.remove(&(s.foot, s.step)) {
                Some(tc) if measured(&s) => {
                    t.heard_before_logged += 1;
                    count(&mut t, &tc, s.terrain, None, None);
                }
                Some(_) => {}
                None => {
                    pending.insert((s.foot, s.step), (at, at_bus, s.terrain, measured(&s)));
                }
            }
        }
        let Some(st) = got else { continue };
        let (foot, tc) = match messages::decode(&st.frame, ids) {
            Ok(Some((foot, Message::TerrainClass(tc)))) => (foot, tc),
            Ok(Some((_, Message::NodeStatus(ns)))) => {
                t.node_status = Some(ns);
                continue;
            }
            _ => continue,
        };
        let Some((at, at_bus, terrain, measured)) = pending.remove(&(foot, tc.step)) else {
            early.insert((foot, tc.step), tc);
            continue;
        };
        if measured {
            let on_bus = Duration::from_micros(st.t_us.saturating_sub(at_bus));
            count(
                &mut t,
                &tc,
                terrain,
                Some(now.saturating_duration_since(at)),
                Some(on_bus),
            );
        }
    }
    Ok(t)
}

/// One matched TerrainClass into the tally; `latency` when it is known.
/// `on_bus`: the same latency on the bus's clock.
pub(super) fn count(
    t: &mut Tally,
    tc: &TerrainClass,
    terrain: u8,
    latency: Option<Duration>,
    on_bus: Option<Duration>,
) {
    t.decisions += 1;
    if tc.flags & flags::NO_SAMPLE == 0 {
        t.classified += 1;
        t.correct += u64::from(tc.terrain == terrain);
        if let Some(l) = latency {
            t.latencies_us.push(l.as_secs_f64() * 1e6);
        }
        if let Some(l) = on_bus {
            t.bus_latencies_us.push(l.as_secs_f64() * 1e6);
        }
    }
}
