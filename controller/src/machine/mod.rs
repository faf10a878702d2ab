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

use protocol::emit::Emit;
use std::collections::BTreeMap;

use protocol::messages::{
    GaitReason, GaitStatus, LegCommand, LegMode, Message, Phase, TERRAIN_UNKNOWN,
};
use protocol::terrain::TerrainCatalog;

use crate::gait::Gait;
use crate::laws;

mod takeover;

pub use crate::config::ControllerConfig;
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
    /// us), so the node gets a whole timeout from now. Measured on vcan before: after a 2 s
    /// link outage the controller declared the node lost 0.11 s after the link came back,
    /// when the node's heartbeat had been back for 0.07 s; judged from the reopen, the first
    /// heartbeat after it decides. A node already lost stays lost until it is heard.
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
            }
            Message::FootContact(fc) if foot == self.cfg.foot => {
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
            }
            Message::TerrainClass(tc) if foot == self.cfg.foot => {
                if tc.terrain == TERRAIN_UNKNOWN {
                    // Confirmed like a terrain: one unknown step among known ones (an unusual
                    // stance, a gait transition) is not new ground, and each needless switch to
                    // the safe gait and back costs steps at the wrong speed. Measured with
                    // `presrs demo --steps 300 --json`, seeds 1-3 (a model calibrated to 2%
                    // false unknowns): switching on every unknown step made 32, 23 and 31 gait
                    // switches and took up to 3, 4 and 5 steps to reach a terrain's gait;
                    // switching on the second in a row 21, 21, 21 and 3, 2, 3 (an unknown step
                    // that also restarted the terrain's count: 3, 3, 4).
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
                        let gid = self
                            .gait_of_terrain
                            .get(&tc.terrain)
                            .copied()
                            .unwrap_or(self.cfg.safe_gait);
                        self.request(gid, GaitReason::Terrain, tc.terrain);
                    }
                }
                if !self.stance {
                    self.apply_pending(out);
                }
            }
            _ => {}
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
mod tests {
    use super::*;
    use crate::config::tests::fresh;
    use protocol::messages::{FootContact, NodeStatus, TerrainClass};

    fn tc(terrain: u8, conf: f64) -> Message {
        Message::TerrainClass(TerrainClass {
            terrain,
            confidence_pct: conf,
            ..Default::default()
        })
    }

    /// A switch edge stamped `foot_us` by the foot.
    fn contact(stance: bool, foot_us: u64) -> Message {
        Message::FootContact(FootContact {
            stance,
            seq: 0,
            timestamp_us: foot_us as u32,
        })
    }

    #[test]
    fn switches_in_flight_after_two_confident_steps() {
        let mut c = Controller::new(fresh(), &TerrainCatalog::paper());
        let mut out = Vec::new();
        let mut t = 0;
        let hb = Message::NodeStatus(NodeStatus::default());
        let wood = protocol::Terrain::WOOD.id();
        for step in 0..3 {
            t += 100_000;
            let before = c.gait().id;
            c.on_message(0, &hb, t, &mut out);
            c.on_message(0, &contact(true, t), t, &mut out);
            c.on_message(0, &tc(wood, 90.0), t + 70_000, &mut out);
            // in stance: no switch yet, whatever the count
            assert_eq!(c.gait().id, before, "step {step}: switched in stance");
            c.on_message(0, &contact(false, t + 140_000), t + 140_000, &mut |m| {
                out.push(m)
            });
            t += 140_000;
            let expect = if step >= 1 { 3 } else { 2 };
            assert_eq!(c.gait().id, expect, "after step {step}");
        }
        assert_eq!(c.switches, 1);
        assert_eq!(c.reason(), GaitReason::Terrain);
        // A low-confidence step neither counts nor resets the gait.
        c.on_message(0, &tc(protocol::Terrain::CLAY.id(), 10.0), t, &mut |m| {
            out.push(m)
        });
        assert_eq!(c.gait().id, 3);
    }

    /// Issue 17: unknown is confirmed like a terrain (two in a row put the safe gait), and one
    /// unknown step in a terrain's run neither switches nor restarts that terrain's count.
    #[test]
    fn an_unknown_step_is_confirmed_before_the_safe_gait() {
        let mut c = Controller::new(fresh(), &TerrainCatalog::paper());
        let mut out = Vec::new();
        let hb = Message::NodeStatus(NodeStatus::default());
        let wood = protocol::Terrain::WOOD.id();
        let unknown = protocol::messages::TERRAIN_UNKNOWN;
        let mut t = 0;
        let mut step = |c: &mut Controller, terrain: u8| {
            t += 240_000;
            c.on_message(0, &hb, t, &mut out);
            c.on_message(0, &contact(true, t), t, &mut out);
            c.on_message(0, &tc(terrain, 90.0), t + 70_000, &mut out);
            c.on_message(0, &contact(false, t + 140_000), t + 140_000, &mut |m| {
                out.push(m)
            });
            c.gait().id
        };
        // wood, unknown, wood: wood's second step switches to G3 (the unknown between is not
        // new ground); then one unknown keeps G3, the second in a row gives the safe G1.
        assert_eq!(step(&mut c, wood), 2);
        assert_eq!(step(&mut c, unknown), 2);
        assert_eq!(step(&mut c, wood), 3);
        assert_eq!(step(&mut c, unknown), 3);
        assert_eq!(step(&mut c, unknown), 1);
        assert_eq!(c.reason(), GaitReason::Unknown);
        assert_eq!(step(&mut c, wood), 1);
        assert_eq!(step(&mut c, wood), 3);
    }

    #[test]
    fn after_a_switch_eq5_aims_at_the_new_beta_des_in_steps() {
        let mut c = Controller::new(fresh(), &TerrainCatalog::paper());
        let mut out = Vec::new();
        let hb = Message::NodeStatus(NodeStatus::default());
        let wood = protocol::Terrain::WOOD.id();
        let ls = |angle: f64, foot_us: u64| {
            Message::LegState(protocol::messages::LegState {
                leg_angle_rad: angle,
                leg_length_m: 0.14,
                timestamp_us: foot_us as u32,
            })
        };
        let mut aims = Vec::new();
        let mut t = 0;
        for _ in 0..6 {
            t += 200_000;
            c.on_message(0, &hb, t, &mut out);
            c.on_message(0, &contact(true, t), t, &mut out);
            c.on_message(0, &tc(wood, 90.0), t + 70_000, &mut out);
            // A symmetric stance about the angle aimed at.
            c.on_message(0, &ls(-c.beta_des, t + 150_000), t + 150_000, &mut |m| {
                out.push(m)
            });
            c.on_message(0, &contact(false, t + 150_000), t + 150_000, &mut |m| {
                out.push(m)
            });
            aims.push((c.gait().id, (c.beta_des * 100.0).round() / 100.0));
        }
        // G2 (0.42) until the second wood step's liftoff, then G3 (0.57) in 0.05 rad steps.
        assert_eq!(
            aims,
            [
                (2, 0.42),
                (3, 0.42),
                (3, 0.47),
                (3, 0.52),
                (3, 0.57),
                (3, 0.57)
            ]
        );
    }

    #[test]
    fn a_lab_terrain_from_the_catalog_gets_its_gait() {
        let cat =
            TerrainCatalog::from_toml("[[terrain]]\nid = 20\nname = \"asphalt\"\n", "t").unwrap();
        let mut cfg = fresh();
        cfg.terrain_gaits.insert("asphalt".into(), 3);
        let e = cfg.validate(&TerrainCatalog::paper()).unwrap_err();
        assert_eq!(e.key, "terrain_gaits.asphalt");
        assert!(e.message.contains("terrains file"), "{e}");
        cfg.validate(&cat).unwrap();
        let mut c = Controller::new(cfg, &cat);
        let mut out = Vec::new();
        let hb = Message::NodeStatus(NodeStatus::default());
        let mut t = 0;
        for _ in 0..2 {
            t += 100_000;
            c.on_message(0, &hb, t, &mut out);
            c.on_message(0, &contact(true, t), t, &mut out);
            c.on_message(0, &tc(20, 90.0), t + 70_000, &mut out);
            t += 140_000;
            c.on_message(0, &contact(false, t), t, &mut out);
        }
        assert_eq!(c.gait().id, 3);
        assert_eq!(c.reason(), GaitReason::Terrain);
    }

    /// Issue 28: a controller started in mid-hop listens to one step, then runs the gait whose
    /// eq. (5) explains it, from the angle the leg came down at; another controller's
    /// GaitStatus names the gait outright; nothing heard in `takeover_ms` is a fresh start.
    #[test]
    fn a_controller_started_in_mid_hop_takes_over_the_gait_the_leg_runs() {
        let leg = |angle: f64, t: u64| {
            Message::LegState(protocol::messages::LegState {
                leg_angle_rad: angle,
                leg_length_m: 0.9,
                timestamp_us: t as u32,
            })
        };
        // G3's leg: touchdown at 0.49, liftoff at 0.51 (law sign); eq. (5) with G3's
        // beta_des 0.57 and c 0.2 sends it down next at 0.51 + 0.2 (0.49 - 0.57) = 0.494.
        let g3 = Gait::g3();
        let next = laws::next_touchdown_angle(0.51, 0.49, g3.c, g3.beta_des);
        let hop = |c: &mut Controller, out: &mut Vec<Message>| {
            // (message or a tick, time): heard in mid-stance, the phase, then the liftoff (not
            // ours: nothing learned); then one whole step: touchdown, bounce, liftoff; then
            // the next touchdown.
            let events = [
                (Some(contact(true, 10_000)), 10_000),
                (Some(leg(-0.5, 60_000)), 60_000),
                (Some(contact(false, 60_000)), 60_000),
                (Some(leg(0.49, 300_000)), 300_000),
                (Some(contact(true, 300_000)), 300_000),
                (Some(contact(false, 300_400)), 300_400),
                (Some(contact(true, 300_800)), 300_800),
                (None, 350_000),
                (Some(leg(-0.51, 440_000)), 440_000),
                (Some(contact(false, 440_000)), 440_000),
                (Some(Message::NodeStatus(NodeStatus::default())), 600_000),
                (None, 600_000),
                (Some(leg(next, 680_000)), 680_000),
                (Some(contact(true, 680_000)), 680_000),
                (None, 681_000),
            ];
            for (m, t) in events {
                match m {
                    Some(m) => c.on_message(0, &m, t, out),
                    None => c.tick(t, out),
                }
            }
        };
        let cat = TerrainCatalog::paper();
        let mut c = Controller::new(ControllerConfig::default(), &cat);
        let mut out = Vec::new();
        c.tick(0, &mut out);
        hop(&mut c, &mut out);
        let t = c.takeover.expect("took over at the second touchdown");
        assert_eq!((t.gait, t.gait_from), (3, "touchdown law"), "{t:?}");
        assert_eq!(t.at_us, 680_000);
        assert!((t.beta_des_rad - g3.beta_des).abs() < 1e-9);
        // Silent until then; then the gait and a stance command for G3.
        let first = out
            .iter()
            .position(|m| !matches!(m, Message::GaitStatus(_)))
            .expect("commands after the takeover");
        assert!(
            matches!(out[first - 1], Message::GaitStatus(g) if g.gait == 3),
            "{out:?}"
        );
        assert!(
            matches!(out[first], Message::LegCommand(l) if l.gait == 3 && l.phase == Phase::Stance)
        );
        assert!(
            out.iter()
                .all(|m| !matches!(m, Message::GaitStatus(g) if g.gait != 3)),
            "{out:?}"
        );

        // Another controller's GaitStatus names the gait, whatever the step says.
        let mut c = Controller::new(ControllerConfig::default(), &cat);
        let mut out = Vec::new();
        let other = GaitStatus {
            gait: 1,
            terrain: protocol::Terrain::CLAY.id(),
            omega_rad_s: 6.0,
            beta_des_rad: 0.27,
            reason: GaitReason::Terrain,
            foot: 0,
        };
        c.on_message(0, &Message::GaitStatus(other), 0, &mut out);
        hop(&mut c, &mut out);
        let t = c.takeover.expect("took over");
        assert_eq!((t.gait, t.gait_from), (1, "gait status"));
        assert_eq!(c.reason(), GaitReason::Terrain);

        // No leg heard: a fresh start after takeover_ms, in the initial gait.
        let mut c = Controller::new(ControllerConfig::default(), &cat);
        let mut out = Vec::new();
        c.tick(0, &mut out);
        c.tick(1_999_000, &mut out);
        assert!(out.is_empty() && c.takeover.is_none());
        c.tick(2_000_000, &mut out);
        let t = c.takeover.expect("fresh start");
        assert_eq!(
            (t.gait, t.gait_from, t.touchdown_angle_rad),
            (2, "initial", None)
        );
        assert!(out.iter().any(|m| matches!(m, Message::LegCommand(l)
            if (l.touchdown_angle_rad - Gait::g2().beta_des).abs() < 1e-9)));
    }

    /// After a gap in a regular LegState stream the controller has lost the leg: it stops
    /// commanding and takes it over again as at a start.
    #[test]
    fn a_gap_in_the_legs_reports_makes_the_controller_listen_again() {
        let mut c = Controller::new(ControllerConfig::default(), &TerrainCatalog::paper());
        let mut out = Vec::new();
        c.tick(0, &mut out);
        c.tick(2_000_000, &mut out);
        assert!(c.takeover.is_some(), "fresh start after takeover_ms");
        let ls = |t: u64| {
            Message::LegState(protocol::messages::LegState {
                leg_angle_rad: 0.3,
                leg_length_m: 0.9,
                timestamp_us: t as u32,
            })
        };
        for t in (2_000_000..2_100_000).step_by(10_000) {
            c.on_message(0, &ls(t), t, &mut out);
        }
        c.tick(2_100_000, &mut out);
        assert_eq!(c.leg_gaps, 0);
        // 300 ms of reports lost.
        c.on_message(0, &ls(2_400_000), 2_400_000, &mut out);
        assert_eq!(c.leg_gaps, 1);
        out.clear();
        c.tick(2_401_000, &mut out);
        c.tick(2_500_000, &mut out);
        assert!(out.is_empty(), "commanded a leg it lost track of: {out:?}");
    }

    /// A leg of motors (it says its mode in LegStatus) stops when commands stop: after a gap
    /// in its reports (its bridge stalled) the controller commands on, and the foot's reports,
    /// all heard, keep the phase.
    #[test]
    fn a_gap_in_a_motor_legs_reports_keeps_the_commands_coming() {
        let mut c = Controller::new(ControllerConfig::default(), &TerrainCatalog::paper());
        let mut out = Vec::new();
        c.tick(0, &mut out);
        c.tick(2_000_000, &mut out);
        let status = Message::LegStatus(protocol::messages::LegStatus {
            mode: protocol::messages::LegMode::Running,
            joint: 0,
            command_age_ms: 2,
            fault_code: 0,
        });
        c.on_message(0, &status, 2_000_000, &mut out);
        let ls = |t: u64| {
            Message::LegState(protocol::messages::LegState {
                leg_angle_rad: 0.3,
                leg_length_m: 0.9,
                timestamp_us: t as u32,
            })
        };
        let seq = std::cell::Cell::new(0u8);
        let fc = |stance: bool, t: u64| {
            seq.set(seq.get().wrapping_add(1));
            Message::FootContact(FootContact {
                stance,
                seq: seq.get(),
                timestamp_us: t as u32,
            })
        };
        for t in (2_000_000..2_100_000).step_by(10_000) {
            c.on_message(0, &ls(t), t, &mut out);
            c.on_message(0, &fc(false, t), t, &mut out);
        }
        c.on_message(0, &fc(true, 2_100_000), 2_100_000, &mut out);
        // The bridge silent for 300 ms; the foot's reports keep coming.
        for t in (2_110_000..2_400_000).step_by(10_000) {
            c.on_message(0, &fc(true, t), t, &mut out);
        }
        c.on_message(0, &ls(2_400_000), 2_400_000, &mut out);
        assert_eq!(c.leg_gaps, 1);
        // The phase of the first LegCommand at `t`.
        let mut phase_at = |c: &mut Controller, t: u64| {
            out.clear();
            c.tick(t, &mut out);
            match out.as_slice() {
                [Message::LegCommand(l), ..] => Some(l.phase),
                _ => None,
            }
        };
        assert_eq!(phase_at(&mut c, 2_401_000), Some(Phase::Stance));
        // The foot's reports lost for `lost` µs (`skipped` of them), a liftoff before and a
        // touchdown after.
        let lose = |c: &mut Controller, from: u64, lost: u64, skipped: u8| {
            let mut sink = |_| {};
            c.on_message(0, &fc(false, from), from, &mut sink);
            seq.set(seq.get().wrapping_add(skipped));
            c.on_message(0, &fc(true, from + lost), from + lost, &mut sink);
        };
        // 100 ms lost (longer than a stance): the phase is not known, and the stance the next
        // report says is left to the leg.
        lose(&mut c, 2_410_000, 100_000, 9);
        assert_eq!(phase_at(&mut c, 2_520_000), Some(Phase::Flight));
        // 20 ms lost (shorter than any stance): one edge at most, taken at the next report.
        lose(&mut c, 2_700_000, 20_000, 1);
        assert_eq!(phase_at(&mut c, 2_730_000), Some(Phase::Stance));
    }

    /// A controller started beside a leg of motors that nobody commands (its bridge waits for
    /// a first command or holds its damped stop) takes the leg at once; beside one that runs
    /// another controller's commands it listens as always.
    #[test]
    fn a_restarted_controller_commands_a_leg_of_motors_nobody_commands_at_once() {
        let status = |mode| {
            Message::LegStatus(protocol::messages::LegStatus {
                mode,
                joint: 0,
                command_age_ms: 60,
                fault_code: 0,
            })
        };
        let commands = |out: &[Message]| {
            out.iter()
                .filter(|m| matches!(m, Message::LegCommand(_)))
                .count()
        };
        for (mode, at_once) in [
            (LegMode::CommandTimeout, true),
            (LegMode::Waiting, true),
            (LegMode::Running, false),
            (LegMode::DriverFault, false),
        ] {
            let mut c = Controller::new(ControllerConfig::default(), &TerrainCatalog::paper());
            let mut out = Vec::new();
            c.tick(0, &mut out);
            c.on_message(0, &status(mode), 100_000, &mut out);
            c.tick(101_000, &mut out);
            assert_eq!(commands(&out) > 0, at_once, "{mode:?}: {out:?}");
            let t = c.takeover;
            assert_eq!(
                t.map(|t| (t.at_us, t.gait_from)),
                at_once.then_some((100_000, "initial"))
            );
            // Another foot's bridge says nothing of ours.
            let mut c = Controller::new(ControllerConfig::default(), &TerrainCatalog::paper());
            out.clear();
            c.on_message(1, &status(mode), 100_000, &mut out);
            c.tick(101_000, &mut out);
            assert_eq!(commands(&out), 0, "{mode:?} of foot 1: {out:?}");
        }
    }

    #[test]
    fn a_heartbeat_gap_while_our_bus_was_down_is_not_a_lost_node() {
        let mut c = Controller::new(fresh(), &TerrainCatalog::paper());
        let mut out = Vec::new();
        let hb = Message::NodeStatus(NodeStatus::default());
        c.on_message(0, &hb, 100_000, &mut out);
        c.tick(200_000, &mut out);
        // Our interface was down from 0.2 s to 2.2 s; reopened, the node has a timeout again.
        c.on_bus_open(2_200_000);
        c.tick(2_250_000, &mut out);
        assert_eq!(c.reason(), GaitReason::Initial);
        c.on_message(0, &hb, 2_270_000, &mut out);
        c.tick(2_600_000, &mut out);
        assert_eq!(c.reason(), GaitReason::Initial);
        // Silent for the timeout after the reopen: lost.
        c.tick(2_771_000, &mut out);
        assert_eq!(c.reason(), GaitReason::NodeLost);
    }

    #[test]
    fn lost_heartbeat_goes_to_the_safe_gait() {
        let mut c = Controller::new(fresh(), &TerrainCatalog::paper());
        let mut out = Vec::new();
        c.on_message(0, &Message::NodeStatus(NodeStatus::default()), 0, &mut out);
        c.tick(400_000, &mut out);
        assert_eq!(c.gait().id, 2);
        c.tick(501_000, &mut out);
        assert_eq!((c.gait().id, c.reason()), (1, GaitReason::NodeLost));
        assert!(
            out.iter()
                .any(|m| matches!(m, Message::GaitStatus(g) if g.reason == GaitReason::NodeLost))
        );
    }

    #[test]
    fn stance_commands_follow_eq4_and_bounce_is_ignored() {
        let mut c = Controller::new(fresh(), &TerrainCatalog::paper());
        let mut out = Vec::new();
        c.on_message(0, &contact(true, 1_000_000), 1_000_000, &mut |m| {
            out.push(m)
        });
        c.on_message(0, &contact(false, 1_000_400), 1_000_400, &mut |m| {
            out.push(m)
        }); // bounce
        // The foot's 100 Hz report keeps its clock fresh.
        c.on_message(0, &contact(true, 1_060_000), 1_060_000, &mut |m| {
            out.push(m)
        });
        out.clear();
        c.tick(1_070_000, &mut out);
        let g = c.gait().clone();
        let want = laws::aer_leg_length(0.07, g.zeta0, g.zeta_dev, g.omega, g.phi);
        let cmd = out.iter().find_map(|m| match m {
            Message::LegCommand(lc) => Some(*lc),
            _ => None,
        });
        let cmd = cmd.unwrap_or_default();
        assert_eq!(cmd.phase, Phase::Stance);
        assert!((cmd.leg_length_m - want).abs() < 1e-9);
    }

    #[test]
    fn late_edges_in_a_burst_are_judged_by_the_foots_clock() {
        // No node on this bus: a long heartbeat timeout keeps the gait.
        let cfg = ControllerConfig {
            heartbeat_timeout_ms: 60_000,
            ..fresh()
        };
        let mut c = Controller::new(cfg, &TerrainCatalog::paper());
        let mut out = Vec::new();
        // A touchdown at foot time 5.000 s and its liftoff at 5.150 s, both arriving 2 ms
        // apart at our 9.000 s (the leg's frames were held up): not a bounce.
        c.on_message(0, &contact(true, 5_000_000), 9_000_000, &mut |m| {
            out.push(m)
        });
        c.on_message(0, &contact(false, 5_150_000), 9_002_000, &mut |m| {
            out.push(m)
        });
        assert!(!c.stance, "the liftoff was taken for bounce");
        // The next touchdown at foot time 5.400 s arrives at our 9.001 s (the clocks differ);
        // 70 ms later on our clock the stance law is at 70 ms of the foot's stance.
        c.on_message(0, &contact(true, 5_400_000), 9_001_000, &mut |m| {
            out.push(m)
        });
        // The foot reports at its time 5.460 s, arriving at our 9.061 s; at our 9.071 s the
        // stance law is at 70 ms of the foot's stance.
        c.on_message(0, &contact(true, 5_460_000), 9_061_000, &mut |m| {
            out.push(m)
        });
        // A LegState on the leg's own clock (another device's, seconds apart) moves nothing.
        let ls = Message::LegState(protocol::messages::LegState {
            leg_angle_rad: 0.4,
            leg_length_m: 0.14,
            timestamp_us: 1_000_000,
        });
        c.on_message(0, &ls, 9_062_000, &mut out);
        let stance_len = |c: &mut Controller, now: u64| {
            let mut out = Vec::new();
            c.next_cmd_us = 0;
            c.tick(now, &mut out);
            out.iter()
                .find_map(|m| match m {
                    Message::LegCommand(lc) if lc.phase == Phase::Stance => Some(lc.leg_length_m),
                    _ => None,
                })
                .unwrap_or(f64::NAN)
        };
        let g = c.gait().clone();
        let law = |t: f64| laws::aer_leg_length(t, g.zeta0, g.zeta_dev, g.omega, g.phi);
        assert!((stance_len(&mut c, 9_071_000) - law(0.07)).abs() < 1e-9);
        // The foot's reports stop: the stance law holds 20 ms past the last one (80 ms), not
        // 200 ms on.
        assert!((stance_len(&mut c, 9_261_000) - law(0.08)).abs() < 1e-9);
        // The foot's 32-bit clock wraps: an edge just after the wrap is still 100 ms later.
        let mut c = Controller::new(fresh(), &TerrainCatalog::paper());
        let before = u32::MAX as u64 - 50_000;
        c.on_message(0, &contact(true, before), 0, &mut out);
        c.on_message(0, &contact(false, before + 100_000), 100_000, &mut |m| {
            out.push(m)
        });
        assert!(!c.stance, "an edge after the wrap was taken for bounce");
    }

    #[test]
    fn a_fall_restarts_the_touchdown_law_from_beta_des() {
        let mut c = Controller::new(fresh(), &TerrainCatalog::paper());
        let mut out = Vec::new();
        let ls = |angle: f64, foot_us: u32| {
            Message::LegState(protocol::messages::LegState {
                leg_angle_rad: angle,
                leg_length_m: 0.14,
                timestamp_us: foot_us,
            })
        };
        let b = c.gait().beta_des;
        // A normal step: liftoff 0.05 rad past beta_des, eq. (5) applies.
        c.on_message(0, &ls(b, 1_000_000), 1_000_000, &mut out);
        c.on_message(0, &contact(true, 1_000_000), 1_000_000, &mut |m| {
            out.push(m)
        });
        c.on_message(0, &ls(-(b + 0.05), 1_150_000), 1_150_000, &mut |m| {
            out.push(m)
        });
        c.on_message(0, &contact(false, 1_150_000), 1_150_000, &mut |m| {
            out.push(m)
        });
        let g = c.gait().clone();
        let law = laws::next_touchdown_angle(b + 0.05, b, g.c, g.beta_des);
        assert!((c.next_beta_td - law).abs() < 1e-12);
        assert_eq!(c.gait_resets, 0);
        // A fall: the leg swept to 1.3 rad before the foot left the ground.
        c.on_message(0, &ls(b, 1_400_000), 1_400_000, &mut out);
        c.on_message(0, &contact(true, 1_400_000), 1_400_000, &mut |m| {
            out.push(m)
        });
        c.on_message(0, &ls(-1.3, 1_520_000), 1_520_000, &mut out);
        c.on_message(0, &contact(false, 1_520_000), 1_520_000, &mut |m| {
            out.push(m)
        });
        assert_eq!((c.next_beta_td, c.gait_resets), (b, 1));
        // A stance of 10 ms (a stumble) is no step either.
        c.on_message(0, &contact(true, 1_800_000), 1_800_000, &mut |m| {
            out.push(m)
        });
        c.on_message(0, &ls(-b, 1_810_000), 1_810_000, &mut out);
        c.on_message(0, &contact(false, 1_830_000), 1_830_000, &mut |m| {
            out.push(m)
        });
        assert_eq!(c.gait_resets, 2);
    }
}
