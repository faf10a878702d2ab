//! The leg bridge: a [`Component`] that turns LegCommand into the drivers' impedance commands
//! and the drivers' encoders into LegState, and keeps the motors safe.
//!
//! Each period (`rate_hz`, default 500 Hz, the LegCommand rate):
//! - a fresh LegCommand: inverse kinematics to joint targets; the leg spring (stance) or the
//!   length hold (flight) becomes the length joint's stiffness and damping through the
//!   kinematics (`k_joint = k_leg * (dl/dq)^2`, then over the gear and screw to the driver);
//!   the hip holds the touchdown angle in flight and is left free (damping only) in stance,
//!   where the leg sweeps. The damping acts on the joint's own speed (no velocity target), as
//!   the hopper's leg damper does.
//! - no LegCommand for `command_timeout_ms`, a driver fault, or a driver silent for
//!   `reply_timeout_ms`: the damped stop (no stiffness, damping only), said in LegStatus and
//!   in the log; commands resume only with a LegCommand that arrives after it.
//! - LegState from the joints' last readings (forward kinematics), when both are fresh.
//!
//! Before the first LegCommand nothing is moved: the joints are only queried. At exit
//! ([`Component::stop`]) every motor is stopped.

mod run;

pub use run::{run, run_two_buses};

use protocol::component::{Component, Outbox};
use protocol::ids::MessageKind;
use protocol::messages::{LegCommand, LegMode, LegState, LegStatus, Message, Phase, decode};

use protocol::{IdConfig, Stamped};

use crate::config::{JointMap, LegConfig};
use crate::driver::{Driver, JointCommand, Reply};
use crate::kinematics::Kinematics;

/// LegStatus period, µs (10 Hz, and at every change of mode).
const STATUS_PERIOD_US: u64 = 100_000;

/// What the bridge last heard from a joint.
#[derive(Clone, Copy, Debug, Default)]
struct Joint {
    /// Joint coordinate (rad; m for a prismatic length) and its speed.
    position: f64,
    velocity: f64,
    /// Robot time of the last reading.
    seen_us: Option<u64>,
    /// The driver's fault code (0 none).
    fault: u32,
}

/// Counters for the log and `presrs leg --json`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct LegCounters {
    /// LegCommands heard for this leg.
    pub commands: u64,
    /// Set points outside the workspace, clamped to its edge.
    pub clamped: u64,
    /// Driver frames that were not what the protocol allows.
    pub malformed_replies: u64,
    /// Periods spent in the damped stop.
    pub stopped_periods: u64,
    /// Impedance commands sent (per joint, summed).
    pub joint_commands: u64,
}

/// The leg bridge. See the [module docs](self).
pub struct LegService {
    kin: Kinematics,
    maps: [JointMap; 2],
    drivers: [Driver; 2],
    cfg: LegConfig,
    ids: IdConfig,
    period_us: u64,
    next_us: Option<u64>,
    next_status_us: u64,
    started_us: Option<u64>,
    last_cmd: Option<(LegCommand, u64)>,
    /// A command must have arrived after this time to run (set by every stop).
    fresh_after_us: Option<u64>,
    enabled: bool,
    /// A driver went silent: it may come back from power-up (MIT out of motor mode, ODrive
    /// idle without its gains), so the next run enables every driver again.
    reenable: bool,
    check: bool,
    joints: [Joint; 2],
    mode: LegMode,
    fault: (u8, u32),
    sent_mode: Option<LegMode>,
    counters: LegCounters,
    clamp_logged: bool,
}

impl LegService {
    /// The bridge for a checked config. With `check`, it never commands a joint: it reads
    /// them (`presrs leg --check`).
    pub fn new(cfg: LegConfig, check: bool) -> Self {
        for w in cfg.quantisation_warnings() {
            tracing::warn!("{w}");
        }
        Self {
            kin: cfg.kinematics.clone(),
            maps: [cfg.map(0), cfg.map(1)],
            drivers: [cfg.driver(0), cfg.driver(1)],
            ids: cfg.ids.clone(),
            period_us: (1e6 / cfg.rate_hz).round() as u64,
            cfg,
            next_us: None,
            next_status_us: 0,
            started_us: None,
            last_cmd: None,
            fresh_after_us: None,
            enabled: false,
            reenable: false,
            check,
            joints: [Joint::default(); 2],
            mode: if check {
                LegMode::Check
            } else {
                LegMode::Waiting
            },
            fault: (0, 0),
            sent_mode: None,
            counters: LegCounters::default(),
            clamp_logged: false,
        }
    }

    /// What the bridge does now.
    pub fn mode(&self) -> LegMode {
        self.mode
    }

    /// Its counters.
    pub fn counters(&self) -> LegCounters {
        self.counters
    }

    /// The leg's `(angle rad, length m)` from the last readings, when both joints have one.
    pub fn measured(&self) -> Option<(f64, f64)> {
        let [h, l] = self.joints;
        (h.seen_us.is_some() && l.seen_us.is_some())
            .then(|| self.kin.forward([h.position, l.position]))
    }

    /// The LegStatus it would send now.
    pub fn status(&self, now_us: u64) -> LegStatus {
        let age = self.last_cmd.map_or(u16::MAX, |(_, t)| {
            ((now_us.saturating_sub(t)) / 1000).min(65_535) as u16
        });
        LegStatus {
            mode: self.mode,
            joint: self.fault.0,
            command_age_ms: age,
            fault_code: self.fault.1,
        }
    }

    fn send(&self, m: Message, out: &mut Outbox) {
        if let Some(f) = m.to_frame(&self.ids, self.cfg.foot) {
            out.push(f);
        }
    }

    /// The first joint at fault: (joint 1|2, code, silent).
    fn health(&self, now_us: u64) -> Option<(u8, u32, bool)> {
        let timeout = self.cfg.reply_timeout_ms * 1000;
        let since = self.started_us.unwrap_or(now_us);
        for (i, j) in self.joints.iter().enumerate() {
            if j.fault != 0 {
                return Some((i as u8 + 1, j.fault, false));
            }
            let last = j.seen_us.unwrap_or(since);
            if now_us.saturating_sub(last) > timeout {
                return Some((i as u8 + 1, 0, true));
            }
        }
        None
    }

    fn set_mode(&mut self, mode: LegMode, fault: (u8, u32), now_us: u64) {
        if mode == self.mode && fault == self.fault {
            return;
        }
        let name = |j: u8| match j {
            1 => "hip",
            2 => "length",
            _ => "none",
        };
        match mode {
            LegMode::Running => {
                tracing::info!(foot = self.cfg.foot, "leg running: following LegCommand")
            }
            LegMode::CommandTimeout => tracing::warn!(
                foot = self.cfg.foot,
                timeout_ms = self.cfg.command_timeout_ms,
                "no LegCommand within the command timeout: every joint in the damped stop until fresh commands come"
            ),
            LegMode::DriverFault => tracing::error!(
                foot = self.cfg.foot,
                joint = name(fault.0),
                driver = self.drivers[(fault.0.max(1) - 1) as usize].name(),
                code = fault.1,
                "driver reports a fault: every joint in the damped stop (clear the fault, then send fresh commands)"
            ),
            LegMode::DriverSilent => tracing::error!(
                foot = self.cfg.foot,
                joint = name(fault.0),
                driver = self.drivers[(fault.0.max(1) - 1) as usize].name(),
                timeout_ms = self.cfg.reply_timeout_ms,
                "driver silent: every joint in the damped stop (check its power, wiring and CAN id)"
            ),
            _ => {}
        }
        if mode.is_stopped() && mode != LegMode::Waiting && mode != LegMode::Check {
            self.fresh_after_us = Some(now_us);
        }
        // Measured on vcan: a bridge commanded before its simulated drivers were up sent the
        // MIT enter-motor-mode frame to nobody; the motors answered later but ignored every
        // command (out of motor mode) while the bridge reported Running.
        if mode == LegMode::DriverSilent {
            self.reenable = true;
        }
        self.mode = mode;
        self.fault = fault;
    }

    /// The impedance commands for a fresh LegCommand.
    fn run(&mut self, c: LegCommand, out: &mut Outbox) {
        if !self.enabled || self.reenable {
            for d in &mut self.drivers {
                d.enable(out);
            }
            self.enabled = true;
            self.reenable = false;
        }
        let imp = &self.cfg.impedance;
        let stance = c.phase == Phase::Stance;
        // In stance the hip is free and the measured angle stands in for the set point, so
        // that a two-link knee target is the length's alone.
        let angle = if stance {
            self.measured().map_or(c.touchdown_angle_rad, |(a, _)| a)
        } else {
            c.touchdown_angle_rad
        };
        let inv = self.kin.inverse(c.leg_length_m, angle);
        // Only the command's own values count as out of the workspace (a measured angle past
        // the limit, a fallen robot's, is clamped without a word).
        let (lo, hi) = self.kin.length_range();
        let commanded_out = !(lo..=hi).contains(&c.leg_length_m)
            || (!stance && c.touchdown_angle_rad.abs() > crate::kinematics::MAX_ANGLE_RAD);
        if inv.clamped && commanded_out {
            self.counters.clamped += 1;
            if !self.clamp_logged {
                self.clamp_logged = true;
                tracing::warn!(
                    length_m = c.leg_length_m,
                    angle_rad = c.touchdown_angle_rad,
                    min_length_m = lo,
                    max_length_m = hi,
                    "LegCommand outside the leg's workspace: clamped to its edge (said once)"
                );
            }
        }
        let g2 = self.kin.length_gain(inv.joints).powi(2);
        let (k_leg, b_leg) = if stance {
            (imp.stance_stiffness_n_per_m, imp.stance_damping_n_s_per_m)
        } else {
            (imp.flight_stiffness_n_per_m, imp.flight_damping_n_s_per_m)
        };
        let (hip_k, hip_b) = if stance {
            (0.0, imp.hip_damping_nm_s_per_rad)
        } else {
            (imp.hip_stiffness_nm_per_rad, imp.hip_damping_nm_s_per_rad)
        };
        let targets = [
            (inv.joints[0], hip_k, hip_b),
            (inv.joints[1], k_leg * g2, b_leg * g2),
        ];
        for (i, (x, k, b)) in targets.into_iter().enumerate() {
            let m = self.maps[i];
            let cmd = JointCommand {
                position_rad: m.to_driver(x),
                velocity_rad_s: 0.0,
                kp: m.stiffness_to_driver(k),
                kd: m.stiffness_to_driver(b),
                torque_nm: 0.0,
            };
            self.drivers[i].command(&cmd, out);
            self.counters.joint_commands += 1;
        }
    }

    /// The damped stop on every joint.
    fn damp(&mut self, out: &mut Outbox) {
        let imp = &self.cfg.impedance;
        let g2 = self
            .measured()
            .map(|(a, l)| self.kin.length_gain(self.kin.inverse(l, a).joints).powi(2))
            .unwrap_or(1.0);
        let kd = [
            self.maps[0].stiffness_to_driver(imp.hip_damping_nm_s_per_rad),
            self.maps[1].stiffness_to_driver(imp.stop_damping_n_s_per_m * g2),
        ];
        for (d, kd) in self.drivers.iter_mut().zip(kd) {
            d.damp(kd, out);
        }
        self.counters.stopped_periods += 1;
    }
}

impl Component for LegService {
    fn name(&self) -> &'static str {
        "leg"
    }

    fn filters(&self) -> Vec<(u32, u32)> {
        let mut f = vec![self.ids.foot_filter(MessageKind::LegCommand, self.cfg.foot)];
        f.extend(self.drivers.iter().flat_map(Driver::filters));
        f
    }

    fn start(&mut self, now_us: u64, _out: &mut Outbox) {
        // A driver is judged silent from the first start on, not before the bus was open.
        if self.started_us.is_none() {
            self.started_us = Some(now_us);
            self.next_status_us = now_us;
        }
        // After a reopen, the silence of the time the bus was down does not count.
        for j in &mut self.joints {
            if j.seen_us.is_some() {
                j.seen_us = Some(now_us);
            }
        }
        self.next_us = None;
    }

    fn on_frame(&mut self, st: &Stamped, now_us: u64, _out: &mut Outbox) {
        if let Ok(Some((foot, Message::LegCommand(c)))) = decode(&st.frame, &self.ids) {
            if foot == self.cfg.foot {
                self.last_cmd = Some((c, now_us));
                self.counters.commands += 1;
            }
            return;
        }
        for (i, d) in self.drivers.iter().enumerate() {
            match d.decode(&st.frame) {
                None => continue,
                Some(Ok(Reply::Reading {
                    position_rad,
                    velocity_rad_s,
                    fault,
                    ..
                })) => {
                    let m = self.maps[i];
                    let j = &mut self.joints[i];
                    j.position = m.to_joint(position_rad);
                    j.velocity = velocity_rad_s / m.scale;
                    j.seen_us = Some(now_us);
                    if let Some(f) = fault {
                        j.fault = f;
                    }
                }
                Some(Ok(Reply::Status { fault })) => self.joints[i].fault = fault,
                Some(Err(e)) => {
                    self.counters.malformed_replies += 1;
                    if self.counters.malformed_replies.is_power_of_two() {
                        tracing::warn!(
                            error = %e,
                            count = self.counters.malformed_replies,
                            "malformed driver frame ignored (said at powers of two)"
                        );
                    }
                }
            }
            return;
        }
    }

    fn tick(&mut self, now_us: u64, out: &mut Outbox) {
        let next = *self.next_us.get_or_insert(now_us);
        if now_us < next {
            return;
        }
        // Catch up by whole periods after a stall: one command per tick, never a burst.
        let behind = (now_us - next) / self.period_us;
        self.next_us = Some(next + (behind + 1) * self.period_us);

        let fresh = self.last_cmd.filter(|&(_, t)| {
            now_us.saturating_sub(t) <= self.cfg.command_timeout_ms * 1000
                && self.fresh_after_us.is_none_or(|after| t > after)
        });
        let mode = if self.check {
            (
                LegMode::Check,
                self.health(now_us).map_or((0, 0), |(j, c, _)| (j, c)),
            )
        } else if let Some((j, code, silent)) = self.health(now_us) {
            let m = if silent {
                LegMode::DriverSilent
            } else {
                LegMode::DriverFault
            };
            (m, (j, code))
        } else if fresh.is_some() {
            (LegMode::Running, (0, 0))
        } else if self.last_cmd.is_none() || (self.mode == LegMode::Waiting && !self.enabled) {
            (LegMode::Waiting, (0, 0))
        } else {
            // A stale command, or a fault now cleared: stopped until fresh commands come.
            (LegMode::CommandTimeout, (0, 0))
        };
        self.set_mode(mode.0, mode.1, now_us);

        match (self.mode, fresh) {
            (LegMode::Running, Some((c, _))) => self.run(c, out),
            (LegMode::Waiting | LegMode::Check, _) => {
                for d in &mut self.drivers {
                    d.query(out);
                }
            }
            // Motors never commanded are unpowered already: a damping command would power
            // them (a moteus takes it as position mode). Measured: a driver silent before the
            // simulator came up was answered with damping, which took the simulated leg over
            // before the controller did, and the hopper fell 8 times.
            _ if !self.enabled => {
                for d in &mut self.drivers {
                    d.query(out);
                }
            }
            _ => self.damp(out),
        }

        let timeout = self.cfg.reply_timeout_ms * 1000;
        let fresh_joints = self.joints.iter().all(|j| {
            j.seen_us
                .is_some_and(|t| now_us.saturating_sub(t) <= timeout)
        });
        if fresh_joints && let Some((angle, length)) = self.measured() {
            // Stamped when sent, at `rate_hz`: a regular stream, whose gaps mean lost reports
            // to the controller. Stamped with the readings' time instead, every stall of a
            // driver's answers (the simulator's, under emulation) showed as a gap, and the
            // controller stopped commanding to listen for a takeover: the leg fell.
            self.send(
                Message::LegState(LegState {
                    leg_angle_rad: angle,
                    leg_length_m: length,
                    timestamp_us: now_us as u32,
                }),
                out,
            );
        }
        if now_us >= self.next_status_us || self.sent_mode != Some(self.mode) {
            self.next_status_us = now_us + STATUS_PERIOD_US;
            self.sent_mode = Some(self.mode);
            self.send(Message::LegStatus(self.status(now_us)), out);
        }
    }

    fn stop(&mut self, now_us: u64, out: &mut Outbox) {
        for d in &mut self.drivers {
            d.stop(out);
        }
        self.mode = LegMode::Stopped;
        self.send(Message::LegStatus(self.status(now_us)), out);
        tracing::info!(foot = self.cfg.foot, "leg stopped: every motor stopped");
    }

    fn is_own(&self, frame: &protocol::CanFrame) -> bool {
        matches!(
            self.ids.lookup(frame.raw_id(), frame.is_extended()),
            Some((MessageKind::LegState | MessageKind::LegStatus, f)) if f == self.cfg.foot
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulated::SimulatedLeg;
    use protocol::CanFrame;

    fn config(driver: &str, kinematics: &str) -> LegConfig {
        let joint = |id: u8| match driver {
            "moteus" => {
                format!("driver = \"moteus\"\nid = {id}\nmoteus_kp = 400.0\nmoteus_kd = 40.0\n")
            }
            "odrive" => format!("driver = \"odrive\"\nid = {id}\n"),
            _ => format!("driver = \"mit\"\nid = {id}\nmit_model = \"AK80-6-V1.1\"\n"),
        };
        let (kin, len_extra) = match kinematics {
            "two-link" => (
                "type = \"two-link\"\nthigh_m = 0.1\nshank_m = 0.1\nknee_sign = 1.0\nmin_length_m = 0.08\nmax_length_m = 0.19\n",
                "",
            ),
            _ => (
                "type = \"prismatic\"\nmin_length_m = 0.10\nmax_length_m = 0.20\n",
                "metres_per_turn = 0.25\n",
            ),
        };
        let text = format!(
            "foot = 1\nmotor_iface = \"motors\"\n[kinematics]\n{kin}[hip]\n{}[length]\n{}{len_extra}",
            joint(3),
            joint(4)
        );
        LegConfig::from_text(&text, "leg.toml").unwrap_or_else(|e| panic!("{e}"))
    }

    fn cmd(ids: &IdConfig, length: f64, angle: f64, phase: Phase, seq: u8) -> CanFrame {
        Message::LegCommand(LegCommand {
            leg_length_m: length,
            touchdown_angle_rad: angle,
            gait: 2,
            phase,
            seq,
        })
        .to_frame(ids, 1)
        .unwrap()
    }

    /// Runs bridge and motors for `ms` milliseconds from `t0`, the motors' joints following
    /// their set points exactly; a LegCommand each 2 ms while `commanding`. Returns what the
    /// bridge sent on our identifiers.
    fn run(
        leg: &mut LegService,
        motors: &mut SimulatedLeg,
        t0: u64,
        ms: u64,
        commanding: bool,
        truth: (f64, f64),
    ) -> Vec<(u64, Message)> {
        let ids = IdConfig::default();
        let mut out = Outbox::default();
        let mut heard = Vec::new();
        for i in 0..ms {
            let now = t0 + i * 1000;
            if commanding && i % 2 == 0 {
                let st = Stamped {
                    t_us: now,
                    frame: cmd(&ids, truth.1, truth.0, Phase::Flight, i as u8),
                };
                leg.on_frame(&st, now, &mut out);
            }
            leg.tick(now, &mut out);
            let sent: Vec<CanFrame> = out.drain().collect();
            for f in &sent {
                motors.on_frame(f);
                if let Ok(Some((1, m))) = decode(f, &ids) {
                    heard.push((now, m));
                }
            }
            let mut replies = Outbox::default();
            motors.emit(now, truth.0, truth.1, 1e-3, &mut replies);
            for f in replies.drain() {
                leg.on_frame(
                    &Stamped {
                        t_us: now,
                        frame: f,
                    },
                    now,
                    &mut out,
                );
            }
        }
        heard
    }

    #[test]
    fn every_driver_and_leg_follows_commands_reports_the_leg_and_stops_when_they_stop() {
        for driver in ["mit", "moteus", "odrive"] {
            for kin in ["prismatic", "two-link"] {
                let cfg = config(driver, kin);
                let mut leg = LegService::new(cfg.clone(), false);
                let mut motors = SimulatedLeg::new(&cfg, 1);
                let mut o = Outbox::default();
                leg.start(0, &mut o);
                // Before any command: queried, never moved.
                run(&mut leg, &mut motors, 0, 30, false, (0.1, 0.15));
                assert_eq!(leg.mode(), LegMode::Waiting, "{driver} {kin}");
                assert_eq!(
                    motors.applied(),
                    [None, None],
                    "{driver} {kin}: moved before a command"
                );
                let truth = (0.2, 0.16);
                let heard = run(&mut leg, &mut motors, 30_000, 100, true, truth);
                assert_eq!(leg.mode(), LegMode::Running, "{driver} {kin}");
                // The motors got the set point back through the kinematics.
                let sp = motors.set_point();
                assert!(
                    (sp.length_m - truth.1).abs() < 2e-4,
                    "{driver} {kin}: {sp:?}"
                );
                assert!(
                    (sp.angle_rad - truth.0).abs() < 2e-3,
                    "{driver} {kin}: {sp:?}"
                );
                assert!(sp.hip_stiff);
                // The flight hold: 1000 N/m within the protocol's quantisation.
                assert!(
                    (sp.stiffness_n_per_m / 1000.0 - 1.0).abs() < 0.02,
                    "{driver} {kin}: {sp:?}"
                );
                let states: Vec<&LegState> = heard
                    .iter()
                    .filter_map(|(_, m)| match m {
                        Message::LegState(s) => Some(s),
                        _ => None,
                    })
                    .collect();
                assert!(
                    states.len() > 40,
                    "{driver} {kin}: {} LegState",
                    states.len()
                );
                let last = states[states.len() - 1];
                assert!(
                    (last.leg_angle_rad - truth.0).abs() < 0.01,
                    "{driver} {kin}: {last:?}"
                );
                assert!(
                    (last.leg_length_m - truth.1).abs() < 0.002,
                    "{driver} {kin}: {last:?}"
                );
                // Commands stop: within the timeout plus a period, the damped stop.
                let heard = run(&mut leg, &mut motors, 130_000, 60, false, truth);
                let stopped_at = heard.iter().find_map(|(t, m)| match m {
                    Message::LegStatus(s) if s.mode == LegMode::CommandTimeout => Some(*t),
                    _ => None,
                });
                let last_cmd = 130_000 - 2_000;
                let limit = last_cmd + cfg.command_timeout_ms * 1000 + 2_000 + 1_000;
                assert!(
                    stopped_at.is_some_and(|t| t <= limit),
                    "{driver} {kin}: {stopped_at:?}"
                );
                for (j, a) in motors.applied().iter().enumerate() {
                    let a = a.unwrap_or_else(|| panic!("{driver} {kin}: joint {j} unpowered"));
                    assert_eq!(a.kp, 0.0, "{driver} {kin}: joint {j} still stiff");
                    assert!(a.kd > 0.0, "{driver} {kin}: joint {j} undamped");
                }
                // Fresh commands resume.
                run(&mut leg, &mut motors, 190_000, 20, true, truth);
                assert_eq!(leg.mode(), LegMode::Running, "{driver} {kin}");
                // Exit leaves every motor stopped or limp.
                let mut out = Outbox::default();
                leg.stop(210_000, &mut out);
                for f in out.drain() {
                    motors.on_frame(&f);
                }
                let a = motors.applied();
                assert!(
                    a.iter().all(|c| c.is_none_or(|c| c.kp == 0.0)),
                    "{driver} {kin}: {a:?}"
                );
                assert_eq!(leg.counters().malformed_replies, 0);
            }
        }
    }

    #[test]
    fn a_silent_driver_and_a_fault_stop_the_leg_and_are_named() {
        for driver in ["mit", "moteus", "odrive"] {
            let cfg = config(driver, "prismatic");
            let mut leg = LegService::new(cfg.clone(), false);
            let mut motors = SimulatedLeg::new(&cfg, 2);
            let mut o = Outbox::default();
            leg.start(0, &mut o);
            run(&mut leg, &mut motors, 0, 50, true, (0.1, 0.15));
            assert_eq!(leg.mode(), LegMode::Running, "{driver}");
            motors.silence(1, true);
            let heard = run(&mut leg, &mut motors, 50_000, 80, true, (0.1, 0.15));
            assert_eq!(leg.mode(), LegMode::DriverSilent, "{driver}");
            assert!(heard.iter().any(|(_, m)| matches!(m,
                Message::LegStatus(s) if s.mode == LegMode::DriverSilent && s.joint == 2)));
            motors.silence(1, false);
            motors.set_fault(0, 33);
            run(&mut leg, &mut motors, 130_000, 150, true, (0.1, 0.15));
            assert_eq!(leg.mode(), LegMode::DriverFault, "{driver}");
            assert_eq!(leg.status(280_000).joint, 1);
            assert_eq!(leg.status(280_000).fault_code, 33, "{driver}");
            // Cleared, with fresh commands: running again.
            motors.set_fault(0, 0);
            run(&mut leg, &mut motors, 280_000, 150, true, (0.1, 0.15));
            assert_eq!(leg.mode(), LegMode::Running, "{driver}");
        }
    }

    /// A driver that browns out comes back from power-up: MIT out of motor mode, ODrive idle
    /// without its gains. The bridge enables it again before commanding it; before it did,
    /// the MIT and ODrive joints stayed unpowered while the bridge said Running.
    #[test]
    fn a_driver_back_from_a_power_cut_is_enabled_again() {
        for driver in ["mit", "moteus", "odrive"] {
            let cfg = config(driver, "prismatic");
            let mut leg = LegService::new(cfg.clone(), false);
            let mut motors = SimulatedLeg::new(&cfg, 5);
            let mut o = Outbox::default();
            leg.start(0, &mut o);
            run(&mut leg, &mut motors, 0, 50, true, (0.1, 0.15));
            assert_eq!(leg.mode(), LegMode::Running, "{driver}");
            motors.power(1, false);
            run(&mut leg, &mut motors, 50_000, 80, true, (0.1, 0.15));
            assert_eq!(leg.mode(), LegMode::DriverSilent, "{driver}");
            motors.power(1, true);
            run(&mut leg, &mut motors, 130_000, 150, true, (0.1, 0.15));
            assert_eq!(leg.mode(), LegMode::Running, "{driver}");
            let a = motors.applied();
            assert!(
                a.iter().all(|c| c.is_some_and(|c| c.kd > 0.0)),
                "{driver}: a joint unpowered after the power came back: {a:?}"
            );
            assert!(a[1].is_some_and(|c| c.kp > 0.0), "{driver}: {a:?}");
        }
    }

    #[test]
    fn drivers_silent_before_any_command_are_named_but_never_powered() {
        for driver in ["mit", "moteus", "odrive"] {
            let cfg = config(driver, "prismatic");
            let mut leg = LegService::new(cfg.clone(), false);
            let mut motors = SimulatedLeg::new(&cfg, 4);
            let mut out = Outbox::default();
            leg.start(0, &mut out);
            // The motors hear the bridge but their answers never reach it.
            for i in 0..120u64 {
                leg.tick(i * 1000, &mut out);
                for f in out.drain() {
                    motors.on_frame(&f);
                }
            }
            assert_eq!(leg.mode(), LegMode::DriverSilent, "{driver}");
            assert_eq!(
                motors.applied(),
                [None, None],
                "{driver}: powered while silent"
            );
            assert!(!motors.commanded, "{driver}");
        }
    }

    #[test]
    fn check_mode_never_moves_a_joint() {
        let cfg = config("mit", "two-link");
        let mut leg = LegService::new(cfg.clone(), true);
        let mut motors = SimulatedLeg::new(&cfg, 3);
        let heard = run(&mut leg, &mut motors, 0, 100, true, (0.1, 0.15));
        assert_eq!(leg.mode(), LegMode::Check);
        assert_eq!(motors.applied(), [None, None]);
        let (a, l) = leg.measured().unwrap();
        assert!((a - 0.1).abs() < 0.01 && (l - 0.15).abs() < 0.002);
        assert!(heard.iter().any(|(_, m)| matches!(m, Message::LegState(_))));
    }
}
