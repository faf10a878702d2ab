//! Adaptation to a damaged sensor: the model refitted to a foot's dead sensor lines (see
//! [`crate::classifier::train::refit`]), inline or on a background thread, and the per-frame
//! decision that uses it ([`classify`]: crop, repair, the refitted or the installed model).

use std::sync::Arc;

use crossbeam_channel::{Receiver, Sender};

use super::{Counters, Foot};
use crate::classifier::train::{RefitError, refit};
use crate::classifier::{Classifier, Decision, Model};
use crate::config::{NodeConfig, RefitMode, RepairMode};
use crate::health::LineHealth;

/// A model refitted to one foot's dead lines, and the lines it was fitted for.
pub(super) struct Adapted {
    pub(super) cls: Classifier,
    dead_rows: Vec<bool>,
    dead_cols: Vec<bool>,
}

impl Adapted {
    pub(super) fn fits(&self, h: &LineHealth) -> bool {
        self.dead_rows == h.dead_rows() && self.dead_cols == h.dead_cols()
    }
}

/// A refit asked of the background thread, and its answer. `generation` tells answers for a
/// model that has since been replaced (SIGHUP) from current ones.
struct RefitJob {
    foot: u8,
    generation: u64,
    model: Arc<Model>,
    dead_rows: Vec<bool>,
    dead_cols: Vec<bool>,
}

struct RefitDone {
    foot: u8,
    generation: u64,
    result: Result<Adapted, RefitError>,
}

fn run_refit(job: RefitJob) -> RefitDone {
    let result = refit(&job.model, &job.dead_rows, &job.dead_cols).map(|mut m| {
        // The adapted model classifies; it never refits again, so it need not hold the images.
        m.images = None;
        Adapted {
            cls: Classifier::new(m),
            dead_rows: job.dead_rows,
            dead_cols: job.dead_cols,
        }
    });
    RefitDone {
        foot: job.foot,
        generation: job.generation,
        result,
    }
}

/// Refits of the model to the feet's dead lines (see [`crate::classifier::train::refit`]).
#[derive(Default)]
pub(super) struct Refitter {
    /// The installed model, shared with refit jobs.
    pub(super) model: Option<Arc<Model>>,
    pub(super) generation: u64,
    /// The background thread's queues (RefitMode::Background), started on first use.
    tx: Option<Sender<RefitJob>>,
    rx: Option<Receiver<RefitDone>>,
    /// The installed model cannot be refitted (it holds no images): said once per model.
    pub(super) unavailable: bool,
}

impl Refitter {
    /// Takes in finished background refits (a channel poll: nothing allocated, nothing blocks).
    pub(super) fn collect(&mut self, feet: &mut [Foot], counters: &mut Counters) {
        while let Some(done) = self.rx.as_ref().and_then(|rx| rx.try_recv().ok()) {
            if done.generation == self.generation
                && let Some(f) = feet.get_mut(done.foot as usize)
            {
                self.install(done.foot, f, done.result, counters);
            }
        }
    }

    fn install(
        &mut self,
        foot: u8,
        f: &mut Foot,
        result: Result<Adapted, RefitError>,
        counters: &mut Counters,
    ) {
        match result {
            Ok(a) => {
                counters.refits += 1;
                let dead = a
                    .dead_rows
                    .iter()
                    .chain(&a.dead_cols)
                    .filter(|&&d| d)
                    .count();
                tracing::info!(
                    foot,
                    dead_lines = dead,
                    h = a.cls.model().h,
                    "model refitted to the foot's dead sensor lines"
                );
                f.adapted = Some(a);
            }
            Err(RefitError::NoImages) => {
                if !self.unavailable {
                    tracing::warn!("{}", RefitError::NoImages);
                }
                self.unavailable = true;
            }
            Err(e) => tracing::warn!(foot, "refit to the dead sensor lines failed: {e}"),
        }
    }

    /// Asks for a refit when the foot's dead lines are not those of its adapted model and not
    /// already asked for.
    pub(super) fn request(
        &mut self,
        mode: RefitMode,
        foot: u8,
        f: &mut Foot,
        counters: &mut Counters,
    ) {
        if mode == RefitMode::Off || self.unavailable || !f.health.any_dead() {
            return;
        }
        let h = &f.health;
        if f.adapted.as_ref().is_some_and(|a| a.fits(h))
            || f.asked
                .as_ref()
                .is_some_and(|(r, c)| r == h.dead_rows() && c == h.dead_cols())
        {
            return;
        }
        let Some(model) = self.model.clone() else {
            return;
        };
        let job = RefitJob {
            foot,
            generation: self.generation,
            model,
            dead_rows: h.dead_rows().to_vec(),
            dead_cols: h.dead_cols().to_vec(),
        };
        f.asked = Some((job.dead_rows.clone(), job.dead_cols.clone()));
        if mode == RefitMode::Inline {
            let done = run_refit(job);
            self.install(foot, f, done.result, counters);
            return;
        }
        if self.tx.is_none() {
            let (job_tx, job_rx) = crossbeam_channel::unbounded::<RefitJob>();
            let (done_tx, done_rx) = crossbeam_channel::unbounded();
            let spawned = std::thread::Builder::new()
                .name("refit".into())
                .spawn(move || {
                    for job in job_rx {
                        if done_tx.send(run_refit(job)).is_err() {
                            break;
                        }
                    }
                });
            if let Err(e) = spawned {
                tracing::warn!("cannot start the refit thread: {e}; refitting inline");
                let done = run_refit(job);
                self.install(foot, f, done.result, counters);
                return;
            }
            self.tx = Some(job_tx);
            self.rx = Some(done_rx);
        }
        if let Some(tx) = &self.tx {
            let _ = tx.send(job);
        }
    }
}

/// What a decision adapts with: the config (repair mode, refit mode), the refitter and the
/// counters it counts refits in.
pub(super) struct Adaptation<'a> {
    pub cfg: &'a NodeConfig,
    pub refitter: &'a mut Refitter,
    pub counters: &'a mut Counters,
}

/// What a multi-frame decision keeps of a frame: its log posteriors added to the stance's
/// sum, and (for the frame nearest the sample time) the checks' verdict for each class.
pub(super) struct FrameSums<'a> {
    pub sum_lp: &'a mut Vec<f64>,
    pub verdicts: Option<&'a mut Vec<Option<crate::unknown::Reason>>>,
}

/// Crop, repair and decision for one frame (the foot's `best`). Returns the decision and
/// whether any line was filled; `observe` feeds the frame to the stance history (once per
/// stance); `sums` (multi-frame) gets the decision's log posteriors and verdicts. With history
/// repair, a model refitted to the foot's current dead lines decides. An image without contact
/// is neither learned from nor repaired.
pub(super) fn classify(
    cls: &mut Classifier,
    foot: u8,
    f: &mut Foot,
    (rows, cols): (usize, usize),
    observe: bool,
    sums: Option<FrameSums<'_>>,
    ctx: Adaptation<'_>,
) -> Option<(Decision, bool)> {
    let Adaptation {
        cfg,
        refitter,
        counters,
    } = ctx;
    cls.prepare(&f.best[..f.best_len], rows, cols).ok()?;
    // Measured once here: the decisions below skip the check.
    if !cls.in_contact() {
        return Some((Decision::NO_CONTACT, false));
    }
    let add = |sums: Option<FrameSums<'_>>, c: &mut Classifier| {
        if let Some(s) = sums {
            for (a, b) in s.sum_lp.iter_mut().zip(c.log_posteriors()) {
                *a += b;
            }
            if let Some(v) = s.verdicts {
                c.verdicts_per_class(v);
            }
        }
    };
    let repaired = match cfg.repair {
        RepairMode::None => false,
        RepairMode::PerImage => cls.repair_work() > 0,
        RepairMode::History => {
            if observe {
                f.health.observe(cls.work_mut(), cfg.dead_after_stances);
                refitter.request(cfg.refit, foot, f, counters);
            }
            if let Some(a) = f.adapted.as_mut().filter(|a| a.fits(&f.health)) {
                a.cls.work_mut().copy_from_slice(cls.work_mut());
                let repaired = f.health.repair(a.cls.work_mut()) > 0;
                let d = a.cls.decide_in_contact();
                add(sums, &mut a.cls);
                return Some((d, repaired));
            }
            f.health.repair(cls.work_mut()) > 0
        }
    };
    let d = cls.decide_in_contact();
    add(sums, cls);
    Some((d, repaired))
}
