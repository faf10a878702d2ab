//! A replay's decisions held against the run's true terrain (`presrs node --replay LOG --truth
//! CSV`): per true terrain, how many steps the node decided right, called unknown or took for
//! another terrain; for ground the model does not know, unknown is the right answer.
//!
//! Why here: a lab's first question of a model on a new run is "how much known ground went to
//! the safe gait, and how much new ground was found", and the summary of a replay counts
//! unknowns by reason, not by truth. The labels are the capture's (`presrs capture --labels`,
//! `presrs demo --truth`): a step is the terrain of the range its touchdown falls in (on its
//! foot, or any foot's range).

use std::fmt;

use protocol::messages::{TERRAIN_UNKNOWN, TerrainClass};

use crate::capture::Labelling;

/// One true terrain's steps and what the node made of them.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TruthRow {
    /// The terrain's name.
    pub terrain: String,
    /// Its id.
    pub id: u8,
    /// The model knows it (else unknown is right).
    pub known: bool,
    /// Steps on it.
    pub steps: usize,
    /// Decided as it.
    pub right: usize,
    /// Called unknown.
    pub unknown: usize,
    /// Taken for another terrain.
    pub other: usize,
}

/// The tally over a replay; see the module docs.
#[derive(Clone, Debug)]
pub struct TruthTally {
    labels: Labelling,
    model_ids: Vec<u8>,
    /// Per true terrain, in the order first met.
    pub rows: Vec<TruthRow>,
    /// Steps whose touchdown falls in no range.
    pub outside: usize,
}

impl TruthTally {
    /// A tally for `labels` and a model of the terrains `model_ids`.
    pub fn new(labels: Labelling, model_ids: Vec<u8>) -> Self {
        Self {
            labels,
            model_ids,
            rows: Vec::new(),
            outside: 0,
        }
    }

    /// A tally for the labels file `path` (`start_s,end_s,terrain[,foot]`, as `capture
    /// --labels` reads it) in `catalog`, and a model of the terrains `model_ids`.
    pub fn from_file(
        path: &std::path::Path,
        catalog: &protocol::terrain::TerrainCatalog,
        model_ids: Vec<u8>,
    ) -> Result<Self, crate::capture::CaptureError> {
        let labels = Labelling::from_args(None, Some(path), catalog)?;
        Ok(Self::new(labels, model_ids))
    }

    /// One decided step of `foot`, touching down at `touchdown_us` (the log's clock).
    pub fn add(&mut self, foot: u8, touchdown_us: u64, class: &TerrainClass) {
        // Capture's own rule, at the touchdown alone: the range it falls in on this foot.
        let Ok(terrain) = self.labels.label(foot, touchdown_us, touchdown_us) else {
            self.outside += 1;
            return;
        };
        let id = terrain.id();
        let i = match self.rows.iter().position(|r| r.id == id) {
            Some(i) => i,
            None => {
                self.rows.push(TruthRow {
                    terrain: terrain.name().to_string(),
                    id,
                    known: self.model_ids.contains(&id),
                    steps: 0,
                    right: 0,
                    unknown: 0,
                    other: 0,
                });
                self.rows.len() - 1
            }
        };
        let r = &mut self.rows[i];
        r.steps += 1;
        match class.terrain {
            t if t == id => r.right += 1,
            TERRAIN_UNKNOWN => r.unknown += 1,
            _ => r.other += 1,
        }
    }

    /// Known ground's steps, and of them called unknown (what sent the robot to its safe gait).
    pub fn known_unknown(&self) -> (usize, usize) {
        let known = self.rows.iter().filter(|r| r.known);
        known.fold((0, 0), |(n, u), r| (n + r.steps, u + r.unknown))
    }

    /// New ground's steps, and of them called unknown (found).
    pub fn new_found(&self) -> (usize, usize) {
        let new = self.rows.iter().filter(|r| !r.known);
        new.fold((0, 0), |(n, u), r| (n + r.steps, u + r.unknown))
    }
}

/// The table `presrs node --replay --truth` prints.
impl fmt::Display for TruthTally {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let pct = |n: usize, of: usize| 100.0 * n as f64 / of.max(1) as f64;
        writeln!(f, "against the truth, per true terrain:")?;
        writeln!(
            f,
            "  {:<14} {:<5}  {:>5}  {:>5}  {:>7}  {:>13}",
            "terrain", "model", "steps", "right", "unknown", "other terrain"
        )?;
        for r in &self.rows {
            let right = match r.known {
                true => format!("{:.0}%", pct(r.right, r.steps)),
                false => "-".into(),
            };
            writeln!(
                f,
                "  {:<14} {:<5}  {:>5}  {right:>5}  {:>7}  {:>13}",
                r.terrain,
                if r.known { "knows" } else { "new" },
                r.steps,
                format!("{:.0}%", pct(r.unknown, r.steps)),
                format!("{:.0}%", pct(r.other, r.steps))
            )?;
        }
        let (kn, ku) = self.known_unknown();
        let (nn, nu) = self.new_found();
        write!(
            f,
            "known ground called unknown (the safe gait): {ku} of {kn} steps ({:.1}%)",
            pct(ku, kn)
        )?;
        if nn > 0 {
            write!(f, "; new ground found: {nu} of {nn} ({:.1}%)", pct(nu, nn))?;
        }
        if self.outside > 0 {
            write!(f, "; {} steps in no labelled range", self.outside)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use protocol::terrain::Terrain;

    fn class(terrain: u8) -> TerrainClass {
        TerrainClass {
            terrain,
            ..Default::default()
        }
    }

    /// Each step counts for the range its touchdown falls in; unknown on new ground is found,
    /// on known ground it is the safe gait; a step in no range is counted apart.
    #[test]
    fn steps_are_scored_against_the_range_their_touchdown_falls_in() {
        let range = |start_us, end_us, terrain, foot| crate::capture::LabelRange {
            start_us,
            end_us,
            terrain,
            foot,
        };
        let labels = vec![
            range(0, 100, Terrain::WOOD, None),
            range(100, 200, Terrain::SAND, Some(0)),
        ];
        let mut t = TruthTally::new(Labelling::Ranges(labels), vec![Terrain::WOOD.id()]);
        let wood = Terrain::WOOD.id();
        t.add(0, 10, &class(wood));
        t.add(0, 20, &class(TERRAIN_UNKNOWN));
        t.add(0, 30, &class(Terrain::SAND.id()));
        t.add(0, 150, &class(TERRAIN_UNKNOWN));
        t.add(0, 160, &class(wood));
        t.add(1, 150, &class(wood));
        assert_eq!(t.rows.len(), 2);
        let w = &t.rows[0];
        assert_eq!(
            (w.known, w.steps, w.right, w.unknown, w.other),
            (true, 3, 1, 1, 1)
        );
        let s = &t.rows[1];
        assert_eq!((s.known, s.steps, s.unknown, s.other), (false, 2, 1, 1));
        assert_eq!(t.known_unknown(), (3, 1));
        assert_eq!(t.new_found(), (2, 1));
        assert_eq!(t.outside, 1, "foot 1 has no range at 150");
        let text = t.to_string();
        assert!(text.contains("1 of 3 steps (33.3%)"), "{text}");
        assert!(text.contains("new ground found: 1 of 2"), "{text}");
    }
}
