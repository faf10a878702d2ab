//! A model's unknown-ground checks, as its file keeps them (format 3's `unknown` section): the
//! rate they were calibrated to, the density rule, the novelty score and its thresholds, the
//! load and texture bands, the energy maps, and how `train` chose them. Everything that can
//! call a stance unknown is here, so that one reading of a model says what it rejects.
//!
//! Files of format 1 and 2 kept these as separate top-level keys (`unknown_threshold`,
//! `unknown_rate`, `unknown_thresholds`, `load_ranges`, `texture_ranges`, `novelty`,
//! `energy`, `unknown_choice`); [`upgrade_v2`] moves them here on loading, with the decisions
//! they had (`node/tests/fixtures/model-v2`, written by a format-2 build, checks it).

use serde::{Deserialize, Serialize};

use super::energy::ReturnMap;
use super::novelty::Novelty;
use super::{Bands, ChoiceRecord, MAX_UNKNOWN_RATE};

/// The unknown-ground checks of a model.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Checks {
    /// The share of known images the checks were calibrated to call unknown (`train
    /// --unknown-rate`); 0: the paper's classifier, which rejects almost nothing.
    pub rate: f64,
    /// Per class: the log density below which an image decided as that class is unknown (the
    /// rule of models without a novelty score).
    pub density_thresholds: Vec<f64>,
    /// The novelty score and its per-class thresholds ([`super::novelty`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub novelty: Option<Novelty>,
    /// Per class: the band of load (summed working image, before any normalisation) its known
    /// images show; outside its best class's band an image is unknown.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub load_bands: Option<Vec<[f64; 2]>>,
    /// Per class: the band of roughness ([`crate::classifier::texture::roughness`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub texture_bands: Option<Vec<[f64; 2]>>,
    /// Per class: the return map of the stance's energy balance ([`super::energy`]), `null`
    /// for a class without one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub energy: Option<Vec<Option<ReturnMap>>>,
    /// How `train` chose them, with the table it measured.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub choice: Option<ChoiceRecord>,
}

impl Checks {
    /// No check of a model of `n_classes` classes: the density rule at the least finite number
    /// (nothing is unknown) until training sets it.
    pub fn none(n_classes: usize) -> Self {
        Self {
            rate: 0.0,
            density_thresholds: vec![f64::MIN; n_classes],
            novelty: None,
            load_bands: None,
            texture_bands: None,
            energy: None,
            choice: None,
        }
    }

    /// The bands an image is held against.
    #[inline]
    pub fn bands(&self) -> Bands<'_> {
        Bands {
            load: self.load_bands.as_deref(),
            texture: self.texture_bands.as_deref(),
        }
    }

    /// The verdict on an image measured as `m` ([`super::image_verdict`] with this model's
    /// bands).
    #[inline]
    pub fn judge(
        &self,
        m: super::Measured,
        roughness: impl FnOnce() -> f64,
    ) -> Option<super::Reason> {
        super::image_verdict(m, self.bands(), roughness)
    }

    /// The lowest density threshold (what format 1 and 2 called `unknown_threshold`).
    pub fn lowest_density_threshold(&self) -> f64 {
        self.density_thresholds
            .iter()
            .copied()
            .fold(f64::INFINITY, f64::min)
    }

    /// Checks sizes and numbers against a model of `n_classes` classes, `n_features` features
    /// and `h` dimensions, whose working images have `pixels` pixels; the message names the key.
    pub fn validate(
        &self,
        n_classes: usize,
        n_features: usize,
        h: usize,
        pixels: usize,
    ) -> Result<(), (&'static str, String)> {
        if !(0.0..=MAX_UNKNOWN_RATE).contains(&self.rate) {
            return Err((
                "unknown.rate",
                format!("{} is not a share in 0..={MAX_UNKNOWN_RATE}", self.rate),
            ));
        }
        let t = &self.density_thresholds;
        if t.len() != n_classes {
            return Err((
                "unknown.density_thresholds",
                format!("{} thresholds for {n_classes} classes", t.len()),
            ));
        }
        // A NaN or +inf threshold would make every decision of its class unknown.
        if let Some(v) = t.iter().find(|v| v.is_nan() || **v == f64::INFINITY) {
            return Err((
                "unknown.density_thresholds",
                format!("a threshold of {v} would make every decision of its class unknown"),
            ));
        }
        for (key, bands) in [
            ("unknown.load_bands", &self.load_bands),
            ("unknown.texture_bands", &self.texture_bands),
        ] {
            if let Some(l) = bands
                && (l.len() != n_classes
                    || l.iter().any(|[a, b]| a.is_nan() || b.is_nan() || a > b))
            {
                return Err((
                    key,
                    format!("want one [low, high] pair per class ({n_classes}), low <= high"),
                ));
            }
        }
        if let Some(e) = &self.energy
            && (e.len() != n_classes || e.iter().flatten().any(|m| !m.is_valid()))
        {
            return Err((
                "unknown.energy",
                format!(
                    "want one return map (or null) per class ({n_classes}), finite, residual_s \
                     low <= high; fit it again with `presrs lab energy`"
                ),
            ));
        }
        if let Some(nv) = &self.novelty {
            validate_novelty(nv, n_classes, n_features, h, pixels)
                .map_err(|m| ("unknown.novelty", m))?;
        }
        Ok(())
    }
}

/// [`Checks::validate`] for the novelty score: its own figures, then what ties it to the
/// model's PCA and working images.
fn validate_novelty(
    nv: &Novelty,
    n_classes: usize,
    n_features: usize,
    h: usize,
    pixels: usize,
) -> Result<(), String> {
    nv.validate(n_classes).map_err(|e| e.0)?;
    if n_features == 0 || !nv.nuisance.len().is_multiple_of(n_features) {
        return Err(format!(
            "novelty.nuisance has {} values: not whole rows of {n_features} features",
            nv.nuisance.len()
        ));
    }
    if nv.nuisance.iter().any(|v| !v.is_finite()) {
        return Err("non-finite numbers in novelty.nuisance".into());
    }
    if nv.reference.len() != nv.reference_classes.len() * h {
        return Err(format!(
            "novelty.reference has {} values for {} images of h = {h}",
            nv.reference.len(),
            nv.reference_classes.len(),
        ));
    }
    if let Some(i) = nv.calibration.pixels.iter().position(|p| p.len() != pixels) {
        return Err(format!(
            "calibration image {i} has {} pixels, expected {pixels}",
            nv.calibration.pixels[i].len()
        ));
    }
    Ok(())
}

/// The keys of format 1 and 2 that [`Checks`] holds now.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Legacy {
    unknown_threshold: Option<f64>,
    #[serde(default)]
    unknown_rate: Option<f64>,
    #[serde(default)]
    unknown_thresholds: Option<Vec<f64>>,
    #[serde(default)]
    load_ranges: Option<Vec<[f64; 2]>>,
    #[serde(default)]
    texture_ranges: Option<Vec<[f64; 2]>>,
    #[serde(default)]
    novelty: Option<Novelty>,
    #[serde(default)]
    energy: Option<Vec<Option<ReturnMap>>>,
    #[serde(default)]
    unknown_choice: Option<ChoiceRecord>,
}

/// The top-level keys of format 1 and 2 that moved into `unknown`.
const LEGACY_KEYS: [&str; 8] = [
    "unknown_threshold",
    "unknown_rate",
    "unknown_thresholds",
    "load_ranges",
    "texture_ranges",
    "novelty",
    "energy",
    "unknown_choice",
];

/// A format 1 or 2 model's JSON object made format 3's: its unknown-ground keys moved into
/// `unknown`, with the decisions they made (a file without per-class thresholds held every
/// class to its one `unknown_threshold`; one without a rate was calibrated to none).
pub fn upgrade_v2(obj: &mut serde_json::Map<String, serde_json::Value>) -> Result<(), String> {
    let n_classes = obj
        .get("classes")
        .and_then(|c| c.as_array())
        .map_or(0, |c| c.len());
    let mut old = serde_json::Map::new();
    for k in LEGACY_KEYS {
        if let Some(v) = obj.remove(k) {
            old.insert(k.to_string(), v);
        }
    }
    let l: Legacy =
        serde_json::from_value(serde_json::Value::Object(old)).map_err(|e| e.to_string())?;
    // `unknown_threshold` was written as `null` when it was -inf (JSON has no infinity).
    let lowest = l.unknown_threshold.unwrap_or(f64::NEG_INFINITY);
    let checks = Checks {
        rate: l.unknown_rate.unwrap_or(0.0),
        density_thresholds: l
            .unknown_thresholds
            .unwrap_or_else(|| vec![lowest; n_classes]),
        novelty: l.novelty,
        load_bands: l.load_ranges,
        texture_bands: l.texture_ranges,
        energy: l.energy,
        choice: l.unknown_choice,
    };
    let v = serde_json::to_value(&checks).map_err(|e| e.to_string())?;
    obj.insert("unknown".into(), v);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_format_2_file_keeps_its_checks_and_one_without_per_class_thresholds_its_one() {
        let mut obj: serde_json::Map<String, serde_json::Value> = serde_json::from_str(
            r#"{"classes": [{}, {}], "unknown_threshold": -12.5, "unknown_rate": 0.02,
                "load_ranges": [[1.0, 2.0], [3.0, 4.0]], "other": 1}"#,
        )
        .unwrap();
        upgrade_v2(&mut obj).unwrap();
        let c: Checks = serde_json::from_value(obj["unknown"].clone()).unwrap();
        assert_eq!(c.density_thresholds, vec![-12.5, -12.5]);
        assert_eq!(
            (c.rate, c.load_bands.as_ref().unwrap()[1]),
            (0.02, [3.0, 4.0])
        );
        assert!(obj.contains_key("other") && !obj.contains_key("load_ranges"));
        assert!(c.validate(2, 10, 3, 100).is_ok());
        let mut bad = c.clone();
        bad.density_thresholds[1] = f64::NAN;
        assert_eq!(
            bad.validate(2, 10, 3, 100).unwrap_err().0,
            "unknown.density_thresholds"
        );
        bad = c;
        bad.rate = 0.9;
        assert_eq!(bad.validate(2, 10, 3, 100).unwrap_err().0, "unknown.rate");
    }
}
