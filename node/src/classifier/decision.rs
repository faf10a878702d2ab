//! The outcome of classifying one image: the terrain (or why it is unknown), the best class,
//! its confidence and the novelty score against its threshold; printed by `presrs lab classify`.

use crate::unknown::Reason;

/// The outcome for one image.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Decision {
    /// The class, or `None` when the image is unknown ground (see `reason`) or shows no contact.
    pub class: Option<usize>,
    /// The most probable class, known or not.
    pub best: usize,
    /// Terrain id of `class` (0xFF when unknown).
    pub terrain_id: u8,
    /// Posterior of the best class (equal priors), 0..=1.
    pub confidence: f64,
    /// Log Parzen density of the best class (-inf without contact).
    pub log_density: f64,
    /// The image shows a foot on the ground (see [`MinContact`](super::model::MinContact)).
    /// Without contact nothing else was computed: the decision is unknown, confidence 0, and no
    /// class is "best".
    pub contact: bool,
    /// How unlike any known terrain the image is, larger = less like (see
    /// [`crate::unknown::novelty`]); for a model without a novelty score, the negated log density.
    /// +inf without contact.
    pub novelty: f64,
    /// The best class's threshold the novelty was held against: above it, unknown. (For a
    /// model without a novelty score, the negated density threshold.)
    pub threshold: f64,
    /// Which check called the image unknown ([`crate::unknown::image_verdict`]); `None` for a
    /// terrain and for an image without contact.
    pub reason: Option<Reason>,
}

impl Decision {
    /// The decision for an image without contact: unknown, confidence 0.
    pub const NO_CONTACT: Decision = Decision {
        class: None,
        best: 0,
        terrain_id: protocol::messages::TERRAIN_UNKNOWN,
        confidence: 0.0,
        log_density: f64::NEG_INFINITY,
        contact: false,
        novelty: f64::INFINITY,
        threshold: f64::INFINITY,
        reason: None,
    };

    /// What to call this decision among the model's class `names`: the class, `unknown`, or
    /// `unknown (no contact)` for an image without contact, which is no terrain whatever it
    /// lies nearest.
    pub fn label<'a>(&self, names: &'a [String]) -> &'a str {
        match self.class {
            _ if !self.contact => "unknown (no contact)",
            Some(k) => names.get(k).map_or("unknown", String::as_str),
            None => "unknown",
        }
    }

    /// The decision as `presrs lab classify --json` prints it: `file`, `terrain` ([`Self::label`]),
    /// `contact`, `best` (the nearest class, also when unknown), `confidence`, `novelty` and
    /// `threshold` (null without contact: JSON has no infinity), so that anyone can draw the
    /// novelty's ROC on their own images.
    pub fn to_json(&self, file: &str, names: &[String]) -> serde_json::Value {
        let num = |v: f64| v.is_finite().then_some(v);
        serde_json::json!({
            "file": file,
            "terrain": self.label(names),
            "contact": self.contact,
            "best": self.contact.then(|| names.get(self.best).map(String::as_str)).flatten(),
            "confidence": self.confidence,
            "novelty": num(self.novelty),
            "threshold": num(self.threshold),
            "reason": self.reason.map(Reason::name),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_decision_without_contact_is_no_terrain_whatever_it_lies_nearest() {
        let names = vec!["wood".to_string(), "carpet".to_string()];
        let mut d = Decision::NO_CONTACT;
        d.class = Some(1);
        assert_eq!(d.label(&names), "unknown (no contact)");
        d.contact = true;
        assert_eq!(d.label(&names), "carpet");
        d.class = None;
        assert_eq!(d.label(&names), "unknown");
        d.class = Some(7);
        assert_eq!(d.label(&names), "unknown");
    }

    #[test]
    fn the_json_report_gives_the_score_and_its_threshold_or_null() {
        let names = vec!["wood".to_string(), "carpet".to_string()];
        let v = Decision::NO_CONTACT.to_json("a.pgm", &names);
        assert_eq!(v["terrain"], "unknown (no contact)");
        assert!(v["best"].is_null() && v["novelty"].is_null() && v["threshold"].is_null());
        let d = Decision {
            class: None,
            best: 1,
            contact: true,
            confidence: 0.75,
            novelty: 1.5,
            threshold: 1.1,
            ..Decision::NO_CONTACT
        };
        let v = d.to_json("b.pgm#2", &names);
        assert_eq!(v["file"], "b.pgm#2");
        assert_eq!(v["terrain"], "unknown");
        assert_eq!(v["best"], "carpet");
        assert_eq!(
            (v["novelty"].as_f64(), v["threshold"].as_f64()),
            (Some(1.5), Some(1.1))
        );
    }
}
