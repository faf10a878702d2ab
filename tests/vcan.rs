//! The vcan suite: real SocketCAN sockets on a virtual CAN interface.
//!
//! Needs `vcan0` up with MTU 72 (CAN FD) and `vcan1` up with MTU 16 (classic only); names can be
//! changed with PRESRS_VCAN and PRESRS_VCAN_CLASSIC (tests/vcan/lanes.sh runs two lanes of tests
//! at once, the second on vcan2 and vcan3, and sets the four up). `tests/vcan/run.sh` runs
//! this suite through it, in User-mode Linux (or a virtme-ng VM) when this kernel has no CAN.
//! Behind the `vcan` feature, and each test ignored, so that `cargo test` does not need CAN:
//! ./test-all.sh's `cargo test --features interop,vcan` builds this binary with the rest (a
//! build of it alone recompiled part of the workspace, 84 s) and lists its tests as ignored;
//! run.sh runs them all (`--include-ignored`) and fails when fewer pass than the binary lists.
//!
//! One module per concept, in tests/vcan/: `sockets` (the kernel's sockets), `logs` (candump
//! and other readers), `faults`, `gaits`, `bench`, `capture`, `firmware`, `record` (MCAP and
//! Foxglove) and `motors` (the leg bridge). The helpers they share are here. lanes.sh names
//! tests by their module path.
#![cfg(feature = "vcan")]

mod common;

use std::time::{Duration, Instant};

use common::*;
use protocol::bus::{CanBus, SocketCanBus};
use protocol::ids::{IdConfig, MessageKind};
use protocol::messages::decode;
use protocol::tactile::{ImageRef, Reassembler, Segmenter, Variant};
use protocol::{BusError, Message};
use rand::{Rng, SeedableRng};

// A crate root's modules are looked for beside it in tests/, where other test binaries live:
// `#[path]` keeps these in tests/vcan/.
#[path = "vcan/bench.rs"]
mod bench;
#[path = "vcan/capture.rs"]
mod capture;
#[path = "vcan/faults.rs"]
mod faults;
#[path = "vcan/firmware.rs"]
mod firmware;
#[path = "vcan/gaits.rs"]
mod gaits;
#[path = "vcan/logs.rs"]
mod logs;
#[path = "vcan/motors.rs"]
mod motors;
#[path = "vcan/record.rs"]
mod record;
#[path = "vcan/sockets.rs"]
mod sockets;

fn fd_iface() -> String {
    std::env::var("PRESRS_VCAN").unwrap_or_else(|_| "vcan0".into())
}
fn classic_iface() -> String {
    std::env::var("PRESRS_VCAN_CLASSIC").unwrap_or_else(|_| "vcan1".into())
}

/// Says how long its test took when dropped (also when the test fails), for the suite's time
/// budget: the emulated kernel's tests are most of the test command (tests/vcan/lanes.sh runs them alone or
/// in two lanes, and says which).
struct Timed(&'static str, Instant);

impl Drop for Timed {
    fn drop(&mut self) {
        eprintln!(
            "vcan test {} took {:.1} s",
            self.0,
            self.1.elapsed().as_secs_f64()
        );
    }
}

fn open(iface: &str) -> SocketCanBus {
    SocketCanBus::open(iface).unwrap_or_else(|e| panic!("{e}"))
}

/// The binary under test: PRESRS_BIN (run.sh passes the release build: the simulator must keep
/// real time, in the VM too), else this build's.
fn presrs() -> std::path::PathBuf {
    std::env::var_os("PRESRS_BIN")
        .map(Into::into)
        .unwrap_or_else(|| env!("CARGO_BIN_EXE_presrs").into())
}

/// A model trained on simulated G2 stances; run.sh makes it on the host (PRESRS_MODEL).
fn system_model() -> std::path::PathBuf {
    let p: std::path::PathBuf = std::env::var_os("PRESRS_MODEL").map(Into::into).expect(
        "PRESRS_MODEL must name a model (tests/vcan/run.sh trains one on simulated G2 data)",
    );
    assert!(p.exists(), "PRESRS_MODEL {} does not exist", p.display());
    p
}

/// A child process killed when dropped, so that a failing test leaves nothing running.
struct Proc(std::process::Child);

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// `presrs ARGS` at real-time priority (SCHED_FIFO 20, `chrt`), as a robot runs its motor
/// loop (docs/real-robot.md); as [`spawn`] where this machine does not allow it. Under
/// emulation the simulator takes most of the one CPU, and the leg's bridge and controller,
/// commanding motors at 500 Hz, waited behind it: in User-mode Linux at 0.5, 2 of 3 runs of
/// the leg test fell (at gait switches, 1.7-2.7 robot s) as plain processes, 0 of 3 at
/// real-time priority.
fn spawn_rt(args: &[&str]) -> Proc {
    static RT: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    let rt = *RT.get_or_init(|| {
        let ok = std::process::Command::new("chrt")
            .args(["-f", "20", "true"])
            .status()
            .is_ok_and(|s| s.success());
        if !ok {
            eprintln!("chrt -f 20 not allowed here: the leg's processes run at normal priority");
        }
        ok
    });
    if !rt {
        return spawn(args);
    }
    Proc(
        std::process::Command::new("chrt")
            .args(["-f", "20"])
            .arg(presrs())
            .args(args)
            .env("RUST_LOG", "warn")
            .spawn()
            .unwrap_or_else(|e| panic!("starting presrs {args:?} under chrt: {e}")),
    )
}

fn spawn(args: &[&str]) -> Proc {
    Proc(
        std::process::Command::new(presrs())
            .args(args)
            .env("RUST_LOG", "warn")
            .spawn()
            .unwrap_or_else(|e| panic!("starting presrs {args:?}: {e}")),
    )
}

/// Steps whose classified terrain is the true one, and all steps, of a `presrs lab sim` report.
fn accuracy(r: &serde_json::Value) -> (usize, usize) {
    let steps = r["steps"].as_array().unwrap();
    let correct = steps
        .iter()
        .filter(|s| s["truth"] == s["classified"])
        .count();
    (correct, steps.len())
}

/// P(X <= k) for X ~ Binomial(n, p).
fn binomial_cdf(k: usize, n: usize, p: f64) -> f64 {
    // ln C(n, i) by sums of logs: exact enough for n in the hundreds.
    let ln_fact = |m: usize| (1..=m).map(|x| (x as f64).ln()).sum::<f64>();
    (0..=k.min(n))
        .map(|i| {
            (ln_fact(n) - ln_fact(i) - ln_fact(n - i)
                + i as f64 * p.ln()
                + (n - i) as f64 * (1.0 - p).ln())
            .exp()
        })
        .sum()
}

/// `candump -L IFACE > log` while `run` runs; returns the log's path.
fn candump_during(iface: &str, name: &str, run: impl FnOnce()) -> std::path::PathBuf {
    let log = std::env::temp_dir().join(format!("presrs-{name}-{}.log", std::process::id()));
    let file = std::fs::File::create(&log).unwrap();
    let mut candump = Proc(
        std::process::Command::new("candump")
            // 10 000 frames/s of tactile segments: under TCG on a busy host, candump's default
            // socket buffer overflowed (290 of 300 images logged, sim reporting 0 send errors).
            .args(["-r", "8388608", "-L", iface])
            .stdout(file)
            .spawn()
            .expect("candump from can-utils must be installed (apt-get install can-utils)"),
    );
    std::thread::sleep(Duration::from_millis(500));
    run();
    std::thread::sleep(Duration::from_millis(500));
    let _ = candump.0.kill();
    let _ = candump.0.wait();
    log
}

fn system_speed() -> f64 {
    std::env::var("PRESRS_SYSTEM_SPEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1.0)
}

/// `presrs lab sim` on `iface` for `sim_s` of robot time; returns its per-step report.
fn sim_report(iface: &str, extra: &[&str], sim_s: f64, seed: u64, name: &str) -> serde_json::Value {
    let report = std::env::temp_dir().join(format!("presrs-{name}-{}.json", std::process::id()));
    let status = std::process::Command::new(presrs())
        .args([
            "lab",
            "sim",
            "--iface",
            iface,
            "--duration",
            &sim_s.to_string(),
        ])
        .args([
            "--seed",
            &seed.to_string(),
            "--speed",
            &system_speed().to_string(),
        ])
        .args(extra)
        .arg("--report")
        .arg(&report)
        .env("RUST_LOG", "warn")
        .status()
        .unwrap();
    assert!(status.success(), "presrs lab sim {extra:?}: {status}");
    let r = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    let _ = std::fs::remove_file(&report);
    r
}

fn presrs_ok(args: &[&str]) -> String {
    let out = std::process::Command::new(presrs())
        .args(args)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "presrs {args:?}: {}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).to_string()
}
