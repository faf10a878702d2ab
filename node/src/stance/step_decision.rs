//! A step's decision as the bus carries it: how the step ended (a terrain, no contact, no
//! sample), its flags, the multi-frame posterior, and how late the decision came.

use protocol::messages::{self, TerrainClass, flags};

/// How a step ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Outcome {
    /// Its image showed no foot on the ground (and no frame of the stance did).
    NoContact,
    /// No image inside the stance, or no model to decide with.
    NoSample,
    /// Decided from an image (a terrain, or unknown).
    Classified,
}

/// `no_contact`: an image of the stance showed no contact; `used`: frames the multi-frame
/// rule summed; `sampled`: the stance had an image to decide on.
pub(super) fn outcome(no_contact: bool, used: u32, sampled: bool, have_model: bool) -> Outcome {
    if no_contact && used == 0 {
        Outcome::NoContact
    } else if !sampled || !have_model {
        Outcome::NoSample
    } else {
        Outcome::Classified
    }
}

/// Sets `tc`'s flags for `outcome`: a classified step below `low_confidence` (0..1) is
/// LOW_CONFIDENCE, and REPAIRED when a dead line of its image was filled.
pub(super) fn set_flags(
    tc: &mut TerrainClass,
    outcome: Outcome,
    low_confidence: f64,
    repaired: bool,
) {
    match outcome {
        Outcome::NoContact => tc.flags |= flags::NO_CONTACT,
        Outcome::NoSample => tc.flags |= flags::NO_SAMPLE,
        Outcome::Classified => {
            if tc.confidence_pct < low_confidence * 100.0 {
                tc.flags |= flags::LOW_CONFIDENCE;
            }
            if repaired {
                tc.flags |= flags::REPAIRED;
            }
        }
    }
}

/// The multi-frame decision from summed log posteriors: the best class and its posterior,
/// percent (equal priors).
pub(super) fn combine(sum_lp: &[f64]) -> (usize, f64) {
    let best = (0..sum_lp.len()).fold(0, |b, k| if sum_lp[k] > sum_lp[b] { k } else { b });
    let mx = sum_lp.get(best).copied().unwrap_or(0.0);
    let z: f64 = sum_lp.iter().map(|lp| (lp - mx).exp()).sum();
    (best, 100.0 / z)
}

/// From the receipt of the sampled frame (`sampled_rx_us`) to the decision (`now_us`),
/// saturated as the CAN field is; 0 when no frame was sampled (flag NO_SAMPLE), so that a log
/// and the bus say the same.
pub(super) fn latency_us(tc: &TerrainClass, now_us: u64, sampled_rx_us: u64) -> u32 {
    if tc.flags & flags::NO_SAMPLE != 0 {
        0
    } else {
        now_us
            .saturating_sub(sampled_rx_us)
            .min(messages::LATENCY_MAX_US as u64) as u32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tc(confidence_pct: f64) -> TerrainClass {
        TerrainClass {
            step: 1,
            terrain: 3,
            confidence_pct,
            damage_pct: 0.0,
            flags: 0,
            latency_us: 0,
        }
    }

    #[test]
    fn no_contact_wins_over_no_sample_and_neither_is_a_terrain() {
        assert_eq!(outcome(true, 0, true, true), Outcome::NoContact);
        assert_eq!(outcome(true, 0, false, true), Outcome::NoContact);
        // A multi-frame stance with frames in contact: decided on those.
        assert_eq!(outcome(true, 2, true, true), Outcome::Classified);
        assert_eq!(outcome(false, 0, false, true), Outcome::NoSample);
        assert_eq!(
            outcome(false, 0, true, false),
            Outcome::NoSample,
            "no model"
        );
        let mut t = tc(90.0);
        set_flags(&mut t, Outcome::NoContact, 0.5, true);
        assert_eq!(t.flags, flags::NO_CONTACT, "no REPAIRED without a terrain");
    }

    #[test]
    fn a_classified_step_says_low_confidence_and_repair() {
        let mut t = tc(40.0);
        set_flags(&mut t, Outcome::Classified, 0.5, true);
        assert_eq!(t.flags, flags::LOW_CONFIDENCE | flags::REPAIRED);
        let mut t = tc(60.0);
        set_flags(&mut t, Outcome::Classified, 0.5, false);
        assert_eq!(t.flags, 0);
    }

    #[test]
    fn multi_frame_posteriors_combine_with_equal_priors() {
        let (best, pct) = combine(&[-3.0, -1.0, -1.0 - 2f64.ln()]);
        assert_eq!(best, 1);
        // exp(0) / (exp(-2) + 1 + 0.5)
        assert!((pct - 100.0 / (1.5 + (-2f64).exp())).abs() < 1e-9, "{pct}");
    }

    #[test]
    fn latency_is_zero_without_a_sample_and_saturates() {
        let mut t = tc(90.0);
        assert_eq!(latency_us(&t, 5_000, 2_000), 3_000);
        assert_eq!(latency_us(&t, 1_000, 2_000), 0, "a clock behind the frame");
        assert_eq!(latency_us(&t, u64::MAX, 0), messages::LATENCY_MAX_US);
        t.flags |= flags::NO_SAMPLE;
        assert_eq!(latency_us(&t, 5_000, 2_000), 0);
    }
}
