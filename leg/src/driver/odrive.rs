//! ODrive CANSimple (firmware 0.6), by hand: no maintained Rust crate speaks it, and it is a
//! handful of fixed little-endian layouts (the `odrive-cansimple` DBC that ODrive publishes,
//! which the interop tests read with cantools, is the reference).
//!
//! Identifiers are `node << 5 | command`: every node takes 32 ids, so a node's range can land
//! on ours (node 8 is 0x100-0x11F, FootContact's); the config check refuses that.
//!
//! ODrive has no per-command gains: its position loop is cascaded, `vel = pos_gain (p - p_set)
//! + vel_ff`, `torque = vel_gain (vel - v) + torque_ff`, so a stiffness `kp` with damping `kd`
//! is `vel_gain = kd`, `pos_gain = kp / kd` (in turns); the gains are sent when they change.
//! A stiffness without damping cannot be had (the config check refuses it). The damped stop is
//! `pos_gain = 0`: velocity held at zero through `vel_gain`.

use std::f64::consts::TAU;

use protocol::CanFrame;
use protocol::component::Outbox;

use super::{BusId, JointCommand, Reply, ReplyError, push};

const NAME: &str = "odrive";

/// CANSimple command ids used here.
pub mod cmd {
    /// ODrive -> host: axis error, state, procedure result, trajectory done.
    pub const HEARTBEAT: u32 = 0x01;
    /// Host -> ODrive: requested axis state.
    pub const SET_AXIS_STATE: u32 = 0x07;
    /// ODrive -> host: position (turns) and velocity (turns/s) estimates.
    pub const GET_ENCODER_ESTIMATES: u32 = 0x09;
    /// Host -> ODrive: control mode and input mode.
    pub const SET_CONTROLLER_MODE: u32 = 0x0B;
    /// Host -> ODrive: position set point, velocity and torque feed-forward.
    pub const SET_INPUT_POS: u32 = 0x0C;
    /// Host -> ODrive: position gain.
    pub const SET_POS_GAIN: u32 = 0x1A;
    /// Host -> ODrive: velocity gain and integrator gain.
    pub const SET_VEL_GAINS: u32 = 0x1B;
}

/// Axis states used here.
pub mod state {
    /// Motor off.
    pub const IDLE: u32 = 1;
    /// Following set points.
    pub const CLOSED_LOOP_CONTROL: u32 = 8;
}

/// Position control (`Set_Controller_Mode`'s control mode).
pub const POSITION_CONTROL: u32 = 3;
/// Passthrough input (no filtering or trajectory).
pub const INPUT_PASSTHROUGH: u32 = 1;

/// The feed-forward fields' scale: 0.001 rev/s and 0.001 N m per count.
const FF_SCALE: f64 = 1e-3;

fn id(node: u8, command: u32) -> u32 {
    ((node as u32 & 0x3F) << 5) | command
}

fn f32_at(d: &[u8], i: usize) -> f32 {
    f32::from_le_bytes([d[i], d[i + 1], d[i + 2], d[i + 3]])
}

fn u32_at(d: &[u8], i: usize) -> u32 {
    u32::from_le_bytes([d[i], d[i + 1], d[i + 2], d[i + 3]])
}

fn sat_i16(v: f64) -> i16 {
    v.round().clamp(i16::MIN as f64, i16::MAX as f64) as i16
}

/// One ODrive axis, the bridge's side.
#[derive(Clone, Debug)]
pub struct Odrive {
    node: u8,
    /// The gains last sent, turns: (pos_gain, vel_gain); `None` before any.
    gains: Option<(f32, f32)>,
    /// The set point last sent, to hold in the damped stop, turns.
    last_pos_turns: f32,
}

impl Odrive {
    /// The axis with CAN node id `node` (0..=63).
    pub fn new(node: u8) -> Self {
        Self {
            node: node & 0x3F,
            gains: None,
            last_pos_turns: 0.0,
        }
    }

    /// Closed loop, position control with passthrough input.
    pub fn enable(&mut self, out: &mut Outbox) {
        let mut d = [0u8; 8];
        d[0..4].copy_from_slice(&POSITION_CONTROL.to_le_bytes());
        d[4..8].copy_from_slice(&INPUT_PASSTHROUGH.to_le_bytes());
        push(
            out,
            id(self.node, cmd::SET_CONTROLLER_MODE),
            false,
            &d,
            false,
        );
        self.set_state(state::CLOSED_LOOP_CONTROL, out);
        self.gains = None;
    }

    fn set_state(&self, s: u32, out: &mut Outbox) {
        let mut d = [0u8; 8];
        d[0..4].copy_from_slice(&s.to_le_bytes());
        push(out, id(self.node, cmd::SET_AXIS_STATE), false, &d, false);
    }

    fn set_gains(&mut self, kp: f64, kd: f64, out: &mut Outbox) {
        // In turns: vel_gain N m/(turn/s) = kd * 2 pi; pos_gain (turn/s)/turn = kp / kd.
        let vel_gain = (kd * TAU) as f32;
        let pos_gain = if kd > 0.0 { (kp / kd) as f32 } else { 0.0 };
        if self.gains == Some((pos_gain, vel_gain)) {
            return;
        }
        let mut d = [0u8; 8];
        d[0..4].copy_from_slice(&pos_gain.to_le_bytes());
        push(out, id(self.node, cmd::SET_POS_GAIN), false, &d, false);
        let mut d = [0u8; 8];
        d[0..4].copy_from_slice(&vel_gain.to_le_bytes());
        push(out, id(self.node, cmd::SET_VEL_GAINS), false, &d, false);
        self.gains = Some((pos_gain, vel_gain));
    }

    /// Gains (when changed) and the set point. With `kp = 0` the last position is kept as the
    /// set point: only damping acts.
    pub fn command(&mut self, c: &JointCommand, out: &mut Outbox) {
        self.set_gains(c.kp, c.kd, out);
        if c.kp > 0.0 {
            self.last_pos_turns = (c.position_rad / TAU) as f32;
        }
        let mut d = [0u8; 8];
        d[0..4].copy_from_slice(&self.last_pos_turns.to_le_bytes());
        d[4..6].copy_from_slice(&sat_i16(c.velocity_rad_s / TAU / FF_SCALE).to_le_bytes());
        d[6..8].copy_from_slice(&sat_i16(c.torque_nm / FF_SCALE).to_le_bytes());
        push(out, id(self.node, cmd::SET_INPUT_POS), false, &d, false);
    }

    /// Idle.
    pub fn stop(&mut self, out: &mut Outbox) {
        self.set_state(state::IDLE, out);
    }

    /// A heartbeat or encoder estimate of this axis; `None` for other frames.
    pub fn decode(&self, f: &CanFrame) -> Option<Result<Reply, ReplyError>> {
        if f.is_extended() || f.is_remote() || (f.raw_id() >> 5) != self.node as u32 {
            return None;
        }
        let d = f.data();
        let len = |message, want| {
            Err(ReplyError::Length {
                driver: NAME,
                message,
                want,
                got: d.len(),
            })
        };
        Some(match f.raw_id() & 0x1F {
            cmd::HEARTBEAT => {
                if d.len() < 5 {
                    return Some(len("Heartbeat", 8));
                }
                Ok(Reply::Status {
                    fault: u32_at(d, 0),
                })
            }
            cmd::GET_ENCODER_ESTIMATES => {
                if d.len() != 8 {
                    return Some(len("Get_Encoder_Estimates", 8));
                }
                let (p, v) = (f32_at(d, 0), f32_at(d, 4));
                if !p.is_finite() || !v.is_finite() {
                    return Some(Err(ReplyError::Value {
                        driver: NAME,
                        message: "Get_Encoder_Estimates",
                        what: "a non-finite position or velocity",
                    }));
                }
                Ok(Reply::Reading {
                    position_rad: p as f64 * TAU,
                    velocity_rad_s: v as f64 * TAU,
                    torque_nm: f64::NAN,
                    fault: None,
                })
            }
            // Our own commands echoed by a second socket, and messages not used here.
            _ => return None,
        })
    }

    /// All 32 identifiers of the node.
    pub fn bus_ids(&self) -> Vec<BusId> {
        (0..32)
            .map(|c| BusId {
                id: id(self.node, c),
                extended: false,
                what: format!("ODrive node {} command 0x{c:02X}", self.node),
            })
            .collect()
    }
}

/// What an ODrive was told, as the motor's side reads it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Order {
    /// Axis state requested.
    State(u32),
    /// Control and input mode.
    ControllerMode(u32, u32),
    /// Position set point (rad), velocity (rad/s) and torque (N m) feed-forward.
    InputPos(f64, f64, f64),
    /// Position gain, (turn/s)/turn.
    PosGain(f64),
    /// Velocity gain, N m/(turn/s).
    VelGain(f64),
}

/// One ODrive axis, the motor's side (the simulator's).
#[derive(Clone, Debug)]
pub struct Server {
    node: u8,
}

impl Server {
    /// The axis with node id `node`.
    pub fn new(node: u8) -> Self {
        Self { node: node & 0x3F }
    }

    /// A command to it; `None` for other frames (its own messages included).
    pub fn on_frame(&self, f: &CanFrame) -> Option<Result<Order, ReplyError>> {
        if f.is_extended() || f.is_remote() || (f.raw_id() >> 5) != self.node as u32 {
            return None;
        }
        let d = f.data();
        let need = |message: &'static str| {
            (d.len() < 8).then_some(Err(ReplyError::Length {
                driver: NAME,
                message,
                want: 8,
                got: d.len(),
            }))
        };
        Some(match f.raw_id() & 0x1F {
            cmd::SET_AXIS_STATE => {
                if let Some(e) = need("Set_Axis_State") {
                    return Some(e);
                }
                Ok(Order::State(u32_at(d, 0)))
            }
            cmd::SET_CONTROLLER_MODE => {
                if let Some(e) = need("Set_Controller_Mode") {
                    return Some(e);
                }
                Ok(Order::ControllerMode(u32_at(d, 0), u32_at(d, 4)))
            }
            cmd::SET_INPUT_POS => {
                if let Some(e) = need("Set_Input_Pos") {
                    return Some(e);
                }
                let vel = i16::from_le_bytes([d[4], d[5]]) as f64 * FF_SCALE * TAU;
                let tq = i16::from_le_bytes([d[6], d[7]]) as f64 * FF_SCALE;
                Ok(Order::InputPos(f32_at(d, 0) as f64 * TAU, vel, tq))
            }
            cmd::SET_POS_GAIN => {
                if d.len() < 4 {
                    return need("Set_Pos_Gain");
                }
                Ok(Order::PosGain(f32_at(d, 0) as f64))
            }
            cmd::SET_VEL_GAINS => {
                if let Some(e) = need("Set_Vel_Gains") {
                    return Some(e);
                }
                Ok(Order::VelGain(f32_at(d, 0) as f64))
            }
            _ => return None,
        })
    }

    /// The cyclic encoder estimate.
    pub fn encoder_estimates(&self, position_rad: f64, velocity_rad_s: f64, out: &mut Outbox) {
        let mut d = [0u8; 8];
        d[0..4].copy_from_slice(&((position_rad / TAU) as f32).to_le_bytes());
        d[4..8].copy_from_slice(&((velocity_rad_s / TAU) as f32).to_le_bytes());
        push(
            out,
            id(self.node, cmd::GET_ENCODER_ESTIMATES),
            false,
            &d,
            false,
        );
    }

    /// The cyclic heartbeat.
    pub fn heartbeat(&self, axis_error: u32, axis_state: u8, out: &mut Outbox) {
        let mut d = [0u8; 8];
        d[0..4].copy_from_slice(&axis_error.to_le_bytes());
        d[4] = axis_state;
        push(out, id(self.node, cmd::HEARTBEAT), false, &d, false);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn impedance_becomes_cascaded_gains_sent_once() {
        let mut o = Odrive::new(3);
        let s = Server::new(3);
        let mut out = Outbox::default();
        o.enable(&mut out);
        let c = JointCommand {
            position_rad: 2.0,
            velocity_rad_s: 1.0,
            kp: 4.0,
            kd: 0.5,
            torque_nm: 0.125,
        };
        o.command(&c, &mut out);
        o.command(&c, &mut out);
        let f: Vec<CanFrame> = out.drain().collect();
        let orders: Vec<Order> = f.iter().filter_map(|f| s.on_frame(f)?.ok()).collect();
        assert_eq!(
            orders[0],
            Order::ControllerMode(POSITION_CONTROL, INPUT_PASSTHROUGH)
        );
        assert_eq!(orders[1], Order::State(state::CLOSED_LOOP_CONTROL));
        let (Order::PosGain(pg), Order::VelGain(vg)) = (orders[2], orders[3]) else {
            panic!("{orders:?}");
        };
        // Stiffness in N m/turn is pos_gain * vel_gain: kp * 2 pi.
        assert!((pg * vg - 4.0 * TAU).abs() < 1e-4 && (vg - 0.5 * TAU).abs() < 1e-5);
        let Order::InputPos(p, v, t) = orders[4] else {
            panic!("{orders:?}")
        };
        assert!((p - 2.0).abs() < 1e-6 && (v - 1.0).abs() < 0.01 && (t - 0.125).abs() < 1e-3);
        // The second command sends the set point only.
        assert_eq!(orders.len(), 6);
        assert!(matches!(orders[5], Order::InputPos(..)));
        assert_eq!(f[4].raw_id(), 3 << 5 | cmd::SET_INPUT_POS);
    }

    #[test]
    fn estimates_and_heartbeat_decode_and_bad_lengths_are_errors() {
        let o = Odrive::new(3);
        let s = Server::new(3);
        let mut out = Outbox::default();
        s.encoder_estimates(1.5, -2.0, &mut out);
        s.heartbeat(0x800, 8, &mut out);
        let f: Vec<CanFrame> = out.drain().collect();
        let Some(Ok(Reply::Reading {
            position_rad,
            velocity_rad_s,
            ..
        })) = o.decode(&f[0])
        else {
            panic!()
        };
        assert!((position_rad - 1.5).abs() < 1e-6 && (velocity_rad_s + 2.0).abs() < 1e-6);
        assert_eq!(o.decode(&f[1]), Some(Ok(Reply::Status { fault: 0x800 })));
        let short = CanFrame::classic(
            protocol::frame::make_id(f[0].raw_id(), false).unwrap(),
            &[1, 2, 3],
        )
        .unwrap();
        assert!(matches!(
            o.decode(&short),
            Some(Err(ReplyError::Length { .. }))
        ));
        let nan = CanFrame::classic(
            protocol::frame::make_id(f[0].raw_id(), false).unwrap(),
            &[0, 0, 0xC0, 0x7F, 0, 0, 0, 0],
        )
        .unwrap();
        assert!(matches!(
            o.decode(&nan),
            Some(Err(ReplyError::Value { .. }))
        ));
        assert!(Odrive::new(4).decode(&f[0]).is_none());
    }

    #[test]
    fn node_8_takes_foot_contacts_ids() {
        let ids = Odrive::new(8).bus_ids();
        assert_eq!(ids[1].id, 0x101);
        assert_eq!(ids.len(), 32);
    }
}
