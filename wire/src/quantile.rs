//! A running quantile of a stream of times, in constant memory and without allocation: the
//! runner's oversleep and the node's image lateness, each measured on the machine it runs on
//! instead of a constant tuned on ours.
//!
//! Each observation moves the estimate by a fixed step: down when the observation is below it,
//! up when above. It settles where `up / (up + down)` of the observations lie below it, and
//! follows a drift at `up` (or `down`) per observation.

/// A running quantile, with the steps that choose which one (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StepQuantile {
    value: i64,
    down: i64,
    up: i64,
}

impl StepQuantile {
    /// Starts at `initial`; `down` and `up` are the steps (their ratio chooses the quantile,
    /// their size how fast it follows and how much it jitters).
    pub const fn new(initial: i64, down: i64, up: i64) -> Self {
        Self {
            value: initial,
            down,
            up,
        }
    }

    /// One observation.
    pub fn observe(&mut self, x: i64) {
        if x < self.value {
            self.value -= self.down;
        } else if x > self.value {
            self.value += self.up;
        }
    }

    /// The estimate.
    pub fn get(&self) -> i64 {
        self.value
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn it_settles_at_the_quantile_its_steps_choose() {
        // 0..100 over and over: the eighth from below and from above.
        let (mut low, mut high) = (
            StepQuantile::new(500, 14, 2),
            StepQuantile::new(-500, 2, 14),
        );
        for i in 0..20_000i64 {
            let x = (i * 37) % 100;
            low.observe(x);
            high.observe(x);
        }
        assert!((5..=20).contains(&low.get()), "low {}", low.get());
        assert!((80..=95).contains(&high.get()), "high {}", high.get());
    }

    #[test]
    fn a_constant_stream_holds_it_still() {
        let mut q = StepQuantile::new(0, 14, 2);
        for _ in 0..10 {
            q.observe(0);
        }
        assert_eq!(q.get(), 0);
    }
}
