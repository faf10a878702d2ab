//! A bumpless start: what a starting controller listens to, and how it takes over the gait the
//! leg runs (see [`Controller`]).

use protocol::emit::Emit;
use protocol::messages::{GaitReason, Message};

use super::{BETA_DES_STEP, Controller, Gait, MAX_ANGLE_FROM_DESIRED, laws};

/// What a starting controller has heard before it takes over (see
/// [`ControllerConfig::takeover_ms`]).
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Listen {
    /// Our time when listening began.
    pub(super) since_us: Option<u64>,
    /// The gait, reason and terrain another controller last said it ran for our foot.
    pub(super) gait: Option<(u8, GaitReason, u8)>,
    /// The step listened to: its touchdown angle, then its liftoff angle (the law's sign).
    pub(super) td: Option<f64>,
    pub(super) lo: Option<f64>,
}

/// The largest miss, rad, of a gait's eq. (5) in predicting the listened step's next touchdown
/// angle for that gait to be the one the leg runs (why 0.012: docs/decisions/controller-takeover.md).
pub const TAKEOVER_FIT_RAD: f64 = 0.012;

/// How a controller took over a leg (see [`ControllerConfig::takeover_ms`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Takeover {
    /// Our time of the takeover, µs.
    pub at_us: u64,
    /// The gait taken over.
    pub gait: u8,
    /// Where the gait came from: "gait status" (another controller's), "touchdown law" (the
    /// gait whose eq. (5) explains the step listened to) or "initial" (the config's; the
    /// node's terrains then switch it at a liftoff as usual).
    pub gait_from: &'static str,
    /// The touchdown angle the leg came down at, rad; `None` when no step was heard in
    /// `takeover_ms` (a fresh start).
    pub touchdown_angle_rad: Option<f64>,
    /// The beta_des eq. (5) aims at from the takeover on, rad.
    pub beta_des_rad: f64,
}

impl Controller {
    /// Ends listening (see [`Controller`]): after a touchdown (`touchdown`) from the step
    /// heard, otherwise (no step within `takeover_ms`) as on a fresh robot. A gait requested
    /// from the node's terrains while listening stays pending, for a liftoff.
    pub(super) fn take_over(
        &mut self,
        touchdown: bool,
        now_us: u64,
        out: &mut (impl Emit<Message> + ?Sized),
    ) {
        let Some(l) = self.listen.take() else {
            return;
        };
        let b1 = self.beta_td;
        let mut gait_from = "initial";
        let mut beta_des = if touchdown { b1 } else { self.gait.beta_des };
        let named = l
            .gait
            .and_then(|(g, reason, terrain)| Some((self.gait_by_id(g)?, reason, terrain)));
        if let Some((g, reason, terrain)) = named {
            beta_des = g.beta_des;
            self.gait = g;
            self.reason = reason;
            self.terrain = terrain;
            gait_from = "gait status";
        } else if let (true, Some(td0), Some(lo0)) = (touchdown, l.td, l.lo) {
            let miss =
                |g: &Gait| (laws::next_touchdown_angle(lo0, td0, g.c, g.beta_des) - b1).abs();
            let best = self
                .cfg
                .gaits
                .iter()
                .min_by(|a, b| miss(a).total_cmp(&miss(b)))
                .filter(|g| miss(g) <= TAKEOVER_FIT_RAD && g.c > 0.0)
                .cloned();
            if let Some(g) = best {
                // Eq. (5) solved for beta_des: mid-way through a walk after a switch the leg
                // aims between two gaits' angles, and the walk goes on from there.
                let aimed = td0 - (b1 - lo0) / g.c;
                beta_des = if (aimed - g.beta_des).abs() <= BETA_DES_STEP {
                    g.beta_des
                } else {
                    aimed.clamp(
                        g.beta_des - MAX_ANGLE_FROM_DESIRED,
                        g.beta_des + MAX_ANGLE_FROM_DESIRED,
                    )
                };
                self.gait = g;
                self.reason = GaitReason::Initial;
                gait_from = "touchdown law";
            }
        }
        // A terrain request heard while listening that this gait already serves.
        if self
            .pending
            .as_ref()
            .is_some_and(|p| p.0.id == self.gait.id)
        {
            self.pending = None;
        }
        self.beta_des = beta_des;
        self.next_beta_td = if touchdown { b1 } else { beta_des };
        if !touchdown {
            self.beta_td = beta_des;
        }
        self.takeover = Some(Takeover {
            at_us: now_us,
            gait: self.gait.id,
            gait_from,
            touchdown_angle_rad: touchdown.then_some(b1),
            beta_des_rad: beta_des,
        });
        out.emit(Message::GaitStatus(self.status()));
    }
}
