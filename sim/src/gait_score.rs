//! A gait judged on a ground, in the simulator: what a lab judges a gait by on its robot.
//!
//! - **Stride speed**: the body's travel from one touchdown to the next over that hop's time,
//!   averaged over steady hops. (The body's speed at mid-stance, which the demo's table once
//!   showed, reads about a quarter lower: the stance brakes, then pushes.)
//! - **Cost of transport**: the leg actuator's positive work per metre over weight,
//!   `W / (m g d)` ([`crate::hopper::Hopper::actuator_work_j`]), dimensionless.
//! - **Energy ratio**: the body's energy at a touchdown over that at the touchdown before. A
//!   steady gait keeps it at 1 whatever the ground takes, because the stance law puts back what
//!   the hop lost; a gait that is running down or speeding up reads below or above 1.
//! - **Margin**: the largest sudden loss of forward speed at one touchdown (a fraction of the
//!   speed) after which the gait keeps hopping for [`ScoreOptions::recover_hops`] hops: a push,
//!   a snag, a patch that grips. Found by bisection on the loss; what "robust" means when the
//!   controller picks the gait for ground it does not know.
//!
//! Everything here is a fixed gait on one ground (the laws of eqs. 4 and 5 with no controller
//! switching), so a score belongs to the pair and can be compared across gaits and grounds.

use controller::Gait;

use crate::fixed_gait::FixedGait;
use crate::hopper::{Event, G, Ground, Hopper, HopperParams};

/// How long a gait is hopped before and while it is scored.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScoreOptions {
    /// Hops from launch before anything is measured: the touchdown law settles in about ten.
    pub settle_hops: usize,
    /// Steady hops measured for speed, cost and energy ratio.
    pub measure_hops: usize,
    /// Hops a perturbed gait must keep hopping to count as having survived.
    pub recover_hops: usize,
    /// Halvings of the margin's bisection (0 to [`MAX_LOSS`]): 8 give 0.4% of speed.
    pub halvings: usize,
}

impl Default for ScoreOptions {
    fn default() -> Self {
        Self {
            settle_hops: 20,
            measure_hops: 20,
            recover_hops: 30,
            halvings: 8,
        }
    }
}

/// The largest speed loss the margin's bisection tries: a hopper that loses 90% of its speed
/// at one touchdown is standing.
pub const MAX_LOSS: f64 = 0.9;

/// A gait's figures on one ground.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GaitScore {
    /// Mean stride speed over the measured hops, m/s.
    pub stride_speed_m_s: f64,
    /// Positive actuator work per metre over weight.
    pub cost_of_transport: f64,
    /// Mean energy ratio of the measured hops (touchdown to touchdown).
    pub energy_ratio: f64,
    /// Mean stance time, s.
    pub stance_s: f64,
    /// Largest sudden speed loss survived, a fraction of the speed (0 when even the unperturbed
    /// gait does not keep hopping).
    pub margin: f64,
    /// Largest sudden speed gain survived, a fraction of the speed: where the ground's
    /// friction shows (a faster stance ends at a flatter leg, and the foot slips).
    pub gain_margin: f64,
    /// The least friction the gait keeps hopping on, this ground otherwise ([`grip_needed`]).
    pub grip_needed: f64,
}

impl GaitScore {
    /// The narrower of the two margins: the largest sudden change of speed, either way, the
    /// gait survives. What the safe gait is chosen by.
    pub fn change_margin(&self) -> f64 {
        self.margin.min(self.gain_margin)
    }
}

/// The unperturbed gait did not keep hopping on this ground: it fell or stopped.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
#[error("gait G{gait} does not keep hopping on this ground (it fell or stopped at hop {hop})")]
pub struct DoesNotHop {
    /// The gait's id.
    pub gait: u8,
    /// The hop at which it fell or stopped.
    pub hop: usize,
}

/// A hopper running one gait on one ground, hop by hop.
struct Run {
    hopper: Hopper,
    cmd: FixedGait,
    ground: Ground,
    /// The last touchdown's time and the last stance's length, s.
    touchdown_t: f64,
    stance_s: f64,
}

/// What a touchdown finds: the body's position, energy and time, and the stance before it.
#[derive(Clone, Copy, Debug)]
struct AtTouchdown {
    t: f64,
    x: f64,
    energy_j: f64,
    work_j: f64,
    /// The stance of the hop this touchdown closes, s.
    stance_s: f64,
}

/// A hopper slower than this at touchdown has stopped (m/s).
const STOPPED_M_S: f64 = 0.05;

impl Run {
    fn new(gait: &Gait, ground: Ground, params: &HopperParams) -> Self {
        Self {
            hopper: Hopper::launch(params.clone(), gait),
            cmd: FixedGait::new(gait.clone()),
            ground,
            touchdown_t: 0.0,
            stance_s: 0.0,
        }
    }

    /// Hops to the next touchdown; `None` when the hopper fell, stopped or did not land within
    /// two seconds.
    fn next_touchdown(&mut self) -> Option<AtTouchdown> {
        let deadline = self.hopper.t + 2.0;
        while self.hopper.t < deadline {
            match self.hopper.advance(0.001, self.ground, &mut self.cmd) {
                Some(Event::Touchdown { t, beta, vx, .. }) => {
                    self.cmd.on_touchdown(beta);
                    self.touchdown_t = t;
                    if vx < STOPPED_M_S {
                        return None;
                    }
                    return Some(self.at());
                }
                Some(Event::Liftoff { t, beta, .. }) => {
                    self.cmd.on_liftoff(beta);
                    self.stance_s = t - self.touchdown_t;
                }
                Some(Event::Fell { .. }) => return None,
                None => {}
            }
        }
        None
    }

    fn at(&self) -> AtTouchdown {
        AtTouchdown {
            t: self.hopper.t,
            x: self.hopper.x,
            energy_j: self.hopper.energy_j(),
            work_j: self.hopper.actuator_work_j,
            stance_s: self.stance_s,
        }
    }

    /// Hops `n` times; the number of hops made before a failure, as the error.
    fn hops(&mut self, n: usize) -> Result<Vec<AtTouchdown>, usize> {
        let mut out = Vec::with_capacity(n);
        for i in 0..n {
            out.push(self.next_touchdown().ok_or(i)?);
        }
        Ok(out)
    }
}

/// Scores `gait` on `ground`: steady figures, then the margins and the grip it needs.
pub fn score(
    gait: &Gait,
    ground: Ground,
    params: &HopperParams,
    opts: &ScoreOptions,
) -> Result<GaitScore, DoesNotHop> {
    let fail = |hop| DoesNotHop { gait: gait.id, hop };
    let mut run = Run::new(gait, ground, params);
    run.hops(opts.settle_hops).map_err(fail)?;
    let first = run.next_touchdown().ok_or(fail(opts.settle_hops))?;
    let rest = run
        .hops(opts.measure_hops)
        .map_err(|h| fail(opts.settle_hops + 1 + h))?;
    let mut prev = first;
    let mut ratio = 0.0;
    for td in &rest {
        ratio += td.energy_j / prev.energy_j;
        prev = *td;
    }
    let last = rest.last().copied().unwrap_or(first);
    let (dx, dt) = (last.x - first.x, last.t - first.t);
    let weight = params.mass_kg * G;
    let n = rest.len().max(1) as f64;
    Ok(GaitScore {
        stride_speed_m_s: if dt > 0.0 { dx / dt } else { 0.0 },
        cost_of_transport: if dx > 0.0 {
            (last.work_j - first.work_j) / (weight * dx)
        } else {
            f64::INFINITY
        },
        energy_ratio: ratio / n,
        stance_s: rest.iter().map(|td| td.stance_s).sum::<f64>() / n,
        margin: margin(gait, ground, params, opts),
        gain_margin: gain_margin(gait, ground, params, opts),
        grip_needed: grip_needed(gait, ground, params, opts),
    })
}

/// The largest sudden loss of forward speed at one touchdown (a fraction in 0..[`MAX_LOSS`])
/// after which `gait` keeps hopping on `ground` for `opts.recover_hops` hops.
pub fn margin(gait: &Gait, ground: Ground, params: &HopperParams, opts: &ScoreOptions) -> f64 {
    margin_toward(gait, ground, params, opts, -1.0)
}

/// The largest sudden gain of forward speed at one touchdown (a fraction in 0..[`MAX_LOSS`])
/// after which `gait` keeps hopping on `ground`: a push, a step down. A faster stance sweeps
/// the leg further behind the hip, and past the friction cone the foot slips.
pub fn gain_margin(gait: &Gait, ground: Ground, params: &HopperParams, opts: &ScoreOptions) -> f64 {
    margin_toward(gait, ground, params, opts, 1.0)
}

/// The least friction (foot on ground) on which `gait` keeps hopping on a ground otherwise
/// like `ground`, within [`MAX_GRIP`]: how slippery a ground the gait can take (bisection,
/// `opts.halvings` halvings; [`MAX_GRIP`] when it needs more).
pub fn grip_needed(gait: &Gait, ground: Ground, params: &HopperParams, opts: &ScoreOptions) -> f64 {
    let hops = |friction: f64| {
        let mut run = Run::new(gait, Ground { friction, ..ground }, params);
        run.hops(opts.settle_hops + opts.recover_hops).is_ok()
    };
    if !hops(MAX_GRIP) {
        return MAX_GRIP;
    }
    // Hopping at `hi` and not at `lo`: the least friction that holds is the boundary.
    boundary(MAX_GRIP, 0.0, opts.halvings, hops)
}

/// The edge between `ok` (where `holds` is true) and `bad` (where it is not), by `halvings`
/// halvings of the interval; the last point found to hold.
fn boundary(mut ok: f64, mut bad: f64, halvings: usize, holds: impl Fn(f64) -> bool) -> f64 {
    for _ in 0..halvings {
        let mid = 0.5 * (ok + bad);
        if holds(mid) {
            ok = mid;
        } else {
            bad = mid;
        }
    }
    ok
}

/// The largest friction [`grip_needed`] tries: rubber on dry concrete reads about 1.
pub const MAX_GRIP: f64 = 1.5;

/// The bisection of [`margin`] and [`gain_margin`]: speed changed by `sign` times the fraction.
fn margin_toward(
    gait: &Gait,
    ground: Ground,
    params: &HopperParams,
    opts: &ScoreOptions,
    sign: f64,
) -> f64 {
    let survives = |change: f64| {
        let mut run = Run::new(gait, ground, params);
        if run.hops(opts.settle_hops).is_err() {
            return false;
        }
        run.hopper.vx *= 1.0 + sign * change;
        run.hops(opts.recover_hops).is_ok()
    };
    if !survives(0.0) {
        return 0.0;
    }
    if survives(MAX_LOSS) {
        return MAX_LOSS;
    }
    boundary(0.0, MAX_LOSS, opts.halvings, survives)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::terrain::Physics;

    fn g(gait: Gait, physics: Physics) -> GaitScore {
        score(
            &gait,
            physics.ground(),
            &HopperParams::default(),
            &ScoreOptions::default(),
        )
        .unwrap()
    }

    #[test]
    fn a_steady_gait_keeps_its_energy_from_touchdown_to_touchdown() {
        for gait in Gait::paper_gaits() {
            for p in [Physics::Wood, Physics::Clay, Physics::Grass] {
                let s = g(gait.clone(), p);
                assert!(
                    (s.energy_ratio - 1.0).abs() <= 0.02,
                    "G{} on {p:?}: {s:?}",
                    gait.id
                );
            }
        }
    }

    #[test]
    fn faster_gaits_are_faster_and_a_gait_costs_work() {
        let s: Vec<GaitScore> = Gait::paper_gaits()
            .into_iter()
            .map(|gait| g(gait, Physics::Wood))
            .collect();
        assert!(s[0].stride_speed_m_s < s[1].stride_speed_m_s, "{s:?}");
        assert!(s[1].stride_speed_m_s < s[2].stride_speed_m_s, "{s:?}");
        for x in &s {
            assert!(
                x.cost_of_transport > 0.0 && x.cost_of_transport < 1.0,
                "{x:?}"
            );
            assert!(x.margin > 0.0 && x.margin < MAX_LOSS, "{x:?}");
        }
    }

    /// G3 lands and leaves with the flattest leg: it needs the most grip; on damp grass
    /// (friction 0.6, near that need) a push at touchdown fells it at half the gain it
    /// survives where the foot cannot slip.
    #[test]
    fn the_fastest_gait_needs_the_most_grip() {
        for p in [Physics::Wood, Physics::Grass] {
            let s: Vec<GaitScore> = Gait::paper_gaits().into_iter().map(|x| g(x, p)).collect();
            assert!(s[2].grip_needed > s[0].grip_needed + 0.05, "{p:?}: {s:?}");
            assert!(s[2].grip_needed < p.ground().friction, "{p:?}: {s:?}");
        }
        let on = |friction: f64| {
            let ground = Ground {
                friction,
                ..Physics::Grass.ground()
            };
            score(
                &Gait::g3(),
                ground,
                &HopperParams::default(),
                &ScoreOptions::default(),
            )
            .unwrap()
        };
        let (damp, no_slip) = (on(0.6), on(Ground::NO_SLIP));
        assert!(
            damp.gain_margin < 0.7 * no_slip.gain_margin,
            "{damp:?} {no_slip:?}"
        );
    }
}
