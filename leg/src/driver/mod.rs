//! The motor drivers: one small module per protocol, each from its public description.
//!
//! - [`moteus`]: mjbots moteus, CAN FD register protocol, through mjbots' own `moteus-protocol`
//!   crate (no_std, from the vendor).
//! - [`odrive`]: ODrive CANSimple (firmware 0.6), by hand: no maintained Rust crate speaks it.
//! - [`mit`]: the MIT mini-cheetah protocol of T-Motor AK / CubeMars actuators and their
//!   clones, by hand: it is eight packed bytes, and no maintained crate carries the per-model
//!   ranges.
//!
//! A [`Driver`] is the bridge's side (it commands and reads a joint); each module's `Server` is
//! the motor's side, which the simulator uses to present its leg as motors. Units at this
//! level are the driver's own output shaft in SI: rad, rad/s, N m/rad, N m s/rad, N m. The
//! joint's gear ratio, direction and zero offset are the bridge's business ([`crate::config`]).

pub mod mit;
pub mod moteus;
pub mod odrive;

use protocol::CanFrame;
use protocol::component::Outbox;
use thiserror::Error;

/// One joint's impedance set point: `torque = kp (position - p) + kd (velocity - v) + torque_ff`.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct JointCommand {
    /// Position target, rad.
    pub position_rad: f64,
    /// Velocity target, rad/s.
    pub velocity_rad_s: f64,
    /// Stiffness, N m/rad (0: none).
    pub kp: f64,
    /// Damping, N m s/rad.
    pub kd: f64,
    /// Feed-forward torque, N m.
    pub torque_nm: f64,
}

/// What a driver said about its joint.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Reply {
    /// The encoder: position, rad; velocity, rad/s; torque, N m (NaN where the message has
    /// none). `fault` is the driver's own code (0 none) where the message carries one.
    Reading {
        /// Output position, rad.
        position_rad: f64,
        /// Output velocity, rad/s.
        velocity_rad_s: f64,
        /// Torque, N m.
        torque_nm: f64,
        /// The driver's fault code, if this message carries one.
        fault: Option<u32>,
    },
    /// A status without a position (the ODrive heartbeat): its fault code (0 none).
    Status {
        /// The driver's fault code.
        fault: u32,
    },
}

/// A frame on one of a driver's identifiers that is not what the protocol allows.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum ReplyError {
    /// Wrong length for the message.
    #[error("{driver} {message}: {got} data bytes, the protocol has {want}")]
    Length {
        /// The protocol.
        driver: &'static str,
        /// The message.
        message: &'static str,
        /// Bytes expected.
        want: usize,
        /// Bytes received.
        got: usize,
    },
    /// A value the message cannot carry (a NaN position, a missing register).
    #[error("{driver} {message}: {what}")]
    Value {
        /// The protocol.
        driver: &'static str,
        /// The message.
        message: &'static str,
        /// What was wrong.
        what: &'static str,
    },
}

/// An identifier a driver uses on the bus, for the collision check against ours.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BusId {
    /// The raw identifier.
    pub id: u32,
    /// 29-bit.
    pub extended: bool,
    /// What it carries, for the error that names a collision ("ODrive node 8 Heartbeat").
    pub what: String,
}

/// One joint's driver, the bridge's side.
#[derive(Clone, Debug)]
pub enum Driver {
    /// mjbots moteus.
    Moteus(moteus::Moteus),
    /// ODrive CANSimple.
    Odrive(odrive::Odrive),
    /// MIT protocol.
    Mit(mit::Mit),
}

impl Driver {
    /// The protocol.
    pub fn kind(&self) -> crate::DriverKind {
        match self {
            Driver::Moteus(_) => crate::DriverKind::Moteus,
            Driver::Odrive(_) => crate::DriverKind::Odrive,
            Driver::Mit(_) => crate::DriverKind::Mit,
        }
    }

    /// The protocol's name.
    pub fn name(&self) -> &'static str {
        self.kind().name()
    }

    /// Frames that make the driver follow commands (ODrive closed loop, MIT motor mode); sent
    /// once, just before the first command.
    pub fn enable(&mut self, out: &mut Outbox) {
        match self {
            Driver::Moteus(_) => {}
            Driver::Odrive(d) => d.enable(out),
            Driver::Mit(d) => d.enable(out),
        }
    }

    /// An impedance command (with a request for the joint's state where the protocol asks).
    pub fn command(&mut self, c: &JointCommand, out: &mut Outbox) {
        match self {
            Driver::Moteus(d) => d.command(c, out),
            Driver::Odrive(d) => d.command(c, out),
            Driver::Mit(d) => d.command(c, out),
        }
    }

    /// The damped stop: no stiffness, damping `kd` (N m s/rad), no torque.
    pub fn damp(&mut self, kd: f64, out: &mut Outbox) {
        let c = JointCommand {
            position_rad: 0.0,
            velocity_rad_s: 0.0,
            kp: 0.0,
            kd,
            torque_nm: 0.0,
        };
        match self {
            Driver::Moteus(d) => d.damp(kd, out),
            Driver::Odrive(d) => d.command(&c, out),
            Driver::Mit(d) => d.command(&c, out),
        }
    }

    /// Asks for the joint's state without moving it (before the first command and in
    /// `presrs leg --check`). ODrive reports on its own.
    pub fn query(&mut self, out: &mut Outbox) {
        match self {
            Driver::Moteus(d) => d.query(out),
            Driver::Odrive(_) => {}
            Driver::Mit(d) => d.query(out),
        }
    }

    /// Leaves the motor stopped (exit): moteus stop, ODrive idle, MIT zero command and exit.
    pub fn stop(&mut self, out: &mut Outbox) {
        match self {
            Driver::Moteus(d) => d.stop(out),
            Driver::Odrive(d) => d.stop(out),
            Driver::Mit(d) => d.stop(out),
        }
    }

    /// A received frame: `None` when it is not this driver's.
    pub fn decode(&self, f: &CanFrame) -> Option<Result<Reply, ReplyError>> {
        match self {
            Driver::Moteus(d) => d.decode(f),
            Driver::Odrive(d) => d.decode(f),
            Driver::Mit(d) => d.decode(f),
        }
    }

    /// Kernel filters `(id, mask)` passing every identifier of [`Driver::bus_ids`].
    pub fn filters(&self) -> impl Iterator<Item = (u32, u32)> {
        self.bus_ids()
            .into_iter()
            .map(|b| (b.id, if b.extended { 0x1FFF_FFFF } else { 0x7FF }))
    }

    /// Every identifier the driver sends or answers on.
    pub fn bus_ids(&self) -> Vec<BusId> {
        match self {
            Driver::Moteus(d) => d.bus_ids(),
            Driver::Odrive(d) => d.bus_ids(),
            Driver::Mit(d) => d.bus_ids(),
        }
    }
}

/// A frame from parts that are in range by construction (ids masked to their width, lengths
/// fixed by the protocol); `None` never happens for them, and a frame that cannot be built is
/// not sent.
pub(crate) fn push(out: &mut Outbox, id: u32, extended: bool, data: &[u8], fd: bool) {
    let Some(id) = protocol::frame::make_id(id, extended) else {
        return;
    };
    let frame = if fd {
        CanFrame::fd(id, data, true)
    } else {
        CanFrame::classic(id, data)
    };
    if let Some(f) = frame {
        out.push(f);
    }
}
