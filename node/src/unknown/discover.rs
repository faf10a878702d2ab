//! New ground from the stances a node kept as unknown (`presrs node --keep-unknown DIR`):
//! `presrs discover` groups them into proposed terrains.
//!
//! **Where.** Each stance is taken to its spectrum's shape ([`BANDS`] log-spaced bands of the
//! model's feature vector, log mean magnitude, less the mean): by band a ground's texture
//! shows while one stance's speckle averages out, and less the mean a hop that lands harder
//! is the same ground. The model's stored stances, its known terrains, are taken there too.
//!
//! **Linking.** Two kept stances are linked when they lie nearer each other than they lie, on
//! average, to the nearest stored stance: no distance scale has to be chosen, and a chain
//! does not run through known ground; unknown steps that follow each other, ground the robot
//! is on, link a little further ([`PATCH_LINK`]). A linked group of [`MIN_GROUP`] or more is
//! a proposal; smaller ones are scattered stances. Two new grounds in one run may each lie
//! nearer the other than known ground: a group is split in two (two Gaussians, each its own
//! spread) where one part stands apart from the other twice as much as new ground must from
//! known ground.
//!
//! **New or known.** A group's separation is the median, over its members, of the distance to
//! known ground over the distance to the nearest other member. The known terrains measure
//! what the edge of a band looks like: each terrain's quarter of stored stances farthest from
//! its mean, taken as a group against the model's other stored stances; a group is new ground
//! when it stands apart at least as much as the most separated of those edges, else it is
//! known ground at the edge of its band. A group of a run's first [`SETTLING_STEPS`] steps
//! alone is the robot settling into its gait.
//!
//! Why these and not the candidates measured beside them (the whole feature vector, its PCA
//! projection, a distance quantile of the model's, other linking rules):
//! docs/decisions/discover-grouping.md. Off the robot's hot path: this runs on a folder.

use std::path::Path;

use crate::classifier::dataset::read_image;
use crate::classifier::{Classifier, Model, PressureImage};
use crate::order_stats::median;

/// A run's first steps, in which the robot settles into its gait (a launch lands from another
/// height at another speed): a group of them alone is no ground.
pub const SETTLING_STEPS: usize = 10;

/// The fewest stances a proposed terrain holds: fewer are a stumble, not ground.
pub const MIN_GROUP: usize = 5;

/// Kept stances of one run and foot whose step numbers are at most this far apart, and whose
/// touchdowns are at most [`PATCH_GAP_US`] apart, are neighbouring steps (one known step
/// between two unknown ones).
pub const PATCH_GAP: u16 = 2;

/// The most two neighbouring steps' touchdowns lie apart, µs: two steps of a slow gait (a
/// live keep names its run by the interface, and the node's step counter restarts with it).
pub const PATCH_GAP_US: u64 = 4_000_000;

/// Neighbouring unknown steps link when nearer each other than this many times the mean of
/// their distances to known ground (any two others: 1). Unknown steps that follow each other
/// are ground the robot is on, not known ground's stragglers, which come one at a time: a few
/// stances of new ground that scatter as far from each other as from known ground stay one
/// group (docs/decisions/discover-grouping.md, "Neighbouring steps").
pub const PATCH_LINK: f64 = 1.5;

/// One stance of a keep folder (a line of its `kept.csv` and its image).
#[derive(Clone, Debug)]
pub struct KeptStance {
    /// The image, relative to the folder (`unknown/<name>.pgm`).
    pub file: String,
    /// The foot.
    pub foot: u8,
    /// The step number the node gave it.
    pub step: u16,
    /// Why the node called it unknown.
    pub reason: String,
    /// The run it was kept from.
    pub source: String,
    /// For a known stance kept as the session's reference (reason `known`), the terrain the
    /// node decided; None for an unknown one.
    pub known: Option<String>,
    /// The stance image.
    pub image: PressureImage,
}

/// Why a keep folder cannot be grouped.
#[derive(Debug, thiserror::Error)]
pub enum DiscoverError {
    /// The folder is not a keep folder, or holds nothing.
    #[error("{dir}: {msg}")]
    Folder {
        /// The folder.
        dir: String,
        /// What is wrong and how to fix it.
        msg: String,
    },
    /// A group cannot be added as a terrain.
    #[error("{0}")]
    Add(String),
    /// One stance does not fit the model.
    #[error("{file}: {msg}")]
    Stance {
        /// The stance's image.
        file: String,
        /// What does not fit.
        msg: String,
    },
}

/// A kept stance's touchdown, µs on the log's clock, from its file name
/// (`<source>_f<foot>_s<step>_<touchdown_us>.pgm`, as `--keep-unknown` names it).
pub fn touchdown_us(file: &str) -> Option<u64> {
    let stem = file.rsplit('/').next()?.strip_suffix(".pgm")?;
    stem.rsplit('_').next()?.parse().ok()
}

/// Reads a keep folder: its `kept.csv` and every image it names.
pub fn read_kept(dir: &Path) -> Result<Vec<KeptStance>, DiscoverError> {
    let folder = |msg: String| DiscoverError::Folder {
        dir: dir.display().to_string(),
        msg,
    };
    let table = dir.join("kept.csv");
    let text = std::fs::read_to_string(&table).map_err(|e| {
        folder(format!(
            "no kept.csv ({e}): not a folder of kept stances; write one with `presrs node \
             --keep-unknown DIR`"
        ))
    })?;
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate().skip(1) {
        let line = line.strip_suffix('\r').unwrap_or(line);
        if line.is_empty() {
            continue;
        }
        let f: Vec<&str> = line.splitn(9, ',').collect();
        let bad = |what: &str| folder(format!("kept.csv line {}: {what}", n + 1));
        if f.len() != 9 {
            return Err(bad("not the 9 columns of `presrs node --keep-unknown`"));
        }
        let image = read_image(&dir.join(f[0])).map_err(|e| DiscoverError::Stance {
            file: f[0].to_string(),
            msg: e.to_string(),
        })?;
        out.push(KeptStance {
            file: f[0].to_string(),
            foot: f[1].parse().map_err(|_| bad("foot is not a number"))?,
            step: f[2].parse().map_err(|_| bad("step is not a number"))?,
            reason: f[3].to_string(),
            source: f[8].to_string(),
            known: (f[3] == "known")
                .then(|| f[0].split('/').nth(1).map(str::to_string))
                .flatten(),
            image,
        });
    }
    if out.is_empty() {
        return Err(folder(
            "kept.csv lists no stance: the node kept nothing from its run".into(),
        ));
    }
    Ok(out)
}

/// One proposed group.
#[derive(Clone, Debug, PartialEq)]
pub struct Group {
    /// Its stances, indices into the stances given, in order.
    pub members: Vec<usize>,
    /// The median distance of a member to its nearest other member (spectrum shapes).
    pub spread: f64,
    /// The median distance of a member to the nearest stored stance of a known terrain.
    pub to_known: f64,
    /// The median, over members, of the distance to known ground over the distance to the
    /// nearest other member: how much more the group is its own than any known terrain's.
    pub separation: f64,
    /// The known terrain nearest the group (a class index of the model).
    pub nearest_class: usize,
    /// Whether the group is new ground: it stands apart from known ground at least as the
    /// edge of a known terrain's band does ([`Discovery::min_separation`]), and it is not
    /// only the first [`SETTLING_STEPS`] steps of its runs.
    pub new_ground: bool,
    /// Every member is one of the first [`SETTLING_STEPS`] steps of its run: the robot
    /// settling into its gait, not ground.
    pub settling: bool,
}

/// What [`discover`] found.
#[derive(Clone, Debug, PartialEq)]
pub struct Discovery {
    /// The separation a group needs to be new ground: the most the edge of a known terrain's
    /// band shows (the quarter of its stored stances farthest from its mean shape, taken as a
    /// group against the model's other stored stances).
    pub min_separation: f64,
    /// The known terrain whose edge that is (a class index).
    pub least_separated: usize,
    /// How much further than any two others neighbouring unknown steps link ([`PATCH_LINK`];
    /// 1: as any two).
    pub neighbour_link: f64,
    /// The groups of at least [`MIN_GROUP`] stances, largest first.
    pub groups: Vec<Group>,
    /// Each stance's group (an index into `groups`), `None` for scattered stances and those
    /// without contact.
    pub group_of: Vec<Option<usize>>,
    /// Stances without contact (the model's test): no ground to group.
    pub no_contact: Vec<usize>,
}

impl Discovery {
    /// The groups that are new ground.
    pub fn new_ground(&self) -> impl Iterator<Item = (usize, &Group)> {
        self.groups.iter().enumerate().filter(|(_, g)| g.new_ground)
    }
}

/// Groups `stances` against `model`'s known terrains (see the module docs).
pub fn discover(model: &Model, stances: &[KeptStance]) -> Result<Discovery, DiscoverError> {
    discover_at(model, stances, Grouping::default())
}

/// How [`discover_at`] groups: the defaults are [`discover`]'s; the others are there to
/// measure them (`scripts/discover_study.py`).
#[derive(Clone, Copy, Debug, Default)]
pub struct Grouping {
    /// A fixed separation for new ground instead of the known terrains' own.
    pub min_separation: Option<f64>,
    /// A fixed separation for a split instead of the known terrains' own ([`split_floor`]);
    /// infinite: each linked group left whole.
    pub split_at: Option<f64>,
    /// Neighbouring steps link as any two others do ([`PATCH_LINK`]: off).
    pub no_patches: bool,
    /// The neighbours' link factor instead of [`PATCH_LINK`].
    pub patch_link: Option<f64>,
}

/// [`discover`] grouped as `how` says.
pub fn discover_at(
    model: &Model,
    stances: &[KeptStance],
    how: Grouping,
) -> Result<Discovery, DiscoverError> {
    let mut c = Classifier::new(model.clone());
    let known = Shapes::of_stored(model, &mut c);
    let no_distance = || DiscoverError::Folder {
        dir: "the model".into(),
        msg: "holds no training images (an older file) or fewer than two of a terrain: no \
              distance to group by; retrain it with `presrs train`"
            .into(),
    };
    let (own, least_separated) = edge_separation(model, &known).ok_or_else(no_distance)?;
    let min_separation = how.min_separation.unwrap_or(own);
    let kept = KeptShapes::of(&mut c, stances)?;
    let near_known: Vec<(f64, usize)> = (0..kept.at.len())
        .map(|a| {
            (0..known.len())
                .map(|j| (known.dist(j, kept.points.get(a)), model.sample_classes[j]))
                .min_by(|x, y| x.0.total_cmp(&y.0))
                .unwrap_or((f64::INFINITY, 0))
        })
        .collect();
    let neighbour_link = match how.no_patches {
        true => 1.0,
        false => how.patch_link.unwrap_or(PATCH_LINK).max(1.0),
    };
    let (linked, nearest_member) = link(&kept, &near_known, neighbour_link);
    let split_at = how
        .split_at
        .unwrap_or_else(|| split_floor(model, &known).max(min_separation));
    // Each group, and whether it is a part of a linked group split.
    let mut components: Vec<(Vec<usize>, bool)> = Vec::new();
    for members in linked.into_iter().filter(|m| m.len() >= MIN_GROUP) {
        let mut parts = Vec::new();
        split(&kept.points, members, split_at, &mut parts);
        let whole = parts.len() == 1;
        components.extend(parts.into_iter().map(|p| (p, !whole)));
    }
    components.sort_by_key(|(m, _)| std::cmp::Reverse(m.len()));
    let mut group_of = vec![None; stances.len()];
    let mut groups = Vec::new();
    for (g, (members, part)) in components.into_iter().enumerate() {
        let mut classes = vec![0usize; model.classes.len()];
        for &a in &members {
            if let Some(c) = classes.get_mut(near_known[a].1) {
                *c += 1;
            }
            group_of[kept.at[a]] = Some(g);
        }
        // A part of a split group: its spread among its own members (the nearest kept stance
        // may be in the other part).
        let own = |a: usize| match part {
            true => nearest_in(&kept.points, a, &members),
            false => nearest_member[a],
        };
        let med = |f: &dyn Fn(usize) -> f64| {
            median(&mut members.iter().map(|&a| f(a)).collect::<Vec<_>>())
        };
        let separation = med(&|a| near_known[a].0 / own(a).max(f64::MIN_POSITIVE));
        let settling = members
            .iter()
            .all(|&a| stances[kept.at[a]].step as usize <= SETTLING_STEPS);
        groups.push(Group {
            spread: med(&own),
            to_known: med(&|a| near_known[a].0),
            separation,
            nearest_class: (0..classes.len()).max_by_key(|&k| classes[k]).unwrap_or(0),
            new_ground: separation >= min_separation && !settling,
            settling,
            members: members.iter().map(|&a| kept.at[a]).collect(),
        });
    }
    Ok(Discovery {
        min_separation,
        least_separated,
        neighbour_link,
        groups,
        group_of,
        no_contact: kept.no_contact,
    })
}

/// The kept unknown stances in contact, as spectrum shapes.
struct KeptShapes {
    points: Shapes,
    /// Each point's stance (an index into the stances given).
    at: Vec<usize>,
    /// The stances without contact.
    no_contact: Vec<usize>,
    /// Pairs of points that were neighbouring steps (one run and foot, [`PATCH_GAP`]).
    neighbours: Vec<(usize, usize)>,
}

impl KeptShapes {
    fn of(c: &mut Classifier, stances: &[KeptStance]) -> Result<Self, DiscoverError> {
        let mut out = KeptShapes {
            points: Shapes::default(),
            at: Vec::new(),
            no_contact: Vec::new(),
            neighbours: Vec::new(),
        };
        for (i, s) in stances
            .iter()
            .enumerate()
            .filter(|(_, s)| s.known.is_none())
        {
            c.classify_image(&s.image, false)
                .map_err(|e| DiscoverError::Stance {
                    file: s.file.clone(),
                    msg: format!("{e}: keep and discover with the model of this sensor"),
                })?;
            if c.in_contact() {
                out.points.push(c.features());
                out.at.push(i);
            } else {
                out.no_contact.push(i);
            }
        }
        out.neighbours = neighbours(stances, &out.at);
        Ok(out)
    }
}

/// The pairs of `at` (indices of `stances`) that are neighbouring steps: one run and foot,
/// step numbers at most [`PATCH_GAP`] apart (the node's step counter wraps), touchdowns at
/// most [`PATCH_GAP_US`] apart (the kept file's name; none: not a neighbour).
fn neighbours(stances: &[KeptStance], at: &[usize]) -> Vec<(usize, usize)> {
    // Each touchdown read from its file name once, not once per pair.
    let touchdown: Vec<Option<u64>> = at.iter().map(|&i| touchdown_us(&stances[i].file)).collect();
    let mut out = Vec::new();
    for (a, &i) in at.iter().enumerate() {
        for (b, &j) in at.iter().enumerate().skip(a + 1) {
            let (x, y) = (&stances[i], &stances[j]);
            let gap = x.step.wrapping_sub(y.step).min(y.step.wrapping_sub(x.step));
            let near_in_time = match (touchdown[a], touchdown[b]) {
                (Some(tx), Some(ty)) => tx.abs_diff(ty) <= PATCH_GAP_US,
                _ => false,
            };
            if x.source == y.source
                && x.foot == y.foot
                && (1..=PATCH_GAP).contains(&gap)
                && near_in_time
            {
                out.push((a, b));
            }
        }
    }
    out
}

/// The linked groups of the kept points (each point's index in one), and each point's
/// distance to its nearest other point. Neighbouring steps link within `neighbour_link` times
/// the others' reach.
fn link(
    kept: &KeptShapes,
    near_known: &[(f64, usize)],
    neighbour_link: f64,
) -> (Vec<Vec<usize>>, Vec<f64>) {
    let points = &kept.points;
    let n = points.len();
    let mut parent: Vec<usize> = (0..n).collect();
    let mut nearest_member = vec![f64::INFINITY; n];
    for a in 0..n {
        for b in a + 1..n {
            let d = points.dist(a, points.get(b));
            // An identical image (the same stance kept from two copies of a log) is no
            // neighbour to measure a spread by.
            if d > 0.0 {
                nearest_member[a] = nearest_member[a].min(d);
                nearest_member[b] = nearest_member[b].min(d);
            }
            // Linked when nearer each other than they are, on average, to known ground: no
            // distance scale to choose, and a chain does not run through a known terrain.
            // (Nearer than either: a terrain splits in two; than both: known ground's edge
            // joins it. docs/decisions/discover-grouping.md.)
            if d < 0.5 * (near_known[a].0 + near_known[b].0) {
                let (ra, rb) = (root(&mut parent, a), root(&mut parent, b));
                parent[ra.max(rb)] = ra.min(rb);
            }
        }
    }
    // Unknown steps that follow each other: ground the robot is on links a little further.
    if neighbour_link > 1.0 {
        for &(a, b) in &kept.neighbours {
            let d = points.dist(a, points.get(b));
            if d < neighbour_link * 0.5 * (near_known[a].0 + near_known[b].0) {
                let (ra, rb) = (root(&mut parent, a), root(&mut parent, b));
                parent[ra.max(rb)] = ra.min(rb);
            }
        }
    }
    let mut components: Vec<Vec<usize>> = vec![Vec::new(); n];
    for a in 0..n {
        let r = root(&mut parent, a);
        components[r].push(a);
    }
    components.retain(|m| !m.is_empty());
    (components, nearest_member)
}

/// The distance from point `a` to the nearest other (not identical) point of `members`.
fn nearest_in(points: &Shapes, a: usize, members: &[usize]) -> f64 {
    members
        .iter()
        .map(|&b| points.dist(b, points.get(a)))
        .filter(|&d| d > 0.0)
        .fold(f64::INFINITY, f64::min)
}

/// Pushes `members` to `out`, split in two (each part again) where the link joined two
/// grounds: one part stands apart from the other at least twice `at` and the other is nearer
/// its own members than the first's ([`apart`]). Two new terrains in one run may each lie
/// nearer the other than known ground, which the link cannot tell from one terrain; a ground
/// whose stances fall in two modes (carpet, landing in two ways) stands apart from itself
/// too, but less (docs/decisions/discover-grouping.md).
fn split(points: &Shapes, members: Vec<usize>, at: f64, out: &mut Vec<Vec<usize>>) {
    if members.len() >= 2 * MIN_GROUP
        && let Some((a, b)) = two_means(points, &members)
        && a.len() >= MIN_GROUP
        && b.len() >= MIN_GROUP
    {
        let (ab, ba) = (apart(points, &a, &b), apart(points, &b, &a));
        if ab.max(ba) >= 2.0 * at && ab.min(ba) >= 1.0 {
            split(points, a, at, out);
            split(points, b, at, out);
            return;
        }
    }
    out.push(members);
}

/// How far apart the two parts of one ground stand: the most that any known terrain's stored
/// stances, split in two as [`split`] splits, stand apart (the lesser of the two parts'
/// [`apart`]). [`split`] measures against this or the separation of new ground from known
/// ground, the larger. Infinite (no split) when no terrain stores enough stances to split.
fn split_floor(model: &Model, known: &Shapes) -> f64 {
    let m = known.len();
    if m != model.sample_classes.len() {
        return f64::INFINITY;
    }
    (0..model.classes.len())
        .filter_map(|k| {
            let own: Vec<usize> = (0..m).filter(|&i| model.sample_classes[i] == k).collect();
            if own.len() < 2 * MIN_GROUP {
                return None;
            }
            let (a, b) = two_means(known, &own)?;
            Some(apart(known, &a, &b).min(apart(known, &b, &a)))
        })
        .filter(|r| r.is_finite())
        .reduce(f64::max)
        .unwrap_or(f64::INFINITY)
}

/// The median, over `a`'s members, of the distance to the nearest of `b` over that to the
/// nearest other of `a`: a group's separation with `b` for known ground.
fn apart(points: &Shapes, a: &[usize], b: &[usize]) -> f64 {
    let mut r: Vec<f64> = a
        .iter()
        .map(|&i| {
            let other = b
                .iter()
                .map(|&j| points.dist(j, points.get(i)))
                .fold(f64::INFINITY, f64::min);
            other / nearest_in(points, i, a).max(f64::MIN_POSITIVE)
        })
        .collect();
    median(&mut r)
}

/// `members` in two: started from the two sides of their widest direction (a farthest pair
/// would start from an outlier), then two Gaussians each with its own spread. None when
/// they do not part.
fn two_means(points: &Shapes, members: &[usize]) -> Option<(Vec<usize>, Vec<usize>)> {
    let mean = |side: &dyn Fn(usize) -> bool| {
        let mut m = [0f64; BANDS];
        let mut n = 0usize;
        for (_, &i) in members.iter().enumerate().filter(|&(k, _)| side(k)) {
            m.iter_mut()
                .zip(points.get(i))
                .for_each(|(m, x)| *m += *x as f64);
            n += 1;
        }
        (n > 0).then(|| m.map(|x| (x / n as f64) as f32))
    };
    let centre = mean(&|_| true)?;
    // The widest direction by power iteration from the member farthest from the centre.
    let dev = |i: usize| -> [f64; BANDS] {
        let mut d = [0f64; BANDS];
        for ((d, x), c) in d.iter_mut().zip(points.get(i)).zip(&centre) {
            *d = (*x - *c) as f64;
        }
        d
    };
    let far = *members
        .iter()
        .max_by(|&&x, &&y| points.dist(x, &centre).total_cmp(&points.dist(y, &centre)))?;
    let mut axis = dev(far);
    for _ in 0..30 {
        let mut next = [0f64; BANDS];
        for &i in members {
            let d = dev(i);
            let t: f64 = d.iter().zip(&axis).map(|(a, b)| a * b).sum();
            next.iter_mut().zip(&d).for_each(|(n, x)| *n += t * x);
        }
        let norm = next.iter().map(|x| x * x).sum::<f64>().sqrt();
        if norm.is_nan() || norm <= 0.0 {
            return None;
        }
        axis = next.map(|x| x / norm);
    }
    let mut side: Vec<bool> = members
        .iter()
        .map(|&i| dev(i).iter().zip(&axis).map(|(a, b)| a * b).sum::<f64>() > 0.0)
        .collect();
    // Two isotropic Gaussians, each with its own spread (EM, hard assignments): a tight
    // ground inside a scattered one parts where equal spreads (2-means) would cut the
    // scattered one.
    for _ in 0..30 {
        let centres = [mean(&|i| !side[i])?, mean(&|i| side[i])?];
        // Per part: its spread (variance per band) and the log of its share.
        let fit = |k: usize| {
            let (mut n, mut ss) = (0usize, 0f64);
            for (_, &m) in members
                .iter()
                .enumerate()
                .filter(|(i, _)| side[*i] == (k == 1))
            {
                n += 1;
                ss += points.dist(m, &centres[k]).powi(2);
            }
            let var = (ss / (n as f64 * BANDS as f64)).max(1e-9);
            (var, (n as f64 / members.len() as f64).ln())
        };
        let parts = [fit(0), fit(1)];
        let log_likelihood = |m: usize, k: usize| {
            let (var, share) = parts[k];
            -points.dist(m, &centres[k]).powi(2) / (2.0 * var) - 0.5 * BANDS as f64 * var.ln()
                + share
        };
        let next: Vec<bool> = members
            .iter()
            .map(|&m| log_likelihood(m, 1) > log_likelihood(m, 0))
            .collect();
        if next == side {
            break;
        }
        side = next;
    }
    let part = |k: bool| -> Vec<usize> {
        members
            .iter()
            .zip(&side)
            .filter(|(_, s)| **s == k)
            .map(|(&i, _)| i)
            .collect()
    };
    Some((part(false), part(true)))
}

/// The bands a spectrum's shape is taken over.
pub const BANDS: usize = 24;

/// Spectrum shapes, [`BANDS`] numbers each: the log mean magnitude of the feature vector in
/// log-spaced frequency bands, less their mean. By band, a ground's texture shows and one
/// stance's speckle averages out (a grass stance's bins are as far from another grass
/// stance's as from wood's); less the mean, a hop that lands harder is the same ground.
#[derive(Default)]
struct Shapes(Vec<f32>);

impl Shapes {
    fn push(&mut self, features: &[f32]) {
        let h = features.len().max(1);
        let edge =
            |i: usize| ((h as f64).powf(i as f64 / BANDS as f64).round() as usize).clamp(1, h);
        let start = self.0.len();
        for i in 0..BANDS {
            let lo = edge(i).min(h - 1);
            let hi = edge(i + 1).max(lo + 1).min(h);
            let band = features.get(lo..hi).unwrap_or(&[]);
            let mean = band.iter().map(|x| x.abs()).sum::<f32>() / band.len().max(1) as f32;
            self.0.push((mean + 1e-3).ln());
        }
        let shape = &mut self.0[start..];
        let level = shape.iter().sum::<f32>() / BANDS as f32;
        shape.iter_mut().for_each(|x| *x -= level);
    }

    /// The shapes of the model's stored stances (from its stored working images), in the
    /// order of its samples; empty for a model without them.
    fn of_stored(model: &Model, c: &mut Classifier) -> Self {
        let mut out = Shapes::default();
        let Some(stored) = &model.images else {
            return out;
        };
        if stored.pixels.len() != model.sample_classes.len() {
            return out;
        }
        for work in &stored.pixels {
            if work.len() != c.work_mut().len() {
                return Shapes::default();
            }
            c.classify_work(work);
            out.push(c.features());
        }
        out
    }

    fn len(&self) -> usize {
        self.0.len() / BANDS
    }

    fn get(&self, i: usize) -> &[f32] {
        &self.0[i * BANDS..(i + 1) * BANDS]
    }

    fn dist(&self, i: usize, p: &[f32]) -> f64 {
        self.get(i)
            .iter()
            .zip(p)
            .map(|(x, y)| ((*x - *y) as f64).powi(2))
            .sum::<f64>()
            .sqrt()
    }
}

/// The separation known ground at the edge of its band shows (see
/// [`Discovery::min_separation`]), the most of any known terrain's, and whose it is; None when
/// no terrain stores [`MIN_GROUP`] + 1 stances. A terrain's edge: the quarter of its stored
/// stances farthest from its mean shape (at least [`MIN_GROUP`]), taken as a group against
/// the rest of the model's stances.
fn edge_separation(model: &Model, known: &Shapes) -> Option<(f64, usize)> {
    let m = known.len();
    if m == 0 || m != model.sample_classes.len() {
        return None;
    }
    let class = &model.sample_classes;
    let mut worst: Option<(f64, usize)> = None;
    for k in 0..model.classes.len() {
        let own: Vec<usize> = (0..m).filter(|&i| class[i] == k).collect();
        let n_edge = (own.len() / 4).max(MIN_GROUP);
        if own.len() <= n_edge {
            continue;
        }
        let mut mean = [0f32; BANDS];
        for &i in &own {
            mean.iter_mut()
                .zip(known.get(i))
                .for_each(|(m, x)| *m += x / own.len() as f32);
        }
        let mut by_far: Vec<(f64, usize)> =
            own.iter().map(|&i| (known.dist(i, &mean), i)).collect();
        by_far.sort_by(|a, b| b.0.total_cmp(&a.0));
        let edge: Vec<usize> = by_far[..n_edge].iter().map(|&(_, i)| i).collect();
        let mut ratios: Vec<f64> = edge
            .iter()
            .map(|&i| {
                let (mut member, mut rest) = (f64::INFINITY, f64::INFINITY);
                for j in (0..m).filter(|&j| j != i) {
                    let d = known.dist(j, known.get(i));
                    if edge.contains(&j) {
                        member = member.min(d);
                    } else {
                        rest = rest.min(d);
                    }
                }
                rest / member.max(f64::MIN_POSITIVE)
            })
            .collect();
        let r = median(&mut ratios);
        if worst.is_none_or(|(w, _)| r > w) {
            worst = Some((r, k));
        }
    }
    worst
}

/// The union-find root of `a`, halving the path on the way.
fn root(parent: &mut [usize], mut a: usize) -> usize {
    while parent[a] != a {
        parent[a] = parent[parent[a]];
        a = parent[a];
    }
    a
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `n` points around `centre` in every band, scattered by `spread` (a fixed generator:
    /// the same points every run).
    fn blob(out: &mut Shapes, n: usize, centre: f32, spread: f32, seed: u64) {
        let mut x = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        for _ in 0..n {
            for _ in 0..BANDS {
                x = x
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                let u = ((x >> 40) as f32 / (1u64 << 24) as f32) - 0.5;
                out.0.push(centre + spread * u);
            }
        }
    }

    fn parts(points: &Shapes, at: f64) -> Vec<usize> {
        let mut out = Vec::new();
        split(points, (0..points.len()).collect(), at, &mut out);
        let mut sizes: Vec<usize> = out.iter().map(Vec::len).collect();
        sizes.sort_unstable();
        sizes
    }

    /// Six stances of one ground a step apart on a line, each 1.0 from the next and 0.8 from
    /// known ground, and a seventh far off: by distance alone nothing links; as neighbouring
    /// steps the six are one group and the far one stays alone.
    #[test]
    fn neighbouring_unknown_steps_link_further_and_a_far_one_does_not() {
        let mut points = Shapes::default();
        for i in 0..6 {
            points
                .0
                .extend((0..BANDS).map(|b| if b == 0 { i as f32 } else { 0.0 }));
        }
        points
            .0
            .extend((0..BANDS).map(|b| if b == 1 { 9.0 } else { 0.0 }));
        let kept = KeptShapes {
            points,
            at: (0..7).collect(),
            no_contact: Vec::new(),
            neighbours: (0..6).map(|a| (a, a + 1)).collect(),
        };
        let near_known = vec![(0.8, 0); 7];
        let sizes = |link_factor: f64| {
            let mut s: Vec<usize> = link(&kept, &near_known, link_factor)
                .0
                .iter()
                .map(Vec::len)
                .collect();
            s.sort_unstable();
            s
        };
        assert_eq!(sizes(1.0), vec![1; 7]);
        assert_eq!(sizes(PATCH_LINK), vec![1, 6]);
    }

    #[test]
    fn two_grounds_the_link_joined_are_split_and_one_ground_is_not() {
        let mut one = Shapes::default();
        blob(&mut one, 40, 0.0, 1.0, 1);
        // One ground's halves stand no further apart than its members do from each other.
        let (a, b) = two_means(&one, &(0..40).collect::<Vec<_>>()).unwrap();
        let halves = apart(&one, &a, &b).min(apart(&one, &b, &a));
        assert!(halves < 1.5, "{halves}");
        assert_eq!(parts(&one, 1.5), vec![40]);
        // Two grounds: a tight one and a scattered one, apart.
        let mut two = Shapes::default();
        blob(&mut two, 12, 0.0, 0.3, 2);
        blob(&mut two, 25, 1.5, 1.0, 3);
        assert_eq!(parts(&two, 1.5), vec![12, 25]);
        // Too few for two groups of MIN_GROUP: left whole.
        let mut small = Shapes::default();
        blob(&mut small, 4, 0.0, 0.3, 4);
        blob(&mut small, 4, 3.0, 0.3, 5);
        assert_eq!(parts(&small, 1.5), vec![8]);
        // Identical stances do not part.
        let same = Shapes(vec![0.5; BANDS * 12]);
        assert_eq!(parts(&same, 1.5), vec![12]);
    }
}
