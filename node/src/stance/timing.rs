//! When a foot's images come: the frame period on the foot's clock (which image is the
//! nearest to the sample time) and on the receiver's (when the next image will be received,
//! so a live runner can wake before the image that decides a step instead of being woken by
//! it; docs/decisions/node-wake.md).
//!
//! The two clocks are kept apart: the foot's period is robot time, which runs slower than the
//! receiver's under emulation (the simulator at 0.35), so the receiver's gap between two
//! images is measured on the receiver's clock.

use super::sample;
use protocol::quantile::StepQuantile;

/// One foot's image timing.
#[derive(Debug, Clone)]
pub(super) struct ImageClock {
    /// The foot's timestamp of its last image (µs, wrapping).
    last_ts: Option<u32>,
    /// The foot's frame period, from two consecutive images' timestamps.
    period_us: Option<u32>,
    /// The receive time of the last image (the receiver's clock, µs).
    last_rx_us: u64,
    /// The gap between two consecutive images' receipts, smoothed.
    rx_period_us: Option<u32>,
    /// The last image's receipt on the grid of the earliest receipts.
    grid_rx_us: u64,
    /// How late images come after the grid's due time (µs): a low quantile, measured on every
    /// image, so the runner polls where this foot's images come (see `LATE_STEPS`).
    late_us: StepQuantile,
}

impl Default for ImageClock {
    fn default() -> Self {
        Self {
            last_ts: None,
            period_us: None,
            last_rx_us: 0,
            rx_period_us: None,
            grid_rx_us: 0,
            late_us: StepQuantile::new(0, LATE_STEPS.0, LATE_STEPS.1),
        }
    }
}

/// The lateness quantile's steps, µs (down, up): it settles where one image in eight comes
/// earlier (the runner polls from a little before the time), and follows a few hundred µs
/// within about two seconds of images. A grid whose smoothed gap is a few µs short lags the
/// receipts by sixteen times that (docs/decisions/node-wake.md, "Second stop").
const LATE_STEPS: (i64, i64) = (14, 2);

impl ImageClock {
    /// A new image, taken at `ts` on the foot's clock and received at `rx_us`.
    pub(super) fn on_image(&mut self, ts: u32, rx_us: u64) {
        if let Some(last) = self.last_ts {
            let gap = sample::plausible_period(ts.wrapping_sub(last));
            // Consecutive images (no frame lost between them): their receipts' gap, smoothed.
            if gap.is_some() && gap == self.period_us {
                if let Some(p) = self.rx_period_us {
                    let due = self.grid_rx_us + u64::from(p);
                    self.late_us.observe(rx_us as i64 - due as i64);
                }
                let d = rx_us.saturating_sub(self.last_rx_us);
                if let Some(d) = u32::try_from(d).ok().and_then(sample::plausible_period) {
                    self.rx_period_us = Some(self.rx_period_us.map_or(d, |p| (7 * p + d) / 8));
                }
                // A receipt is only ever late (a sender or a bus that held it), so the grid
                // follows the earliest receipts, and a later one only by a sixteenth (a clock
                // that drifts): a late last image does not make the next one look late.
                let due = self.rx_period_us.map(|p| self.grid_rx_us + u64::from(p));
                self.grid_rx_us = match due {
                    Some(due) if rx_us > due => due + (rx_us - due) / 16,
                    _ => rx_us,
                };
            } else {
                self.grid_rx_us = rx_us;
            }
            self.period_us = gap.or(self.period_us);
        }
        self.last_ts = Some(ts);
        self.last_rx_us = rx_us;
    }

    /// The foot's timestamp of its last image.
    pub(super) fn last_ts(&self) -> Option<u32> {
        self.last_ts
    }

    /// The foot's frame period, once two consecutive images showed it.
    pub(super) fn period_us(&self) -> Option<u32> {
        self.period_us
    }

    /// When the image `k` periods after the last is due on the receiver's clock (the grid's
    /// time plus the measured lateness); `None` until both periods are known.
    pub(super) fn due(&self, k: u32) -> Option<u64> {
        let rx_p = u64::from(self.rx_period_us?);
        self.period_us?;
        let grid = self.grid_rx_us + u64::from(k) * rx_p;
        Some(grid.saturating_add_signed(self.late_us.get()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Images every 10 ms of the foot's clock, received every `rx_gap` µs with `late[i]` µs of
    /// delay on top.
    fn feed(c: &mut ImageClock, rx_gap: u64, late: &[u64]) {
        for (i, l) in late.iter().enumerate() {
            c.on_image(10_000 * i as u32, 1_000_000 + rx_gap * i as u64 + l);
        }
    }

    #[test]
    fn the_next_image_is_due_one_receipt_gap_after_the_last() {
        let mut c = ImageClock::default();
        assert_eq!(c.due(1), None, "no period yet");
        // Robot time at a third of the receiver's: the receipts are 30 ms apart.
        feed(&mut c, 30_000, &[0; 6]);
        assert_eq!(c.period_us(), Some(10_000));
        assert_eq!(c.due(1), Some(1_000_000 + 6 * 30_000));
        assert_eq!(c.due(3), Some(1_000_000 + 8 * 30_000));
    }

    #[test]
    fn a_late_image_does_not_make_the_next_one_look_late() {
        let mut c = ImageClock::default();
        feed(&mut c, 10_000, &[0, 0, 0, 0, 0, 800]);
        let at = c.due(1).unwrap_or_default();
        // The smoothed gap took an eighth of the 800 us (100), the grid a sixteenth of what
        // was left; from the late receipt itself it would be 1_060_900.
        assert!(at <= 1_060_000 + 100 + 150, "due at {at}");
        assert!(at >= 1_060_000, "due at {at}");
    }

    #[test]
    fn images_that_come_steadily_after_the_grid_are_expected_when_they_come() {
        // Receipts 10_003 us apart with the smoothed gap a few us short: the grid lags them.
        let mut c = ImageClock::default();
        for i in 0..400u32 {
            let rx = 1_000_000 + 10_003 * u64::from(i) + [0, 40, 10, 25][i as usize % 4];
            c.on_image(10_000 * i, rx);
        }
        let at = c.due(1).unwrap_or_default();
        let truth = 1_000_000 + 10_003 * 400;
        // One image in eight earlier than `at`: within the spread of the last receipts.
        assert!(
            at >= truth - 10 && at <= truth + 40,
            "due at {at}, images at {truth}+0..40"
        );
    }

    #[test]
    fn a_lost_image_restarts_the_grid_at_the_next_receipt() {
        let mut c = ImageClock::default();
        for i in [0u32, 1, 2, 4] {
            c.on_image(10_000 * i, 1_000_000 + 10_000 * u64::from(i) + 300);
        }
        let at = c.due(1).unwrap_or_default();
        assert_eq!(at, 1_040_300 + 10_000);
    }
}
