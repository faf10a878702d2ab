//! Ahead of the image that decides a step: which foot's step is decided soonest and when its
//! deciding image is due on the receiver's clock, so a live runner sleeps in batches until
//! then and wakes before it; and the warm-up that puts the model in cache for it
//! (docs/decisions/node-wake.md).

use super::{StancePipeline, sample};

impl StancePipeline {
    /// The foot whose step is decided soonest, and when the image that decides it is due on
    /// the receiver's clock (`stance/timing.rs`: the foot's images k periods ahead), soonest
    /// first. `Some((None, u64::MAX))` when no step is waiting for an image (every foot in the
    /// air or decided): the frames before a deciding image need no instant answer. `None`
    /// without a model, or while a foot waits for a decision whose image cannot be told (its
    /// frame period not known yet): any frame may decide. A live runner wakes before the
    /// deciding image instead of being woken by it, and takes the frames before it in batches
    /// ([`protocol::component::Component::expected_frame_us`]).
    pub fn next_decision(&self) -> Option<(Option<u8>, u64)> {
        self.classifier.as_ref()?;
        let sample_us = self.sample.ms * 1000;
        let w1 = self.cfg.window_ms[1] * 1000;
        let mut next: (Option<u8>, u64) = (None, u64::MAX);
        for (i, f) in self.feet.iter().enumerate() {
            if !f.switch.stance || f.decided {
                continue;
            }
            let last = f.clock.last_ts()?;
            let p = f.clock.period_us()?;
            let dt = last.wrapping_sub(f.touchdown_us);
            if dt > sample::FAR_US {
                continue; // the last image is from before the touchdown: not this stance's
            }
            // The first image from dt on that decides: single frame, the first at or past
            // half a period before the sample time (`nearest_is_final`); multi-frame, the
            // first at or past the window's end.
            let target = if self.cfg.multi_frame {
                w1
            } else {
                sample_us.saturating_sub(p / 2)
            };
            let k = target.saturating_sub(dt).div_ceil(p).max(1);
            let at = f.clock.due(k)?;
            if at < next.1 {
                next = (Some(i as u8), at);
            }
        }
        Some(next)
    }

    /// Runs the classifier the step of `foot` will be decided with on the foot's last kept
    /// image and drops the result: the model's matrices and samples, and the code that reads
    /// them, are in cache when the deciding image comes (a foot alone idles 10 ms between
    /// images: cold and warm decisions in docs/decisions/node-wake.md). The
    /// classifier's state is its scratch, written again by the next decision: nothing about
    /// the step changes.
    pub fn warm_up(&mut self, foot: u8) {
        let Some(cls) = self.classifier.as_mut() else {
            return;
        };
        let Some(f) = self.feet.get_mut(foot as usize) else {
            return;
        };
        if f.best_len == 0 {
            return;
        }
        let (rows, cols) = (cls.model().input_rows, cls.model().input_cols);
        let px = &f.best[..f.best_len];
        for c in std::iter::once(cls).chain(f.adapted.as_mut().map(|a| &mut a.cls)) {
            if c.prepare(px, rows, cols).is_ok() && c.in_contact() {
                let _ = c.decide_in_contact();
            }
        }
    }
}
