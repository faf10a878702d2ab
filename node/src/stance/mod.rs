//! Per-step terrain classification: micro-switch debounce, the stance, the sampled frame, the
//! repair, the decision, the hop's energy balance ([`crate::unknown::energy`]), and exactly one `TerrainClass`
//! per step.
//!
//! [`StancePipeline::on_frame`] and [`StancePipeline::tick`] are the whole decision on one
//! thread; [`crate::NodeService`] drives them live, in a replay and in the demo. All times in the decision are the foot's own timestamps (FootContact and the
//! tactile header), so a replay decides exactly as the live run did. Nothing here allocates per
//! frame: buffers are sized when the model is installed.
//!
//! One concept in one file (near 700 lines): the pipeline driving each foot's state; that
//! state ([`foot`]) and the pipeline's parts (debounce, sample, decision, adapt) are the
//! submodules.

mod adapt;
mod ahead;
mod debounce;
mod foot;
mod frame_decision;
mod sample;
mod step_decision;
mod timing;

use protocol::clock::Clock;
use protocol::emit::Emit;
use protocol::messages::{self, FootContact, Message, TerrainClass, flags};
use protocol::tactile::{Reassembler, ReassemblyStats};
use protocol::{IdConfig, Stamped};

use std::sync::Arc;

use crate::classifier::{Classifier, Model};
use crate::config::NodeConfig;
use crate::health::LineHealth;
use crate::unknown::energy::EnergyObservation;
use crate::unknown::{self, Reason, ReasonCounts};
use adapt::Refitter;
use debounce::Edge;
use foot::Foot;
use frame_decision::{Adaptation, FrameSums, decide_frame};
pub use sample::{SampleSource, SampleTime};

/// Counters per stage, for NodeStatus and the logs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counters {
    /// Frames received.
    pub frames: u64,
    /// Frames with our identifiers that did not decode.
    pub decode_errors: u64,
    /// Tactile images reassembled.
    pub images: u64,
    /// Touchdowns.
    pub steps: u64,
    /// Steps that ended without an image.
    pub no_sample: u64,
    /// Steps decided from an image.
    pub classified: u64,
    /// Steps whose sampled image showed no foot on the ground (flag NO_CONTACT).
    pub no_contact: u64,
    /// Steps the texture gave a terrain that the energy check called unknown (flag ENERGY).
    pub energy_unknown: u64,
    /// Images skipped because their size is not the model's (said once per size in the log).
    pub wrong_size: u64,
    /// Unknown steps per reason (no sample and no contact included).
    pub unknown_by_reason: ReasonCounts,
    /// Models refitted to a foot's dead lines.
    pub refits: u64,
}

/// The times after touchdown (ms) at which `presrs capture` keeps a stance's frames beside its
/// sampled image: the candidates `train` measures the deciding frame among.
pub const FRAME_OFFSETS_MS: [u32; 9] = [30, 50, 70, 90, 110, 130, 150, 170, 190];

/// A stance frame counts for an offset when it lies within this of it: half the array's 10 ms
/// period (further, the stance had ended or its frame was lost).
const FRAME_NEAR_US: u32 = 5_000;

/// Capture mode decides a stance once its frames are past the last offset (or at liftoff).
const CAPTURE_DONE_US: u32 = (FRAME_OFFSETS_MS[FRAME_OFFSETS_MS.len() - 1] * 1000) + FRAME_NEAR_US;

/// Receiver time without a frame from a foot after which its switch's last reading counts as
/// held (see [`StancePipeline::tick`]).
const SILENT_US: u64 = 1_000_000;

/// The node's pipeline, one thread's worth.
pub struct StancePipeline {
    cfg: NodeConfig,
    classifier: Option<Classifier>,
    refitter: Refitter,
    reassembler: Reassembler,
    feet: Vec<Foot>,
    /// Receive time of the frame being processed (or the tick's time).
    now_rx_us: u64,
    /// The bus's clock, when the pipeline runs live: a decision's latency ends at its reading
    /// when the decision is made, so a node that was stopped or behind shows it. Without one
    /// (lock-step, replays) it ends at `now_rx_us`, the driver's clock.
    clock: Option<Arc<dyn Clock>>,
    /// The last image size said not to fit the model (said once per size).
    said_size: Option<(u8, u8, u8)>,
    /// Per foot: its latest image was of a size the model does not take.
    wrong_size_now: Vec<bool>,
    /// Counters per stage.
    pub counters: Counters,
    /// Capture mode: no model; every stance's sampled image is kept for [`Self::sample`].
    capture: bool,
    /// Per class of the model: stances the energy check judged, and of them those outside
    /// the class's map (sized when a model with another class count is installed).
    energy_tally: Vec<[u32; 2]>,
    /// The deciding frame's time after touchdown, and whose word it is.
    sample: SampleTime,
}

/// One step's decision as the pipeline hands it on: exactly one per step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Decided {
    /// The foot that stepped.
    pub foot: u8,
    /// The decision, as the bus carries it.
    pub class: TerrainClass,
    /// The step's touchdown (the debounced switch edge) on the receiver's clock, a log's
    /// timestamps (µs): the foot's own time of the edge moved onto the receive time of the
    /// report that confirmed it.
    pub touchdown_us: u64,
}

/// The image a step was decided on, as the node picked it: see [`StancePipeline::sample`].
#[derive(Clone, Copy, Debug)]
pub struct StanceSample<'a> {
    /// The foot.
    pub foot: u8,
    /// The step's number (the TerrainClass's `step`).
    pub step: u16,
    /// Touchdown, the foot's clock (µs, wrapping).
    pub touchdown_us: u32,
    /// The image's sample time, the foot's clock.
    pub sample_us: u32,
    /// Receive time of the image's last segment, the bus's clock (a log's timestamps).
    pub rx_us: u64,
    /// Rows.
    pub rows: usize,
    /// Columns.
    pub cols: usize,
    /// 8 or 16.
    pub bits: u8,
    /// Row-major pixels as received (not cropped or repaired).
    pub pixels: &'a [u16],
}

impl StancePipeline {
    /// A pipeline for `cfg`, with `model` installed (or none: every step "no sample").
    pub fn new(cfg: NodeConfig, model: Option<Model>) -> Self {
        let mut p = Self {
            reassembler: Reassembler::new(cfg.reassembly_timeout_us),
            classifier: None,
            refitter: Refitter::default(),
            feet: Vec::new(),
            now_rx_us: 0,
            clock: None,
            said_size: None,
            wrong_size_now: Vec::new(),
            counters: Counters::default(),
            capture: false,
            energy_tally: Vec::new(),
            sample: SampleTime::of(cfg.sample_ms, None),
            cfg,
        };
        p.set_model(model);
        p
    }

    /// A pipeline without a model that picks every stance's image as the node would (the same
    /// debounce, stance and sample-time rules), for `presrs capture`: after a step's
    /// TerrainClass (always NoSample: there is no model), [`Self::sample`] gives its image.
    /// Single-frame: `multi_frame` is ignored.
    pub fn for_capture(mut cfg: NodeConfig) -> Self {
        cfg.multi_frame = false;
        let mut p = Self::new(cfg, None);
        p.capture = true;
        for f in &mut p.feet {
            f.best = vec![0; protocol::tactile::MAX_PIXELS];
            f.frames = vec![(None, vec![0; protocol::tactile::MAX_PIXELS]); FRAME_OFFSETS_MS.len()];
        }
        p
    }

    /// Capture mode: the foot's latest decided stance's frame nearest each of
    /// [`FRAME_OFFSETS_MS`] (`None` where the stance had no image within half a frame period
    /// of it: it had ended), of the sampled image's size.
    pub fn stance_frames(&self, foot: u8) -> impl Iterator<Item = Option<&[u16]>> + '_ {
        let f = self.feet.get(foot as usize);
        let n = f.map_or(0, |f| f.best_len);
        f.into_iter()
            .flat_map(|f| &f.frames)
            .map(move |(err, px)| err.filter(|&e| e <= FRAME_NEAR_US).map(|_| &px[..n]))
    }

    /// Capture mode, at the end of a run: decides every stance still open with an image (the run
    /// ended before its liftoff or its last frame offset), as a live capture's stop does.
    pub fn decide_open(&mut self, out: &mut (impl Emit<Decided> + ?Sized)) {
        if !self.capture {
            return;
        }
        for foot in 0..self.feet.len() {
            let f = &self.feet[foot];
            if f.switch.stance && !f.decided && f.best_err.is_some() {
                self.decide(foot as u8, out);
            }
        }
    }

    /// The deciding frame's time after touchdown the pipeline uses, and where it came from.
    pub fn sample_time(&self) -> SampleTime {
        self.sample
    }

    /// Per class of the model: the stances its energy check judged and, of them, those outside
    /// the class's return map (judged when the next touchdown gives the flight after).
    pub fn energy_tally(&self) -> &[[u32; 2]] {
        &self.energy_tally
    }

    /// What the foot's latest judged stance did to the hop (the flights either side of it and
    /// its texture class); a stance is judged at the touchdown after it.
    pub fn energy_observation(&self, foot: u8) -> Option<EnergyObservation> {
        self.feet.get(foot as usize)?.balance.last
    }

    /// The image the foot's latest decided step was sampled from; `None` before its first
    /// decision, while a step is open, or when the step had no image inside its stance. Valid
    /// from the step's TerrainClass until the foot's next touchdown.
    pub fn sample(&self, foot: u8) -> Option<StanceSample<'_>> {
        let f = self.feet.get(foot as usize)?;
        if !f.decided || f.best_err.is_none() {
            return None;
        }
        let (rows, cols, bits) = f.best_shape;
        Some(StanceSample {
            foot,
            step: f.step,
            touchdown_us: f.touchdown_us,
            sample_us: f.best_ts,
            rx_us: f.best_rx_us,
            rows: rows as usize,
            cols: cols as usize,
            bits,
            pixels: &f.best[..f.best_len],
        })
    }

    /// Installs a model (SIGHUP reload); sizes every buffer for it.
    ///
    /// Stance tracking does not depend on the model, so a reload keeps each foot's switch state,
    /// stance and step count: the step in progress still gets its one TerrainClass. Only what the
    /// model sizes changes: a sample of another image size is dropped, and the sensor health is
    /// learned afresh when the working image's size changes.
    pub fn set_model(&mut self, model: Option<Model>) {
        // The config's word, else the model's deciding frame (measured on the lab's stances;
        // older models have none).
        self.sample = SampleTime::of(self.cfg.sample_ms, model.as_ref().and_then(|m| m.sample_ms));
        let (rows, cols) = model.as_ref().and_then(|m| m.work_size()).unwrap_or((1, 1));
        let input = model.as_ref().map_or(1, |m| m.input_rows * m.input_cols);
        let classes = model.as_ref().map_or(0, |m| m.classes.len());
        let model = model.map(Arc::new);
        self.classifier = model.as_ref().map(|m| {
            // The images are for refits (the shared copy has them); the classifier needs none.
            let mut own = Model::clone(m);
            own.images = None;
            Classifier::new(own)
        });
        self.refitter.generation += 1;
        self.refitter.unavailable = false;
        self.refitter.model = model.clone();
        // A foot's dead lines are judged against the footprint of the model's training images
        // (see `crate::health`); a model file without them keeps the rule it had.
        let health = || match model.as_deref() {
            Some(m) => LineHealth::for_model(m),
            None => LineHealth::new(rows, cols),
        };
        self.feet.resize_with(self.cfg.feet as usize, || {
            Foot::new(input, classes, health())
        });
        self.wrong_size_now = vec![false; self.feet.len()];
        self.said_size = None;
        if self.energy_tally.len() != classes {
            self.energy_tally = vec![[0; 2]; classes];
        }
        for f in &mut self.feet {
            if f.sum_lp.len() != classes {
                f.sum_lp = vec![0.0; classes];
                f.sample_verdicts = vec![None; classes];
                f.used = 0;
            }
            if f.best.len() != input {
                f.best = vec![0; input];
                f.best_len = input;
                f.best_err = None;
            }
            if f.health.size() != (rows, cols) {
                f.health = health();
            }
            f.adapted = None;
            f.asked = None;
            // Class indices are the old model's.
            f.balance.forget_classes();
        }
    }

    /// A foot's latest image was of a size the model does not take (NodeStatus says so).
    pub fn wrong_image_size(&self) -> bool {
        self.wrong_size_now.iter().any(|&w| w)
    }

    /// The installed model.
    pub fn model(&self) -> Option<&Model> {
        self.refitter.model.as_deref()
    }

    /// The CAN identifiers.
    pub fn ids(&self) -> &IdConfig {
        &self.cfg.ids
    }

    /// Tactile reassembly counters.
    pub fn reassembly_stats(&self) -> ReassemblyStats {
        self.reassembler.stats()
    }

    /// Largest learned damage over the feet, percent (eq. (6)).
    pub fn damage_pct(&self) -> f64 {
        self.feet
            .iter()
            .map(|f| f.health.damage_pct())
            .fold(0.0, f64::max)
    }

    /// Measures each decision's latency on `clock` (the bus's: see
    /// [`protocol::bus::BusSource::clock`]) instead of the driver's time.
    pub fn set_clock(&mut self, clock: Arc<dyn Clock>) {
        self.clock = Some(clock);
    }

    /// Processes one received frame; every TerrainClass it decides goes to `out`.
    pub fn on_frame(&mut self, st: &Stamped, out: &mut (impl Emit<Decided> + ?Sized)) {
        self.counters.frames += 1;
        self.now_rx_us = st.t_us;
        let decoded = match messages::decode(&st.frame, &self.cfg.ids) {
            Ok(d) => d,
            Err(_) => {
                self.counters.decode_errors += 1;
                return;
            }
        };
        match decoded {
            Some((foot, Message::FootContact(fc))) if foot < self.cfg.feet => {
                self.on_contact(foot, fc, out)
            }
            Some((foot, Message::TactileSegment(v))) if foot < self.cfg.feet => {
                let done = self
                    .reassembler
                    .push(v, foot, st.frame.data(), st.t_us)
                    .is_some();
                if done {
                    self.counters.images += 1;
                    self.on_image(foot, st.t_us, out);
                }
            }
            _ => {}
        }
    }

    fn on_contact(&mut self, foot: u8, fc: FootContact, out: &mut (impl Emit<Decided> + ?Sized)) {
        // The state this report ends held until now: settle it first. A foot that reports only
        // its edges (and sends no image in flight) would otherwise never confirm a liftoff,
        // and every later stance would run on as the first one (1 of 3 steps decided).
        self.settle(foot, fc.timestamp_us, out);
        let f = &mut self.feet[foot as usize];
        f.heard = Some((self.now_rx_us, fc.timestamp_us));
        f.contact_heard = f.heard;
        f.switch.read(fc.stance, fc.timestamp_us);
        self.settle(foot, fc.timestamp_us, out);
    }

    /// Accepts a switch state that has held for the debounce time by `now` (foot clock).
    fn settle(&mut self, foot: u8, now: u32, out: &mut (impl Emit<Decided> + ?Sized)) {
        let debounce = self.cfg.debounce_us;
        let f = &mut self.feet[foot as usize];
        let Some(edge) = f.switch.settle(now, debounce) else {
            return;
        };
        if let Edge::Touchdown { at_us } = edge {
            // A new step; the one before it is judged by the flight between them.
            let maps = self
                .classifier
                .as_ref()
                .and_then(|c| c.model().unknown.energy.as_deref());
            let judged = f
                .balance
                .touchdown(foot, f.step, at_us, self.now_rx_us, maps);
            if let Some((k, outside)) = judged
                && let Some(t) = self.energy_tally.get_mut(k)
            {
                t[0] = t[0].saturating_add(1);
                t[1] = t[1].saturating_add(u32::from(outside));
            }
            f.touchdown_us = at_us;
            // The edge on the receiver's clock, from the last switch report (received as it
            // was sent), else from the frame that confirmed it (`now` is the foot's time in the
            // frame received at `now_rx_us`).
            let (rx, ts) = f.contact_heard.unwrap_or((self.now_rx_us, now));
            let since = ts.wrapping_sub(at_us) as i32;
            f.touchdown_rx_us = rx.saturating_add_signed(-i64::from(since));
            f.decided = false;
            f.best_err = None;
            for (err, _) in &mut f.frames {
                *err = None;
            }
            f.sum_lp.fill(0.0);
            f.used = 0;
            f.sample_err = None;
            f.no_contact = false;
            f.repaired = false;
            f.step = f.step.wrapping_add(1);
            self.counters.steps += 1;
        } else if let Edge::Liftoff { at_us } = edge {
            f.balance.liftoff(at_us, self.now_rx_us);
            if !f.decided {
                // Liftoff before the decision: decide with what the stance gave.
                self.decide(foot, out);
            }
        }
    }

    fn on_image(&mut self, foot: u8, rx_us: u64, out: &mut (impl Emit<Decided> + ?Sized)) {
        let ts = self.reassembler.last_image().timestamp_us;
        // The image's own timestamp also settles a pending switch edge.
        self.settle(foot, ts, out);
        self.refitter.collect(&mut self.feet, &mut self.counters);
        let img = self.reassembler.last_image();
        let [w0, w1] = [self.cfg.window_ms[0] * 1000, self.cfg.window_ms[1] * 1000];
        let multi = self.cfg.multi_frame;
        let f = &mut self.feet[foot as usize];
        f.clock.on_image(ts, rx_us);
        f.heard = Some((rx_us, ts));
        if !f.switch.stance || f.decided {
            return;
        }
        let dt = ts.wrapping_sub(f.touchdown_us);
        if dt > sample::FAR_US {
            return; // an image from before the touchdown
        }
        if f.switch.after_open_edge(ts, self.cfg.debounce_us) {
            // Sampled after a liftoff edge that the debounce has not confirmed yet: outside the
            // stance unless the edge was bounce, and then the next images are inside again.
            return;
        }
        let (rows, cols) = (img.rows as usize, img.cols as usize);
        let Some(cls) = self.classifier.as_mut() else {
            if self.capture {
                self.pick_nearest(foot, dt, rx_us, out);
            }
            return;
        };
        let m = cls.model();
        let wrong =
            rows != m.input_rows || cols != m.input_cols || m.check_depth(img.bits).is_err();
        if let Some(w) = self.wrong_size_now.get_mut(foot as usize) {
            *w = wrong;
        }
        if wrong {
            self.counters.wrong_size += 1;
            if self.said_size != Some((img.rows, img.cols, img.bits)) {
                self.said_size = Some((img.rows, img.cols, img.bits));
                tracing::warn!(
                    foot,
                    "the foot's images are {rows}x{cols} at {} bits but the model takes {}x{} \
                     images at {} bits: its steps are not classified (train a model on this \
                     foot's images)",
                    img.bits,
                    m.input_rows,
                    m.input_cols,
                    m.bits.map_or("any".to_string(), |b| b.to_string())
                );
            }
            return;
        }
        if multi {
            if sample::in_window(dt, [w0, w1]) {
                f.keep(img, rx_us);
                // The stance history learns from one frame per stance, not every frame.
                let observe = f.used == 0;
                let err = dt.abs_diff(self.sample.ms * 1000);
                let nearest = f.sample_err.is_none_or(|e| err < e);
                let (mut sum_lp, mut verdicts) = (
                    std::mem::take(&mut f.sum_lp),
                    std::mem::take(&mut f.sample_verdicts),
                );
                let ctx = Adaptation {
                    cfg: &self.cfg,
                    refitter: &mut self.refitter,
                    counters: &mut self.counters,
                };
                let sums = FrameSums {
                    sum_lp: &mut sum_lp,
                    verdicts: nearest.then_some(&mut verdicts),
                };
                let decided = decide_frame(cls, foot, f, (rows, cols), observe, Some(sums), ctx);
                (f.sum_lp, f.sample_verdicts) = (sum_lp, verdicts);
                match decided {
                    Some((d, repaired)) if d.contact => {
                        f.repaired |= repaired;
                        f.used += 1;
                        if nearest {
                            f.sample_err = Some(err);
                        }
                    }
                    Some(_) => f.no_contact = true,
                    None => {}
                }
            }
            if dt >= w1 {
                self.decide(foot, out);
            }
            return;
        }
        self.pick_nearest(foot, dt, rx_us, out);
    }

    /// Single frame: keeps the latest image (`dt` after touchdown) if it is the nearest to the
    /// sample time so far, and decides once no nearer one can come.
    fn pick_nearest(
        &mut self,
        foot: u8,
        dt: u32,
        rx_us: u64,
        out: &mut (impl Emit<Decided> + ?Sized),
    ) {
        let sample_us = self.sample.ms * 1000;
        let img = self.reassembler.last_image();
        let f = &mut self.feet[foot as usize];
        if let Some(err) = sample::nearer(dt, sample_us, f.best_err) {
            f.best_err = Some(err);
            f.keep(img, rx_us);
        }
        // Capture: the stance's frame nearest each candidate deciding time too, and the stance
        // is decided once past them all (or at liftoff), not at its sample time.
        for ((err, px), &o) in f.frames.iter_mut().zip(&FRAME_OFFSETS_MS) {
            if let Some(e) = sample::nearer(dt, o * 1000, *err) {
                *err = Some(e);
                px[..img.len()].copy_from_slice(img.pixels());
            }
        }
        let done = if self.capture {
            dt >= CAPTURE_DONE_US
        } else {
            sample::nearest_is_final(dt, sample_us, f.clock.period_us())
        };
        if done {
            self.decide(foot, out);
        }
    }

    /// Decides every step whose sample deadline has passed by `now_rx_us` (the receiver's
    /// clock, as in [`Stamped::t_us`]) when no nearer frame can still come: a frame lost right
    /// after the best candidate would otherwise hold the decision until liftoff (~200 ms later).
    ///
    /// The deadline is in the foot's time: the last time on the array's sampling grid at which
    /// an image nearer the sample time than the best one could have been taken (without a known
    /// period: the sample time plus the best image's distance from it), plus one frame period
    /// for the transfer of an image already captured. The foot's time is the newest timestamp
    /// heard from it (a FootContact or an image), never extrapolated with the receiver's
    /// clock: robot time may run slower than the receiver's (the simulator under emulation runs
    /// at 0.35), and an extrapolated foot clock could pass the deadline before a nearer frame
    /// arrived. So the deadline only moves with frames; a foot that falls silent is decided at
    /// liftoff.
    pub fn tick(&mut self, now_rx_us: u64, out: &mut (impl Emit<Decided> + ?Sized)) {
        let sample_us = self.sample.ms * 1000;
        let w1 = self.cfg.window_ms[1] * 1000;
        for foot in 0..self.feet.len() {
            let f = &self.feet[foot];
            let Some((rx, ts)) = f.heard else { continue };
            // A foot silent for a second (it reports its switch at 100 Hz, and only its edges
            // if it departs from the spec) has held its last reading: a liftoff it reported
            // before the end of a log, or before it stopped, is taken, and its stance decided.
            if now_rx_us.saturating_sub(rx) >= SILENT_US && f.switch.pending() {
                self.now_rx_us = now_rx_us;
                let held = f.switch.raw_since.wrapping_add(self.cfg.debounce_us);
                self.settle(foot as u8, held, out);
            }
            let f = &self.feet[foot];
            if !f.switch.stance || f.decided || now_rx_us < rx {
                continue;
            }
            let dt = ts.wrapping_sub(f.touchdown_us);
            if dt > sample::FAR_US {
                continue;
            }
            let margin = f.clock.period_us().unwrap_or(10_000);
            let due = if self.capture {
                // Capture keeps the stance's frames to the last offset.
                f.best_err.is_some() && dt >= CAPTURE_DONE_US + margin
            } else if self.cfg.multi_frame {
                f.used > 0 && dt >= w1 + margin
            } else {
                let last_dt = f.clock.last_ts().map(|l| l.wrapping_sub(f.touchdown_us));
                f.best_err.is_some_and(|e| {
                    sample::deadline_passed(dt, sample_us, e, last_dt, f.clock.period_us(), margin)
                })
            };
            if due {
                self.now_rx_us = now_rx_us;
                self.decide(foot as u8, out);
            }
        }
    }

    /// A stance's decision, in three steps: the image's (the frames summed, or the sampled
    /// frame), how the step ended and its verdict, then the bus's fields.
    fn decide(&mut self, foot: u8, out: &mut (impl Emit<Decided> + ?Sized)) {
        self.feet[foot as usize].decided = true;
        let mut tc = TerrainClass {
            step: self.feet[foot as usize].step,
            terrain: messages::TERRAIN_UNKNOWN,
            confidence_pct: 0.0,
            damage_pct: 0.0,
            flags: 0,
            latency_us: 0,
        };
        let image_reason = if self.cfg.multi_frame {
            self.decide_frames(foot, &mut tc)
        } else {
            self.decide_sampled(foot, &mut tc)
        };
        self.verdict(foot, &mut tc, image_reason);
        let f = &self.feet[foot as usize];
        tc.damage_pct = f.health.damage_pct();
        // From the receipt of the sampled frame to now (the decision made, handed to the
        // send queue), saturated as the CAN field is; 0 when no frame was sampled (flag
        // NO_SAMPLE), so that a log and the bus say the same. Live, "now" is the bus clock's
        // reading here: the frame that completes a decision was received when the frame
        // before it was (docs/decisions/figures-behind-comments.md, latency-field).
        let now = self
            .clock
            .as_ref()
            .map_or(self.now_rx_us, |c| c.now_us().max(self.now_rx_us));
        tc.latency_us = step_decision::latency_us(&tc, now, f.best_rx_us);
        out.emit(Decided {
            foot,
            class: tc,
            touchdown_us: f.touchdown_rx_us,
        });
    }

    /// The multi-frame decision: the class of the stance's summed log posteriors, and the
    /// checks' verdict on it at the sample-time frame (why the image is unknown ground, if it
    /// is).
    fn decide_frames(&mut self, foot: u8, tc: &mut TerrainClass) -> Option<Reason> {
        let f = &mut self.feet[foot as usize];
        let cls = self.classifier.as_ref().filter(|_| f.used > 0)?;
        let m = cls.model();
        let lp = f.sum_lp.get(..m.classes.len()).unwrap_or(&f.sum_lp);
        let (best, pct) = step_decision::combine(lp);
        tc.confidence_pct = pct;
        tc.flags |= flags::MULTI_FRAME;
        let reason = f
            .sample_err
            .and_then(|_| f.sample_verdicts.get(best).copied().flatten());
        if reason.is_none() {
            tc.terrain = m.classes[best].terrain_id;
        }
        f.balance.class = reason.is_none().then_some(best);
        reason
    }

    /// The single-frame decision on the frame nearest the sample time: crop, repair, the
    /// classifier's terrain and the checks' verdict.
    fn decide_sampled(&mut self, foot: u8, tc: &mut TerrainClass) -> Option<Reason> {
        let f = &mut self.feet[foot as usize];
        let cls = self.classifier.as_mut().filter(|_| f.best_err.is_some())?;
        let (rows, cols) = (cls.model().input_rows, cls.model().input_cols);
        let ctx = Adaptation {
            cfg: &self.cfg,
            refitter: &mut self.refitter,
            counters: &mut self.counters,
        };
        match decide_frame(cls, foot, f, (rows, cols), true, None, ctx)? {
            (d, _) if !d.contact => {
                f.no_contact = true;
                None
            }
            (d, repaired) => {
                f.repaired = repaired;
                tc.terrain = d.terrain_id;
                tc.confidence_pct = d.confidence * 100.0;
                f.balance.class = d.class;
                d.reason
            }
        }
    }

    /// How the step ended, counted, and its verdict in one place for both paths: the image's
    /// checks, then the energy check (the texture's terrain took energy out of the last hop
    /// that it does not: other ground that looks like it). Unknown ground sets TERRAIN_UNKNOWN
    /// and the reason's flags.
    fn verdict(&mut self, foot: u8, tc: &mut TerrainClass, image_reason: Option<Reason>) {
        let f = &self.feet[foot as usize];
        let multi = self.cfg.multi_frame;
        let sampled = f.used > 0 || (!multi && f.best_err.is_some());
        let outcome =
            step_decision::outcome(f.no_contact, f.used, sampled, self.classifier.is_some());
        let c = &mut self.counters;
        match outcome {
            step_decision::Outcome::NoContact => c.no_contact += 1,
            step_decision::Outcome::NoSample => c.no_sample += 1,
            step_decision::Outcome::Classified => c.classified += 1,
        }
        step_decision::set_flags(tc, outcome, self.cfg.low_confidence, f.repaired);
        let reason = match outcome {
            step_decision::Outcome::NoContact => Some(Reason::NoContact),
            step_decision::Outcome::NoSample => Some(Reason::NoSample),
            step_decision::Outcome::Classified => unknown::step_verdict(
                image_reason,
                f.balance.class.is_some_and(|k| f.balance.rejects(k)),
            ),
        };
        if let Some(r) = reason {
            tc.terrain = messages::TERRAIN_UNKNOWN;
            tc.flags |= r.flag_bits();
            c.unknown_by_reason.add(r);
            if r == Reason::Energy {
                c.energy_unknown += 1;
            }
        }
    }
}
