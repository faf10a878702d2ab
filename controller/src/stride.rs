//! Each hop measured from what the bus carries: the foot switch's edges and LegState (leg angle
//! and length), with no speed sensor. The estimate is the spring-loaded inverted pendulum's
//! (SLIP) kinematics: in stance the foot is a fixed pivot, so the hip's horizontal position
//! over the foot is `x = -l sin(beta)` and its change over the stance is the stance's
//! travel; in flight the body is ballistic, so its horizontal speed stays the speed it left
//! the ground with, `dx/dt` at liftoff. A stride, touchdown to touchdown, is then
//!
//! ```text
//! speed = (x(liftoff) - x(touchdown) + v_liftoff * flight time) / (stance + flight time)
//! ```
//!
//! which is what the simulator's truth measures (the body's travel between touchdowns over
//! their interval). The hop's energy ratio is what the stance law (AER) put in or took out:
//! the body's energy per unit mass, `v^2/2 + g y` with `y = l cos(beta)` the hip's height over
//! the foot (a SLIP's spring is at rest at the edges, so it holds none), at this stance's
//! liftoff over that at the last one's. Flight keeps the energy, so the last liftoff's is this
//! touchdown's; measured at the same edge of each stance, the fit's error at that edge divides
//! out, and a steady gait's hops multiply to 1 (docs/decisions/energy-ratio.md).
//! The first hop after a lost phase, with no liftoff before it, is read touchdown to liftoff.
//! The ends of the stance come from the first and last LegState reports of it, each end
//! fitted with a quadratic in time (value and slope at the edge): a leg reports at 100 Hz to
//! 1 kHz, and an edge falls between two reports.
//!
//! Fixed-size: the first and the last [`END_SAMPLES`] reports of a stance are kept, so a leg
//! that reports at 1 kHz costs what one at 100 Hz does, and nothing allocates.

/// Reports kept at each end of a stance for its fit.
pub const END_SAMPLES: usize = 5;

/// Stances shorter than this (µs) give no estimate: a bounce or a stumble, not a hop.
pub const MIN_STANCE_US: u64 = 30_000;

/// One hop, touchdown to the next touchdown, as the controller measured it.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct StrideEstimate {
    /// The stride's first touchdown, µs on the foot's clock.
    pub touchdown_us: u64,
    /// Stance time, s.
    pub stance_s: f64,
    /// Flight time, s (liftoff to the next touchdown).
    pub flight_s: f64,
    /// Leg angle at touchdown (rad, positive with the foot ahead of the hip).
    pub touchdown_angle_rad: f64,
    /// Leg angle at liftoff (rad, same sign convention: negative with the foot behind).
    pub liftoff_angle_rad: f64,
    /// The hip's forward travel over the stance, m.
    pub stance_travel_m: f64,
    /// Forward speed over the stride, m/s.
    pub speed_m_s: f64,
    /// The body's energy at liftoff over its energy at the last liftoff, which flight carried
    /// to this touchdown (per unit mass, kinetic and gravitational about the foot).
    pub energy_ratio: f64,
}

/// A liftoff longer ago than this (µs) before a touchdown was not a hop's flight: the energy
/// it left with says nothing of the touchdown's.
pub const MAX_FLIGHT_US: u64 = 1_000_000;

/// Gravity, m/s² (the hip's height over the foot carries the stance's potential energy).
const G_M_S2: f64 = 9.81;

/// One stance's ends: the hip's horizontal position over the foot at the reports nearest each
/// edge.
#[derive(Clone, Copy, Debug, Default)]
struct Ends {
    first: [(f64, f64); END_SAMPLES],
    first_y: [(f64, f64); END_SAMPLES],
    n_first: usize,
    last: [(f64, f64); END_SAMPLES],
    last_y: [(f64, f64); END_SAMPLES],
    /// Reports in the stance so far (the ring `last` holds the latest of them).
    n: usize,
    first_angle: f64,
    last_angle: f64,
}

impl Ends {
    fn push(&mut self, t_s: f64, (x, y): (f64, f64), angle: f64) {
        if self.n_first < END_SAMPLES {
            self.first[self.n_first] = (t_s, x);
            self.first_y[self.n_first] = (t_s, y);
            self.n_first += 1;
            if self.n_first == 1 {
                self.first_angle = angle;
            }
        }
        self.last[self.n % END_SAMPLES] = (t_s, x);
        self.last_y[self.n % END_SAMPLES] = (t_s, y);
        self.n += 1;
        self.last_angle = angle;
    }

    /// The latest reports of `ring` (`last` or `last_y`), oldest first.
    fn latest(&self, ring: &[(f64, f64); END_SAMPLES]) -> ([(f64, f64); END_SAMPLES], usize) {
        let k = self.n.min(END_SAMPLES);
        let mut out = [(0.0, 0.0); END_SAMPLES];
        for (i, o) in out.iter_mut().take(k).enumerate() {
            *o = ring[(self.n - k + i) % END_SAMPLES];
        }
        (out, k)
    }

    /// The body's energy per unit mass at `t` from the fits of `x` and `y` through `pts_x`,
    /// `pts_y`.
    fn energy_at(pts_x: &[(f64, f64)], pts_y: &[(f64, f64)], t: f64) -> Option<f64> {
        let (_, vx) = fit_at(pts_x, t)?;
        let (y, vy) = fit_at(pts_y, t)?;
        Some(0.5 * (vx * vx + vy * vy) + G_M_S2 * y)
    }
}

/// The liftoff's measurements, waiting for the next touchdown to close the stride.
#[derive(Clone, Copy, Debug)]
struct Lifted {
    touchdown_us: u64,
    liftoff_us: u64,
    travel_m: f64,
    speed_m_s: f64,
    touchdown_angle_rad: f64,
    liftoff_angle_rad: f64,
    energy_ratio: f64,
}

/// Estimates each stride from the foot switch's debounced edges and the leg's reports.
#[derive(Clone, Debug, Default)]
pub struct StrideEstimator {
    touchdown_us: Option<u64>,
    ends: Ends,
    lifted: Option<Lifted>,
    /// The last stance's liftoff: when, and the body's energy per unit mass then.
    last_liftoff: Option<(u64, f64)>,
    last: Option<StrideEstimate>,
}

impl StrideEstimator {
    /// A leg report at `t_us` (the foot's clock) with the leg at `angle_rad`, `length_m`.
    pub fn on_leg_state(&mut self, t_us: u64, angle_rad: f64, length_m: f64) {
        if self.touchdown_us.is_some() && angle_rad.is_finite() && length_m.is_finite() {
            self.ends.push(
                t_us as f64 * 1e-6,
                (-length_m * angle_rad.sin(), length_m * angle_rad.cos()),
                angle_rad,
            );
        }
    }

    /// The debounced touchdown at `t_us`: closes the stride that began at the last one.
    pub fn on_touchdown(&mut self, t_us: u64) -> Option<StrideEstimate> {
        let done = self.lifted.take().and_then(|l| {
            let stride_s = t_us.checked_sub(l.touchdown_us)? as f64 * 1e-6;
            let flight_s = t_us.checked_sub(l.liftoff_us)? as f64 * 1e-6;
            let speed = (l.travel_m + l.speed_m_s * flight_s) / stride_s;
            speed.is_finite().then_some(StrideEstimate {
                touchdown_us: l.touchdown_us,
                stance_s: (l.liftoff_us - l.touchdown_us) as f64 * 1e-6,
                flight_s,
                touchdown_angle_rad: l.touchdown_angle_rad,
                liftoff_angle_rad: l.liftoff_angle_rad,
                stance_travel_m: l.travel_m,
                speed_m_s: speed,
                energy_ratio: l.energy_ratio,
            })
        });
        self.touchdown_us = Some(t_us);
        self.ends = Ends::default();
        if done.is_some() {
            self.last = done;
        }
        done
    }

    /// The debounced liftoff at `t_us`: the stance's travel and the speed it left with.
    pub fn on_liftoff(&mut self, t_us: u64) {
        let before = self.last_liftoff.take();
        self.lifted = self.touchdown_us.take().and_then(|td| {
            if t_us.saturating_sub(td) < MIN_STANCE_US || self.ends.n < 3 {
                return None;
            }
            let (t0, t1) = (td as f64 * 1e-6, t_us as f64 * 1e-6);
            let n0 = self.ends.n_first;
            let (x0, _) = fit_at(&self.ends.first[..n0], t0)?;
            let (latest, k) = self.ends.latest(&self.ends.last);
            let (latest_y, _) = self.ends.latest(&self.ends.last_y);
            let (x1, v1) = fit_at(&latest[..k], t1)?;
            let e1 = Ends::energy_at(&latest[..k], &latest_y[..k], t1)?;
            self.last_liftoff = Some((t_us, e1));
            // The energy at touchdown: the last liftoff's, when its flight ended here; else
            // the touchdown's own fit.
            let e0 = match before.filter(|&(lo, _)| lo <= td && td - lo <= MAX_FLIGHT_US) {
                Some((_, e)) => e,
                None => Ends::energy_at(&self.ends.first[..n0], &self.ends.first_y[..n0], t0)?,
            };
            Some(Lifted {
                touchdown_us: td,
                liftoff_us: t_us,
                travel_m: x1 - x0,
                speed_m_s: v1,
                touchdown_angle_rad: self.ends.first_angle,
                liftoff_angle_rad: self.ends.last_angle,
                energy_ratio: if e0 > 0.0 { e1 / e0 } else { f64::NAN },
            })
        });
    }

    /// Forgets the stance under way (the phase was lost: a gap in the reports, a takeover).
    pub fn reset(&mut self) {
        self.touchdown_us = None;
        self.lifted = None;
        self.last_liftoff = None;
        self.ends = Ends::default();
    }

    /// The last stride closed.
    pub fn last(&self) -> Option<StrideEstimate> {
        self.last
    }
}

/// The value and slope at `t` of the least-squares quadratic through `pts` (a line through two
/// points, nothing for fewer): time is centred on `t`, so the fit's constant and linear terms
/// are the answer.
fn fit_at(pts: &[(f64, f64)], t: f64) -> Option<(f64, f64)> {
    match pts.len() {
        0 | 1 => None,
        2 => {
            let ((ta, xa), (tb, xb)) = (pts[0], pts[1]);
            let dt = tb - ta;
            (dt > 0.0).then(|| {
                let v = (xb - xa) / dt;
                (xa + v * (t - ta), v)
            })
        }
        _ => {
            // Normal equations of x = a + b u + c u^2, u = t_i - t.
            let mut s = [0.0f64; 5];
            let mut r = [0.0f64; 3];
            for &(ti, xi) in pts {
                let u = ti - t;
                let mut p = 1.0;
                for (k, sk) in s.iter_mut().enumerate() {
                    *sk += p;
                    if k < 3 {
                        r[k] += p * xi;
                    }
                    p *= u;
                }
            }
            let m = [[s[0], s[1], s[2]], [s[1], s[2], s[3]], [s[2], s[3], s[4]]];
            let det = det3(&m);
            if det.abs() < 1e-30 {
                return fit_at(&pts[pts.len() - 2..], t);
            }
            let col = |j: usize| {
                let mut mj = m;
                for (row, rv) in mj.iter_mut().zip(r) {
                    row[j] = rv;
                }
                det3(&mj) / det
            };
            Some((col(0), col(1)))
        }
    }
}

fn det3(m: &[[f64; 3]; 3]) -> f64 {
    m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_quadratic_fit_gives_value_and_slope_at_the_edge() {
        let pts: Vec<(f64, f64)> = (0..5)
            .map(|i| {
                let t = 0.01 * i as f64;
                (t, 0.2 + 1.5 * t - 3.0 * t * t)
            })
            .collect();
        let (x, v) = fit_at(&pts, 0.05).unwrap();
        assert!((x - (0.2 + 1.5 * 0.05 - 3.0 * 0.0025)).abs() < 1e-9, "{x}");
        assert!((v - (1.5 - 6.0 * 0.05)).abs() < 1e-9, "{v}");
        assert_eq!(fit_at(&pts[..1], 0.0), None);
    }

    /// A hip that crosses its foot at a constant 1 m/s (a stiff leg's limit) and flies on at
    /// the same speed: the stride's speed is 1 m/s whatever the report rate.
    /// (The energy ratio within the quadratic fit of `y = sqrt(l^2 - x^2)` at the edges.)
    #[test]
    fn a_constant_speed_hop_is_measured_at_its_speed() {
        for period_us in [1_000u64, 10_000] {
            let mut e = StrideEstimator::default();
            let (l, v) = (0.3f64, 1.0f64);
            let mut t = 0u64;
            let hop = |e: &mut StrideEstimator, t: &mut u64| {
                e.on_touchdown(*t);
                let td = *t;
                let x0 = -0.12;
                let mut s = td + 3_000;
                while s < td + 240_000 {
                    let x = x0 + v * (s - td) as f64 * 1e-6;
                    e.on_leg_state(s, (-x / l).asin(), l);
                    s += period_us;
                }
                e.on_liftoff(td + 240_000);
                *t = td + 400_000;
            };
            // The third closes the second: its energy ratio is liftoff over liftoff.
            hop(&mut e, &mut t);
            hop(&mut e, &mut t);
            hop(&mut e, &mut t);
            let s = e.last().unwrap();
            assert!((s.speed_m_s - v).abs() < 1e-6, "{period_us}: {s:?}");
            assert!((s.stance_s - 0.24).abs() < 1e-9 && (s.flight_s - 0.16).abs() < 1e-9);
            // A symmetric stance: the hip as high and as fast at liftoff as at touchdown.
            assert!((s.energy_ratio - 1.0).abs() < 1e-3, "{period_us}: {s:?}");
        }
    }

    /// A stance that sends the hip off faster than it came in gained energy: the ratio is its
    /// liftoff's `v^2/2 + g y` over the last liftoff's (which flight carried to its touchdown).
    /// The first hop after a lost phase has no liftoff before it: its own touchdown's, then.
    #[test]
    fn the_energy_ratio_is_liftoff_over_the_last_liftoffs_energy() {
        let l = 0.3f64;
        let energy = |x: f64, vx: f64| {
            let y = (l * l - x * x).sqrt();
            let vy = -x * vx / y;
            0.5 * (vx * vx + vy * vy) + G_M_S2 * y
        };
        // x from -0.12 m at 1 m/s, accelerating at `a` m/s^2 over 240 ms.
        let stance = |e: &mut StrideEstimator, td: u64, a: f64| {
            e.on_touchdown(td);
            let mut s = td + 2_000;
            while s <= td + 238_000 {
                let u = (s - td) as f64 * 1e-6;
                let x = -0.12 + u + 0.5 * a * u * u;
                e.on_leg_state(s, (-x / l).asin(), l);
                s += 2_000;
            }
            e.on_liftoff(td + 240_000);
        };
        let (u1, a) = (0.24, 2.0);
        let gained = energy(-0.12 + u1 + 0.5 * a * u1 * u1, 1.0 + a * u1);
        for first_steady in [true, false] {
            let mut e = StrideEstimator::default();
            if first_steady {
                // A symmetric stance: it leaves at x = +0.12, 1 m/s.
                stance(&mut e, 0, 0.0);
            }
            stance(&mut e, 400_000, a);
            e.on_touchdown(800_000);
            let s = e.last().unwrap();
            // Either way the stance began with the energy of x = -0.12 at 1 m/s, which is
            // that of x = +0.12 at 1 m/s.
            let want = gained / energy(0.12, 1.0);
            assert!(
                (s.energy_ratio - want).abs() < 5e-3,
                "{first_steady}: {} against {want}",
                s.energy_ratio
            );
            assert!(s.energy_ratio > 1.0);
        }
    }

    #[test]
    fn a_bounce_or_a_stance_without_reports_gives_no_stride() {
        let mut e = StrideEstimator::default();
        e.on_touchdown(0);
        e.on_leg_state(5_000, 0.1, 0.3);
        e.on_liftoff(10_000);
        assert_eq!(e.on_touchdown(200_000), None);
        e.on_liftoff(300_000);
        assert_eq!(e.on_touchdown(500_000), None);
        e.on_leg_state(510_000, f64::NAN, 0.3);
        assert_eq!(e.last(), None);
    }
}
