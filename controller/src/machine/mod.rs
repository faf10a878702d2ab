//! The controller's state machine: stance and flight from the foot switch, eq. (4) in stance,
//! eq. (5) at liftoff, and the gait chosen per terrain, switched only in flight.
//!
//! Time is passed in (`now_us`), so tests and the demo drive it with a simulated clock.
//!
//! Stance timing runs on the *foot's* clock: the touchdown is the FootContact edge's own
//! timestamp, bounce is judged between edge timestamps, and "now" in stance is the latest
//! FootContact timestamp (the foot reports at 100 Hz besides its edges) plus our time since it
//! arrived. Frames from the leg can arrive late and in bursts (a loaded computer, a slow
//! simulator); judged by arrival time, a burst holding a touchdown and the liftoff looks like
//! one bounce, and the stance law runs late by the delay. LegState runs on the leg's clock,
//! another device's (the leg bridge's, `presrs leg`): its timestamps judge gaps in the leg's
//! own stream only. Mixed into the foot's clock they put the stance law a second off when the
//! two clocks started a second apart (every hop fell, measured with the bridge on vcan).

use std::collections::BTreeMap;

use protocol::emit::Emit;
use protocol::messages::{
    FootContact, GaitReason, GaitStatus, LegCommand, LegMode, Message, Phase, StepState,
    TERRAIN_UNKNOWN, TerrainClass,
};
use protocol::terrain::TerrainCatalog;

use crate::gait::Gait;
use crate::laws;
use crate::stride::{StrideEstimate, StrideEstimator};

mod takeover;

use crate::config::ControllerConfig;
use takeover::Listen;
pub use takeover::{TAKEOVER_FIT_RAD, Takeover};

/// Unwraps a 32-bit µs timestamp (wrapping every 71 min) on `clock`, relative to its latest
/// (a step of up to +-35 min either way), and moves the clock on when it is newer.
fn unwrap_clock(clock: &mut Option<(u64, u64)>, ts: u32, now_us: u64) -> u64 {
    let t = match *clock {
        Some((last, _)) => last.wrapping_add(ts.wrapping_sub(last as u32) as i32 as i64 as u64),
        None => ts as u64,
    };
    if clock.is_none_or(|(last, _)| t >= last) {
        *clock = Some((t, now_us));
    }
    t
}

/// How far the foot's clock is extrapolated past its latest timestamp, µs (two frame periods).
pub const FOOT_CLOCK_HOLDOVER_US: u64 = 20_000;
/// A stance outside these bounds (µs) was not a step of the gait (the paper's: ~140 ms).
pub const MIN_STANCE_US: u64 = 40_000;
/// A stance longer than this (µs) is taken for a stuck foot switch.
pub const MAX_STANCE_US: u64 = 600_000;
/// Touchdown and liftoff angles stay within this of the gait's beta_des, rad.
pub const MAX_ANGLE_FROM_DESIRED: f64 = 0.35;
/// After a gait switch eq. (5) aims at the new beta_des in steps of at most this, rad per
/// liftoff: G1 -> G3 (0.30 rad) takes 6 steps, about as many as the speed takes to follow.
pub const BETA_DES_STEP: f64 = 0.05;

/// LegState reports further apart than this on the foot's clock, in a stream that was regular
/// (the leg reports at 100-500 Hz), mean that reports were lost, edges perhaps among them: the
/// controller no longer knows the phase, µs. A stalled leg (a simulator the machine cannot keep
/// up with) leaves no such gap: its clock stops too. See [`Controller`].
pub const LEG_GAP_US: u64 = 50_000;

/// The controller.
///
/// **Bumpless start.** A controller restarted in mid-hop knows nothing of the leg it takes
/// over (the initial gait's angle sent to a leg running another gait felled it). So a starting controller first listens (no LegCommand, no GaitStatus) to one step of
/// the leg (touchdown, liftoff, next touchdown, after a first report of the phase) and takes
/// over at the second touchdown, running the gait the leg runs:
/// - another controller's GaitStatus for the foot names it, when one was heard;
/// - else the leg's touchdown law does: the gait whose eq. (5), applied to the step heard,
///   gives the touchdown angle the leg came down at (within [`TAKEOVER_FIT_RAD`]); its
///   beta_des is the one eq. (5) inverted gives;
/// - else the initial gait, aiming first at the angle the leg came down at and walked to the
///   gait's beta_des by [`BETA_DES_STEP`] per step, as after any switch.
///
/// The node's TerrainClass reports are counted while listening, so a terrain it has confirmed
/// switches the gait at a liftoff after the takeover, in flight as always. What each
/// alternative cost in falls: docs/decisions/controller-takeover.md.
///
/// No touchdown within `takeover_ms`: a fresh start.
///
/// **Gaps in the leg's reports.** After reports were lost (an interface down, a stalled
/// process: [`LEG_GAP_US`]) the controller may have missed an edge, and a missed liftoff made
/// it take the next touchdown for more of the old stance and run eq. (4) from a touchdown
/// long past. So after a
/// gap the next FootContact gives the phase only, as at a takeover, and a stance whose
/// touchdown was not heard is left to the leg (a flight command: the leg holds its rest
/// length); eq. (5) restarts from beta_des at its liftoff. The foot's own reports lost for
/// longer than a stance (their sequence numbers skip) do the same.
///
/// **A leg of motors** (its bridge, `presrs leg`, says its mode in LegStatus) has no laws of
/// its own: without commands it holds its damped stop, so after a gap this controller does
/// not listen but commands on, and only the foot's reports judge the phase (a bridge that
/// stalled lost no FootContact). Nor does a starting controller listen to a leg whose bridge
/// says nobody commands it (waiting for a first command, or in its damped stop): it would
/// only leave the leg limp, and the simulated hopper fell 1-10 times after a restart (0-1
/// once it took the leg at once). See `lab/tests/faults.rs` for what each costs in falls.
pub struct Controller {
    cfg: ControllerConfig,
    /// `terrain_gaits` by terrain id (the catalog's), resolved once.
    gait_of_terrain: BTreeMap<u8, u8>,
    gait: Gait,
    reason: GaitReason,
    terrain: u8,
    pending: Option<(Gait, GaitReason, u8)>,
    stance: bool,
    /// Foot time of the last accepted switch edge.
    last_edge_us: Option<u64>,
    /// Foot time of the touchdown.
    touchdown_us: u64,
    /// The foot's clock: its latest timestamp (unwrapped to 64 bits) and our time when it came.
    foot_clock: Option<(u64, u64)>,
    /// The leg's clock likewise (LegState timestamps: another device's clock).
    leg_clock: Option<(u64, u64)>,
    leg_angle: f64,
    /// The beta_des eq. (5) aims at: the gait's, reached in steps after a switch.
    beta_des: f64,
    beta_td: f64,
    next_beta_td: f64,
    candidate: (u8, u32),
    /// Unknown steps in a row (counted apart: one does not break a terrain's run).
    unknown_run: u32,
    last_heartbeat_us: Option<u64>,
    next_cmd_us: u64,
    next_status_us: u64,
    seq: u8,
    /// Gait switches so far.
    pub switches: u64,
    /// Liftoffs after which eq. (5) was restarted from beta_des (an implausible step).
    pub gait_resets: u64,
    /// Listening before the takeover (`None` once commanding).
    listen: Option<Listen>,
    /// The foot's phase is known: the next FootContact that differs is an edge. After a gap
    /// in the leg's reports, and while listening, the first FootContact gives the phase only
    /// (it may be the 100 Hz report of a phase under way); bounce is judged from it (taken as
    /// nothing, the bounce after a first liftoff read as a touchdown at the liftoff's angle).
    phase_known: bool,
    /// The current stance's touchdown edge was heard: its stance law can run.
    touchdown_known: bool,
    /// Gaps in the leg's reports so far ([`LEG_GAP_US`]).
    pub leg_gaps: u64,
    /// Foot time of the last LegState, and whether the stream was regular up to it.
    last_leg_state_us: Option<u64>,
    leg_state_regular: bool,
    /// The foot's leg says its mode (LegStatus): a bridge to motors (`presrs leg`), which has
    /// no laws of its own and stops the leg when commands stop.
    leg_needs_commands: bool,
    /// The last FootContact's sequence number and foot time, and whether the numbers count.
    last_contact: Option<(u8, u64)>,
    contact_counts: bool,
    /// How the controller took over, once it has.
    pub takeover: Option<Takeover>,
    /// Each hop measured from the edges and LegState ([`crate::stride`]).
    stride: StrideEstimator,
    /// With `sweep_steps`: each terrain's confirmed steps so far, by terrain id (fixed-size:
    /// a step allocates nothing).
    swept: [u32; 256],
}

impl Controller {
    /// A controller for a validated config; `catalog` maps the TerrainClass ids it will hear
    /// to the names of `terrain_gaits`.
    pub fn new(cfg: ControllerConfig, catalog: &TerrainCatalog) -> Self {
        let gait_of_terrain = cfg
            .terrain_gaits
            .iter()
            .filter_map(|(name, &g)| Some((catalog.by_name(name)?.id(), g)))
            .collect();
        let gait = cfg
            .gaits
            .iter()
            .find(|g| g.id == cfg.initial_gait)
            .cloned()
            .unwrap_or_else(Gait::g2);
        let b = gait.beta_des;
        Self {
            gait,
            reason: GaitReason::Initial,
            terrain: TERRAIN_UNKNOWN,
            pending: None,
            stance: false,
            last_edge_us: None,
            touchdown_us: 0,
            foot_clock: None,
            leg_clock: None,
            leg_angle: 0.0,
            beta_des: b,
            beta_td: b,
            next_beta_td: b,
            candidate: (TERRAIN_UNKNOWN, 0),
            unknown_run: 0,
            last_heartbeat_us: None,
            next_cmd_us: 0,
            next_status_us: 0,
            seq: 0,
            switches: 0,
            gait_resets: 0,
            listen: (cfg.takeover_ms > 0).then(Listen::default),
            takeover: None,
            stride: StrideEstimator::default(),
            swept: [0; 256],
            // A fresh start assumes flight (the leg is set down after the first command).
            phase_known: cfg.takeover_ms == 0,
            touchdown_known: false,
            leg_gaps: 0,
            last_leg_state_us: None,
            leg_state_regular: false,
            leg_needs_commands: false,
            last_contact: None,
            contact_counts: false,
            gait_of_terrain,
            cfg,
        }
    }

    /// The gait in force.
    pub fn gait(&self) -> &Gait {
        &self.gait
    }

    /// The foot's leg said its mode (LegStatus): a bridge to motors, which stops the leg when
    /// commands stop, so a gap in its reports does not make this controller listen.
    pub fn leg_needs_commands(&self) -> bool {
        self.leg_needs_commands
    }

    /// Why the gait in force was chosen.
    pub fn reason(&self) -> GaitReason {
        self.reason
    }

    /// The last hop measured from the bus (touchdown to touchdown): speed, stance and flight
    /// time, the leg's angles ([`crate::stride`]).
    pub fn last_stride(&self) -> Option<StrideEstimate> {
        self.stride.last()
    }

    /// Takes a foot timestamp (32-bit µs, wrapping every 71 min) and returns it unwrapped.
    fn foot_time(&mut self, ts: u32, now_us: u64) -> u64 {
        unwrap_clock(&mut self.foot_clock, ts, now_us)
    }

    /// A LegState stamped `ts`: a gap in the leg's regular stream ([`LEG_GAP_US`]) makes the
    /// phase unknown. Only a stream that was regular counts (the last interval within the
    /// gap): a leg that reports now and then has no gaps to find.
    fn leg_state(&mut self, ts: u32, now_us: u64) {
        let t = unwrap_clock(&mut self.leg_clock, ts, now_us);
        if let Some(last) = self.last_leg_state_us {
            let gap = t.saturating_sub(last) > LEG_GAP_US;
            if gap && self.leg_state_regular {
                self.leg_gaps += 1;
                // A leg of motors: the stall may have been the bridge's alone (its process
                // not run; measured under emulation) while the foot's reports all came, and
                // their sequence numbers say whether one was lost (below).
                if !self.leg_needs_commands {
                    self.phase_known = false;
                }
                // Commands were lost as well, and the leg's own laws ran it meanwhile: the
                // controller knows as little of it as a restarted one. A leg of motors has no
                // laws of its own: silence would leave it in its damped stop for the step
                // listened to, and the hopper falls (docs/decisions/controller-takeover.md).
                // It is commanded on, phase unknown:
                // flight commands until the next FootContact gives the phase.
                if self.cfg.takeover_ms > 0 && self.listen.is_none() && !self.leg_needs_commands {
                    self.listen = Some(Listen {
                        since_us: Some(now_us),
                        ..Listen::default()
                    });
                }
            }
            self.leg_state_regular = !gap;
        }
        self.last_leg_state_us = Some(t);
    }

    /// Now on the foot's clock: its latest timestamp plus our time since, for at most
    /// [`FOOT_CLOCK_HOLDOVER_US`]. The foot reports every 10 ms; when its reports stop (a
    /// stalled simulator, a loaded bus) the stance law waits for the foot instead of running
    /// ahead of it.
    fn foot_now(&self, now_us: u64) -> u64 {
        match self.foot_clock {
            Some((foot, ours)) => foot + now_us.saturating_sub(ours).min(FOOT_CLOCK_HOLDOVER_US),
            None => now_us,
        }
    }

    /// Our time on the foot's clock with no holdover: for measuring a hop from LegState,
    /// whose samples keep their spacing when the foot's reports pause (the stance law's
    /// wait is [`Self::foot_now`]'s).
    fn foot_clock(&self, now_us: u64) -> u64 {
        match self.foot_clock {
            Some((foot, ours)) => foot + now_us.saturating_sub(ours),
            None => now_us,
        }
    }

    fn gait_by_id(&self, id: u8) -> Option<Gait> {
        self.cfg.gaits.iter().find(|g| g.id == id).cloned()
    }

    fn request(&mut self, gait_id: u8, reason: GaitReason, terrain: u8) {
        let Some(g) = self.gait_by_id(gait_id) else {
            return;
        };
        if g.id == self.gait.id && reason == self.reason {
            self.pending = None;
            return;
        }
        if g.id == self.gait.id {
            // Same gait, new reason: no mechanical change, take it at once.
            self.reason = reason;
            self.terrain = terrain;
            self.pending = None;
            return;
        }
        self.pending = Some((g, reason, terrain));
    }

    /// The controller's own bus handle (re)opened at `now_us`. A heartbeat gap while we were
    /// off the bus says nothing about the node (its NodeStatus frames were sent and lost to
    /// us), so the node gets a whole timeout from now: the first heartbeat after the reopen
    /// decides (docs/decisions/figures-behind-comments.md, bus-reopen). A node already lost
    /// stays lost until it is heard.
    pub fn on_bus_open(&mut self, now_us: u64) {
        if self.reason != GaitReason::NodeLost {
            self.last_heartbeat_us = Some(now_us);
        }
    }

    /// Feeds one received message (foot is the message's foot index).
    pub fn on_message(
        &mut self,
        foot: u8,
        msg: &Message,
        now_us: u64,
        out: &mut (impl Emit<Message> + ?Sized),
    ) {
        if let Some(l) = self.listen.as_mut() {
            l.since_us.get_or_insert(now_us);
        }
        match *msg {
            Message::NodeStatus(_) => self.last_heartbeat_us = Some(now_us),
            Message::GaitStatus(gs) if gs.foot == self.cfg.foot => {
                if let Some(l) = self.listen.as_mut() {
                    l.gait = Some((gs.gait, gs.reason, gs.terrain));
                }
            }
            Message::LegStatus(s) if foot == self.cfg.foot => {
                self.leg_needs_commands = true;
                // A bridge waiting for its first command, or in its damped stop for want of
                // them, is commanded by nobody: there is no step to listen to, and listening
                // leaves the leg limp for `takeover_ms` (see [`Controller`]).
                if self.listen.is_some()
                    && matches!(s.mode, LegMode::Waiting | LegMode::CommandTimeout)
                {
                    self.take_over(false, now_us, out);
                }
            }
            Message::LegState(ls) if foot == self.cfg.foot => {
                self.leg_state(ls.timestamp_us, now_us);
                self.leg_angle = ls.leg_angle_rad;
                // On the foot's clock, as the edges: the leg's is another device's.
                let t = self.foot_clock(now_us);
                self.stride
                    .on_leg_state(t, ls.leg_angle_rad, ls.leg_length_m);
            }
            Message::FootContact(fc) if foot == self.cfg.foot => self.on_contact(&fc, now_us, out),
            Message::TerrainClass(tc) if foot == self.cfg.foot => self.on_terrain(&tc, out),
            _ => {}
        }
    }

    /// A foot-switch report: a touchdown or a liftoff once the phase is known and the edge is
    /// not a bounce.
    fn on_contact(
        &mut self,
        fc: &FootContact,
        now_us: u64,
        out: &mut (impl Emit<Message> + ?Sized),
    ) {
        let t = self.foot_time(fc.timestamp_us, now_us);
        // Reports lost (a sequence number skipped) for longer than the shortest stance:
        // a whole phase, its two edges, may be among them. A shorter loss holds one
        // edge at most, taken at this report (up to that loss late); taking every loss
        // as an unknown phase felled the hopper (docs/decisions/controller-takeover.md).
        // Only a foot whose numbers have counted is judged (a foot that leaves them at
        // 0 loses nothing).
        let next = self
            .last_contact
            .map(|(seq, last)| (seq.wrapping_add(1), last));
        if let Some((want, last)) = next {
            if fc.seq == want {
                self.contact_counts = true;
            } else if self.contact_counts && t.saturating_sub(last) > MIN_STANCE_US {
                self.phase_known = false;
            }
        }
        self.last_contact = Some((fc.seq, t));
        if !self.phase_known {
            self.stride.reset();
            self.phase_known = true;
            self.stance = fc.stance;
            self.touchdown_known = false;
            self.last_edge_us = Some(t);
            return;
        }
        if fc.stance == self.stance {
            return;
        }
        if self
            .last_edge_us
            .is_some_and(|last| t.saturating_sub(last) < self.cfg.lockout_us)
        {
            return; // bounce
        }
        self.last_edge_us = Some(t);
        self.stance = fc.stance;
        if fc.stance {
            // The hop this touchdown closes, on the bus (a listening controller stays quiet).
            if let Some(h) = self.stride.on_touchdown(t)
                && self.listen.is_none()
            {
                out.emit(Message::StepState(StepState {
                    speed_m_s: h.speed_m_s,
                    stance_s: h.stance_s,
                    flight_s: h.flight_s,
                    touchdown_angle_rad: h.touchdown_angle_rad,
                    liftoff_angle_rad: h.liftoff_angle_rad,
                    energy_ratio: h.energy_ratio,
                }));
            }
        } else {
            self.stride.on_liftoff(t);
        }
        if fc.stance {
            self.touchdown_us = t;
            self.touchdown_known = true;
            self.beta_td = self.leg_angle;
            if let Some(l) = self.listen.as_mut() {
                if l.td.is_some() && l.lo.is_some() {
                    self.take_over(true, now_us, out);
                } else {
                    l.td = Some(self.leg_angle);
                    l.lo = None;
                }
            }
        } else if let Some(l) = self.listen.as_mut() {
            // The stance was another's: only heard.
            if l.td.is_some() {
                l.lo = Some(laws::liftoff_angle_from_signed(self.leg_angle));
            }
        } else {
            self.on_liftoff(t, out);
        }
    }

    /// The controller's own liftoff: eq. (5) sets the next touchdown angle.
    fn on_liftoff(&mut self, t: u64, out: &mut (impl Emit<Message> + ?Sized)) {
        let beta_lo = laws::liftoff_angle_from_signed(self.leg_angle);
        let g = &self.gait;
        let step = BETA_DES_STEP;
        self.beta_des += (g.beta_des - self.beta_des).clamp(-step, step);
        let b = self.beta_des;
        let stance_us = t.saturating_sub(self.touchdown_us);
        // Eq. (5) assumes the step was a step. After a stumble or a fall (a stance
        // far too short or long, the leg swept far from the gait's angle) it would
        // carry the bad angle into the next touchdown and the next fall: start the
        // gait afresh instead.
        let plausible = self.touchdown_known
            && (MIN_STANCE_US..=MAX_STANCE_US).contains(&stance_us)
            && (beta_lo - b).abs() <= MAX_ANGLE_FROM_DESIRED;
        self.next_beta_td = if plausible {
            laws::next_touchdown_angle(beta_lo, self.beta_td, g.c, b)
                .clamp(b - MAX_ANGLE_FROM_DESIRED, b + MAX_ANGLE_FROM_DESIRED)
        } else {
            self.gait_resets += 1;
            b
        };
        self.apply_pending(out);
    }

    /// The node's verdict on a step: a terrain confirmed over `switch_after_steps` steps
    /// requests its gait, unknown ground the safe gait.
    fn on_terrain(&mut self, tc: &TerrainClass, out: &mut (impl Emit<Message> + ?Sized)) {
        if tc.terrain == TERRAIN_UNKNOWN {
            // Confirmed like a terrain: one unknown step among known ones (an unusual
            // stance, a gait transition) is not new ground, and each needless switch to
            // the safe gait and back costs steps at the wrong speed
            // (docs/decisions/figures-behind-comments.md, unknown-confirmation).
            self.unknown_run += 1;
            if self.unknown_run >= self.cfg.switch_after_steps {
                self.candidate = (TERRAIN_UNKNOWN, 0);
                self.request(self.cfg.safe_gait, GaitReason::Unknown, TERRAIN_UNKNOWN);
            }
        } else if tc.confidence_pct >= self.cfg.min_confidence_pct {
            self.unknown_run = 0;
            if self.candidate.0 == tc.terrain {
                self.candidate.1 += 1;
            } else {
                self.candidate = (tc.terrain, 1);
            }
            if self.candidate.1 >= self.cfg.switch_after_steps {
                let gid = self.gait_for(tc.terrain);
                self.request(gid, GaitReason::Terrain, tc.terrain);
            }
        }
        if !self.stance {
            self.apply_pending(out);
        }
    }

    /// The gait for a confirmed step on `terrain`: the table's (the safe gait for a terrain it
    /// leaves out), or while sweeping ([`ControllerConfig::sweep_steps`]) the safe gait, then
    /// each other configured gait, for `sweep_steps` of the terrain's steps each.
    fn gait_for(&mut self, terrain: u8) -> u8 {
        let table = self
            .gait_of_terrain
            .get(&terrain)
            .copied()
            .unwrap_or(self.cfg.safe_gait);
        let n = self.cfg.sweep_steps;
        if n == 0 {
            return table;
        }
        let done = &mut self.swept[terrain as usize];
        let turn = (*done / n) as usize;
        *done = done.saturating_add(1);
        let safe = self.cfg.safe_gait;
        match turn {
            0 => safe,
            k => self
                .cfg
                .gaits
                .iter()
                .map(|g| g.id)
                .filter(|&id| id != safe)
                .nth(k - 1)
                .unwrap_or(table),
        }
    }

    fn apply_pending(&mut self, out: &mut (impl Emit<Message> + ?Sized)) {
        if self.listen.is_some() {
            return;
        }
        if let Some((g, reason, terrain)) = self.pending.take() {
            self.gait = g;
            self.reason = reason;
            self.terrain = terrain;
            self.switches += 1;
            // The touchdown angle is not reset: eq. (5) walks it to the new beta_des over the
            // next steps, which keeps the hopper on its feet (a jump of 0.3 rad at low speed
            // throws it backwards). Its target moves by BETA_DES_STEP per step too: aiming at
            // the new beta_des at once still let a G1 -> G3 switch at G1's speed (or the safe
            // gait at G3's) topple the simulated hopper after 2 of 40 node outages.
            out.emit(Message::GaitStatus(self.status()));
        }
    }

    /// The GaitStatus describing the gait in force.
    pub fn status(&self) -> GaitStatus {
        GaitStatus {
            gait: self.gait.id,
            terrain: self.terrain,
            omega_rad_s: self.gait.omega,
            beta_des_rad: self.gait.beta_des,
            reason: self.reason,
            foot: self.cfg.foot,
        }
    }

    /// Time-driven outputs: LegCommand at the command rate, GaitStatus at the status rate, and
    /// the heartbeat watchdog.
    pub fn tick(&mut self, now_us: u64, out: &mut (impl Emit<Message> + ?Sized)) {
        if let Some(l) = self.listen.as_mut() {
            let since = *l.since_us.get_or_insert(now_us);
            if now_us.saturating_sub(since) < self.cfg.takeover_ms * 1000 {
                return;
            }
            self.take_over(false, now_us, out);
        }
        let lost = match self.last_heartbeat_us {
            Some(t) => now_us.saturating_sub(t) > self.cfg.heartbeat_timeout_ms * 1000,
            None => now_us > self.cfg.heartbeat_timeout_ms * 1000,
        };
        if lost && self.reason != GaitReason::NodeLost {
            self.candidate = (TERRAIN_UNKNOWN, 0);
            self.request(self.cfg.safe_gait, GaitReason::NodeLost, TERRAIN_UNKNOWN);
            if self.pending.is_none() {
                self.reason = GaitReason::NodeLost;
            }
            // At once, in stance too: terrain switches wait for flight so that a stance runs
            // one law, but the safe gait is for when nothing can be trusted, and waiting for
            // the liftoff would add up to a stance (~200 ms) to the 500 ms timeout.
            self.apply_pending(out);
        }
        if now_us >= self.next_cmd_us {
            self.next_cmd_us = now_us + (1e6 / self.cfg.command_hz) as u64;
            let g = &self.gait;
            let (phase, len) = if self.stance && self.touchdown_known {
                let t = self.foot_now(now_us).saturating_sub(self.touchdown_us) as f64 * 1e-6;
                (
                    Phase::Stance,
                    laws::aer_leg_length(t, g.zeta0, g.zeta_dev, g.omega, g.phi),
                )
            } else {
                (
                    Phase::Flight,
                    laws::aer_leg_length(0.0, g.zeta0, g.zeta_dev, g.omega, g.phi),
                )
            };
            self.seq = self.seq.wrapping_add(1);
            out.emit(Message::LegCommand(LegCommand {
                leg_length_m: len,
                touchdown_angle_rad: self.next_beta_td,
                gait: g.id,
                phase,
                seq: self.seq,
            }));
        }
        if now_us >= self.next_status_us {
            self.next_status_us = now_us + (1e6 / self.cfg.status_hz) as u64;
            out.emit(Message::GaitStatus(self.status()));
        }
    }
}

#[cfg(test)]
mod tests;
