//! Per-step terrain classification: micro-switch debounce, the stance, the sampled frame, the
//! repair, the decision, and exactly one `TerrainClass` per step.
//!
//! [`StancePipeline::on_frame`] is the whole node on one thread: the live node and the replay
//! both drive it. All times in the decision are the foot's own timestamps (FootContact and the
//! tactile header), so a replay decides exactly as the live run did. Nothing here allocates per
//! frame: buffers are sized when the model is installed.

use protocol::messages::{self, FootContact, Message, TerrainClass, flags};
use protocol::tactile::{Reassembler, ReassemblyStats};
use protocol::{CanFrame, IdConfig, Stamped};

use crate::classifier::repair;
use crate::classifier::{Classifier, Model, model::MAX_CLASSES};
use crate::config::{NodeConfig, RepairMode};

/// Counters per stage, for NodeStatus and the logs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counters {
    pub frames: u64,
    pub decode_errors: u64,
    pub images: u64,
    pub steps: u64,
    pub no_sample: u64,
    pub classified: u64,
}

/// Learns dead lines of the working image from the stance history.
#[derive(Clone, Debug)]
struct LineHealth {
    rows: usize,
    cols: usize,
    row_runs: Vec<u32>,
    col_runs: Vec<u32>,
    dead_rows: Vec<bool>,
    dead_cols: Vec<bool>,
}

impl LineHealth {
    fn new(rows: usize, cols: usize) -> Self {
        Self {
            rows,
            cols,
            row_runs: vec![0; rows],
            col_runs: vec![0; cols],
            dead_rows: vec![false; rows],
            dead_cols: vec![false; cols],
        }
    }

    /// One stance's image: a line is a suspect when it is all zero while a neighbour carries
    /// load; `k` suspect stances in a row make it dead; any reading brings it back.
    fn observe(&mut self, img: &[u16], k: u32) {
        let (rows, cols) = (self.rows, self.cols);
        let row_sum = |r: usize| (0..cols).map(|c| img[r * cols + c] as u32).sum::<u32>();
        let col_sum = |c: usize| (0..rows).map(|r| img[r * cols + c] as u32).sum::<u32>();
        for r in 0..rows {
            let s = row_sum(r);
            let neighbour = (r > 0 && row_sum(r - 1) > 0) || (r + 1 < rows && row_sum(r + 1) > 0);
            update(
                &mut self.row_runs[r],
                &mut self.dead_rows[r],
                s,
                neighbour,
                k,
            );
        }
        for c in 0..cols {
            let s = col_sum(c);
            let neighbour = (c > 0 && col_sum(c - 1) > 0) || (c + 1 < cols && col_sum(c + 1) > 0);
            update(
                &mut self.col_runs[c],
                &mut self.dead_cols[c],
                s,
                neighbour,
                k,
            );
        }
    }

    fn damage_pct(&self) -> f64 {
        let dr = self.dead_rows.iter().filter(|&&d| d).count();
        let dc = self.dead_cols.iter().filter(|&&d| d).count();
        repair::damage_percent(dr, dc, self.rows, self.cols)
    }
}

fn update(run: &mut u32, dead: &mut bool, sum: u32, neighbour: bool, k: u32) {
    if sum > 0 {
        *run = 0;
        *dead = false;
    } else if neighbour {
        *run = run.saturating_add(1);
        if *run >= k {
            *dead = true;
        }
    }
}

/// One foot's stance state.
#[derive(Clone, Debug)]
struct Foot {
    raw: bool,
    raw_since: u32,
    state: bool,
    have_raw: bool,
    touchdown_us: u32,
    decided: bool,
    step: u16,
    /// Single frame: the best candidate so far (|dt - sample| in µs) and its pixels.
    best_err: Option<u32>,
    best_rx_us: u64,
    best: Vec<u16>,
    /// Multi-frame: summed log-posteriors and frames used.
    sum_lp: [f64; MAX_CLASSES],
    used: u32,
    last_rx_us: u64,
    health: LineHealth,
}

/// The node's pipeline, one thread's worth.
pub struct StancePipeline {
    cfg: NodeConfig,
    classifier: Option<Classifier>,
    reassembler: Reassembler,
    feet: Vec<Foot>,
    pub counters: Counters,
}

impl StancePipeline {
    pub fn new(cfg: NodeConfig, model: Option<Model>) -> Self {
        let mut p = Self {
            reassembler: Reassembler::new(cfg.reassembly_timeout_us),
            classifier: None,
            feet: Vec::new(),
            counters: Counters::default(),
            cfg,
        };
        p.set_model(model);
        p
    }

    /// Installs a model (SIGHUP reload); sizes every buffer for it.
    pub fn set_model(&mut self, model: Option<Model>) {
        let (rows, cols) = model.as_ref().and_then(|m| m.work_size()).unwrap_or((1, 1));
        let input = model.as_ref().map_or(1, |m| m.input_rows * m.input_cols);
        self.classifier = model.map(Classifier::new);
        self.feet = (0..self.cfg.feet)
            .map(|_| Foot {
                raw: false,
                raw_since: 0,
                state: false,
                have_raw: false,
                touchdown_us: 0,
                decided: true,
                step: 0,
                best_err: None,
                best_rx_us: 0,
                best: vec![0; input],
                sum_lp: [0.0; MAX_CLASSES],
                used: 0,
                last_rx_us: 0,
                health: LineHealth::new(rows, cols),
            })
            .collect();
    }

    pub fn model(&self) -> Option<&Model> {
        self.classifier.as_ref().map(|c| c.model())
    }

    pub fn ids(&self) -> &IdConfig {
        &self.cfg.ids
    }

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

    /// Processes one received frame; every TerrainClass it decides goes to `out`.
    pub fn on_frame(&mut self, st: &Stamped, out: &mut impl FnMut(u8, TerrainClass)) {
        self.counters.frames += 1;
        let decoded = match messages::decode(&st.frame, &self.cfg.ids) {
            Ok(d) => d,
            Err(_) => {
                self.counters.decode_errors += 1;
                return;
            }
        };
        match decoded {
            Some((foot, Message::FootContact(fc))) if foot < self.cfg.feet => {
                self.on_contact(foot, fc, st.t_us, out)
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

    fn on_contact(
        &mut self,
        foot: u8,
        fc: FootContact,
        rx_us: u64,
        out: &mut impl FnMut(u8, TerrainClass),
    ) {
        let f = &mut self.feet[foot as usize];
        if !f.have_raw || fc.stance != f.raw {
            f.raw = fc.stance;
            f.raw_since = fc.timestamp_us;
            f.have_raw = true;
        }
        f.last_rx_us = rx_us;
        self.settle(foot, fc.timestamp_us, out);
    }

    /// Accepts a switch state that has held for the debounce time by `now` (foot clock).
    fn settle(&mut self, foot: u8, now: u32, out: &mut impl FnMut(u8, TerrainClass)) {
        let debounce = self.cfg.debounce_us;
        let f = &mut self.feet[foot as usize];
        if !f.have_raw || f.raw == f.state || now.wrapping_sub(f.raw_since) < debounce {
            return;
        }
        f.state = f.raw;
        if f.state {
            // Touchdown: a new step.
            f.touchdown_us = f.raw_since;
            f.decided = false;
            f.best_err = None;
            f.sum_lp = [0.0; MAX_CLASSES];
            f.used = 0;
            f.step = f.step.wrapping_add(1);
            self.counters.steps += 1;
        } else if !f.decided {
            // Liftoff before the decision: decide with what the stance gave.
            self.decide(foot, out);
        }
    }

    fn on_image(&mut self, foot: u8, rx_us: u64, out: &mut impl FnMut(u8, TerrainClass)) {
        let ts = self.reassembler.last_image().timestamp_us;
        // The image's own timestamp also settles a pending switch edge.
        self.settle(foot, ts, out);
        let img = self.reassembler.last_image();
        let sample_us = self.cfg.sample_ms * 1000;
        let [w0, w1] = [self.cfg.window_ms[0] * 1000, self.cfg.window_ms[1] * 1000];
        let multi = self.cfg.multi_frame;
        let f = &mut self.feet[foot as usize];
        if !f.state || f.decided {
            return;
        }
        let dt = ts.wrapping_sub(f.touchdown_us);
        if dt > 10_000_000 {
            return; // an image from before the touchdown
        }
        let Some(cls) = self.classifier.as_mut() else {
            return;
        };
        let m = cls.model();
        let (rows, cols) = (img.rows as usize, img.cols as usize);
        if rows != m.input_rows || cols != m.input_cols {
            return;
        }
        if multi {
            if dt >= w0 && dt <= w1 {
                f.best[..rows * cols].copy_from_slice(img.pixels());
                f.best_rx_us = rx_us;
                let n = f.best.len();
                if let Some(d) =
                    classify(cls, &mut f.best[..n], rows, cols, &mut f.health, &self.cfg)
                {
                    for k in 0..d.n_classes {
                        f.sum_lp[k] += d.log_posteriors[k];
                    }
                    f.used += 1;
                }
            }
            if dt >= w1 {
                self.decide(foot, out);
            }
            return;
        }
        let err = dt.abs_diff(sample_us);
        if f.best_err.is_none_or(|e| err < e) {
            f.best_err = Some(err);
            f.best[..rows * cols].copy_from_slice(img.pixels());
            f.best_rx_us = rx_us;
        }
        // The next frame can only be further from the sample time: decide now.
        if dt >= sample_us {
            self.decide(foot, out);
        }
    }

    fn decide(&mut self, foot: u8, out: &mut impl FnMut(u8, TerrainClass)) {
        let cfg = &self.cfg;
        let f = &mut self.feet[foot as usize];
        f.decided = true;
        let mut tc = TerrainClass {
            step: f.step,
            terrain: messages::TERRAIN_UNKNOWN,
            confidence_pct: 0.0,
            damage_pct: f.health.damage_pct(),
            flags: 0,
            latency_us: 0,
        };
        match self.classifier.as_mut() {
            Some(cls) if cfg.multi_frame && f.used > 0 => {
                let m = cls.model();
                let n = m.classes.len();
                let best = (0..n).fold(0, |b, k| if f.sum_lp[k] > f.sum_lp[b] { k } else { b });
                let mx = f.sum_lp[best];
                let z: f64 = (0..n).map(|k| (f.sum_lp[k] - mx).exp()).sum();
                tc.terrain = m.classes[best].terrain_id;
                tc.confidence_pct = 100.0 / z;
                tc.flags |= flags::MULTI_FRAME;
            }
            Some(cls) if !cfg.multi_frame && f.best_err.is_some() => {
                let m = cls.model();
                let (rows, cols) = (m.input_rows, m.input_cols);
                let n = rows * cols;
                if let Some(d) = classify(cls, &mut f.best[..n], rows, cols, &mut f.health, cfg) {
                    tc.terrain = d.terrain_id;
                    tc.confidence_pct = d.confidence * 100.0;
                    if d.class.is_none() {
                        tc.flags |= flags::LOW_CONFIDENCE;
                    }
                }
            }
            _ => {
                tc.flags |= flags::NO_SAMPLE;
                self.counters.no_sample += 1;
            }
        }
        if tc.flags & flags::NO_SAMPLE == 0 {
            self.counters.classified += 1;
            if tc.confidence_pct < cfg.low_confidence * 100.0 {
                tc.flags |= flags::LOW_CONFIDENCE;
            }
            if f.health.damage_pct() > 0.0 && cfg.repair != RepairMode::None {
                tc.flags |= flags::REPAIRED;
            }
        }
        tc.damage_pct = f.health.damage_pct();
        tc.latency_us = f
            .last_rx_us
            .max(f.best_rx_us)
            .saturating_sub(f.best_rx_us)
            .min(u32::MAX as u64) as u32;
        out(foot, tc);
    }

    /// The frame for a sent TerrainClass, with the latency measured from the sampled frame's
    /// last segment to `now_us` (receive clock).
    pub fn to_frame(&self, foot: u8, tc: &TerrainClass) -> Option<CanFrame> {
        Message::TerrainClass(*tc).to_frame(&self.cfg.ids, foot)
    }

    /// Receive time of the frame the last decision of `foot` used.
    pub fn sampled_rx_us(&self, foot: u8) -> u64 {
        self.feet.get(foot as usize).map_or(0, |f| f.best_rx_us)
    }
}

fn classify(
    cls: &mut Classifier,
    pixels: &mut [u16],
    rows: usize,
    cols: usize,
    health: &mut LineHealth,
    cfg: &NodeConfig,
) -> Option<crate::classifier::Decision> {
    cls.prepare(pixels, rows, cols).ok()?;
    let (wr, wc) = cls.work_size();
    match cfg.repair {
        RepairMode::None => {}
        RepairMode::PerImage => {
            cls.repair_work();
        }
        RepairMode::History => {
            health.observe(cls.work_mut(), cfg.dead_after_stances);
            if health.dead_rows.iter().chain(&health.dead_cols).any(|&d| d) {
                repair::repair_lines(
                    cls.work_mut(),
                    wr,
                    wc,
                    &health.dead_rows,
                    &health.dead_cols,
                    None,
                );
            }
        }
    }
    Some(cls.decide())
}
