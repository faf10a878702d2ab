//! Unknown ground: every check that can call a stance "unknown", and the one place where the
//! verdict is made. Unknown ground sends the robot to its safe gait, so this is the robot's
//! safety feature.
//!
//! Each check is fitted on the training run and the calibration run (the next run of known
//! ground), judges one stance against its best terrain, and names itself as the [`Reason`]:
//!
//! | check | judges | fitted by |
//! |---|---|---|
//! | [`novelty`] | the image is unlike every known terrain | `train` (calibration) |
//! | load | the image's load lies outside its terrain's band | `train` (when chosen) |
//! | texture | the image's roughness lies outside its terrain's band | `train` (when chosen) |
//! | [`energy`] | the terrain took energy out of the last hop that it does not | `train` (a candidate, from the flights), `presrs lab energy` |
//!
//! A model carries them in one section, [`checks::Checks`] (model format 3; a version 2 file's
//! keys are moved there on load, with identical decisions), and every threshold is held by one
//! comparison, [`within_threshold`] (a figure that is not a number is unknown, never known).
//! The image checks' thresholds and bands are fitted with the model, in
//! [`crate::classifier::train`] (`calibrate`, `cross_fit`, `bands`); the energy check's return
//! maps here, in [`energy_fit`]; `train` chooses among them ([`crate::training::choice`]).
//! [`image_verdict`] judges a stance image (called by the classifier, so by the node's
//! single-frame and multi-frame paths, `classify`, `eval`, `capture`, replays and experiments
//! alike); [`step_verdict`] adds the energy check for a step. [`crate::training::choice`] is
//! how `train` decides which score and checks a model carries: by measurement on the lab's
//! own runs.
//!
//! The reason travels on the bus (TerrainClass `UnknownReason`, `FlagEnergy`), in the node's
//! statistics and in recordings, so a monitor can count unknowns per reason.
//!
//! What becomes of unknown ground: [`keep`] writes the stances off the node's thread,
//! [`discover`] groups them into proposed terrains, [`add`] makes one a terrain of the model.

pub mod add;
pub mod checks;
pub mod discover;
pub mod energy;
pub mod energy_fit;
pub mod keep;
pub mod lab_word;
pub mod novelty;

pub use protocol::messages::UnknownReason as Reason;
use serde::{Deserialize, Serialize};

/// The largest share of known-terrain images a model may be calibrated to call unknown
/// (`train --unknown-rate`): past it the rejection would discard more than it protects.
pub const MAX_UNKNOWN_RATE: f64 = 0.5;

/// The bands a model's image checks hold an image against, per class (`None`: no such check).
#[derive(Clone, Copy, Debug, Default)]
pub struct Bands<'a> {
    /// The load (summed working image before normalisation) per class.
    pub load: Option<&'a [[f64; 2]]>,
    /// The roughness per class.
    pub texture: Option<&'a [[f64; 2]]>,
}

/// What the classifier measured of one stance image against its best class `best`.
#[derive(Clone, Copy, Debug)]
pub struct Measured {
    /// The best class.
    pub best: usize,
    /// The image's novelty (or, for models without a novelty score, its negated log density).
    pub novelty: f64,
    /// The threshold the novelty is held against.
    pub threshold: f64,
    /// The image's load.
    pub load: f64,
}

/// The verdict on a stance image: `None` when every check calls it known ground, else the
/// first check that calls it unknown. The roughness is measured (`roughness()`) only for an
/// image every other check calls known: it is the dearest.
#[inline]
pub fn image_verdict(
    m: Measured,
    bands: Bands<'_>,
    roughness: impl FnOnce() -> f64,
) -> Option<Reason> {
    let inside = |b: Option<&[[f64; 2]]>, v: f64| {
        b.is_none_or(|b| b.get(m.best).is_some_and(|r| within(v, *r)))
    };
    if !within_threshold(m.novelty, m.threshold) {
        Some(Reason::Novelty)
    } else if !inside(bands.load, m.load) {
        Some(Reason::Load)
    } else if bands.texture.is_some() && !inside(bands.texture, roughness()) {
        Some(Reason::Texture)
    } else {
        None
    }
}

/// The one comparison every check makes: `value` at or below `threshold` is known ground; a
/// NaN on either side is not (a figure that could not be measured never passes).
#[inline]
pub fn within_threshold(value: f64, threshold: f64) -> bool {
    value.partial_cmp(&threshold).is_some_and(|o| o.is_le())
}

/// [`within_threshold`] for a band: `low <= value <= high`.
#[inline]
pub fn within(value: f64, [low, high]: [f64; 2]) -> bool {
    within_threshold(low, value) && within_threshold(value, high)
}

/// The verdict on a step decided from an image: the image's verdict, else the energy check's
/// (`energy_rejects`: the terrain's last stance under this foot took energy its map does not
/// allow).
#[inline]
pub fn step_verdict(image: Option<Reason>, energy_rejects: bool) -> Option<Reason> {
    image.or(energy_rejects.then_some(Reason::Energy))
}

/// How a model's unknown-ground checks were chosen, as its file keeps it (`unknown_choice`;
/// `crate::training::choice` measures it): candidates by their `--unknown-checks` list.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChoiceRecord {
    /// The kept candidate.
    pub chosen: String,
    /// `measured` (by leaving each terrain out), `fixed` (an expert's list) or why nothing
    /// was measured.
    pub how: String,
    /// The known-image budget.
    pub budget: f64,
    /// Per candidate: list, AUROC, share of left-out images found, share of known called
    /// unknown; a figure nothing measured is absent (`null`), never a number made up.
    #[serde(default)]
    pub table: Vec<ChoiceRow>,
}

/// One candidate of a [`ChoiceRecord`]: its list, AUROC, left-out found, known unknown.
pub type ChoiceRow = (String, Option<f64>, Option<f64>, Option<f64>);

/// Unknown steps per [`Reason`]: what a monitor counts (the node's statistics and logs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ReasonCounts(pub [u64; Reason::ALL.len()]);

impl ReasonCounts {
    /// Counts one step unknown for `reason`.
    #[inline]
    pub fn add(&mut self, reason: Reason) {
        self.0[reason as usize] += 1;
    }

    /// Steps counted for `reason`.
    pub fn get(&self, reason: Reason) -> u64 {
        self.0[reason as usize]
    }

    /// All steps counted.
    pub fn total(&self) -> u64 {
        self.0.iter().sum()
    }
}

/// `novelty 3, energy 1`: the reasons with a count, in [`Reason::ALL`]'s order; `none` when
/// there are none.
impl std::fmt::Display for ReasonCounts {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let mut first = true;
        for r in Reason::ALL {
            let n = self.get(r);
            if n > 0 {
                write!(f, "{}{} {n}", if first { "" } else { ", " }, r.name())?;
                first = false;
            }
        }
        if first {
            f.write_str("none")?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn measured(novelty: f64, load: f64) -> Measured {
        Measured {
            best: 1,
            novelty,
            threshold: 1.0,
            load,
        }
    }

    #[test]
    fn the_first_check_that_fails_names_the_reason() {
        let load = [[0.0, 1.0], [10.0, 20.0]];
        let tex = [[0.0, 1.0], [0.2, 0.4]];
        let bands = Bands {
            load: Some(&load),
            texture: Some(&tex),
        };
        assert_eq!(image_verdict(measured(0.5, 15.0), bands, || 0.3), None);
        assert_eq!(
            image_verdict(measured(1.5, 99.0), bands, || 9.0),
            Some(Reason::Novelty)
        );
        assert_eq!(
            image_verdict(measured(f64::NAN, 15.0), bands, || 0.3),
            Some(Reason::Novelty)
        );
        assert_eq!(
            image_verdict(measured(0.5, 99.0), bands, || 9.0),
            Some(Reason::Load)
        );
        assert_eq!(
            image_verdict(measured(0.5, 15.0), bands, || 9.0),
            Some(Reason::Texture)
        );
        assert_eq!(
            image_verdict(measured(0.5, 15.0), bands, || f64::NAN),
            Some(Reason::Texture)
        );
        // Without bands only the novelty decides, and the roughness is never measured.
        let none = Bands::default();
        assert_eq!(
            image_verdict(measured(0.5, 99.0), none, || unreachable!()),
            None
        );
    }

    #[test]
    fn counts_per_reason() {
        let mut c = ReasonCounts::default();
        assert_eq!(c.to_string(), "none");
        c.add(Reason::Novelty);
        c.add(Reason::Novelty);
        c.add(Reason::Energy);
        assert_eq!(c.to_string(), "novelty 2, energy 1");
        assert_eq!((c.get(Reason::Load), c.total()), (0, 3));
        // The index is the enum's order: ALL lists it.
        for (i, r) in Reason::ALL.into_iter().enumerate() {
            assert_eq!(r as usize, i);
        }
    }

    #[test]
    fn energy_counts_only_for_an_image_called_known() {
        assert_eq!(step_verdict(None, false), None);
        assert_eq!(step_verdict(None, true), Some(Reason::Energy));
        assert_eq!(step_verdict(Some(Reason::Load), true), Some(Reason::Load));
    }
}
