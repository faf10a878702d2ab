//! The hopper's two control laws (section 6 of the paper), as pure functions.
//!
//! ## Angle convention
//! Both laws use the paper's convention: an angle is the angle between the leg and the vertical,
//! a non-negative number in normal running. `beta_TD` is measured with the foot *ahead* of the
//! hip at touchdown, `beta_LO` with the foot *behind* the hip at liftoff. The CAN `LegState`
//! message carries a signed angle (positive with the foot ahead), so
//! `beta_LO = -LegState.leg_angle_rad` at liftoff and `beta_TD = LegState.leg_angle_rad` at
//! touchdown ([`liftoff_angle_from_signed`]).
//!
//! ## When the touchdown law converges
//! Write `u_n = beta_TD(n) - beta_des` and `w_n = beta_N(v_n) - beta_des`, where `beta_N(v)` is the
//! neutral touchdown angle at speed `v` (the one that gives a symmetric stance and keeps the
//! speed). A stance landed at `beta_TD` leaves at about `beta_LO = 2 beta_N - beta_TD` (landing
//! steeper than neutral brakes and shortens the sweep behind) and changes the neutral angle by
//! `-K (u_n - w_n)`, where `K` is the hopper's speed sensitivity. Eq. (5) then gives the linear
//! map `u' = (c - 1) u + 2 w`, `w' = -K u + (1 + K) w`, which converges to `beta_des` when both
//! eigenvalues lie inside the unit circle ([`touchdown_law_converges`]): for small `K` that is
//! `0 < c < (2 - K) / (1 + K)`; with `c <= 0` it never converges, because nothing then regulates
//! the speed (the angle copies the last liftoff and the hopper keeps whatever speed it has).
//! On the simulated hopper (`sim` crate, parameters there) `c = 0.2` holds every gait on every
//! ground; `presrs-sim`'s tests check it.

/// Eq. (4): the stance leg length set point `zeta(t) = zeta0 - zeta_dev * sin(omega * t + phi)`,
/// with `t` the time since touchdown (s), lengths in m, `omega` in rad/s, `phi` in rad.
pub fn aer_leg_length(t_s: f64, zeta0: f64, zeta_dev: f64, omega: f64, phi: f64) -> f64 {
    zeta0 - zeta_dev * (omega * t_s + phi).sin()
}

/// Eq. (5): the next touchdown angle from the last step's liftoff and touchdown angles (rad, the
/// convention above).
pub fn next_touchdown_angle(beta_lo: f64, beta_td: f64, c: f64, beta_des: f64) -> f64 {
    beta_lo + c * (beta_td - beta_des)
}

/// Converts a signed leg angle measured at liftoff (positive with the foot ahead of the hip, as
/// in `LegState`) to the law's `beta_LO` (positive with the foot behind).
pub fn liftoff_angle_from_signed(signed: f64) -> f64 {
    -signed
}

/// True when eq. (5) converges to `beta_des` in the linear model above, for weight `c` and speed
/// sensitivity `k` (the spectral radius of the 2x2 map is below 1).
pub fn touchdown_law_converges(c: f64, k: f64) -> bool {
    spectral_radius([[c - 1.0, 2.0], [-k, 1.0 + k]]) < 1.0
}

/// The larger eigenvalue modulus of a 2x2 matrix.
fn spectral_radius(m: [[f64; 2]; 2]) -> f64 {
    let tr = m[0][0] + m[1][1];
    let det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
    let disc = tr * tr / 4.0 - det;
    if disc >= 0.0 {
        let s = disc.sqrt();
        (tr / 2.0 + s).abs().max((tr / 2.0 - s).abs())
    } else {
        det.sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn aer_matches_hand_computed_values() {
        // zeta0 0.30, zeta_dev 0.02, omega 6.5, phi pi/2: zeta(0) = 0.30 - 0.02 = 0.28.
        let phi = std::f64::consts::FRAC_PI_2;
        assert!((aer_leg_length(0.0, 0.30, 0.02, 6.5, phi) - 0.28).abs() < 1e-12);
        // t = 0.07: sin(0.455 + pi/2) = cos(0.455) = 0.898_29..; zeta = 0.30 - 0.017_966 = 0.282_034
        let z = aer_leg_length(0.07, 0.30, 0.02, 6.5, phi);
        assert!((z - 0.282_034).abs() < 1e-6, "{z}");
        // phi 0, omega*t = pi/2: zeta = zeta0 - zeta_dev
        let t = std::f64::consts::FRAC_PI_2 / 6.0;
        assert!((aer_leg_length(t, 0.3, 0.02, 6.0, 0.0) - 0.28).abs() < 1e-12);
    }

    #[test]
    fn touchdown_law_matches_hand_computed_values() {
        // 0.40 + (-0.5)(0.45 - 0.42) = 0.385
        assert!((next_touchdown_angle(0.40, 0.45, -0.5, 0.42) - 0.385).abs() < 1e-12);
        // at the set point with a symmetric stance the angle stays put, for any c
        for c in [-1.9, -1.0, -0.3, 0.0, 0.5] {
            assert!((next_touchdown_angle(0.27, 0.27, c, 0.27) - 0.27).abs() < 1e-12);
        }
        assert_eq!(liftoff_angle_from_signed(-0.3), 0.3);
    }

    #[test]
    fn convergence_over_a_range_of_c() {
        // Iterate the linear model from a 0.1 rad error in the angle and -0.03 in the speed, for
        // c from -1 to 2 and three sensitivities; the prediction must match the iteration.
        let mut converging = 0;
        for k in [0.1, 0.5, 1.0] {
            for i in 0..=30 {
                let c = (i as f64 - 10.0) / 10.0;
                let (mut u, mut w) = (0.1f64, -0.03f64);
                for _ in 0..2000 {
                    // beta_LO = 2 beta_N - beta_TD, in errors: 2w - u; then eq. (5).
                    let beta_lo = 2.0 * w - u;
                    let next_u = next_touchdown_angle(beta_lo, u, c, 0.0);
                    w += -k * (u - w);
                    u = next_u;
                }
                let converged = u.abs() < 1e-6 && w.abs() < 1e-6;
                assert_eq!(
                    converged,
                    touchdown_law_converges(c, k),
                    "c = {c}, K = {k}: u {u} w {w}"
                );
                converging += converged as usize;
                if c <= 0.0 {
                    assert!(!converged, "c = {c} cannot regulate speed");
                }
            }
        }
        assert!(converging > 10, "the test must see converging cases too");
    }
}
