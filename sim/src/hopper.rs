//! A planar spring-loaded inverted pendulum (SLIP) hopper, the model of the FAMU-FSU hopper
//! (section 6 of the paper).
//!
//! A point mass on a massless spring leg. In flight the body is ballistic and the leg is held at
//! the commanded touchdown angle; touchdown is the exact root of the ballistic foot height (a
//! quadratic, solved in closed form). In stance the foot stays where it landed (the paper's foot
//! does not slip), the leg spring and the ground's own stiffness act in series along the leg, and
//! the spring's rest length follows the commanded leg length (eq. (4) from the controller).
//! Liftoff is where the leg force returns to zero, located by bisection inside the integration
//! step rather than by overshooting it.
//!
//! Parameters ([`HopperParams::default`]): 2.0 kg body, 0.15 kg foot (it sets the impact spike),
//! leg stiffness 1.0 kN/m, rest leg length 0.15 m. The body's vertical period on the leg,
//! pi*sqrt(m/k), is then 140 ms, the paper's stance time "the same for each leg gait" (section
//! 7.1); measured stances come out at 0.16-0.19 s (ground compliance and the sweep add to it)
//! and speeds at 0.35-1.0 m/s over G1-G3. Why 1.0 and not a stiffer leg: the paper's point is
//! that the load at 70 ms hardly depends on the gait. With 1.5 kN/m, G3's stance ended at
//! 110 ms, its 70 ms frame saw 25% less load than G2's, and a G2-trained classifier read G3
//! wood as clay; with 1.0 kN/m the loads at 70 ms agree within 3% across gaits.

use serde::{Deserialize, Serialize};

/// Gravity, m/s^2.
pub const G: f64 = 9.81;

/// Mechanical parameters of the hopper.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HopperParams {
    /// Body mass, kg.
    pub mass_kg: f64,
    /// Unsprung foot mass, kg: sets the touchdown impact on stiff ground.
    pub foot_mass_kg: f64,
    /// Leg spring stiffness, N/m.
    pub leg_stiffness: f64,
    /// Leg damping (friction in the leg), N s/m.
    pub leg_damping: f64,
    /// Integration step, s (events are located inside it).
    pub dt: f64,
}

impl Default for HopperParams {
    fn default() -> Self {
        Self {
            mass_kg: 2.0,
            foot_mass_kg: 0.15,
            leg_stiffness: 1000.0,
            leg_damping: 2.0,
            dt: 2e-4,
        }
    }
}

/// The ground under the foot: stiffness and damping in series with the leg.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Ground {
    /// N/m. Wood planks are effectively rigid for a 2 kg hopper; grass, clay and carpet give.
    pub stiffness: f64,
    /// N s/m. Clay is lossy; grass is springy.
    pub damping: f64,
    /// Coulomb friction of the foot's sole on this ground (static and sliding alike): the foot
    /// slips where the leg pushes it along the ground harder than this times the load, that
    /// is where the leg's angle from the vertical passes atan(friction).
    #[serde(default = "Ground::no_slip")]
    pub friction: f64,
}

impl Ground {
    /// A ground the foot never slips on (a friction no leg angle reaches).
    pub const NO_SLIP: f64 = 100.0;

    fn no_slip() -> f64 {
        Self::NO_SLIP
    }
}

/// Stance or flight, with what the phase needs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Phase {
    /// In the air.
    Flight,
    /// On the ground.
    Stance {
        /// Foot position on the ground, m.
        foot_x: f64,
        /// Time of touchdown, s.
        t_touchdown: f64,
    },
}

/// What happened during a call to [`Hopper::advance`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Event {
    /// The foot touched the ground at `t` (s) with the leg at `beta` (rad, foot ahead) and the
    /// body moving at `vx`, `vy` (m/s).
    Touchdown {
        /// Time, s.
        t: f64,
        /// Leg angle, rad.
        beta: f64,
        /// Forward velocity, m/s.
        vx: f64,
        /// Vertical velocity, m/s.
        vy: f64,
    },
    /// The foot left the ground at `t` with the leg at `beta` (rad, foot behind: the paper's
    /// beta_LO).
    Liftoff {
        /// Time, s.
        t: f64,
        /// Leg angle, rad.
        beta: f64,
        /// Leg length at the liftoff (the stance's last, not the flight's rest length), m.
        length: f64,
    },
    /// The body touched the ground: the hopper fell.
    Fell {
        /// Time, s.
        t: f64,
    },
}

/// The commands the leg follows.
pub trait LegCommands {
    /// Rest length of the leg spring at `t_since_touchdown` (s) in stance, m.
    fn stance_length(&mut self, t_since_touchdown: f64) -> f64;
    /// Leg length held in flight, m.
    fn flight_length(&self) -> f64;
    /// Touchdown angle held in flight, rad (foot ahead).
    fn touchdown_angle(&self) -> f64;
}

/// The hopper's state.
#[derive(Clone, Debug)]
pub struct Hopper {
    /// Mass, leg and spring.
    pub params: HopperParams,
    /// Time, s.
    pub t: f64,
    /// Body position along the track, m.
    pub x: f64,
    /// Body height, m.
    pub y: f64,
    /// Forward velocity, m/s.
    pub vx: f64,
    /// Vertical velocity, m/s.
    pub vy: f64,
    /// Stance or flight.
    pub phase: Phase,
    /// Normal force on the foot at the last step, N (0 in flight).
    pub foot_force: f64,
    /// Impact spike of the last touchdown: peak (N) and duration (s).
    pub impact: (f64, f64),
    /// Positive work the leg's actuator has done since the hopper was made, J: the leg force
    /// times the lengthening of the spring's rest length it commands in stance (eq. 4). What a
    /// gait's cost of transport counts; a motor spends energy to push, and gets none back from
    /// a leg that shortens under load.
    pub actuator_work_j: f64,
    /// The rest length commanded at the last stance step, m (None in flight).
    last_rest: Option<f64>,
    /// The foot's speed along the ground while it slips, m/s (0 while it holds).
    foot_vx: f64,
    /// How far the foot has slid along the ground since the hopper was made, m.
    pub slip_m: f64,
    ground: Ground,
}

impl Hopper {
    /// A hopper in flight at height `y` (m) moving at `vx` (m/s).
    pub fn new(params: HopperParams, y: f64, vx: f64) -> Self {
        Self {
            params,
            t: 0.0,
            x: 0.0,
            y,
            vx,
            vy: 0.0,
            phase: Phase::Flight,
            foot_force: 0.0,
            impact: (0.0, 0.0),
            actuator_work_j: 0.0,
            last_rest: None,
            foot_vx: 0.0,
            slip_m: 0.0,
            ground: Ground {
                stiffness: 1e6,
                damping: 0.0,
                friction: Ground::NO_SLIP,
            },
        }
    }

    /// A hopper launched into `gait`: in flight 2 cm above touchdown height, at the speed whose
    /// stance of about 140 ms sweeps the leg from `beta_des` to `-beta_des`.
    pub fn launch(params: HopperParams, gait: &controller::Gait) -> Self {
        let v0 = 2.0 * gait.zeta0 * gait.beta_des.sin() / 0.14;
        Self::new(params, gait.zeta0 + 0.02, v0)
    }

    /// The body's mechanical energy, J: kinetic and gravitational (height over the ground).
    pub fn energy_j(&self) -> f64 {
        let m = self.params.mass_kg;
        0.5 * m * (self.vx * self.vx + self.vy * self.vy) + m * G * self.y
    }

    /// The foot is on the ground.
    pub fn in_stance(&self) -> bool {
        matches!(self.phase, Phase::Stance { .. })
    }

    /// Signed leg angle from the vertical, rad, positive with the foot ahead of the hip.
    pub fn leg_angle(&self, cmd: &dyn LegCommands) -> f64 {
        match self.phase {
            Phase::Flight => cmd.touchdown_angle(),
            Phase::Stance { foot_x, .. } => (foot_x - self.x).atan2(self.y),
        }
    }

    /// Current leg length, m.
    pub fn leg_length(&self, cmd: &dyn LegCommands) -> f64 {
        match self.phase {
            Phase::Flight => cmd.flight_length(),
            Phase::Stance { foot_x, .. } => (self.x - foot_x).hypot(self.y),
        }
    }

    /// Series stiffness and damping of leg and ground.
    fn series(&self) -> (f64, f64) {
        let (kl, kg) = (self.params.leg_stiffness, self.ground.stiffness);
        let k = kl * kg / (kl + kg);
        let share = kl / (kl + kg);
        (
            k,
            self.params.leg_damping + self.ground.damping * share * share,
        )
    }

    /// Leg force (N, along the leg, >= 0 while pushing) for a state.
    fn leg_force(&self, s: &[f64; 4], foot_x: f64, rest: f64) -> f64 {
        let (k, b) = self.series();
        let (dx, dy) = (s[0] - foot_x, s[1]);
        let l = dx.hypot(dy);
        let ldot = (dx * s[2] + dy * s[3]) / l;
        k * (rest - l) - b * ldot
    }

    fn deriv(&self, s: &[f64; 4], foot_x: f64, rest: f64) -> [f64; 4] {
        let f = self.leg_force(s, foot_x, rest).max(0.0);
        let (dx, dy) = (s[0] - foot_x, s[1]);
        let l = dx.hypot(dy);
        let m = self.params.mass_kg;
        [s[2], s[3], f * dx / (l * m), f * dy / (l * m) - G]
    }

    fn rk4(&self, s: [f64; 4], h: f64, foot_x: f64, rest: f64) -> [f64; 4] {
        let add = |a: &[f64; 4], k: &[f64; 4], f: f64| {
            [
                a[0] + f * k[0],
                a[1] + f * k[1],
                a[2] + f * k[2],
                a[3] + f * k[3],
            ]
        };
        let k1 = self.deriv(&s, foot_x, rest);
        let k2 = self.deriv(&add(&s, &k1, h / 2.0), foot_x, rest);
        let k3 = self.deriv(&add(&s, &k2, h / 2.0), foot_x, rest);
        let k4 = self.deriv(&add(&s, &k3, h), foot_x, rest);
        let mut o = s;
        for i in 0..4 {
            o[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        }
        o
    }

    /// Advances by up to `dt_total` seconds on `ground`, stopping early at the first event (which
    /// it returns); the caller calls again for the rest of the interval.
    pub fn advance(
        &mut self,
        dt_total: f64,
        ground: Ground,
        cmd: &mut dyn LegCommands,
    ) -> Option<Event> {
        self.ground = ground;
        let t_end = self.t + dt_total;
        while self.t < t_end - 1e-12 {
            let h = (t_end - self.t).min(self.params.dt);
            let event = match self.phase {
                Phase::Flight => self.flight_step(h, ground, cmd),
                Phase::Stance {
                    foot_x,
                    t_touchdown,
                } => self.stance_step(h, foot_x, t_touchdown, cmd),
            };
            if event.is_some() {
                return event;
            }
        }
        None
    }

    /// Up to `h` s of flight, ballistic; a touchdown where the foot reaches the ground.
    fn flight_step(&mut self, h: f64, ground: Ground, cmd: &mut dyn LegCommands) -> Option<Event> {
        let beta = cmd.touchdown_angle();
        let lf = cmd.flight_length();
        // Foot height: y - lf cos(beta); ballistic y(t) = y + vy t - g t^2 / 2.
        let t_hit = self.time_to_height(lf * beta.cos());
        let step = match t_hit {
            Some(th) if th <= h => th,
            _ => h,
        };
        self.x += self.vx * step;
        self.y += self.vy * step - 0.5 * G * step * step;
        self.vy -= G * step;
        self.t += step;
        self.foot_force = 0.0;
        if matches!(t_hit, Some(th) if th <= h) {
            let foot_x = self.x + lf * beta.sin();
            self.foot_vx = 0.0;
            self.phase = Phase::Stance {
                foot_x,
                t_touchdown: self.t,
            };
            // The foot mass stops against the ground spring: a half-sine spike.
            let mf = self.params.foot_mass_kg;
            let v = (-self.vy).max(0.0);
            let kg = ground.stiffness;
            self.impact = (
                v * (kg * mf).sqrt(),
                std::f64::consts::PI * (mf / kg).sqrt(),
            );
            return Some(Event::Touchdown {
                t: self.t,
                beta,
                vx: self.vx,
                vy: self.vy,
            });
        }
        (self.y <= 0.0).then_some(Event::Fell { t: self.t })
    }

    /// Up to `h` s of stance on the foot at `foot_x`: the leg's spring and actuator (RK4), the
    /// actuator's work, a liftoff where the leg's force ends on the way up, the foot's slide.
    fn stance_step(
        &mut self,
        h: f64,
        foot_x: f64,
        t_touchdown: f64,
        cmd: &mut dyn LegCommands,
    ) -> Option<Event> {
        let s0 = [self.x, self.y, self.vx, self.vy];
        let rest = cmd.stance_length(self.t - t_touchdown);
        let before = self.last_rest.unwrap_or(rest);
        if rest > before {
            // The force half-way through the step's change of rest length.
            let f = self.leg_force(&s0, foot_x, 0.5 * (rest + before));
            self.actuator_work_j += f.max(0.0) * (rest - before);
        }
        self.last_rest = Some(rest);
        let s1 = self.rk4(s0, h, foot_x, rest);
        let f1 = self.leg_force(&s1, foot_x, rest);
        let moving_up = (s1[0] - foot_x) * s1[2] + s1[1] * s1[3] > 0.0;
        if f1 <= 0.0 && moving_up && self.t - t_touchdown > 0.01 {
            let hi = self.liftoff_within(s0, h, foot_x, rest);
            let s = self.rk4(s0, hi, foot_x, rest);
            [self.x, self.y, self.vx, self.vy] = s;
            self.t += hi;
            let beta = (self.x - foot_x).atan2(self.y);
            let length = (self.x - foot_x).hypot(self.y);
            self.phase = Phase::Flight;
            self.foot_force = 0.0;
            self.last_rest = None;
            return Some(Event::Liftoff {
                t: self.t,
                beta,
                length,
            });
        }
        [self.x, self.y, self.vx, self.vy] = s1;
        self.t += h;
        let f = f1.max(0.0);
        let foot_x = self.slide(foot_x, f, h);
        self.phase = Phase::Stance {
            foot_x,
            t_touchdown,
        };
        let l = (self.x - foot_x).hypot(self.y);
        // Normal force on the foot: the vertical component of the leg force.
        self.foot_force = f * self.y / l;
        (self.y <= 0.02).then_some(Event::Fell { t: self.t })
    }

    /// The foot at `foot_x` under leg force `f` (N) over `h` s: it holds while the ground's
    /// friction can take the leg's push along the ground; past that it slides, its mass driven
    /// by the push less the sliding friction, until it stops where the ground holds it again.
    /// Returns where the foot is. The slide takes the leg's compression with it: the energy a
    /// slip costs the hop.
    fn slide(&mut self, foot_x: f64, f: f64, h: f64) -> f64 {
        let (dx, dy) = (foot_x - self.x, self.y);
        let l = dx.hypot(dy).max(1e-9);
        // The leg pushes the foot away from the hip: along the ground, and into it.
        let (along, load) = (f * dx / l, f * dy / l);
        let grip = self.ground.friction * load;
        if self.foot_vx == 0.0 && along.abs() <= grip {
            return foot_x;
        }
        let dir = if self.foot_vx != 0.0 {
            self.foot_vx.signum()
        } else {
            along.signum()
        };
        let a = (along - dir * grip) / self.params.foot_mass_kg;
        let v = self.foot_vx + a * h;
        // Sliding friction stops the foot; it does not push it back.
        self.foot_vx = if v * dir <= 0.0 { 0.0 } else { v };
        let moved = self.foot_vx * h;
        self.slip_m += moved.abs();
        foot_x + moved
    }

    /// Seconds until the body, ballistic, descends to `target` m: y(t) = y + vy t - g t^2 / 2
    /// at its larger root (the descending crossing), if it is ahead.
    fn time_to_height(&self, target: f64) -> Option<f64> {
        let (a, b, c) = (-0.5 * G, self.vy, self.y - target);
        let disc = b * b - 4.0 * a * c;
        if disc < 0.0 {
            return None;
        }
        let r = (-b - disc.sqrt()) / (2.0 * a);
        (r >= 0.0).then_some(r)
    }

    /// The time within a stance step of `h` s from `s0` at which the leg force reaches zero:
    /// bisection on the step fraction (40 halvings).
    fn liftoff_within(&self, s0: [f64; 4], h: f64, foot_x: f64, rest: f64) -> f64 {
        let (mut lo, mut hi) = (0.0, h);
        for _ in 0..40 {
            let mid = 0.5 * (lo + hi);
            let sm = self.rk4(s0, mid, foot_x, rest);
            if self.leg_force(&sm, foot_x, rest) > 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        hi
    }

    /// Normal force under the foot including the touchdown impact, N.
    pub fn foot_load(&self) -> f64 {
        match self.phase {
            Phase::Flight => 0.0,
            Phase::Stance { t_touchdown, .. } => {
                let (peak, dur) = self.impact;
                let dt = self.t - t_touchdown;
                let spike = if dt < dur {
                    peak * (std::f64::consts::PI * dt / dur).sin()
                } else {
                    0.0
                };
                self.foot_force + spike
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixed_gait::FixedGait;
    use crate::terrain::Physics;

    /// Events of `secs` of hopping on `physics` with the gait held.
    fn hop(gait: controller::Gait, physics: Physics, secs: f64) -> (Hopper, Vec<Event>) {
        hop_on(gait, physics.ground(), secs)
    }

    fn hop_on(gait: controller::Gait, ground: Ground, secs: f64) -> (Hopper, Vec<Event>) {
        let mut h = Hopper::launch(HopperParams::default(), &gait);
        let mut cmd = FixedGait::new(gait);
        let mut events = Vec::new();
        while h.t < secs {
            if let Some(e) = h.advance(0.001, ground, &mut cmd) {
                match e {
                    Event::Touchdown { beta, .. } => cmd.on_touchdown(beta),
                    Event::Liftoff { beta, .. } => cmd.on_liftoff(beta),
                    Event::Fell { .. } => {}
                }
                events.push(e);
            }
        }
        (h, events)
    }

    #[test]
    fn touchdown_and_liftoff_alternate_and_g2_does_not_fall() {
        let (h, events) = hop(controller::Gait::g2(), Physics::Wood, 10.0);
        assert!(
            !events.iter().any(|e| matches!(e, Event::Fell { .. })),
            "{events:?}"
        );
        let tds = events
            .iter()
            .filter(|e| matches!(e, Event::Touchdown { .. }))
            .count();
        // The paper's hopper steps about three times a second.
        assert!((20..=45).contains(&tds), "{tds} touchdowns in 10 s");
        for w in events.windows(2) {
            let kinds = (
                matches!(w[0], Event::Touchdown { .. }),
                matches!(w[1], Event::Touchdown { .. }),
            );
            assert!(kinds.0 != kinds.1, "two of a kind in a row: {w:?}");
        }
        // Moving forward.
        assert!(h.x > 2.0, "x = {}", h.x);
    }

    /// G3 lands with its leg about 29 degrees from the vertical (tan 0.55): on ground that
    /// holds the foot it hops (the launch's first stance slides a tenth of a millimetre); on ground whose friction is under that (wet
    /// grass, about 0.2 to 0.4) the foot slides out and the hopper falls, and G1, landing
    /// steeper, keeps hopping where G3 cannot.
    #[test]
    fn the_foot_slips_past_the_grounds_friction() {
        let grass = Physics::Grass.ground();
        let fell = |events: &[Event]| events.iter().any(|e| matches!(e, Event::Fell { .. }));
        let (h, events) = hop_on(controller::Gait::g3(), grass, 6.0);
        assert!(!fell(&events) && h.slip_m < 1e-3, "{}", h.slip_m);
        let wet = Ground {
            friction: 0.48,
            ..grass
        };
        let (h, events) = hop_on(controller::Gait::g3(), wet, 6.0);
        assert!(fell(&events) && h.slip_m > 0.01, "{} {events:?}", h.slip_m);
        let (_, events) = hop_on(controller::Gait::g1(), wet, 6.0);
        assert!(!fell(&events), "{events:?}");
    }

    #[test]
    fn the_foot_carries_load_only_in_stance() {
        let gait = controller::Gait::g2();
        let mut h = Hopper::launch(HopperParams::default(), &gait);
        let mut cmd = FixedGait::new(gait);
        let ground = Physics::Wood.ground();
        let (mut in_stance, mut in_flight) = (0, 0);
        while h.t < 3.0 {
            match h.advance(0.001, ground, &mut cmd) {
                Some(Event::Touchdown { beta, .. }) => cmd.on_touchdown(beta),
                Some(Event::Liftoff { beta, .. }) => cmd.on_liftoff(beta),
                _ => {}
            }
            if h.in_stance() {
                in_stance += 1;
                assert!(h.foot_load() >= 0.0);
            } else {
                in_flight += 1;
                assert_eq!(h.foot_load(), 0.0, "load in flight at t = {}", h.t);
            }
        }
        assert!(
            in_stance > 100 && in_flight > 100,
            "{in_stance} / {in_flight}"
        );
    }
}
