//! The controller as a process runs it: on a bus, on the wall clock (scaled), until told to
//! stop. The laws and the switching live in [`crate::Controller`]; this is its loop.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use protocol::bus::{Backoff, BusSource, HealthWatch, after_bus_error, open_with_retry};
use protocol::ids::MessageKind;
use protocol::messages::{self, Message};
use protocol::terrain::CatalogError;

use crate::{Controller, ControllerConfig};

/// Runs the controller on `source` until `stop` is set; returns the number of gait switches.
/// `time_scale` is robot time per wall time (1 on a robot; the simulator's `--speed` when it
/// runs slower than real time). A bus that fails is reopened with backoff, never fatal.
pub fn run(
    cfg: ControllerConfig,
    source: BusSource,
    time_scale: f64,
    stop: &AtomicBool,
) -> Result<u64, CatalogError> {
    let ids = cfg.ids.clone();
    let foot = cfg.foot;
    let catalog = cfg.catalog()?;
    let mut ctrl = Controller::new(cfg, &catalog);
    let start = Instant::now();
    let now_us = || (start.elapsed().as_secs_f64() * time_scale * 1e6) as u64;
    let stopping = || stop.load(Ordering::Relaxed);
    let mut out: Vec<Message> = Vec::with_capacity(8);
    let mut backoff = Backoff::default();
    let mut switches_logged = 0;
    let (mut gaps_logged, mut takeover_logged) = (0, None);
    // The episodes of the CAN controller under this process (bus-off, error-passive), each
    // logged once with its fix.
    let mut watch = HealthWatch::default();
    'open: while !stopping() {
        let Some(mut bus) = open_with_retry(&source, stop, "controller", &mut || {}) else {
            break;
        };
        // Only what the controller reads: in the kernel, so that the tactile stream (about 2,600
        // frames/s per foot) never reaches this process. Without the filter a controller that
        // fell behind the tactile stream heard touchdowns late, and the hopper fell every step.
        if let Err(e) = bus.set_filters(&ids.filters(&[
            MessageKind::FootContact,
            MessageKind::LegState,
            MessageKind::TerrainClass,
            MessageKind::NodeStatus,
            // Another controller's, heard while taking over a leg in mid-hop.
            MessageKind::GaitStatus,
        ])) {
            after_bus_error("controller filters", &e, &mut backoff, stop);
            continue 'open;
        }
        backoff.reset();
        ctrl.on_bus_open(now_us());
        tracing::info!(iface = %source.label(), foot, gait = ctrl.gait().id, "presrs controller running");
        while !stopping() {
            // Everything queued, then the laws: a burst never waits one loop per frame.
            let mut wait = Duration::from_millis(1);
            loop {
                match bus.recv(wait) {
                    Ok(Some(st)) => {
                        // Undecodable frames (other traffic, garbage) are not ours: ignored.
                        if let Ok(Some((f, m))) = messages::decode(&st.frame, &ids) {
                            ctrl.on_message(f, &m, now_us(), &mut |o| out.push(o));
                        }
                        wait = Duration::ZERO;
                    }
                    Ok(None) => break,
                    Err(e) => {
                        after_bus_error("controller receive", &e, &mut backoff, stop);
                        continue 'open;
                    }
                }
            }
            watch.update("controller", source.label(), &bus.health());
            ctrl.tick(now_us(), &mut |o| out.push(o));
            if ctrl.leg_gaps != gaps_logged {
                gaps_logged = ctrl.leg_gaps;
                tracing::warn!(
                    gaps = gaps_logged,
                    "the leg's reports stopped for a while; listening to take it over again"
                );
            }
            if let Some(t) = ctrl.takeover
                && Some(t.at_us) != takeover_logged
            {
                takeover_logged = Some(t.at_us);
                tracing::info!(
                    gait = t.gait,
                    gait_from = t.gait_from,
                    touchdown_angle_rad = t.touchdown_angle_rad,
                    "took over the leg"
                );
            }
            for m in out.drain(..) {
                if let Message::GaitStatus(g) = &m
                    && ctrl.switches != switches_logged
                {
                    switches_logged = ctrl.switches;
                    tracing::info!(gait = g.gait, terrain = g.terrain, reason = ?g.reason, "gait switch");
                }
                let Some(f) = m.to_frame(&ids, foot) else {
                    continue;
                };
                if let Err(e) = bus.send(&f) {
                    after_bus_error("controller send", &e, &mut backoff, stop);
                    continue 'open;
                }
            }
        }
    }
    tracing::info!(switches = ctrl.switches, "presrs controller stopped");
    Ok(ctrl.switches)
}
