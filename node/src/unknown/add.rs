//! A proposed group made a terrain of the model (`presrs discover --add NAME`), the way of
//! fitting it chosen by measurement on the lab's own run.
//!
//! Four candidates: the PCA subspace extended by the new terrain's directions or fitted
//! again ([`Basis`]), each without or with the run's own known stances (the keep's
//! `session/`, labelled by the running model at 90% or more) stored as samples of their
//! terrains: the new terrain's stances all come from this run, and without known ground
//! from the same run, what the run shares with them (its load, its sensor, its day) is taken
//! for the new terrain's signature and draws known ground to it. Each is scored on what the lab cares about: of the run's known stances it was
//! not calibrated on (every other one of each terrain), the share still decided as the
//! running model decided them, plus the share of the new terrain's stored stances decided as
//! the new terrain with each left out. The best sum wins; on a tie the one that has seen the
//! run's known ground (the held-out half is small, so ties are common), then `extend`, the
//! one that changes least. A keep without known stances (written before they were kept)
//! scores the known terrains on their stored stances instead.
//!
//! Why measured and not fixed: on the simulator's leave-one-terrain-out runs no candidate
//! kept the known terrains best on every seed (docs/decisions/discover-grouping.md).

use std::path::Path;

use protocol::terrain::{TerrainCatalog, append_entry};

use crate::classifier::model::ClassInfo;
use crate::classifier::train::{Basis, ToldApart, add_class, told_apart};
use crate::classifier::{Classifier, Model, PressureImage};

use super::discover::{DiscoverError, Discovery, KeptStance};

/// One way of adding the terrain, and how it scored.
#[derive(Clone, Debug, PartialEq)]
pub struct Candidate {
    /// How the subspace took the terrain in.
    pub basis: Basis,
    /// The run's known stances stored as samples too.
    pub session: bool,
    /// The run's held-out known stances decided as before, and how many there were
    /// (`None` without any: the stored stances scored instead, in `stored_known`).
    pub known_kept: Option<(usize, usize)>,
    /// The known terrains' stored stances decided right with each left out, and how many.
    pub stored_known: (usize, usize),
    /// The new terrain's stored stances decided as it with each left out, and how many.
    pub new_right: (usize, usize),
}

impl Candidate {
    /// The score: the known share (held-out run stances, else stored) plus the new share.
    pub fn score(&self) -> f64 {
        let share = |(a, n): (usize, usize)| a as f64 / n.max(1) as f64;
        share(self.known_kept.unwrap_or(self.stored_known)) + share(self.new_right)
    }

    /// Its name in the table: `extend`, `refit+session`, ...
    pub fn name(&self) -> String {
        format!(
            "{}{}",
            self.basis.name(),
            if self.session { "+session" } else { "" }
        )
    }
}

/// A proposed group made a terrain of the model ([`add_group`]).
pub struct Added {
    /// The model with the terrain added.
    pub model: Model,
    /// The groups' indices in the [`Discovery`] (more than one: a ground the split parted).
    pub groups: Vec<usize>,
    /// The run's known stances the keep holds (its `session/`).
    pub session_refs: usize,
    /// The candidates measured, and which was chosen.
    pub candidates: Vec<Candidate>,
    /// The index of the chosen one.
    pub chosen: usize,
    /// Each class of the model before, its stored stances decided each without itself.
    pub before: Vec<ToldApart>,
    /// The same for the model with the terrain added (the new terrain last).
    pub after: Vec<ToldApart>,
}

/// The most a known terrain's share decided right may fall when a terrain is added before the
/// add is called a loss: beyond counting noise on the few stances a model stores (one of 20 is
/// 5 points), and far beyond what the add costs where it works (docs/decisions/discover-grouping.md).
pub const MAX_KNOWN_DROP: f64 = 0.10;

/// A known terrain the add takes ground from: its share decided right before and after.
#[derive(Clone, Debug, PartialEq)]
pub struct KnownLoss {
    /// The terrain.
    pub terrain: String,
    /// Its stored stances decided right (each without itself) before the add, 0..1.
    pub before: f64,
    /// The same after.
    pub after: f64,
}

impl Added {
    /// The known terrains whose share decided right fell by more than [`MAX_KNOWN_DROP`]:
    /// the new terrain takes their ground, and the model should not be deployed as it is.
    pub fn known_losses(&self) -> Vec<KnownLoss> {
        let names: Vec<&str> = self.model.classes.iter().map(|c| c.name.as_str()).collect();
        losses(&self.before, &self.after, &names)
    }
}

/// [`Added::known_losses`] from the told-apart counts before and after, in class order.
fn losses(before: &[ToldApart], after: &[ToldApart], names: &[&str]) -> Vec<KnownLoss> {
    let share = |t: &ToldApart| t.right as f64 / t.stances.max(1) as f64;
    before
        .iter()
        .zip(after)
        .zip(names)
        .filter(|((b, a), _)| b.stances > 0 && a.stances > 0)
        .map(|((b, a), name)| KnownLoss {
            terrain: name.to_string(),
            before: share(b),
            after: share(a),
        })
        .filter(|l| l.before - l.after > MAX_KNOWN_DROP)
        .collect()
}

/// `model` with groups `groups` of `d` (indices; none: the one new-ground group) added as one
/// terrain `terrain` (its name and id from the lab's catalog). See the module docs.
pub fn add_group(
    model: &Model,
    d: &Discovery,
    stances: &[KeptStance],
    groups: &[usize],
    terrain: ClassInfo,
) -> Result<Added, DiscoverError> {
    let groups = pick(d, groups)?;
    let members: Vec<usize> = groups
        .iter()
        .flat_map(|&g| d.groups[g].members.iter().copied())
        .collect();
    let mut a = add_stances(model, stances, &members, terrain)?;
    a.groups = groups;
    Ok(a)
}

/// `model` with the kept stances `members` (indices into `stances`) added as terrain
/// `terrain`: a group's, or those the lab names ([`super::lab_word`]). See the module docs.
pub fn add_stances(
    model: &Model,
    stances: &[KeptStance],
    members: &[usize],
    terrain: ClassInfo,
) -> Result<Added, DiscoverError> {
    let add = |m: String| DiscoverError::Add(m);
    let images: Vec<PressureImage> = members
        .iter()
        .filter_map(|&i| stances.get(i).map(|s| s.image.clone()))
        .collect();
    if images.len() < super::discover::MIN_GROUP {
        return Err(add(format!(
            "{} stances to add; a terrain needs at least {}",
            images.len(),
            super::discover::MIN_GROUP
        )));
    }
    // The run's known stances of terrains the model has, every other one of each terrain to
    // calibrate on and the rest to score with.
    let mut seen = vec![0usize; model.classes.len()];
    let (mut calibrate, mut check, mut all) = (Vec::new(), Vec::new(), Vec::new());
    for s in stances {
        let Some(name) = s.known.as_deref() else {
            continue;
        };
        let Some(k) = model.classes.iter().position(|c| c.name == name) else {
            continue;
        };
        all.push((&s.image, k));
        if seen[k].is_multiple_of(2) {
            calibrate.push((&s.image, k));
        } else {
            check.push((&s.image, k));
        }
        seen[k] += 1;
    }
    let fit = |session: &[(&PressureImage, usize)], basis| {
        add_class(model, terrain.clone(), &images, session, basis).map_err(|e| add(e.to_string()))
    };
    let mut candidates = Vec::new();
    // The run's own known ground first: on a tie, the model that has seen this run.
    for basis in [Basis::Extend, Basis::Refit] {
        if !calibrate.is_empty() {
            candidates.push(score(&fit(&calibrate, basis)?, basis, true, &check));
        }
        candidates.push(score(&fit(&[], basis)?, basis, false, &check));
    }
    let mut chosen = 0;
    for (i, c) in candidates.iter().enumerate() {
        if c.score() > candidates[chosen].score() + 1e-9 {
            chosen = i;
        }
    }
    let pick = &candidates[chosen];
    // With all of the run's known stances for the model that goes to the robot.
    let m = fit(if pick.session { &all } else { &[] }, pick.basis)?;
    Ok(Added {
        session_refs: all.len(),
        before: told_apart(model),
        after: told_apart(&m),
        model: m,
        groups: Vec::new(),
        candidates,
        chosen,
    })
}

/// The terrain `--add NAME` makes: the catalog's own (its id) when the node's terrains file
/// (`terrains`; the paper's catalog without one, or before it is made) has the name, else
/// the next free lab id, for a new entry in `terrains`.
#[derive(Clone, Debug, PartialEq)]
pub struct NewTerrain {
    /// Its name and id.
    pub class: ClassInfo,
    /// The catalog has it already: no entry to write.
    pub in_catalog: bool,
}

/// [`NewTerrain`] for `name`; an error names `--terrains` when an entry is needed and there is
/// no file to write it to.
pub fn new_terrain(name: &str, terrains: Option<&Path>) -> Result<NewTerrain, DiscoverError> {
    let add = |m: String| DiscoverError::Add(m);
    let catalog = TerrainCatalog::load(terrains.filter(|p| p.exists()))
        .map_err(|e| add(format!("--terrains: {e}")))?;
    if let Some(t) = catalog.by_name(name) {
        return Ok(NewTerrain {
            class: ClassInfo {
                name: name.into(),
                terrain_id: t.id(),
            },
            in_catalog: true,
        });
    }
    if terrains.is_none() {
        return Err(add(format!(
            "--add {name}: the catalog has no `{name}`; give --terrains FILE (the node's \
             terrains file, made if missing) for its entry"
        )));
    }
    let id = catalog
        .free_id()
        .ok_or_else(|| add("--terrains: every terrain id is taken".into()))?;
    Ok(NewTerrain {
        class: ClassInfo {
            name: name.into(),
            terrain_id: id,
        },
        in_catalog: false,
    })
}

/// Writes `a`'s model to `out` (read back: a file every command loads) and, for a terrain the
/// catalog lacks, its entry in `terrains`; when the entry cannot be written the model is
/// removed again (it would name a terrain no catalog has).
pub fn write_added(
    a: &Added,
    t: &NewTerrain,
    out: &Path,
    terrains: Option<&Path>,
) -> Result<(), DiscoverError> {
    let add = |m: String| DiscoverError::Add(m);
    a.model
        .save(out)
        .map_err(|e| add(format!("--out-model: {e}")))?;
    Model::load(out)
        .map_err(|e| add(format!("--out-model: reading the written model back: {e}")))?;
    if let (false, Some(path)) = (t.in_catalog, terrains)
        && let Err(e) = append_entry(path, t.class.terrain_id, &t.class.name)
    {
        let _ = std::fs::remove_file(out);
        return Err(add(format!("--terrains (the model was not written): {e}")));
    }
    Ok(())
}

/// The groups to add: `groups` if each is one (once), else the one new-ground group.
fn pick(d: &Discovery, groups: &[usize]) -> Result<Vec<usize>, DiscoverError> {
    let add = |m: String| DiscoverError::Add(m);
    for (i, &g) in groups.iter().enumerate() {
        if g >= d.groups.len() {
            return Err(add(format!(
                "--group {}: there are {} groups; pick from the table",
                g + 1,
                d.groups.len()
            )));
        }
        if groups[..i].contains(&g) {
            return Err(add(format!("--group {} is given twice", g + 1)));
        }
    }
    if !groups.is_empty() {
        return Ok(groups.to_vec());
    }
    let new: Vec<usize> = d.new_ground().map(|(g, _)| g).collect();
    match new[..] {
        [g] => Ok(vec![g]),
        [] if d.groups.is_empty() => Err(add(
            "no group was formed of the kept stances: say which were the new ground with \
             --stances (step ranges like 12-40, a labels CSV of the run, or a file of kept.csv's \
             names)"
                .into(),
        )),
        [] => Err(add(format!(
            "no group is new ground: a group the table calls known ground can still be added \
             with --group N (1-{}), or say which stances were the new ground with --stances \
             (step ranges like 12-40, a labels CSV of the run, or a file of kept.csv's names)",
            d.groups.len()
        ))),
        _ => Err(add(format!(
            "{} groups are new ground: say which with --group N (or N,M for one ground in \
             several groups: the contact sheets show which look alike)",
            new.len()
        ))),
    }
}

/// Candidate `m`'s scores (see the module docs).
fn score(m: &Model, basis: Basis, session: bool, check: &[(&PressureImage, usize)]) -> Candidate {
    let told = told_apart(m);
    let k_new = m.classes.len() - 1;
    let stored_known = told[..k_new.min(told.len())]
        .iter()
        .fold((0, 0), |(a, n), t| (a + t.right, n + t.stances));
    let new_right = told.get(k_new).map_or((0, 0), |t| (t.right, t.stances));
    let known_kept = (!check.is_empty()).then(|| {
        let mut c = Classifier::new(m.clone());
        let kept = check
            .iter()
            .filter(|(img, k)| {
                c.classify_image(img, false)
                    .is_ok_and(|d| d.class == Some(*k))
            })
            .count();
        (kept, check.len())
    });
    Candidate {
        basis,
        session,
        known_kept,
        stored_known,
        new_right,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::unknown::discover::Group;

    fn discovery(new: &[bool]) -> Discovery {
        let group = |new_ground| Group {
            members: vec![],
            spread: 1.0,
            to_known: 2.0,
            separation: 2.0,
            nearest_class: 0,
            new_ground,
            settling: false,
        };
        Discovery {
            min_separation: 1.5,
            least_separated: 0,
            neighbour_link: 1.0,
            groups: new.iter().map(|&n| group(n)).collect(),
            group_of: vec![],
            no_contact: vec![],
        }
    }

    /// A known terrain that falls more than ten points is a loss; one within it, one without
    /// stored stances, and the new terrain (no "before") are not.
    #[test]
    fn a_known_terrain_that_falls_more_than_ten_points_is_a_loss() {
        let t = |right, stances| ToldApart {
            stances,
            right,
            unknown: stances - right,
            wrong: 0,
        };
        let before = [t(20, 20), t(19, 20), t(0, 0)];
        let after = [t(12, 20), t(18, 20), t(5, 5), t(9, 10)];
        let l = losses(&before, &after, &["clay", "wood", "grass", "sand"]);
        assert_eq!(l.len(), 1, "{l:?}");
        assert_eq!(l[0].terrain, "clay");
        assert!((l[0].before - 1.0).abs() < 1e-12 && (l[0].after - 0.6).abs() < 1e-12);
    }

    #[test]
    fn the_groups_to_add_are_the_ones_named_or_the_one_new_ground() {
        let d = discovery(&[true, false, true]);
        assert_eq!(pick(&d, &[0, 2]).unwrap(), vec![0, 2]);
        assert_eq!(pick(&d, &[1]).unwrap(), vec![1]);
        let err = |g: &[usize]| pick(&d, g).unwrap_err().to_string();
        assert!(err(&[]).contains("2 groups are new ground"), "{}", err(&[]));
        assert!(
            err(&[3]).contains("--group 4: there are 3 groups"),
            "{}",
            err(&[3])
        );
        assert!(
            err(&[0, 0]).contains("--group 1 is given twice"),
            "{}",
            err(&[0, 0])
        );
        assert_eq!(pick(&discovery(&[false, true]), &[]).unwrap(), vec![1]);
        assert!(pick(&discovery(&[false]), &[]).is_err());
    }
}
