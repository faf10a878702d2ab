//! Adaptation to a damaged sensor: the model refitted to a foot's dead sensor lines (see
//! [`crate::classifier::train::refit`]), inline or on a background thread; the per-frame
//! decision that uses it is [`super::classify`].

use std::sync::Arc;

use crossbeam_channel::{Receiver, Sender};

use super::{Counters, Foot};
use crate::classifier::train::{RefitError, refit};
use crate::classifier::{Classifier, Model};
use crate::config::RefitMode;
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
