//! Which image counts for a step: the frame nearest the sample time (the paper's ~70 ms after
//! touchdown), decided as soon as no nearer frame can come; the window of the multi-frame rule;
//! and the deadline that decides a step whose next frame was lost.
//!
//! All times are the foot's own (µs, wrapping), measured from the touchdown (`dt`).

/// The time after touchdown the node samples at, and whose word it is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SampleTime {
    /// Ms after touchdown.
    pub ms: u32,
    /// Where it came from.
    pub source: SampleSource,
}

/// Whose sample time is in force: the config's wins (the lab set it), then the model's (`train`
/// measured it, or the lab pinned it there), then the paper's.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SampleSource {
    /// The config's `sample_ms`.
    Config,
    /// The model's `sample_ms`.
    Model,
    /// Neither names one: the paper's 70 ms.
    Default,
}

impl SampleTime {
    /// The time in force for a config's `sample_ms` and a model's.
    pub fn of(config: Option<u32>, model: Option<u32>) -> Self {
        let (ms, source) = match (config, model) {
            (Some(ms), _) => (ms, SampleSource::Config),
            (None, Some(ms)) => (ms, SampleSource::Model),
            (None, None) => (crate::config::DEFAULT_SAMPLE_MS, SampleSource::Default),
        };
        Self { ms, source }
    }
}

/// `70 ms after touchdown (the model's)`: what the node logs.
impl std::fmt::Display for SampleTime {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let whose = match self.source {
            SampleSource::Config => "the config's sample_ms, which wins over the model's",
            SampleSource::Model => "the model's",
            SampleSource::Default => "the paper's: neither the config nor the model names one",
        };
        write!(f, "{} ms after touchdown ({whose})", self.ms)
    }
}

/// An image `dt` after touchdown further than this is from before the touchdown (the foot
/// clock wrapped backwards across it) or from another stance: not this stance's.
pub(super) const FAR_US: u32 = 10_000_000;

/// A frame period the array can have (PreSRS runs at 100 Hz: 10 ms), from two images'
/// timestamps; `None` for a gap (frames lost) or a clock jump.
pub(super) fn plausible_period(p_us: u32) -> Option<u32> {
    (1_000..=50_000).contains(&p_us).then_some(p_us)
}

/// The single-frame rule keeps the image `dt` after touchdown as its best so far when it is
/// nearer the sample time than the best (`best_err`: the best's distance from it).
pub(super) fn nearer(dt: u32, sample_us: u32, best_err: Option<u32>) -> Option<u32> {
    let err = dt.abs_diff(sample_us);
    best_err.is_none_or(|e| err < e).then_some(err)
}

/// After the image `dt` after touchdown, the next can only be further from the sample time:
/// this one is at or past it, or (with a known frame period) less than half a period before
/// it. Waiting for the next frame would add a whole period to every decision's latency.
pub(super) fn nearest_is_final(dt: u32, sample_us: u32, period_us: Option<u32>) -> bool {
    dt >= sample_us || period_us.is_some_and(|p| dt + p / 2 >= sample_us)
}

/// The single-frame deadline: true when the foot's time (`dt` after touchdown, from the newest
/// timestamp heard from it) has passed the last time an image nearer the sample time than the
/// best could have been taken, plus `margin` (one frame period) for the transfer of an image
/// already captured. The array samples on a fixed period, so the last such image is the last
/// grid point (from the last image, `last_dt`) before the limit; without a known period, any
/// time before it. A frame lost right after the best would otherwise hold the decision until
/// liftoff (~200 ms later).
pub(super) fn deadline_passed(
    dt: u32,
    sample_us: u32,
    best_err: u32,
    last_dt: Option<u32>,
    period_us: Option<u32>,
    margin: u32,
) -> bool {
    let limit = sample_us.saturating_add(best_err);
    let last_nearer = match (period_us, last_dt) {
        (Some(p), Some(l)) if l < limit => l + (limit - 1 - l) / p * p,
        _ => limit,
    };
    dt >= last_nearer.saturating_add(margin)
}

/// The multi-frame rule: images from `window[0]` to `window[1]` after touchdown are summed.
pub(super) fn in_window(dt: u32, window_us: [u32; 2]) -> bool {
    dt >= window_us[0] && dt <= window_us[1]
}

#[cfg(test)]
mod tests {
    use super::*;

    const SAMPLE: u32 = 70_000;
    const PERIOD: u32 = 10_000;

    #[test]
    fn the_nearest_frame_is_kept_and_decided_without_waiting_for_the_next() {
        // Frames at 8, 18, ..., 68 ms: 68 is 2 ms before the sample time, the next (78) would
        // be 8 ms after: 68 is final at once.
        let mut best = None;
        for dt in (8_000..=68_000).step_by(PERIOD as usize) {
            if let Some(e) = nearer(dt, SAMPLE, best) {
                best = Some(e);
            }
            assert_eq!(
                nearest_is_final(dt, SAMPLE, Some(PERIOD)),
                dt == 68_000,
                "{dt}"
            );
        }
        assert_eq!(best, Some(2_000));
        // Frames at 4, 14, ..., 64: 64 is 6 ms before; 74 would be 4 ms after and nearer.
        assert!(!nearest_is_final(64_000, SAMPLE, Some(PERIOD)));
        assert_eq!(nearer(74_000, SAMPLE, Some(6_000)), Some(4_000));
        assert!(nearest_is_final(74_000, SAMPLE, Some(PERIOD)));
        // Without a known period: only at or past the sample time.
        assert!(!nearest_is_final(68_000, SAMPLE, None));
    }

    #[test]
    fn a_frame_further_than_the_best_is_not_kept() {
        assert_eq!(nearer(80_000, SAMPLE, Some(2_000)), None);
        // Equally far: the earlier one stays.
        assert_eq!(nearer(72_000, SAMPLE, Some(2_000)), None);
    }

    #[test]
    fn the_deadline_is_the_last_nearer_grid_point_plus_a_period() {
        // Best at 64 ms (6 ms early); frames at 64 and nothing since. A nearer image could have
        // been taken up to 76 ms; the last grid point before that is 74, and its transfer takes
        // up to a period: decided from 84 ms of foot time.
        let last = Some(64_000);
        assert!(!deadline_passed(
            83_999,
            SAMPLE,
            6_000,
            last,
            Some(PERIOD),
            PERIOD
        ));
        assert!(deadline_passed(
            84_000,
            SAMPLE,
            6_000,
            last,
            Some(PERIOD),
            PERIOD
        ));
        // Without a known period: the limit itself, plus the margin.
        assert!(!deadline_passed(85_999, SAMPLE, 6_000, last, None, PERIOD));
        assert!(deadline_passed(86_000, SAMPLE, 6_000, last, None, PERIOD));
    }

    #[test]
    fn a_late_frame_past_the_deadline_is_decided_at_once() {
        // The best was 1 ms after the sample time; the foot's clock is already far beyond.
        assert!(deadline_passed(
            150_000,
            SAMPLE,
            1_000,
            Some(71_000),
            Some(PERIOD),
            PERIOD
        ));
    }

    #[test]
    fn a_gap_is_no_frame_period() {
        assert_eq!(plausible_period(10_000), Some(10_000));
        assert_eq!(plausible_period(60_000), None, "frames lost");
        assert_eq!(plausible_period(0), None, "a repeated timestamp");
        assert_eq!(plausible_period(u32::MAX - 5), None, "the clock went back");
    }

    #[test]
    fn the_multi_frame_window_holds_its_ends() {
        let w = [40_000, 100_000];
        assert!(!in_window(39_999, w));
        assert!(in_window(40_000, w) && in_window(100_000, w));
        assert!(!in_window(100_001, w));
    }
}
