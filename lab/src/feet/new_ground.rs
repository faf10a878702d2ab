//! The README's path past the third session: the stances the node kept as unknown there are
//! grouped (`presrs discover`), the new terrain is added (`--add`: the one new-ground group,
//! else the lab's word, `--stances` with the run's labels), and a fresh fourth session is
//! decided by the model before and after.

use std::path::Path;

use node::classifier::Model;
use node::classifier::model::ClassInfo;
use node::unknown::add::{add_group, add_stances};
use node::unknown::discover::{Grouping, discover_at, read_kept, touchdown_us};
use node::unknown::lab_word::LabWord;
use protocol::terrain::Terrain;

use super::FeetError;
use super::session::Session;

/// What grouping and adding did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Learned {
    /// The new terrain's steps in the third session the node kept as unknown.
    pub kept_new: usize,
    /// The proposed new-ground group holding the most of them: its size and how many of it
    /// are the new terrain (`None`: no group was proposed as new ground).
    pub group: Option<(usize, usize)>,
    /// How the terrain was added: `group`, `lab's word` (no single new-ground group), or why
    /// it could not be.
    pub added_by: String,
    /// The fourth session: the new terrain's steps and those decided as it by the added model.
    pub fresh_new: (usize, usize),
    /// Its known ground: steps, right by the model before, right after.
    pub fresh_known: (usize, usize, usize),
}

/// Groups the stances kept in `kept` (from `third`, whose new terrain is `new`), adds the
/// terrain to `model`; returns what it did and the model with the terrain (`None` when it
/// could not be added).
pub(super) fn learn(
    kept: &Path,
    third: &Session,
    model: &Model,
    new: Terrain,
    grouping: Grouping,
) -> Result<(Learned, Option<Model>), FeetError> {
    let io = |e: node::unknown::discover::DiscoverError| FeetError::Emulator(e.to_string());
    let mut l = Learned::default();
    let stances = match read_kept(kept) {
        Ok(s) => s,
        Err(e) => {
            l.added_by = format!("nothing kept: {e}");
            return Ok((l, None));
        }
    };
    // Each kept stance's true terrain, by its touchdown against the session's truth.
    let truth = |file: &str| {
        let td = touchdown_us(file)?;
        third
            .recordings
            .iter()
            .flat_map(|r| &r.truth)
            .filter(|t| t.1.abs_diff(td) <= 50_000)
            .min_by_key(|t| t.1.abs_diff(td))
            .map(|t| t.2)
    };
    let is_new: Vec<bool> = stances
        .iter()
        .map(|s| s.known.is_none() && truth(&s.file) == Some(new))
        .collect();
    l.kept_new = is_new.iter().filter(|&&n| n).count();
    let d = discover_at(model, &stances, grouping).map_err(io)?;
    l.group = d
        .new_ground()
        .map(|(_, g)| {
            let of_new = g.members.iter().filter(|&&i| is_new[i]).count();
            (g.members.len(), of_new)
        })
        .max_by_key(|g| g.1);
    let class = ClassInfo {
        name: new.name().to_string(),
        terrain_id: new.id(),
    };
    let added = match add_group(model, &d, &stances, &[], class.clone()) {
        Ok(a) => {
            l.added_by = "group".into();
            Some(a)
        }
        Err(_) => {
            // The lab's word: the run's labels, as `--stances run.csv` reads them.
            let ranges = third
                .recordings
                .iter()
                .flat_map(|r| &r.truth)
                .filter(|t| t.2 == new)
                .map(|t| (t.1.saturating_sub(20_000), t.1 + 20_000, Some(t.0)))
                .collect();
            let members = LabWord::Times(ranges).select(&stances);
            match add_stances(model, &stances, &members, class) {
                Ok(a) => {
                    l.added_by = "lab's word".into();
                    Some(a)
                }
                Err(e) => {
                    l.added_by = format!("not added: {e}");
                    None
                }
            }
        }
    };
    Ok((l, added.map(|a| a.model)))
}
