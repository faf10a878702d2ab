//! The leg's geometry: LegCommand's length and angle to joint coordinates (inverse
//! kinematics) and joint coordinates to LegState (forward kinematics).
//!
//! Two legs research hoppers are built with:
//! - **prismatic**: a hip motor sets the leg angle; a second motor drives the leg length
//!   through a screw, belt or rack (metres per turn, in the length joint's config). The joint
//!   coordinates are the angle (rad) and the length (m).
//! - **two-link**: hip and knee, thigh and shank lengths. The hip angle `q1` is the thigh's
//!   angle from the vertical (positive with the foot ahead, as the leg angle), the knee angle
//!   `q2` the shank's angle to the thigh (0 straight). The leg is the hip-to-foot line:
//!   `length = sqrt(l1^2 + l2^2 + 2 l1 l2 cos q2)` and `angle = q1 + atan2(l2 sin q2, l1 + l2 cos q2)`.
//!   The length depends on the knee alone, so in stance, where the hip is free and only the
//!   length is sprung, the knee alone carries the leg's spring.
//!
//! Both take the same two joint coordinates, `[hip, length joint]`.

use serde::{Deserialize, Serialize};

/// The leg's type and its dimensions.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "kebab-case", deny_unknown_fields)]
pub enum Kinematics {
    /// Hip motor for the angle; a motor driving the length through a screw, belt or rack.
    Prismatic {
        /// Shortest leg, m (the length joint's lower stop).
        min_length_m: f64,
        /// Longest leg, m.
        max_length_m: f64,
    },
    /// Hip and knee motors.
    TwoLink {
        /// Hip to knee, m.
        thigh_m: f64,
        /// Knee to foot, m.
        shank_m: f64,
        /// The side the knee bends to: +1 (knee angle positive) or -1.
        knee_sign: f64,
        /// Shortest leg the knee may fold to, m.
        min_length_m: f64,
        /// Longest leg, m: below thigh + shank, away from the straight-knee singularity.
        max_length_m: f64,
    },
}

/// Largest leg angle from the vertical either way, rad: a set point beyond is clamped.
pub const MAX_ANGLE_RAD: f64 = 1.2;

/// Joint coordinates for a set point, and whether it was clamped to the workspace.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Inverse {
    /// `[hip rad, length joint (m for prismatic, rad for the knee)]`.
    pub joints: [f64; 2],
    /// The set point was outside the workspace and was moved to its edge.
    pub clamped: bool,
}

impl Kinematics {
    /// The leg lengths this geometry reaches, m.
    pub fn length_range(&self) -> (f64, f64) {
        match *self {
            Kinematics::Prismatic {
                min_length_m,
                max_length_m,
            }
            | Kinematics::TwoLink {
                min_length_m,
                max_length_m,
                ..
            } => (min_length_m, max_length_m),
        }
    }

    /// Joint coordinates for leg `length` (m) and `angle` (rad); outside the workspace the set
    /// point is clamped to its edge (and said in [`Inverse::clamped`]). A NaN set point is
    /// clamped to the workspace's longest, vertical leg: a motor never gets a NaN.
    pub fn inverse(&self, length: f64, angle: f64) -> Inverse {
        let (lo, hi) = self.length_range();
        let l = if length.is_nan() {
            hi
        } else {
            length.clamp(lo, hi)
        };
        let a = if angle.is_nan() {
            0.0
        } else {
            angle.clamp(-MAX_ANGLE_RAD, MAX_ANGLE_RAD)
        };
        let clamped = l != length || a != angle;
        let joints = self.joints_of(l, a);
        Inverse { joints, clamped }
    }

    /// The joint coordinates of a leg that is at `length` and `angle`, without the workspace's
    /// limits (only the geometry's): a simulated encoder reads a leg pressed past its stop.
    pub fn joints_of(&self, length: f64, angle: f64) -> [f64; 2] {
        match *self {
            Kinematics::Prismatic { .. } => [angle, length],
            Kinematics::TwoLink {
                thigh_m: l1,
                shank_m: l2,
                knee_sign,
                ..
            } => {
                let c = ((length * length - l1 * l1 - l2 * l2) / (2.0 * l1 * l2)).clamp(-1.0, 1.0);
                let q2 = knee_sign.signum() * c.acos();
                [angle - knee_offset(l1, l2, q2), q2]
            }
        }
    }

    /// Leg `(angle rad, length m)` for joint coordinates `[hip, length joint]`.
    pub fn forward(&self, joints: [f64; 2]) -> (f64, f64) {
        match *self {
            Kinematics::Prismatic { .. } => (joints[0], joints[1]),
            Kinematics::TwoLink {
                thigh_m: l1,
                shank_m: l2,
                ..
            } => {
                let q2 = joints[1];
                let l = (l1 * l1 + l2 * l2 + 2.0 * l1 * l2 * q2.cos())
                    .max(0.0)
                    .sqrt();
                (joints[0] + knee_offset(l1, l2, q2), l)
            }
        }
    }

    /// d(length)/d(length joint) at the set point's joints: maps the leg's spring (N/m) to
    /// the length joint's (`k_joint = k_leg * gain^2`) and its speed.
    pub fn length_gain(&self, joints: [f64; 2]) -> f64 {
        match *self {
            Kinematics::Prismatic { .. } => 1.0,
            Kinematics::TwoLink {
                thigh_m: l1,
                shank_m: l2,
                ..
            } => {
                let (_, l) = self.forward(joints);
                -l1 * l2 * joints[1].sin() / l.max(1e-9)
            }
        }
    }
}

/// The angle between the thigh and the hip-to-foot line for knee angle `q2`.
fn knee_offset(l1: f64, l2: f64, q2: f64) -> f64 {
    (l2 * q2.sin()).atan2(l1 + l2 * q2.cos())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn two_link() -> Kinematics {
        Kinematics::TwoLink {
            thigh_m: 0.1,
            shank_m: 0.1,
            knee_sign: 1.0,
            min_length_m: 0.08,
            max_length_m: 0.19,
        }
    }

    #[test]
    fn two_link_forward_inverts_inverse_over_the_workspace() {
        let k = two_link();
        for i in 0..=20 {
            for j in 0..=20 {
                let l = 0.08 + 0.11 * i as f64 / 20.0;
                let a = -0.6 + 1.2 * j as f64 / 20.0;
                let inv = k.inverse(l, a);
                assert!(!inv.clamped);
                let (a2, l2) = k.forward(inv.joints);
                assert!((a2 - a).abs() < 1e-12 && (l2 - l).abs() < 1e-12, "{l} {a}");
            }
        }
    }

    #[test]
    fn two_link_matches_the_foot_position_of_its_links() {
        // Foot from the links directly: thigh at q1, shank at q1 + q2 from the vertical.
        let k = two_link();
        let q: [f64; 2] = [0.3, 1.1];
        let fx = 0.1 * q[0].sin() + 0.1 * (q[0] + q[1]).sin();
        let fy = -0.1 * q[0].cos() - 0.1 * (q[0] + q[1]).cos();
        let (a, l) = k.forward(q);
        assert!((l - fx.hypot(fy)).abs() < 1e-12);
        assert!((a - fx.atan2(-fy)).abs() < 1e-12);
    }

    #[test]
    fn length_gain_is_the_derivative() {
        let k = two_link();
        let q = [0.1, 1.3];
        let h = 1e-7;
        let d = (k.forward([q[0], q[1] + h]).1 - k.forward([q[0], q[1] - h]).1) / (2.0 * h);
        assert!((k.length_gain(q) - d).abs() < 1e-6);
        let p = Kinematics::Prismatic {
            min_length_m: 0.1,
            max_length_m: 0.2,
        };
        assert_eq!(p.length_gain([0.0, 0.15]), 1.0);
    }

    #[test]
    fn out_of_workspace_and_nan_set_points_are_clamped_and_said() {
        let k = two_link();
        let inv = k.inverse(0.25, 0.0);
        assert!(inv.clamped);
        assert!((k.forward(inv.joints).1 - 0.19).abs() < 1e-12);
        let inv = k.inverse(f64::NAN, f64::NAN);
        assert!(inv.clamped && inv.joints.iter().all(|j| j.is_finite()));
        let p = Kinematics::Prismatic {
            min_length_m: 0.1,
            max_length_m: 0.2,
        };
        let inv = p.inverse(0.15, 2.0);
        assert!(inv.clamped);
        assert_eq!(inv.joints, [MAX_ANGLE_RAD, 0.15]);
    }
}
