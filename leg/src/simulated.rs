//! A simulated leg's two motors: the simulator presents its hopper's leg as the drivers of
//! a leg config (`presrs lab sim --leg moteus|odrive|mit --leg-config leg.toml`).
//!
//! The motors read the bridge's commands as a real driver would (each protocol's `Server`),
//! and the commanded impedance goes back through the same kinematics to the hopper: the length
//! joint's position target is the leg spring's rest length and its stiffness and damping the
//! spring's, the hip's target the touchdown angle. They answer as the drivers do (moteus and
//! MIT to every frame, ODrive with cyclic encoder estimates at 500 Hz and a 10 Hz heartbeat),
//! with the hopper's true joints plus encoder noise, quantised by each protocol's own format.

use protocol::CanFrame;
use protocol::component::Outbox;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::config::{DriverKind, JointMap, LegConfig};
use crate::driver::{JointCommand, mit, moteus, odrive};
use crate::kinematics::Kinematics;

/// Encoder noise, rad at the driver (1 sigma): a 14-bit absolute encoder's count is 3.8e-4.
pub const ENCODER_NOISE_RAD: f64 = 2e-4;
/// ODrive's encoder estimates period, µs (its `encoder_msg_rate_ms`, set to 2 ms here).
pub const ODRIVE_ESTIMATE_US: u64 = 2_000;
/// ODrive's heartbeat period, µs.
pub const ODRIVE_HEARTBEAT_US: u64 = 100_000;

enum Server {
    Moteus(moteus::Server),
    Odrive(odrive::Server),
    Mit(mit::Server),
}

/// One simulated motor's state.
struct Motor {
    server: Server,
    /// The impedance it applies now (driver units); `None`: unpowered.
    applied: Option<JointCommand>,
    /// ODrive: gains in turns, axis state, set point.
    odrive: (f64, f64, u32, f64),
    /// MIT: in motor mode.
    mit_on: bool,
    /// Replies owed: moteus sources (one per command).
    owed: u32,
    moteus_source: u8,
    silenced: bool,
    fault: u32,
    last_position: Option<f64>,
}

/// What the motors make of the leg now, for the hopper.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LegSetPoint {
    /// The leg spring's rest length, m.
    pub length_m: f64,
    /// The hip's angle target, rad (held only if `hip_stiff`).
    pub angle_rad: f64,
    /// The leg spring, N/m (0: limp).
    pub stiffness_n_per_m: f64,
    /// The leg's damping, N s/m.
    pub damping_n_s_per_m: f64,
    /// The hip holds its angle.
    pub hip_stiff: bool,
}

/// The two motors of a simulated leg.
pub struct SimulatedLeg {
    kin: Kinematics,
    maps: [JointMap; 2],
    motors: [Motor; 2],
    rng: ChaCha8Rng,
    next_estimate_us: u64,
    next_heartbeat_us: u64,
    /// Some command has reached the motors (before that the simulator holds its leg).
    pub commanded: bool,
    /// Driver frames that were not what the protocol allows.
    pub malformed: u64,
}

impl SimulatedLeg {
    /// The motors a checked leg config describes; `seed` fixes the encoder noise.
    pub fn new(cfg: &LegConfig, seed: u64) -> Self {
        let motor = |which: usize| {
            let j = if which == 0 { &cfg.hip } else { &cfg.length };
            let id = j.id.unwrap_or(1);
            let server = match j.driver.unwrap_or(DriverKind::Mit) {
                DriverKind::Moteus => Server::Moteus(moteus::Server::new(
                    id,
                    j.moteus_kp.unwrap_or(0.0),
                    j.moteus_kd.unwrap_or(0.0),
                )),
                DriverKind::Odrive => Server::Odrive(odrive::Server::new(id)),
                DriverKind::Mit => Server::Mit(mit::Server::new(
                    id,
                    j.mit_master_id,
                    cfg.mit_ranges_of(which),
                )),
            };
            Motor {
                server,
                applied: None,
                odrive: (0.0, 0.0, odrive::state::IDLE, 0.0),
                mit_on: false,
                owed: 0,
                moteus_source: 0,
                silenced: false,
                fault: 0,
                last_position: None,
            }
        };
        Self {
            kin: cfg.kinematics.clone(),
            maps: [cfg.map(0), cfg.map(1)],
            motors: [motor(0), motor(1)],
            rng: ChaCha8Rng::seed_from_u64(seed),
            next_estimate_us: 0,
            next_heartbeat_us: 0,
            commanded: false,
            malformed: 0,
        }
    }

    /// Silences a joint's driver (0 hip, 1 length): it stops answering, as a driver whose
    /// power or cable failed.
    pub fn silence(&mut self, joint: usize, silent: bool) {
        if let Some(m) = self.motors.get_mut(joint) {
            m.silenced = silent;
        }
    }

    /// Switches a joint's driver off (0 hip, 1 length): it stops answering and, on again,
    /// comes back as from power-up (unpowered; ODrive idle with no gains, MIT out of motor
    /// mode), as a driver whose supply browned out.
    pub fn power(&mut self, joint: usize, on: bool) {
        if let Some(m) = self.motors.get_mut(joint) {
            m.silenced = !on;
            if !on {
                m.applied = None;
                m.odrive = (0.0, 0.0, odrive::state::IDLE, 0.0);
                m.mit_on = false;
                m.owed = 0;
            }
        }
    }

    /// Makes a joint's driver report fault `code` (0 clears it).
    pub fn set_fault(&mut self, joint: usize, code: u32) {
        if let Some(m) = self.motors.get_mut(joint) {
            m.fault = code;
        }
    }

    /// The impedance each joint applies now, driver units (`None`: unpowered).
    pub fn applied(&self) -> [Option<JointCommand>; 2] {
        [self.motors[0].applied, self.motors[1].applied]
    }

    /// A frame from the bus.
    pub fn on_frame(&mut self, f: &CanFrame) {
        for m in &mut self.motors {
            if m.silenced {
                continue;
            }
            match &m.server {
                Server::Moteus(s) => match s.on_frame(f) {
                    Some(Ok((order, source))) => {
                        m.owed += 1;
                        m.moteus_source = source;
                        match order {
                            moteus::Order::Position(c) => {
                                m.applied = Some(c);
                                self.commanded = true;
                            }
                            moteus::Order::Stop => m.applied = None,
                            moteus::Order::Query => {}
                        }
                    }
                    Some(Err(_)) => self.malformed += 1,
                    None => {}
                },
                Server::Odrive(s) => match s.on_frame(f) {
                    Some(Ok(o)) => {
                        let (pg, vg, st, sp) = &mut m.odrive;
                        match o {
                            odrive::Order::State(x) => *st = x,
                            odrive::Order::ControllerMode(..) => {}
                            odrive::Order::PosGain(g) => *pg = g,
                            odrive::Order::VelGain(g) => *vg = g,
                            odrive::Order::InputPos(p, _, _) => {
                                *sp = p;
                                self.commanded |= *st == odrive::state::CLOSED_LOOP_CONTROL;
                            }
                        }
                        m.applied =
                            (*st == odrive::state::CLOSED_LOOP_CONTROL).then(|| JointCommand {
                                position_rad: *sp,
                                velocity_rad_s: 0.0,
                                // N m/turn = pos_gain * vel_gain; per rad, over 2 pi.
                                kp: *pg * *vg / std::f64::consts::TAU,
                                kd: *vg / std::f64::consts::TAU,
                                torque_nm: 0.0,
                            });
                    }
                    Some(Err(_)) => self.malformed += 1,
                    None => {}
                },
                Server::Mit(s) => match s.on_frame(f) {
                    Some(Ok(o)) => {
                        m.owed += 1;
                        match o {
                            mit::Order::Enter => m.mit_on = true,
                            mit::Order::Exit => {
                                m.mit_on = false;
                                m.applied = None;
                            }
                            mit::Order::Zero => {}
                            mit::Order::Command(c) => {
                                if m.mit_on {
                                    m.applied = Some(c);
                                    self.commanded = true;
                                }
                            }
                        }
                    }
                    Some(Err(_)) => self.malformed += 1,
                    None => {}
                },
            }
        }
    }

    /// The leg the hopper gets: the length joint's target and spring through the kinematics.
    pub fn set_point(&self) -> LegSetPoint {
        let hip = self.motors[0].applied;
        let len = self.motors[1].applied;
        let jx =
            |i: usize, c: Option<JointCommand>| c.map(|c| self.maps[i].to_joint(c.position_rad));
        let (hx, lx) = (jx(0, hip), jx(1, len));
        let q = [hx.unwrap_or(0.0), lx.unwrap_or(0.0)];
        let (angle, length) = self.kin.forward(q);
        let g2 = self.kin.length_gain(q).powi(2).max(1e-12);
        let scale2 = self.maps[1].scale.powi(2);
        let (k, b) = len.map_or((0.0, 0.0), |c| (c.kp * scale2 / g2, c.kd * scale2 / g2));
        LegSetPoint {
            length_m: if lx.is_some() {
                length
            } else {
                self.kin.length_range().1
            },
            angle_rad: angle,
            stiffness_n_per_m: k,
            damping_n_s_per_m: b,
            hip_stiff: hip.is_some_and(|c| c.kp > 0.0),
        }
    }

    /// Sends what the motors owe at `now_us`, for the hopper's true leg `angle` and `length`.
    pub fn emit(&mut self, now_us: u64, angle: f64, length: f64, dt_s: f64, out: &mut Outbox) {
        let q = self.kin.joints_of(length, angle);
        let estimate = now_us >= self.next_estimate_us;
        if estimate {
            self.next_estimate_us = now_us + ODRIVE_ESTIMATE_US;
        }
        let heartbeat = now_us >= self.next_heartbeat_us;
        if heartbeat {
            self.next_heartbeat_us = now_us + ODRIVE_HEARTBEAT_US;
        }
        for (i, m) in self.motors.iter_mut().enumerate() {
            let p = self.maps[i].to_driver(q[i]);
            let v = m
                .last_position
                .map_or(0.0, |p0| if dt_s > 0.0 { (p - p0) / dt_s } else { 0.0 });
            m.last_position = Some(p);
            if m.silenced {
                m.owed = 0;
                continue;
            }
            let noisy = p + ENCODER_NOISE_RAD * gauss(&mut self.rng);
            let torque = m.applied.map_or(0.0, |c| {
                c.kp * (c.position_rad - p) - c.kd * v + c.torque_nm
            });
            match &m.server {
                Server::Moteus(s) => {
                    for _ in 0..m.owed.min(1) {
                        s.reply(
                            m.moteus_source,
                            &moteus::MotorState {
                                position_rad: noisy,
                                velocity_rad_s: v,
                                torque_nm: torque,
                                running: m.applied.is_some(),
                                fault: m.fault as i8,
                            },
                            out,
                        );
                    }
                }
                Server::Mit(s) => {
                    for _ in 0..m.owed.min(1) {
                        s.reply(noisy, v, torque, m.fault as u8, out);
                    }
                }
                Server::Odrive(s) => {
                    if estimate {
                        s.encoder_estimates(noisy, v, out);
                    }
                    if heartbeat {
                        s.heartbeat(m.fault, m.odrive.2 as u8, out);
                    }
                }
            }
            m.owed = 0;
        }
    }
}

/// A standard normal draw (Box-Muller).
fn gauss(rng: &mut impl Rng) -> f64 {
    let u1: f64 = rng.random_range(1e-12..1.0);
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}
