//! A bench run: the node in this process or as a process, under the feet's load.

use super::{
    CanBus, Duration, Feet, IdConfig, LoadError, Tally, measure, memory_mb, task_cpu_ns,
    task_slices,
};

/// What a bench run measured, and of what (for [`BenchReport`]).
pub struct BenchRun {
    /// Per-step latencies and the node's CPU time.
    pub tally: Tally,
    /// Resident memory (now, peak), MB.
    pub memory_mb: (Option<f64>, Option<f64>),
    /// Whose memory `memory_mb` is.
    pub memory_scope: &'static str,
    /// Run-specific figures (the in-process node's counters, the recording's).
    pub extra: serde_json::Value,
}

/// The node's own receive/pipeline/send threads ([`node::NodeService::start`]) on an
/// in-process bus in this process, under `feet` for `total_us` (warm-up included); its frames
/// recorded to the MCAP file `mcap` when given. `beside`: a part reading the same bus on its
/// own endpoint and threads, as `presrs bridge` runs beside the node (the ROS 2 bridge).
/// CPU counts the node's threads; memory is the whole process (node and load generator), an
/// upper bound for the node.
pub fn bench_inproc(
    model: node::classifier::Model,
    feet: Feet,
    total_us: u64,
    mcap: Option<&std::path::Path>,
    threads: node::NodeThreads,
    beside: Option<Box<dyn record::FrameConsumer>>,
    keep_unknown: Option<&std::path::Path>,
) -> Result<BenchRun, LoadError> {
    use protocol::bus::{BusSource, InProcBus};
    let ids = feet.ids.clone();
    let cfg = node::NodeConfig {
        feet: feet.feet.len() as u8,
        ..node::NodeConfig::default()
    };
    let bus = InProcBus::new();
    let recording = record::LiveOptions {
        mcap: mcap.map(|p| p.to_path_buf()),
        foxglove: None,
    }
    .start(&ids, &protocol::TerrainCatalog::paper());
    if let (Some(p), None) = (mcap, &recording) {
        return Err(LoadError::Recording(p.display().to_string()));
    }
    let mut node = node::NodeService::new(cfg, model)?;
    let keep = keep_on(&mut node, keep_unknown)?;
    let node = node.start_on(
        BusSource::InProc(bus.clone()),
        recording.as_ref().map(|r| r.bus_tap()),
        threads,
    )?;
    let stop_beside = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let beside = match beside {
        Some(c) => Some(start_beside(&bus, &ids, c, &stop_beside)?),
        None => None,
    };
    let rec_cpu_start = task_cpu_ns("self", Some(&["record"]));
    // Its reader and its writer (the caller records no MCAP beside it: one "record" thread).
    let beside_cpu = || task_cpu_ns("self", Some(&["record-listen", "record"]));
    let beside_cpu_start = beside_cpu();
    const NODE: [&str; 3] = ["receive", "pipeline", "send"];
    let cpu = || task_cpu_ns("self", Some(&NODE));
    let clock = bus.clock();
    let (slices0, t0) = (task_slices("self", &NODE), std::time::Instant::now());
    let result = measure(
        &mut bus.endpoint(),
        &mut bus.endpoint(),
        &ids,
        feet,
        total_us,
        &cpu,
        &|| clock.now_us(),
    );
    let wakeups_per_s = task_slices("self", &NODE)
        .zip(slices0)
        .map(|(b, a)| b.saturating_sub(a) as f64 / t0.elapsed().as_secs_f64().max(1e-9));
    let rec_cpu_end = task_cpu_ns("self", Some(&["record"]));
    let beside_cpu_end = beside_cpu();
    let stats = node.stop();
    let kept = kept_json(keep)?;
    let beside = beside.map(|(rec, listener)| {
        stop_beside.store(true, std::sync::atomic::Ordering::Relaxed);
        let _ = listener.join();
        let s = rec.finish();
        serde_json::json!({
            "dropped": s.dropped,
            "failed": s.failed,
            "cpu_pct_of_one_core": cpu_pct(beside_cpu_start, beside_cpu_end, total_us),
        })
    });
    let memory_mb = memory_mb("self");
    let tally = result?;
    let recorded = recording.map(|r| {
        let s = r.finish();
        serde_json::json!({
            "file": mcap,
            "messages": s.stats.messages,
            "images": s.stats.images,
            "dropped": s.dropped,
            "failed": s.failed,
            "recorder_cpu_pct_of_one_core": cpu_pct(rec_cpu_start, rec_cpu_end, total_us),
        })
    });
    Ok(BenchRun {
        tally,
        memory_mb,
        memory_scope: "whole process: node threads and load generator",
        extra: serde_json::json!({
            "node_threads": threads.count(),
            "node_rx_frames": stats.rx_frames,
            "node_wakeups_per_s": wakeups_per_s,
            "node_stages": stage_means(&stats.stages),
            "node_rx_dropped": stats.rx_dropped,
            "bus_overruns": bus.overruns(),
            "mcap": recorded,
            "beside": beside,
            "kept_unknown": kept,
        }),
    })
}

/// CPU time between two readings (ns) as a share of one core over `total_us`, percent.
fn cpu_pct(start: Option<u64>, end: Option<u64>, total_us: u64) -> Option<f64> {
    let (a0, a1) = start.zip(end)?;
    Some(a1.saturating_sub(a0) as f64 * 1e-9 / (total_us as f64 * 1e-6) * 100.0)
}

/// The node keeping its unknown stances in `dir`, when given; the writer to finish.
fn keep_on(
    node: &mut node::NodeService,
    dir: Option<&std::path::Path>,
) -> Result<Option<node::unknown::keep::KeepWriter>, LoadError> {
    let Some(dir) = dir else { return Ok(None) };
    let (keeper, writer) =
        node::unknown::keep::UnknownKeeper::create(dir, "bench-node", &node.catalog().clone())?;
    node.set_keep_unknown(keeper);
    Ok(Some(writer))
}

/// What the keeper wrote and dropped, once the node is stopped (`null` without one).
fn kept_json(
    keep: Option<node::unknown::keep::KeepWriter>,
) -> Result<serde_json::Value, LoadError> {
    let Some(w) = keep else {
        return Ok(serde_json::Value::Null);
    };
    let c = w.finish()?;
    Ok(serde_json::json!({"written": c.written, "dropped": c.dropped}))
}

/// A consumer beside the node: its own recorder and listener on the bus, as `presrs bridge`
/// runs beside the node.
fn start_beside(
    bus: &protocol::bus::InProcBus,
    ids: &protocol::IdConfig,
    c: Box<dyn record::FrameConsumer>,
    stop: &std::sync::Arc<std::sync::atomic::AtomicBool>,
) -> Result<(record::LiveRecorder, std::thread::JoinHandle<()>), LoadError> {
    let rec = record::LiveRecorder::start_with(
        record::Recorder::new(ids.clone(), protocol::TerrainCatalog::paper()),
        Vec::new(),
        vec![("beside".into(), c)],
        record::LIVE_QUEUE,
    )?;
    let listener = record::listen(
        protocol::bus::BusSource::InProc(bus.clone()),
        rec.tap(),
        stop.clone(),
    )?;
    Ok((rec, listener))
}

/// `presrs node` started from the executable `exe` as a child process on `iface` (the model
/// and a config for `feet` feet handed over in a temporary folder, removed after), under
/// `feet` for `total_us`; CPU and memory are the child's alone.
pub fn bench_process(
    exe: &std::path::Path,
    iface: &str,
    model: &node::classifier::Model,
    feet: Feet,
    total_us: u64,
    mcap: Option<&std::path::Path>,
) -> Result<BenchRun, LoadError> {
    use protocol::bus::SocketCanBus;
    use protocol::ids::MessageKind;
    let ids = feet.ids.clone();
    let dir = std::env::temp_dir().join(format!("presrs-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let model_path = dir.join("model.json");
    model.save(&model_path)?;
    let cfg_path = dir.join("node.toml");
    std::fs::write(&cfg_path, format!("feet = {}\n", feet.feet.len()))?;
    let mut tx = SocketCanBus::open(iface)?;
    let mut rx = SocketCanBus::open(iface)?;
    rx.set_filters(&ids.filters(&[MessageKind::TerrainClass, MessageKind::NodeStatus]))?;
    let mut cmd = std::process::Command::new(exe);
    cmd.args(["node", "--iface", iface, "--model"])
        .arg(&model_path)
        .arg("--config")
        .arg(&cfg_path);
    if let Some(p) = mcap {
        cmd.arg("--mcap").arg(p);
    }
    let mut node = NodeProcess(cmd.stdout(std::process::Stdio::null()).spawn()?);
    let result = node
        .wait_for_heartbeat(&mut rx, &ids, Duration::from_secs(20))
        .and_then(|()| {
            let pid = node.pid();
            let cpu = || task_cpu_ns(&pid, None);
            // The sockets' receive stamps are the real-time clock's.
            let wall = protocol::clock::WallClock::default();
            let bus_us = || protocol::clock::Clock::now_us(&wall);
            measure(&mut tx, &mut rx, &ids, feet, total_us, &cpu, &bus_us)
        });
    let memory_mb = memory_mb(&node.pid());
    node.stop();
    let _ = std::fs::remove_dir_all(&dir);
    Ok(BenchRun {
        tally: result?,
        memory_mb,
        memory_scope: "the presrs node process",
        extra: serde_json::json!({}),
    })
}

/// A node process under test (`presrs node` started by the caller): its first heartbeat
/// awaited, and stopped with SIGTERM (the node's graceful stop), killed if it has not ended
/// 5 s later.
pub struct NodeProcess(pub std::process::Child);

impl NodeProcess {
    /// Waits up to `within` for the node's first NodeStatus on `rx`.
    pub fn wait_for_heartbeat(
        &mut self,
        rx: &mut dyn CanBus,
        ids: &IdConfig,
        within: std::time::Duration,
    ) -> Result<(), LoadError> {
        let end = std::time::Instant::now() + within;
        while std::time::Instant::now() < end {
            if let Some(status) = self.0.try_wait()? {
                return Err(LoadError::NodeExited(status));
            }
            if let Some(st) = rx.recv(std::time::Duration::from_millis(50))?
                && let Ok(Some((_, protocol::Message::NodeStatus(_)))) =
                    protocol::messages::decode(&st.frame, ids)
            {
                return Ok(());
            }
        }
        Err(LoadError::NoHeartbeat(within))
    }

    /// Its process id, for [`task_cpu_ns`] and [`memory_mb`].
    pub fn pid(&self) -> String {
        self.0.id().to_string()
    }

    /// SIGTERM, then SIGKILL after 5 s.
    pub fn stop(mut self) {
        // SAFETY: kill(2) on our own child's pid.
        unsafe {
            libc::kill(self.0.id() as i32, libc::SIGTERM);
        }
        let end = std::time::Instant::now() + std::time::Duration::from_secs(5);
        while std::time::Instant::now() < end {
            if let Ok(Some(_)) = self.0.try_wait() {
                return;
            }
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// The node's [`node::StageTimes`] as means, µs, over the whole run (warm-up included).
pub fn stage_means(s: &node::StageTimes) -> serde_json::Value {
    let per = |sum: f64, n: u64| (n > 0).then(|| sum / n as f64);
    serde_json::json!({
        "frames": s.frames,
        "frame_work_us_mean": per(s.frame_ns as f64 * 1e-3, s.frames),
        "decided": s.decided,
        "decided_frame_work_us_mean": per(s.decided_ns as f64 * 1e-3, s.decided),
        "decided_frame_wait_us_mean": per(s.decided_wait_us as f64, s.decided),
        "decided_frame_wait_and_work_us_max": s.decided_max_us,
        "what": "work: the pipeline's on_frame (decode, reassembly, stance, decision); \
                 wait: the bus's receive stamp to the pipeline (wake-ups, hand-offs)",
    })
}
