//! `presrs bench-node`: issue 5's speed targets measured on the node as it runs.
//!
//! A load generator plays `--feet` feet at 100 Hz (PreSRS frame rate, CAN FD segments) with a
//! step every 300 ms (150 ms stance), using simulated G2 images of the four dynamic terrains.
//! It measures, per step, the wall time from sending the **last segment of the sampled frame**
//! (the frame nearest 70 ms after touchdown) to receiving that step's TerrainClass; and the
//! node's CPU time and resident memory over the measured window.
//!
//! - No `--iface`: the node's own receive/pipeline/send threads ([`node::NodeService::start`]) on an
//!   in-process bus in this process. CPU counts only those three threads; memory is the whole
//!   process (node plus load generator), an upper bound for the node.
//! - `--iface vcan0`: `presrs node` as a child process on that interface; CPU and memory are the
//!   child's alone.
//!
//! The figures go to a report (`--json`), not to a timed test: the machines are noisy.

use std::collections::HashMap;
use std::path::PathBuf;
use std::process::{Child, Command, ExitCode, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use crossbeam_channel::{Receiver, Sender, unbounded};
use node::NodeConfig;
use protocol::bus::{CanBus, InProcBus};
use protocol::ids::IdConfig;
use protocol::ids::MessageKind;
use protocol::messages::{self, FootContact, Message, flags};
use protocol::tactile::{ImageRef, Segmenter, Variant};

use crate::cli::percentile;
use protocol::bus::BusSource;

const FRAME_US: u64 = 10_000;
const STEP_US: u64 = 300_000;
const STANCE_US: u64 = 150_000;
const SAMPLE_US: u64 = 70_000;
const WARMUP_US: u64 = 1_000_000;
const SIDE: usize = 44;

#[derive(clap::Args)]
pub struct BenchNodeArgs {
    /// Run `presrs node` as a child process on this CAN interface (vcan0). Default: the node's
    /// threads on an in-process bus in this process.
    #[arg(long)]
    pub iface: Option<String>,
    /// Model file; default: the demo's model (trained on first run, then cached).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Feet served, each at 100 Hz.
    #[arg(long, default_value_t = 6)]
    pub feet: u8,
    /// Measured seconds, after 1 s of warm-up.
    #[arg(long, default_value_t = 10.0)]
    pub seconds: f64,
    /// A label carried into the report (say "emulated" for a VM).
    #[arg(long)]
    pub label: Option<String>,
    /// Print the report as one JSON object.
    #[arg(long)]
    pub json: bool,
}

/// One foot's schedule: touchdown, liftoff and frame times on the foot clock (µs from start).
struct Foot {
    id: u8,
    td: u64,
    lo: u64,
    frame: u64,
    /// This foot's frame grid: frames at `offset + k * FRAME_US`.
    offset: u64,
    in_stance: bool,
    step: u16,
    contact_seq: u8,
    image_seq: u8,
    /// Time of this stance's sampled frame, and the image shown in this stance.
    sampled: Option<u64>,
    image: usize,
}

/// Sampled frame of (foot, step) sent at this instant; its true terrain id.
struct Sent {
    foot: u8,
    step: u16,
    at: Instant,
    terrain: u8,
    measured: bool,
}

#[derive(Default)]
struct Tally {
    steps: u64,
    decisions: u64,
    classified: u64,
    correct: u64,
    latencies_us: Vec<f64>,
}

pub fn run(a: BenchNodeArgs) -> Result<ExitCode> {
    anyhow::ensure!(
        (1..=protocol::ids::MAX_FEET).contains(&a.feet),
        "--feet {}: allowed 1..={}",
        a.feet,
        protocol::ids::MAX_FEET
    );
    anyhow::ensure!(
        a.seconds > 0.0 && a.seconds <= 3600.0,
        "--seconds {}: allowed (0, 3600]",
        a.seconds
    );
    let model = crate::cli::load_or_train(a.model.as_deref())?;
    anyhow::ensure!(
        model.input_rows == SIDE && model.input_cols == SIDE,
        "the model takes {}x{} images; the benchmark plays the PreSRS's 44x44",
        model.input_rows,
        model.input_cols
    );
    let images = image_pool()?;
    let ids = IdConfig::default();
    let cfg = NodeConfig {
        feet: a.feet,
        ..NodeConfig::default()
    };
    let total_us = WARMUP_US + (a.seconds * 1e6) as u64;

    match &a.iface {
        None => {
            let bus = InProcBus::new();
            let node = node::NodeService::new(cfg.clone(), model)?
                .start(BusSource::InProc(bus.clone()))?;
            let cpu = || task_cpu_ns("self", Some(&["receive", "pipeline", "send"]));
            let result = measure(
                &mut bus.endpoint(),
                &mut bus.endpoint(),
                &ids,
                a.feet,
                &images,
                total_us,
                &cpu,
            );
            let stats = node.stop();
            let (m, cpu_ns) = result?;
            let mem = memory("self");
            let extra = serde_json::json!({
                "node_rx_frames": stats.rx_frames,
                "node_rx_dropped": stats.rx_dropped,
                "bus_overruns": bus.overruns(),
            });
            report(
                &a,
                "inproc",
                "whole process: node threads and load generator",
                &m,
                cpu_ns,
                mem,
                extra,
            )
        }
        Some(iface) => {
            let dir = std::env::temp_dir().join(format!("presrs-bench-{}", std::process::id()));
            std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
            let model_path = dir.join("model.json");
            model
                .save(&model_path)
                .with_context(|| format!("writing {}", model_path.display()))?;
            let cfg_path = dir.join("node.toml");
            std::fs::write(&cfg_path, format!("feet = {}\n", a.feet))
                .with_context(|| format!("writing {}", cfg_path.display()))?;
            let mut tx = protocol::bus::SocketCanBus::open(iface)
                .with_context(|| format!("--iface {iface}"))?;
            let mut rx = protocol::bus::SocketCanBus::open(iface)
                .with_context(|| format!("--iface {iface}"))?;
            rx.set_filters(&ids.filters(&[MessageKind::TerrainClass, MessageKind::NodeStatus]))?;
            let mut child = Command::new(std::env::current_exe()?)
                .args(["node", "--iface", iface, "--model"])
                .arg(&model_path)
                .arg("--config")
                .arg(&cfg_path)
                .stdout(Stdio::null())
                .spawn()
                .context("starting presrs node")?;
            let result = wait_for_status(&mut rx, &ids, &mut child).and_then(|()| {
                let pid = child.id().to_string();
                let cpu = || task_cpu_ns(&pid, None);
                measure(&mut tx, &mut rx, &ids, a.feet, &images, total_us, &cpu)
            });
            let mem = memory(&child.id().to_string());
            stop_child(&mut child);
            let _ = std::fs::remove_dir_all(&dir);
            let (m, cpu_ns) = result?;
            report(
                &a,
                iface,
                "the presrs node process",
                &m,
                cpu_ns,
                mem,
                serde_json::json!({}),
            )
        }
    }
}

/// Eight G2 stance images per dynamic terrain, and their terrain ids.
fn image_pool() -> Result<Vec<(u8, Vec<u16>)>> {
    let samples = sim::dataset::generate(&sim::dataset::Options {
        kind: sim::dataset::Kind::Dynamic,
        n: Some(8),
        gait: controller::Gait::g2(),
        damage_pct: 0.0,
        sensor: sim::DEFAULT_SENSOR,
        seed: 99,
    });
    anyhow::ensure!(!samples.is_empty(), "the simulator gave no images");
    Ok(samples
        .into_iter()
        .filter(|s| s.rows == SIDE && s.cols == SIDE)
        .map(|s| (s.terrain.id(), s.pixels))
        .collect())
}

fn wait_for_status(rx: &mut dyn CanBus, ids: &IdConfig, child: &mut Child) -> Result<()> {
    let end = Instant::now() + Duration::from_secs(20);
    while Instant::now() < end {
        if let Some(status) = child.try_wait()? {
            anyhow::bail!("presrs node exited before the benchmark ({status})");
        }
        if let Some(st) = rx.recv(Duration::from_millis(50))?
            && let Ok(Some((_, Message::NodeStatus(_)))) = messages::decode(&st.frame, ids)
        {
            return Ok(());
        }
    }
    anyhow::bail!("no NodeStatus from presrs node within 20 s")
}

fn stop_child(child: &mut Child) {
    // SIGTERM: the node's graceful stop. It ends within a receive timeout.
    unsafe {
        libc::kill(child.id() as i32, libc::SIGTERM);
    }
    let end = Instant::now() + Duration::from_secs(5);
    while Instant::now() < end {
        if let Ok(Some(_)) = child.try_wait() {
            return;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let _ = child.kill();
    let _ = child.wait();
}

/// Plays the feet for `total_us` of real time and tallies the steps measured after warm-up.
/// Returns the tally and the node's CPU time over the measured window (ns).
fn measure(
    tx: &mut dyn CanBus,
    rx: &mut dyn CanBus,
    ids: &IdConfig,
    feet: u8,
    images: &[(u8, Vec<u16>)],
    total_us: u64,
    cpu_ns: &dyn Fn() -> Option<u64>,
) -> Result<(Tally, Option<u64>)> {
    let (sent_tx, sent_rx) = unbounded::<Sent>();
    let done = std::sync::atomic::AtomicBool::new(false);
    std::thread::scope(|s| {
        let listener = s.spawn(|| listen(rx, ids, &sent_rx, &done));
        let played = play(tx, ids, feet, images, total_us, &sent_tx, cpu_ns);
        // The last decisions arrive within a few ms; then stop listening.
        std::thread::sleep(Duration::from_millis(300));
        done.store(true, std::sync::atomic::Ordering::Relaxed);
        let tally = listener
            .join()
            .map_err(|_| anyhow::anyhow!("the listener thread panicked"))?;
        let (steps, cpu) = played?;
        Ok((Tally { steps, ..tally }, cpu))
    })
}

/// The load generator. Returns the steps whose sampled frame fell in the measured window and the
/// node's CPU time over that window.
fn play(
    bus: &mut dyn CanBus,
    ids: &IdConfig,
    feet: u8,
    images: &[(u8, Vec<u16>)],
    total_us: u64,
    sent: &Sender<Sent>,
    cpu_ns: &dyn Fn() -> Option<u64>,
) -> Result<(u64, Option<u64>)> {
    let seg = Segmenter::new(Variant::Fd, ids.clone());
    let blank = vec![0u16; SIDE * SIDE];
    let n = feet as u64;
    let mut feet: Vec<Foot> = (0..feet)
        .map(|f| {
            let f64_ = f as u64;
            Foot {
                id: f,
                // Touchdowns spread over the step period, 3.3 ms off the frame grid (no ties).
                td: 200_000 + f64_ * STEP_US / n + 3_300,
                lo: u64::MAX,
                frame: 1_000 + f64_ * FRAME_US / n,
                offset: 1_000 + f64_ * FRAME_US / n,
                in_stance: false,
                step: 0,
                contact_seq: 0,
                image_seq: 0,
                sampled: None,
                image: f as usize,
            }
        })
        .collect();
    let start = Instant::now();
    let mut steps = 0u64;
    let mut cpu_start = None;
    let mut send_errors = 0u64;
    let mut send = |bus: &mut dyn CanBus, f: &protocol::CanFrame| {
        // A full socket buffer (ENOBUFS) is retried briefly rather than lost.
        for _ in 0..50 {
            if bus.send(f).is_ok() {
                return;
            }
            std::thread::sleep(Duration::from_micros(100));
        }
        send_errors += 1;
    };
    while let Some((i, t)) = feet
        .iter()
        .enumerate()
        .map(|(i, f)| (i, f.td.min(f.lo).min(f.frame)))
        .min_by_key(|&(_, t)| t)
    {
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
        let f = &mut feet[i];
        if t == f.td || t == f.lo {
            let touchdown = t == f.td;
            if touchdown {
                f.in_stance = true;
                f.step = f.step.wrapping_add(1);
                f.lo = t + STANCE_US;
                f.td = t + STEP_US;
                f.image = (f.image + 7) % images.len();
                // The frame nearest 70 ms after touchdown, on this foot's frame grid.
                let k = ((t + SAMPLE_US - f.offset) as f64 / FRAME_US as f64).round() as u64;
                f.sampled = Some(f.offset + k * FRAME_US);
            } else {
                f.in_stance = false;
                f.lo = u64::MAX;
            }
            f.contact_seq = f.contact_seq.wrapping_add(1);
            let m = Message::FootContact(FootContact {
                stance: touchdown,
                seq: f.contact_seq,
                timestamp_us: t as u32,
            });
            if let Some(frame) = m.to_frame(ids, f.id) {
                send(bus, &frame);
            }
            continue;
        }
        // A tactile frame.
        f.frame += FRAME_US;
        f.image_seq = f.image_seq.wrapping_add(1);
        let (terrain, pixels) = if f.in_stance {
            (images[f.image].0, images[f.image].1.as_slice())
        } else {
            (0, blank.as_slice())
        };
        let img = ImageRef {
            rows: SIDE,
            cols: SIDE,
            bits: 8,
            timestamp_us: t as u32,
            pixels,
        };
        seg.frames(f.id, f.image_seq, &img, |fr| send(bus, &fr))?;
        if f.sampled == Some(t) {
            let measured = t >= WARMUP_US + SAMPLE_US;
            steps += u64::from(measured);
            let _ = sent.send(Sent {
                foot: f.id,
                step: f.step,
                at: Instant::now(),
                terrain,
                measured,
            });
        }
    }
    if send_errors > 0 {
        tracing::warn!(send_errors, "frames the load generator could not send");
    }
    let cpu = match (cpu_start.flatten(), cpu_ns()) {
        (Some(a), Some(b)) => Some(b.saturating_sub(a)),
        _ => None,
    };
    Ok((steps, cpu))
}

/// Receives TerrainClass and matches each to its sampled frame.
fn listen(
    bus: &mut dyn CanBus,
    ids: &IdConfig,
    sent: &Receiver<Sent>,
    done: &std::sync::atomic::AtomicBool,
) -> Tally {
    let mut t = Tally::default();
    let mut pending: HashMap<(u8, u16), (Instant, u8, bool)> = HashMap::new();
    while !done.load(std::sync::atomic::Ordering::Relaxed) {
        let got = bus.recv(Duration::from_millis(5));
        let now = Instant::now();
        for s in sent.try_iter() {
            pending.insert((s.foot, s.step), (s.at, s.terrain, s.measured));
        }
        let Ok(Some(st)) = got else { continue };
        let Ok(Some((foot, Message::TerrainClass(tc)))) = messages::decode(&st.frame, ids) else {
            continue;
        };
        let Some((at, terrain, measured)) = pending.remove(&(foot, tc.step)) else {
            continue;
        };
        if !measured {
            continue;
        }
        t.decisions += 1;
        if tc.flags & flags::NO_SAMPLE == 0 {
            t.classified += 1;
            t.correct += u64::from(tc.terrain == terrain);
            t.latencies_us
                .push(now.saturating_duration_since(at).as_secs_f64() * 1e6);
        }
    }
    t
}

/// CPU time (ns) of a process's threads, all or those named in `names`: from schedstat, or
/// from stat's utime+stime (10 ms ticks) where schedstat is missing.
fn task_cpu_ns(pid: &str, names: Option<&[&str]>) -> Option<u64> {
    let dir = std::fs::read_dir(format!("/proc/{pid}/task")).ok()?;
    let mut total = 0u64;
    for e in dir.flatten() {
        let p = e.path();
        if let Some(names) = names {
            let comm = std::fs::read_to_string(p.join("comm")).unwrap_or_default();
            if !names.contains(&comm.trim()) {
                continue;
            }
        }
        if let Some(ns) = std::fs::read_to_string(p.join("schedstat"))
            .ok()
            .and_then(|s| s.split_whitespace().next()?.parse::<u64>().ok())
        {
            total += ns;
            continue;
        }
        let stat = std::fs::read_to_string(p.join("stat")).ok()?;
        // Fields after the ")" of comm: state is field 3, utime 14, stime 15.
        let rest = stat.rsplit_once(')')?.1;
        let f: Vec<&str> = rest.split_whitespace().collect();
        let ticks = f.get(11)?.parse::<u64>().ok()? + f.get(12)?.parse::<u64>().ok()?;
        total += ticks * 10_000_000;
    }
    Some(total)
}

/// VmRSS and VmHWM of a process, MB.
fn memory(pid: &str) -> (Option<f64>, Option<f64>) {
    let Ok(s) = std::fs::read_to_string(format!("/proc/{pid}/status")) else {
        return (None, None);
    };
    let field = |k: &str| {
        s.lines()
            .find(|l| l.starts_with(k))
            .and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok())
            .map(|kb| kb / 1024.0)
    };
    (field("VmRSS:"), field("VmHWM:"))
}

fn report(
    a: &BenchNodeArgs,
    bus: &str,
    memory_scope: &str,
    t: &Tally,
    cpu_ns: Option<u64>,
    (rss, hwm): (Option<f64>, Option<f64>),
    extra: serde_json::Value,
) -> Result<ExitCode> {
    let mut lat = t.latencies_us.clone();
    lat.sort_by(f64::total_cmp);
    let cpu_pct = cpu_ns.map(|ns| ns as f64 * 1e-9 / a.seconds * 100.0);
    let frames_per_image = Variant::Fd.frames_per_image(SIDE, SIDE, 8);
    let j = serde_json::json!({
        "bus": bus,
        "label": a.label,
        "feet": a.feet,
        "seconds": a.seconds,
        "tactile_hz_per_foot": 1e6 / FRAME_US as f64,
        "can_frames_per_s": a.feet as f64 * (1e6 / FRAME_US as f64) * frames_per_image as f64,
        "steps": t.steps,
        "terrain_class": t.decisions,
        "classified": t.classified,
        "accuracy": if t.classified > 0 { t.correct as f64 / t.classified as f64 } else { 0.0 },
        "latency_us": {
            "what": "last segment of the sampled frame sent -> TerrainClass received",
            "n": lat.len(),
            "median": percentile(&lat, 0.5),
            "p99": percentile(&lat, 0.99),
            "max": lat.last(),
        },
        "node_cpu_pct_of_one_core": cpu_pct,
        "rss_mb": rss,
        "peak_rss_mb": hwm,
        "memory_scope": memory_scope,
        "extra": extra,
    });
    if a.json {
        println!("{j}");
    } else {
        let f = |v: Option<f64>| v.map_or("n/a".to_string(), |v| format!("{v:.1}"));
        println!(
            "bus {bus}{}: {} feet at 100 Hz for {} s ({:.0} CAN FD frames/s)",
            a.label
                .as_deref()
                .map(|l| format!(" ({l})"))
                .unwrap_or_default(),
            a.feet,
            a.seconds,
            j["can_frames_per_s"].as_f64().unwrap_or(0.0)
        );
        println!(
            "steps {}, TerrainClass {}, classified {}, correct {:.1}%",
            t.steps,
            t.decisions,
            t.classified,
            j["accuracy"].as_f64().unwrap_or(0.0) * 100.0
        );
        println!(
            "latency (sampled frame's last segment -> TerrainClass): median {} us, p99 {} us, max {} us",
            f(percentile(&lat, 0.5)),
            f(percentile(&lat, 0.99)),
            f(lat.last().copied())
        );
        println!(
            "node CPU {}% of one core; memory ({memory_scope}) {} MB, peak {} MB",
            f(cpu_pct),
            f(rss),
            f(hwm)
        );
    }
    Ok(ExitCode::SUCCESS)
}
