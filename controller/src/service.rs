//! The controller as a part on the bus: [`ControllerService`] is the [`Controller`] behind the
//! [`Component`] shape (frames in, frames out, ticks), and [`run`] runs it on a bus with the
//! one runner every process uses. The laws and the switching live in [`crate::Controller`].

use std::sync::atomic::AtomicBool;

use protocol::Stamped;
use protocol::bus::BusSource;
use protocol::component::{self, Component, Outbox, RunOptions};
use protocol::ids::{IdConfig, MessageKind};
use protocol::messages::{self, Message};
use protocol::terrain::CatalogError;

use crate::{Controller, ControllerConfig};

/// The controller of one leg as a bus component: decodes what it reads, runs the
/// [`Controller`], encodes what it sends, and logs its events (a gait switch, a takeover, a
/// gap in the leg's reports) once each.
pub struct ControllerService {
    ctrl: Controller,
    ids: IdConfig,
    foot: u8,
    switches_logged: u64,
    gaps_logged: u64,
    takeover_logged: Option<u64>,
}

impl ControllerService {
    /// The controller `cfg` describes; fails on a terrains file that does not load.
    pub fn new(cfg: ControllerConfig) -> Result<Self, CatalogError> {
        let catalog = cfg.catalog()?;
        let (ids, foot) = (cfg.ids.clone(), cfg.foot);
        Ok(Self {
            ctrl: Controller::new(cfg, &catalog),
            ids,
            foot,
            switches_logged: 0,
            gaps_logged: 0,
            takeover_logged: None,
        })
    }

    /// The controller inside.
    pub fn controller(&self) -> &Controller {
        &self.ctrl
    }

    /// Logs a gait switch once.
    fn log_switch(&mut self) {
        if self.ctrl.switches != self.switches_logged {
            self.switches_logged = self.ctrl.switches;
            let g = self.ctrl.status();
            tracing::info!(gait = g.gait, terrain = g.terrain, reason = ?g.reason, "gait switch");
        }
    }
}

impl Component for ControllerService {
    fn name(&self) -> &'static str {
        "controller"
    }

    /// Only what the controller reads: in the kernel, so that the tactile stream (about 2,600
    /// frames/s per foot) never reaches this process. Without the filter a controller that
    /// fell behind the tactile stream heard touchdowns late, and the hopper fell every step.
    fn filters(&self) -> Vec<(u32, u32)> {
        self.ids.filters(&[
            MessageKind::FootContact,
            MessageKind::LegState,
            MessageKind::LegStatus,
            MessageKind::TerrainClass,
            MessageKind::NodeStatus,
            // Another controller's, heard while taking over a leg in mid-hop.
            MessageKind::GaitStatus,
        ])
    }

    fn start(&mut self, now_us: u64, _: &mut Outbox) {
        self.ctrl.on_bus_open(now_us);
        tracing::info!(
            foot = self.foot,
            gait = self.ctrl.gait().id,
            "presrs controller running"
        );
    }

    fn on_frame(&mut self, st: &Stamped, now_us: u64, out: &mut Outbox) {
        // Undecodable frames (other traffic, garbage) are not ours: ignored.
        if let Ok(Some((f, m))) = messages::decode(&st.frame, &self.ids) {
            let (ids, foot) = (&self.ids, self.foot);
            self.ctrl
                .on_message(f, &m, now_us, &mut |o| push(o, ids, foot, out));
            self.log_switch();
        }
    }

    fn tick(&mut self, now_us: u64, out: &mut Outbox) {
        let (ids, foot) = (&self.ids, self.foot);
        self.ctrl.tick(now_us, &mut |o| push(o, ids, foot, out));
        self.log_switch();
        if self.ctrl.leg_gaps != self.gaps_logged {
            self.gaps_logged = self.ctrl.leg_gaps;
            if self.ctrl.leg_needs_commands() {
                tracing::warn!(
                    gaps = self.gaps_logged,
                    "the leg's reports stopped for a while; commanding on (a leg of motors stops without commands)"
                );
            } else {
                tracing::warn!(
                    gaps = self.gaps_logged,
                    "the leg's reports stopped for a while; listening to take it over again"
                );
            }
        }
        if let Some(t) = self.ctrl.takeover
            && Some(t.at_us) != self.takeover_logged
        {
            self.takeover_logged = Some(t.at_us);
            tracing::info!(
                gait = t.gait,
                gait_from = t.gait_from,
                touchdown_angle_rad = t.touchdown_angle_rad,
                "took over the leg"
            );
        }
    }

    fn stop(&mut self, _: u64, _: &mut Outbox) {
        tracing::info!(switches = self.ctrl.switches, "presrs controller stopped");
    }
}

fn push(m: Message, ids: &IdConfig, foot: u8, out: &mut Outbox) {
    if let Some(f) = m.to_frame(ids, foot) {
        out.push(f);
    }
}

/// Runs the controller on `source` until `stop` is set; returns the number of gait switches.
/// `time_scale` is robot time per wall time (1 on a robot; the simulator's `--speed` when it
/// runs slower than real time). A bus that fails is reopened with backoff, never fatal.
pub fn run(
    cfg: ControllerConfig,
    source: BusSource,
    time_scale: f64,
    stop: &AtomicBool,
) -> Result<u64, CatalogError> {
    let mut service = ControllerService::new(cfg)?;
    let opts = RunOptions {
        time_scale,
        ..RunOptions::default()
    };
    component::run(&mut service, &source, &opts, stop);
    Ok(service.ctrl.switches)
}
