//! The simulated robot: the hopper, its foot switch, leg state and skin, on the bus's frames.

use super::{
    CanFrame, ChaCha8Rng, Contact, Event, FRAME_PERIOD_US, FaultParams, FixedGait, FootContact,
    Gait, Hopper, HopperParams, IdConfig, ImageRef, LegCommand, LegCommands, LegState, Message,
    Phase, Rng, Segmenter, Skin, SkinParams, Terrain, Track, Variant,
};
use protocol::emit::Emit;
use rand::SeedableRng;

/// The simulated robot: track, legs, sensors, identifiers.
#[derive(Clone, Debug, PartialEq)]
pub struct SimConfig {
    /// The track it runs on.
    pub track: Track,
    /// The gait held until a controller names another (G1..G3).
    pub gait: u8,
    /// Legs, each with its foot sensor (foot ids 0..feet).
    pub feet: u8,
    /// Sensor faults of every foot.
    pub faults: FaultParams,
    /// Serial of foot 0's sensor; foot `i` wears `sensor + i` (see `Skin::of_sensor`).
    pub sensor: u64,
    /// Commands older than this are ignored and the leg's own laws take over, ms.
    pub command_timeout_ms: u64,
    /// The CAN identifiers.
    pub ids: IdConfig,
    /// Leg `foot` of this config speaks to the bus as two motors (its drivers' protocols)
    /// instead of taking LegCommand and sending LegState: `presrs lab sim --leg`.
    pub leg: Option<leg::LegConfig>,
    /// A leg of motors: its length joint's driver goes silent at this robot time, s (a fault
    /// drill: the bridge must stop the leg and name the joint).
    pub leg_silent_at_s: Option<f64>,
    /// Mass carried on the body, kg ([`crate::check_payload`]): the robot's next run with a
    /// load its model and its energy maps were not made with. The controller is not told.
    pub payload_kg: f64,
    /// The foot every leg wears ([`crate::foot_model`]): the paper's unless told.
    pub foot: crate::foot_model::FootModel,
}

impl SimConfig {
    /// The hopper of this config: the default one carrying [`SimConfig::payload_kg`].
    pub fn hopper_params(&self) -> HopperParams {
        let p = HopperParams::default();
        HopperParams {
            mass_kg: p.mass_kg + self.payload_kg,
            ..p
        }
    }
}

impl Default for SimConfig {
    fn default() -> Self {
        Self {
            track: Track::default(),
            gait: 2,
            feet: 1,
            faults: FaultParams::default(),
            sensor: crate::DEFAULT_SENSOR,
            command_timeout_ms: 100,
            ids: IdConfig::default(),
            leg: None,
            leg_silent_at_s: None,
            payload_kg: 0.0,
            foot: crate::foot_model::FootModel::paper(),
        }
    }
}

/// The leg's commands: the controller's when fresh, its own laws' otherwise; or, for a leg of
/// motors, what the motors were told.
pub(super) struct Commands {
    fixed: FixedGait,
    last: Option<(LegCommand, u64)>,
    now_us: u64,
    timeout_us: u64,
    /// The leg as two motors. Until the bridge first commands them the simulator holds the
    /// leg with its own laws (a lab holds its robot until the motors are live); from then on
    /// the motors alone move it, a damped stop included (the hopper then falls).
    motors: Option<leg::simulated::SimulatedLeg>,
}

impl Commands {
    /// The motors' set point, once they have been commanded.
    fn motor_set_point(&self) -> Option<leg::simulated::LegSetPoint> {
        self.motors
            .as_ref()
            .filter(|m| m.commanded)
            .map(|m| m.set_point())
    }

    fn external(&self) -> Option<&LegCommand> {
        self.last
            .as_ref()
            .filter(|(_, t)| self.now_us.saturating_sub(*t) <= self.timeout_us)
            .map(|(c, _)| c)
    }
}

impl LegCommands for Commands {
    fn stance_length(&mut self, t: f64) -> f64 {
        if let Some(sp) = self.motor_set_point() {
            return sp.length_m;
        }
        match self.external() {
            Some(c) if c.phase == Phase::Stance => c.leg_length_m,
            _ => self.fixed.stance_length(t),
        }
    }
    fn flight_length(&self) -> f64 {
        self.motor_set_point()
            .map_or(self.fixed.flight_length(), |sp| sp.length_m)
    }
    fn touchdown_angle(&self) -> f64 {
        if let Some(sp) = self.motor_set_point() {
            return sp.angle_rad;
        }
        self.external()
            .map_or(self.fixed.touchdown_angle(), |c| c.touchdown_angle_rad)
    }
}

/// One leg with its foot sensor.
pub(super) struct Leg {
    hopper: Hopper,
    cmd: Commands,
    skin: Skin,
    contact: Option<Contact>,
    stance_terrain: Terrain,
    pixels: Vec<u16>,
    contact_seq: u8,
    image_seq: u8,
    /// Pending switch edges (time µs, state), bounce included.
    edges: Vec<(u64, bool)>,
    /// The switch as last sent.
    switch: bool,
    /// Simulated time of the stance's touchdown, µs.
    touchdown_us: u64,
}

/// What the simulator knows about a step (ground truth for the demo and tests).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepTruth {
    /// The foot.
    pub foot: u8,
    /// Touchdown time, µs.
    pub touchdown_us: u64,
    /// The terrain under the foot.
    pub terrain: Terrain,
    /// Forward speed of the step, m/s.
    pub speed_m_s: f64,
}

/// The simulated robot: each leg a hopper with its foot sensor, talking CAN frames. [`SimRobot::advance_to`] moves it in time and emits what it sends; [`SimRobot::on_frame`] hears commands.
pub struct SimRobot {
    cfg: SimConfig,
    legs: Vec<Leg>,
    rng: ChaCha8Rng,
    segmenter: Segmenter,
    now_us: u64,
    next_frame_us: u64,
    /// Every touchdown so far (ground truth).
    pub steps: Vec<StepTruth>,
    /// Falls so far (each leg is set back on its feet where it fell): robot time, µs.
    pub falls: Vec<u64>,
    last_td: Vec<Option<(f64, f64)>>,
    /// A leg of motors' replies of one step, kept so that a step allocates nothing.
    motor_out: protocol::component::Outbox,
}

pub(super) const FRAME_US: u64 = FRAME_PERIOD_US;

impl SimRobot {
    /// A robot for `cfg`; `seed` fixes the terrains' random patches and the sensor noise.
    pub fn new(cfg: SimConfig, seed: u64) -> Self {
        let rng = ChaCha8Rng::seed_from_u64(seed);
        let gait = Gait::by_name(&cfg.gait.to_string()).unwrap_or_else(Gait::g2);
        let foot = &cfg.foot;
        let params = SkinParams {
            full_scale_kpa: SkinParams::default().full_scale_kpa / foot.gain,
            ..SkinParams::default()
        };
        let faults = FaultParams {
            initial_damage_pct: cfg.faults.initial_damage_pct.max(foot.dead_pct),
            ..cfg.faults.clone()
        };
        let legs = (0..cfg.feet.max(1))
            .map(|i| {
                let skin = Skin::of_sensor(cfg.sensor + i as u64, params.clone(), faults.clone());
                let mut hopper = Hopper::launch(cfg.hopper_params(), &gait);
                // Stagger the legs so their steps do not coincide.
                hopper.y += 0.005 * i as f64;
                hopper.x = i as f64 * 0.3;
                Leg {
                    hopper,
                    cmd: Commands {
                        fixed: FixedGait::new(gait.clone()),
                        last: None,
                        now_us: 0,
                        timeout_us: cfg.command_timeout_ms * 1000,
                        motors: cfg
                            .leg
                            .as_ref()
                            .filter(|l| l.foot == i)
                            .map(|l| leg::simulated::SimulatedLeg::new(l, seed ^ 0x1e9)),
                    },
                    skin,
                    contact: None,
                    stance_terrain: Terrain::WOOD,
                    pixels: vec![0; params.rows * params.cols],
                    contact_seq: 0,
                    switch: false,
                    image_seq: 0,
                    edges: Vec::new(),
                    touchdown_us: 0,
                }
            })
            .collect();
        let n = cfg.feet.max(1) as usize;
        Self {
            segmenter: Segmenter::new(Variant::Fd, cfg.ids.clone()),
            legs,
            rng,
            now_us: 0,
            next_frame_us: FRAME_US,
            steps: Vec::new(),
            falls: Vec::new(),
            last_td: vec![None; n],
            motor_out: protocol::component::Outbox::with_capacity(8),
            cfg,
        }
    }

    /// Simulated time, µs.
    pub fn now_us(&self) -> u64 {
        self.now_us
    }

    /// Forward speed of a leg's hopper, m/s, and its position along the track, m.
    pub fn speed_and_position(&self, foot: u8) -> Option<(f64, f64)> {
        self.legs
            .get(foot as usize)
            .map(|l| (l.hopper.vx, l.hopper.x))
    }

    /// The gait a leg runs now: the controller's (from a fresh LegCommand) or the fixed one.
    pub fn gait_in_effect(&self, foot: u8) -> Option<u8> {
        self.legs
            .get(foot as usize)
            .map(|l| l.cmd.external().map_or(l.cmd.fixed.gait.id, |c| c.gait))
    }

    /// A frame from a controller (or, to a leg of motors, from its bridge).
    pub fn on_frame(&mut self, frame: &CanFrame) {
        for l in &mut self.legs {
            if let Some(m) = l.cmd.motors.as_mut() {
                m.on_frame(frame);
            }
        }
        match protocol::messages::decode(frame, &self.cfg.ids) {
            Ok(Some((foot, Message::LegCommand(c)))) => {
                // A leg of motors does not understand LegCommand: its bridge does.
                if let Some(l) = self.legs.get_mut(foot as usize)
                    && l.cmd.motors.is_none()
                {
                    l.cmd.last = Some((c, self.now_us));
                }
            }
            Ok(Some((_, Message::GaitStatus(s)))) => {
                // The leg's own laws follow the controller's gait (lab gaits included), so
                // that a pause in its commands or a relaunch after a fall continues the gait
                // the controller runs. With the simulator's start gait instead, the speed of
                // one gait met the touchdown angle of another: G3's 0.57 rad at G2's launch
                // speed threw the hopper back, G1's 0.27 rad let it pitch forward, and after a
                // forced fall on wood, carpet or clay the hopper fell again every 0.35-0.48 s
                // for the rest of the run (in-process; one vcan run fell 55 times this way).
                if let Some(l) = self.legs.get_mut(s.foot as usize) {
                    let f = &mut l.cmd.fixed;
                    if (f.gait.id, f.gait.omega, f.gait.beta_des)
                        != (s.gait, s.omega_rad_s, s.beta_des_rad)
                    {
                        let mut g = f.gait.clone();
                        (g.id, g.omega, g.beta_des) = (s.gait, s.omega_rad_s, s.beta_des_rad);
                        f.set_gait(g);
                    }
                }
            }
            _ => {}
        }
    }

    /// Runs the robot up to `t_us`, emitting every frame it sends, in time order.
    pub fn advance_to(&mut self, t_us: u64, emit: &mut dyn Emit<CanFrame>) {
        while self.now_us < t_us {
            let next = (self.now_us + 1000)
                .min(t_us)
                .min(self.next_frame_us.max(self.now_us + 1));
            if let Some(at) = self.cfg.leg_silent_at_s
                && next as f64 * 1e-6 >= at
            {
                for l in &mut self.legs {
                    if let Some(m) = l.cmd.motors.as_mut() {
                        m.silence(1, true);
                    }
                }
            }
            for foot in 0..self.legs.len() {
                self.advance_leg(foot, next, emit);
                self.motor_replies(foot, next, emit);
            }
            self.now_us = next;
            if self.now_us >= self.next_frame_us {
                self.next_frame_us += FRAME_US;
                for foot in 0..self.legs.len() {
                    self.send_frame(foot, emit);
                }
            }
        }
    }

    fn advance_leg(&mut self, foot: usize, t_us: u64, emit: &mut dyn Emit<CanFrame>) {
        let ids = &self.cfg.ids;
        let t_end = t_us as f64 * 1e-6;
        loop {
            let leg = &mut self.legs[foot];
            leg.cmd.now_us = self.now_us;
            let dt = t_end - leg.hopper.t;
            if dt <= 1e-9 {
                break;
            }
            let ground = self.cfg.track.segment_at(leg.hopper.x).physics.ground();
            if let Some(sp) = leg.cmd.motor_set_point() {
                // The leg's spring is the length joint's impedance.
                leg.hopper.params.leg_stiffness = sp.stiffness_n_per_m;
                leg.hopper.params.leg_damping = sp.damping_n_s_per_m;
            }
            let ev = leg.hopper.advance(dt, ground, &mut leg.cmd);
            let ev_us = (leg.hopper.t * 1e6) as u64;
            match ev {
                Some(Event::Touchdown { beta, .. }) => {
                    leg.cmd.fixed.on_touchdown(beta);
                    let segment = self.cfg.track.segment_at(leg.hopper.x);
                    let terrain = segment.terrain;
                    leg.stance_terrain = terrain;
                    leg.contact = Some(leg.skin.contact_on(
                        segment.physics,
                        self.cfg.foot.base(),
                        &mut self.rng,
                    ));
                    leg.skin.faults.on_step(&mut self.rng);
                    leg.touchdown_us = ev_us;
                    bounce(
                        &mut leg.edges,
                        ev_us,
                        true,
                        self.cfg.foot.bounce_max,
                        &mut self.rng,
                    );
                    let speed = self.last_td[foot].map_or(leg.hopper.vx, |(t0, x0)| {
                        (leg.hopper.x - x0) / (leg.hopper.t - t0).max(1e-3)
                    });
                    self.last_td[foot] = Some((leg.hopper.t, leg.hopper.x));
                    self.steps.push(StepTruth {
                        foot: foot as u8,
                        touchdown_us: ev_us,
                        terrain,
                        speed_m_s: speed,
                    });
                    if leg.cmd.motors.is_none() {
                        send_leg_state(
                            ids,
                            foot as u8,
                            beta,
                            leg.cmd.fixed.flight_length(),
                            ev_us,
                            emit,
                        );
                    }
                }
                Some(Event::Liftoff { beta, length, .. }) => {
                    leg.cmd.fixed.on_liftoff(beta);
                    bounce(
                        &mut leg.edges,
                        ev_us,
                        false,
                        self.cfg.foot.bounce_max,
                        &mut self.rng,
                    );
                    // The stance's last length: after the event the hopper is in flight and
                    // reports the rest length, which put the hip 8% short of where it left.
                    if leg.cmd.motors.is_none() {
                        send_leg_state(ids, foot as u8, -beta, length, ev_us, emit);
                    }
                }
                Some(Event::Fell { .. }) => {
                    // Pick the hopper up and restart it where it fell, into the gait it runs
                    // (a lab would).
                    let x = leg.hopper.x;
                    leg.hopper = Hopper::launch(self.cfg.hopper_params(), &leg.cmd.fixed.gait);
                    leg.hopper.x = x;
                    leg.hopper.t = t_end;
                    // Picked up: the foot switch opens (it may already be open). Without this
                    // edge a controller that saw the touchdown stays in stance through the
                    // relaunch and its stance law runs on from a stale touchdown.
                    leg.edges.push((t_us, false));
                    self.falls.push(t_us);
                    tracing::warn!(
                        foot,
                        t_s = t_us as f64 * 1e-6,
                        "simulated hopper fell; restarted"
                    );
                }
                None => {}
            }
        }
        self.send_due_edges(foot, t_us, emit);
    }

    /// The foot switch's edges due by `t_us`, as FootContact reports.
    fn send_due_edges(&mut self, foot: usize, t_us: u64, emit: &mut dyn Emit<CanFrame>) {
        let ids = &self.cfg.ids;
        let leg = &mut self.legs[foot];
        leg.edges.sort_by_key(|e| e.0);
        while let Some(&(t, state)) = leg.edges.first() {
            if t > t_us {
                break;
            }
            leg.edges.remove(0);
            leg.switch = state;
            leg.contact_seq = leg.contact_seq.wrapping_add(1);
            let m = Message::FootContact(FootContact {
                stance: state,
                seq: leg.contact_seq,
                timestamp_us: self.cfg.foot.clock(t),
            });
            if let Some(f) = m.to_frame(ids, foot as u8) {
                emit.emit(f);
            }
        }
    }

    fn send_frame(&mut self, foot: usize, emit: &mut dyn Emit<CanFrame>) {
        let leg = &mut self.legs[foot];
        leg.skin.faults.on_time(FRAME_US as f64 * 1e-6);
        let model = &self.cfg.foot;
        // The image is taken `sample_lead_us` before it is sent: the foot as it was then.
        let taken_us = self.now_us.saturating_sub(u64::from(model.sample_lead_us));
        let tau_s = taken_us.saturating_sub(leg.touchdown_us) as f64 * 1e-6;
        let load = leg.hopper.foot_load() * model.load_share(tau_s);
        match (&leg.contact, leg.hopper.in_stance()) {
            (Some(c), true) => {
                leg.skin.image(c, load, &mut self.rng, &mut leg.pixels);
                if let Some(r) = model.rolled_from_row(tau_s) {
                    let cols = leg.skin.params.cols;
                    let n = leg.pixels.len();
                    leg.pixels[(r * cols).min(n)..].fill(0);
                }
            }
            _ => {
                // In flight the array reads its noise floor (below threshold: zeros), faults apply.
                leg.pixels.fill(0);
                let max = 255;
                leg.skin.faults.apply(&mut leg.pixels, max, &mut self.rng);
            }
        }
        // The switch at 100 Hz besides its edges, as a foot sends it (docs/protocol.md): the
        // foot's clock for a controller whose leg reports on a clock of its own.
        leg.contact_seq = leg.contact_seq.wrapping_add(1);
        let m = Message::FootContact(FootContact {
            stance: leg.switch,
            seq: leg.contact_seq,
            timestamp_us: model.clock(self.now_us),
        });
        if let Some(f) = m.to_frame(&self.cfg.ids, foot as u8) {
            emit.emit(f);
        }
        leg.image_seq = leg.image_seq.wrapping_add(1);
        let img = ImageRef {
            rows: 44,
            cols: 44,
            bits: 8,
            timestamp_us: model.clock(taken_us),
            pixels: &leg.pixels,
        };
        let _ = self
            .segmenter
            .frames(foot as u8, leg.image_seq, &img, &mut *emit);
        if leg.cmd.motors.is_none() {
            let angle = leg.hopper.leg_angle(&leg.cmd);
            let len = leg.hopper.leg_length(&leg.cmd);
            send_leg_state(&self.cfg.ids, foot as u8, angle, len, self.now_us, emit);
        }
    }

    /// A leg of motors answers its bridge: replies and cyclic messages due by `t_us`, with
    /// the hopper's true joints.
    fn motor_replies(&mut self, foot: usize, t_us: u64, emit: &mut dyn Emit<CanFrame>) {
        let leg = &mut self.legs[foot];
        let (angle, len) = (
            leg.hopper.leg_angle(&leg.cmd),
            leg.hopper.leg_length(&leg.cmd),
        );
        let dt = t_us.saturating_sub(self.now_us) as f64 * 1e-6;
        if let Some(m) = leg.cmd.motors.as_mut() {
            m.emit(t_us, angle, len, dt, &mut self.motor_out);
            for f in self.motor_out.drain() {
                emit.emit(f);
            }
        }
    }

    /// A leg's true angle (rad) and length (m) now.
    pub fn leg_truth(&self, foot: u8) -> Option<(f64, f64)> {
        self.legs
            .get(foot as usize)
            .map(|l| (l.hopper.leg_angle(&l.cmd), l.hopper.leg_length(&l.cmd)))
    }

    /// A leg of motors whose length joint is sprung now (its bridge is running it, not in
    /// the damped stop); `None` for a leg that is not motors.
    pub fn motors_driven(&self, foot: u8) -> Option<bool> {
        let m = self.legs.get(foot as usize)?.cmd.motors.as_ref()?;
        Some(m.commanded && m.set_point().stiffness_n_per_m > 0.0)
    }

    /// A leg of motors: the simulated drivers (to silence one or make it fault, in tests).
    pub fn motors_mut(&mut self, foot: u8) -> Option<&mut leg::simulated::SimulatedLeg> {
        self.legs.get_mut(foot as usize)?.cmd.motors.as_mut()
    }

    /// Ground truth of the step whose touchdown is nearest before `t_us` (foot clock).
    pub fn step_at(&self, foot: u8, t_us: u64) -> Option<StepTruth> {
        self.steps
            .iter()
            .rev()
            .find(|s| s.foot == foot && s.touchdown_us <= t_us)
            .copied()
    }
}

pub(super) fn send_leg_state(
    ids: &IdConfig,
    foot: u8,
    angle: f64,
    len: f64,
    t_us: u64,
    emit: &mut dyn Emit<CanFrame>,
) {
    let m = Message::LegState(LegState {
        leg_angle_rad: angle,
        leg_length_m: len,
        timestamp_us: t_us as u32,
    });
    if let Some(f) = m.to_frame(ids, foot) {
        emit.emit(f);
    }
}

/// A micro-switch edge with contact bounce: the final state at `t`, then 1 to `most` short
/// reversals within the next few ms (1-3 within 2 ms for a small snap-action switch).
pub(super) fn bounce(
    edges: &mut Vec<(u64, bool)>,
    t: u64,
    state: bool,
    most: u8,
    rng: &mut impl Rng,
) {
    edges.push((t, state));
    let mut at = t;
    for _ in 0..rng.random_range(1..=most.max(1)) {
        at += rng.random_range(150..500);
        edges.push((at, !state));
        at += rng.random_range(100..400);
        edges.push((at, state));
    }
}
