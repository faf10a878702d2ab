//! The MIT mini-cheetah protocol (Ben Katz's motor controller; T-Motor AK and CubeMars
//! actuators and their clones), by hand: eight packed bytes, and the ranges that scale them
//! differ per model and firmware, so they come from the config ([`Ranges`]).
//!
//! - Command, on the motor's id, 8 bytes: position 16 bits, velocity 12, kp 12, kd 12,
//!   torque 12, big-endian bit order, each `uint = (x - min) * (2^bits - 1) / (max - min)`.
//!   We round to the nearest count where the reference firmware and the Python driver
//!   truncate: truncation lowers every gain by up to a whole count (a count of kp is
//!   0.12 N m/rad, of kd 0.0012 N m s/rad), rounding by half of one. Decoding is the same
//!   either way. A count matters: see examples/leg.toml for a damping one count off that cost
//!   the closed loop accuracy, and [`crate::config::LegConfig::quantisation_warnings`].
//! - Special frames: `FF FF FF FF FF FF FF FC` enter motor mode, `..FD` exit, `..FE` set zero.
//! - Reply, on the master's id, 6 bytes: motor id, position 16, velocity 12, torque 12 (some
//!   firmwares add temperature and an error byte: 8 bytes).
//!
//! The motor holds its last command: the damped stop is a command with kp 0, kd > 0, torque 0.

use protocol::CanFrame;
use protocol::component::Outbox;
use serde::{Deserialize, Serialize};

use super::{BusId, JointCommand, Reply, ReplyError, push};

const NAME: &str = "mit";

/// Enter motor mode.
pub const ENTER: [u8; 8] = [0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFC];
/// Exit motor mode.
pub const EXIT: [u8; 8] = [0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFD];
/// Set the present position as zero.
pub const ZERO: [u8; 8] = [0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFE];

/// A model's ranges: positions in rad, velocities rad/s, torques N m; minima are the negated
/// maxima (kp and kd from 0).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Ranges {
    /// Position range ±, rad.
    pub p_max: f64,
    /// Velocity range ±, rad/s.
    pub v_max: f64,
    /// Largest kp, N m/rad.
    pub kp_max: f64,
    /// Largest kd, N m s/rad.
    pub kd_max: f64,
    /// Torque range ±, N m.
    pub t_max: f64,
}

impl Ranges {
    /// A known model's ranges (the names `mini-cheetah-motor-driver-socketcan` uses, with
    /// dashes): AK80-6-V1, AK80-6-V1.1, AK80-6-V2, AK80-9-V1.1, AK80-9-V2, AK70-10-V1.1,
    /// AK10-9-V1.1.
    pub fn of_model(name: &str) -> Option<Self> {
        let r = |p_max, v_max, t_max| Ranges {
            p_max,
            v_max,
            kp_max: 500.0,
            kd_max: 5.0,
            t_max,
        };
        Some(match name {
            "AK80-6-V1" => r(95.5, 45.0, 18.0),
            "AK80-6-V1.1" => r(12.5, 22.5, 12.0),
            "AK80-6-V2" => r(12.5, 76.0, 12.0),
            "AK80-9-V1.1" => r(12.5, 22.5, 18.0),
            "AK80-9-V2" => r(12.5, 25.64, 18.0),
            "AK70-10-V1.1" => r(12.5, 50.0, 24.0),
            "AK10-9-V1.1" => r(12.5, 50.0, 65.0),
            _ => return None,
        })
    }

    /// The model names [`Ranges::of_model`] knows.
    pub const MODELS: [&'static str; 7] = [
        "AK80-6-V1",
        "AK80-6-V1.1",
        "AK80-6-V2",
        "AK80-9-V1.1",
        "AK80-9-V2",
        "AK70-10-V1.1",
        "AK10-9-V1.1",
    ];
}

fn to_uint(x: f64, min: f64, max: f64, bits: u32) -> u32 {
    let top = ((1u32 << bits) - 1) as f64;
    let x = if x.is_nan() { 0.0 } else { x.clamp(min, max) };
    ((x - min) * top / (max - min)).round() as u32
}

fn to_float(u: u32, min: f64, max: f64, bits: u32) -> f64 {
    let top = ((1u32 << bits) - 1) as f64;
    u as f64 * (max - min) / top + min
}

/// Packs a command (clamped to the ranges).
pub fn pack(c: &JointCommand, r: &Ranges) -> [u8; 8] {
    let p = to_uint(c.position_rad, -r.p_max, r.p_max, 16);
    let v = to_uint(c.velocity_rad_s, -r.v_max, r.v_max, 12);
    let kp = to_uint(c.kp, 0.0, r.kp_max, 12);
    let kd = to_uint(c.kd, 0.0, r.kd_max, 12);
    let t = to_uint(c.torque_nm, -r.t_max, r.t_max, 12);
    [
        (p >> 8) as u8,
        p as u8,
        (v >> 4) as u8,
        (((v & 0xF) << 4) | (kp >> 8)) as u8,
        kp as u8,
        (kd >> 4) as u8,
        (((kd & 0xF) << 4) | (t >> 8)) as u8,
        t as u8,
    ]
}

/// Unpacks a command (the motor's side).
pub fn unpack(d: &[u8; 8], r: &Ranges) -> JointCommand {
    let p = ((d[0] as u32) << 8) | d[1] as u32;
    let v = ((d[2] as u32) << 4) | (d[3] as u32 >> 4);
    let kp = ((d[3] as u32 & 0xF) << 8) | d[4] as u32;
    let kd = ((d[5] as u32) << 4) | (d[6] as u32 >> 4);
    let t = ((d[6] as u32 & 0xF) << 8) | d[7] as u32;
    JointCommand {
        position_rad: to_float(p, -r.p_max, r.p_max, 16),
        velocity_rad_s: to_float(v, -r.v_max, r.v_max, 12),
        kp: to_float(kp, 0.0, r.kp_max, 12),
        kd: to_float(kd, 0.0, r.kd_max, 12),
        torque_nm: to_float(t, -r.t_max, r.t_max, 12),
    }
}

/// One MIT-protocol motor, the bridge's side.
#[derive(Clone, Debug)]
pub struct Mit {
    id: u8,
    master: u8,
    ranges: Ranges,
}

impl Mit {
    /// The motor with CAN id `id`, answering on the master id `master`, with its model's
    /// ranges.
    pub fn new(id: u8, master: u8, ranges: Ranges) -> Self {
        Self { id, master, ranges }
    }

    /// Enter motor mode.
    pub fn enable(&mut self, out: &mut Outbox) {
        push(out, self.id as u32, false, &ENTER, false);
    }

    /// A packed command.
    pub fn command(&mut self, c: &JointCommand, out: &mut Outbox) {
        push(out, self.id as u32, false, &pack(c, &self.ranges), false);
    }

    /// Before motor mode the motor answers an exit frame with its state and moves nothing.
    pub fn query(&mut self, out: &mut Outbox) {
        push(out, self.id as u32, false, &EXIT, false);
    }

    /// A zero command (no stiffness, damping or torque) and exit.
    pub fn stop(&mut self, out: &mut Outbox) {
        self.command(&JointCommand::default(), out);
        push(out, self.id as u32, false, &EXIT, false);
    }

    /// Its reply; `None` for other frames (another motor's reply included).
    pub fn decode(&self, f: &CanFrame) -> Option<Result<Reply, ReplyError>> {
        let d = f.data();
        if f.is_extended() || f.is_remote() || f.raw_id() != self.master as u32 {
            return None;
        }
        if d.first() != Some(&self.id) {
            return None;
        }
        if d.len() != 6 && d.len() != 8 {
            return Some(Err(ReplyError::Length {
                driver: NAME,
                message: "reply",
                want: 6,
                got: d.len(),
            }));
        }
        let r = &self.ranges;
        let p = ((d[1] as u32) << 8) | d[2] as u32;
        let v = ((d[3] as u32) << 4) | (d[4] as u32 >> 4);
        let t = ((d[4] as u32 & 0xF) << 8) | d[5] as u32;
        Some(Ok(Reply::Reading {
            position_rad: to_float(p, -r.p_max, r.p_max, 16),
            velocity_rad_s: to_float(v, -r.v_max, r.v_max, 12),
            torque_nm: to_float(t, -r.t_max, r.t_max, 12),
            fault: Some(if d.len() == 8 { d[7] as u32 } else { 0 }),
        }))
    }

    /// Commands on its id, replies on the master's.
    pub fn bus_ids(&self) -> Vec<BusId> {
        vec![
            BusId {
                id: self.id as u32,
                extended: false,
                what: format!("MIT motor {} command", self.id),
            },
            BusId {
                id: self.master as u32,
                extended: false,
                what: format!("MIT master id {} (replies)", self.master),
            },
        ]
    }
}

/// What an MIT motor was told, as the motor's side reads it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Order {
    /// Enter motor mode.
    Enter,
    /// Exit motor mode.
    Exit,
    /// Set zero.
    Zero,
    /// A command.
    Command(JointCommand),
}

/// One MIT motor, the motor's side (the simulator's).
#[derive(Clone, Debug)]
pub struct Server {
    id: u8,
    master: u8,
    ranges: Ranges,
}

impl Server {
    /// The motor with id `id` replying on `master`.
    pub fn new(id: u8, master: u8, ranges: Ranges) -> Self {
        Self { id, master, ranges }
    }

    /// A frame to it; `None` for other frames.
    pub fn on_frame(&self, f: &CanFrame) -> Option<Result<Order, ReplyError>> {
        if f.is_extended() || f.is_remote() || f.raw_id() != self.id as u32 {
            return None;
        }
        let Ok(d) = <[u8; 8]>::try_from(f.data()) else {
            return Some(Err(ReplyError::Length {
                driver: NAME,
                message: "command",
                want: 8,
                got: f.data().len(),
            }));
        };
        Some(Ok(match d {
            ENTER => Order::Enter,
            EXIT => Order::Exit,
            ZERO => Order::Zero,
            _ => Order::Command(unpack(&d, &self.ranges)),
        }))
    }

    /// The 6-byte reply (8 with an error byte when `error` is not 0).
    pub fn reply(
        &self,
        position_rad: f64,
        velocity_rad_s: f64,
        torque_nm: f64,
        error: u8,
        out: &mut Outbox,
    ) {
        let r = &self.ranges;
        let p = to_uint(position_rad, -r.p_max, r.p_max, 16);
        let v = to_uint(velocity_rad_s, -r.v_max, r.v_max, 12);
        let t = to_uint(torque_nm, -r.t_max, r.t_max, 12);
        let d = [
            self.id,
            (p >> 8) as u8,
            p as u8,
            (v >> 4) as u8,
            (((v & 0xF) << 4) | (t >> 8)) as u8,
            t as u8,
            0,
            error,
        ];
        let n = if error != 0 { 8 } else { 6 };
        push(out, self.master as u32, false, &d[..n], false);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn r() -> Ranges {
        Ranges::of_model("AK80-6-V1.1").unwrap()
    }

    #[test]
    fn pack_unpack_round_trips_within_one_quantum() {
        let c = JointCommand {
            position_rad: 1.234,
            velocity_rad_s: -3.3,
            kp: 12.0,
            kd: 0.8,
            torque_nm: -2.5,
        };
        let u = unpack(&pack(&c, &r()), &r());
        let q = |span: f64, bits: u32| span / ((1u32 << bits) - 1) as f64;
        assert!((u.position_rad - c.position_rad).abs() <= q(25.0, 16));
        assert!((u.velocity_rad_s - c.velocity_rad_s).abs() <= q(45.0, 12));
        assert!((u.kp - c.kp).abs() <= q(500.0, 12));
        assert!((u.kd - c.kd).abs() <= q(5.0, 12));
        assert!((u.torque_nm - c.torque_nm).abs() <= q(24.0, 12));
    }

    #[test]
    fn out_of_range_and_nan_are_clamped_never_wrapped() {
        let c = JointCommand {
            position_rad: 100.0,
            velocity_rad_s: f64::NAN,
            kp: 1e9,
            kd: -1.0,
            torque_nm: -1e9,
        };
        let u = unpack(&pack(&c, &r()), &r());
        assert!((u.position_rad - 12.5).abs() < 1e-9);
        assert!(u.velocity_rad_s.abs() < 0.02);
        assert!((u.kp - 500.0).abs() < 1e-9 && u.kd == 0.0);
        assert!((u.torque_nm + 12.0).abs() < 1e-9);
    }

    #[test]
    fn replies_go_to_their_motor_and_bad_lengths_are_errors() {
        let m = Mit::new(2, 0, r());
        let s = Server::new(2, 0, r());
        let mut out = Outbox::default();
        s.reply(0.5, 1.0, -0.75, 0, &mut out);
        s.reply(0.5, 1.0, -0.75, 7, &mut out);
        let f: Vec<CanFrame> = out.drain().collect();
        let Some(Ok(Reply::Reading {
            position_rad,
            fault: Some(0),
            ..
        })) = m.decode(&f[0])
        else {
            panic!("{:?}", m.decode(&f[0]))
        };
        assert!((position_rad - 0.5).abs() < 25.0 / 65535.0);
        assert!(matches!(
            m.decode(&f[1]),
            Some(Ok(Reply::Reading { fault: Some(7), .. }))
        ));
        assert!(Mit::new(1, 0, r()).decode(&f[0]).is_none());
        let short =
            CanFrame::classic(protocol::frame::make_id(0, false).unwrap(), &[2, 0, 0]).unwrap();
        assert!(matches!(m.decode(&short), Some(Err(_))));
    }

    #[test]
    fn special_frames_are_recognised() {
        let mut m = Mit::new(1, 0, r());
        let s = Server::new(1, 0, r());
        let mut out = Outbox::default();
        m.enable(&mut out);
        m.query(&mut out);
        m.stop(&mut out);
        let orders: Vec<Order> = out.drain().filter_map(|f| s.on_frame(&f)?.ok()).collect();
        assert_eq!(orders[0], Order::Enter);
        assert_eq!(orders[1], Order::Exit);
        assert!(matches!(orders[2], Order::Command(c) if c.kp == 0.0 && c.kd == 0.0));
        assert_eq!(orders[3], Order::Exit);
    }
}
