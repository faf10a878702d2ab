//! What `presrs discover` shows of a [`Discovery`]: the table, its JSON, and on disk each
//! stance's group (`groups.csv`) with a contact sheet per group.

use std::fmt::Write as _;
use std::path::Path;

use node::classifier::Model;
use node::classifier::train::ToldApart;
use node::unknown::add::Added;
use node::unknown::discover::{Discovery, KeptStance, MIN_GROUP};

use crate::contact_sheet::contact_sheet;
use crate::plot::PlotError;

/// Why the report could not be written.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// A file or folder.
    #[error("{path}: {source}")]
    Io {
        /// The file or folder.
        path: String,
        /// What the OS said.
        source: std::io::Error,
    },
    /// A contact sheet.
    #[error("{path}: {source}")]
    Sheet {
        /// The sheet.
        path: String,
        /// What the drawing said.
        source: PlotError,
    },
}

fn verdict(d: &Discovery, g: usize, model: &Model) -> String {
    let grp = &d.groups[g];
    let near = model
        .classes
        .get(grp.nearest_class)
        .map_or("?", |c| c.name.as_str());
    if grp.settling {
        "the runs' first steps (settling into the gait)".to_string()
    } else if !grp.new_ground {
        format!("known ground at the edge of {near}'s band")
    } else {
        "new ground".to_string()
    }
}

/// Why the node kept a group's stances: each reason and its count, the most first.
fn reasons(members: &[usize], kept: &[KeptStance]) -> Vec<(String, usize)> {
    let mut out: Vec<(String, usize)> = Vec::new();
    for r in members
        .iter()
        .filter_map(|&i| kept.get(i))
        .map(|k| &k.reason)
    {
        match out.iter_mut().find(|(name, _)| name == r) {
            Some((_, n)) => *n += 1,
            None => out.push((r.clone(), 1)),
        }
    }
    out.sort_by(|a, b| b.1.cmp(&a.1).then_with(|| a.0.cmp(&b.0)));
    out
}

/// The kept stances that are unknown ones (not the session's known references).
fn unknown(kept: &[KeptStance]) -> usize {
    kept.iter().filter(|k| k.known.is_none()).count()
}

/// The table `presrs discover` prints.
pub fn table(d: &Discovery, kept: &[KeptStance], model: &Model, dir: &str) -> String {
    let grouped: usize = d.groups.iter().map(|g| g.members.len()).sum();
    let mut s = format!(
        "{} unknown stances kept in {dir} ({} without contact; {} known ones of the run beside \
         them); stances linked when nearer each other \
         than, on average, to known ground (unknown steps that follow each other: \
         within {} times that), groups of {MIN_GROUP} or more; new ground when a \
         group stands apart by {:.2} or more (as much as the edge of {}'s band does, the most \
         of any known terrain):\n",
        unknown(kept),
        d.no_contact.len(),
        kept.len() - unknown(kept),
        d.neighbour_link,
        d.min_separation,
        model
            .classes
            .get(d.least_separated)
            .map_or("?", |c| c.name.as_str())
    );
    s.push_str("group  stances  separation  nearest known  kept for            verdict\n");
    let mut energy_known = false;
    for (g, grp) in d.groups.iter().enumerate() {
        let near = model
            .classes
            .get(grp.nearest_class)
            .map_or("?", |c| c.name.as_str());
        let why = reasons(&grp.members, kept);
        energy_known |= !grp.new_ground && why.first().is_some_and(|(r, _)| r == "energy");
        let why: Vec<String> = why.iter().map(|(r, n)| format!("{r} {n}")).collect();
        let _ = writeln!(
            s,
            "{:>5}  {:>7}  {:>10.2}  {near:<13}  {:<17}  {}",
            g + 1,
            grp.members.len(),
            grp.separation,
            why.join(", "),
            verdict(d, g, model)
        );
    }
    let new = d.new_ground().count();
    let _ = writeln!(
        s,
        "{} stances in no group; {new} proposed new terrain{} (separation: a member's distance \
         to known ground over its distance to the group, the median)",
        unknown(kept) - grouped - d.no_contact.len(),
        if new == 1 { "" } else { "s" }
    );
    if energy_known {
        s.push_str(
            "a group kept by the energy check passed the image checks: its images look like \
             known ground, the hops on it did not; look at its contact sheet (--out DIR) and \
             add it with --group N if it is one ground\n",
        );
    }
    s
}

/// The same as one JSON object (`--json`).
pub fn json(d: &Discovery, kept: &[KeptStance], model: &Model) -> serde_json::Value {
    serde_json::json!({
        "stances": unknown(kept),
        "session_stances": kept.len() - unknown(kept),
        "no_contact": d.no_contact.len(),
        "min_separation": d.min_separation,
        "neighbour_link": d.neighbour_link,
        "groups": d.groups.iter().enumerate().map(|(g, grp)| serde_json::json!({
            "group": g + 1,
            "stances": grp.members.len(),
            "spread": grp.spread,
            "to_known": grp.to_known,
            "separation": grp.separation,
            "nearest_known": model.classes.get(grp.nearest_class).map(|c| c.name.clone()),
            "new_ground": grp.new_ground,
            "settling": grp.settling,
            "reasons": reasons(&grp.members, kept).into_iter()
                .map(|(r, n)| (r, serde_json::Value::from(n))).collect::<serde_json::Map<_, _>>(),
            "files": grp.members.iter().map(|&i| kept[i].file.clone()).collect::<Vec<_>>(),
        })).collect::<Vec<_>>(),
    })
}

/// Writes `out/groups.csv` (every stance, its group or none) and a contact sheet per group
/// (`out/group-N.png`).
pub fn write_out(
    out: &Path,
    d: &Discovery,
    kept: &[KeptStance],
    model: &Model,
) -> Result<(), ReportError> {
    let io = |p: &Path| {
        let p = p.display().to_string();
        move |source| ReportError::Io { path: p, source }
    };
    std::fs::create_dir_all(out).map_err(io(out))?;
    let mut csv = String::from("file,foot,step,reason,group,source\n");
    for (i, k) in kept.iter().enumerate() {
        let g = d.group_of[i].map_or(String::new(), |g| (g + 1).to_string());
        let _ = writeln!(
            csv,
            "{},{},{},{},{g},{}",
            k.file, k.foot, k.step, k.reason, k.source
        );
    }
    let path = out.join("groups.csv");
    std::fs::write(&path, csv).map_err(io(&path))?;
    for (g, grp) in d.groups.iter().enumerate() {
        let images: Vec<_> = grp
            .members
            .iter()
            .map(|&i| {
                (
                    &kept[i].image,
                    format!("foot {} step {}", kept[i].foot, kept[i].step),
                )
            })
            .collect();
        let title = format!(
            "group {}: {} stances, {}",
            g + 1,
            grp.members.len(),
            verdict(d, g, model)
        );
        let png = out.join(format!("group-{}.png", g + 1));
        contact_sheet(&images, &title, &png).map_err(|e| ReportError::Sheet {
            path: png.display().to_string(),
            source: e,
        })?;
    }
    Ok(())
}

/// What `presrs discover --add` says: how well each terrain is told apart before and after
/// (each stored stance decided without itself), and what to do next.
pub fn added(
    a: &Added,
    old: &Model,
    name: &str,
    id: u8,
    out_model: &Path,
    terrains: Option<&Path>,
    in_catalog: bool,
) -> String {
    let mut s = format!(
        "added group {} as `{name}` (terrain id {id}{}) to {}: each terrain's stored stances \
         decided without themselves (right / unknown / other terrain):\n",
        a.groups
            .iter()
            .map(|g| (g + 1).to_string())
            .collect::<Vec<_>>()
            .join("+"),
        if in_catalog {
            // Said plainly: a lab that passed --terrains looks for a new entry there.
            format!(
                ", the catalog's own{}",
                terrains.map_or(String::new(), |t| format!(
                    "; {} left as it was (the catalog has `{name}`)",
                    t.display()
                ))
            )
        } else {
            terrains.map_or(String::new(), |t| format!(", added to {}", t.display()))
        },
        out_model.display()
    );
    told_apart(&mut s, a, old);
    candidates(&mut s, a);
    next_step(&mut s, a, name, out_model);
    s
}

fn pct(n: usize, of: usize) -> f64 {
    100.0 * n as f64 / of.max(1) as f64
}

/// Each terrain's stored stances, right / unknown / other, before and after the add.
fn told_apart(s: &mut String, a: &Added, old: &Model) {
    s.push_str("terrain         before                 after\n");
    let cell = |t: Option<&ToldApart>| {
        t.map_or("-".to_string(), |t| {
            format!(
                "{:>3.0}% / {:>3.0}% / {:>3.0}%",
                pct(t.right, t.stances),
                pct(t.unknown, t.stances),
                pct(t.wrong, t.stances)
            )
        })
    };
    for (k, c) in a.model.classes.iter().enumerate() {
        let before = if k < old.classes.len() {
            a.before.get(k)
        } else {
            None
        };
        let _ = writeln!(
            s,
            "{:<14}  {:<21}  {}",
            c.name,
            cell(before),
            cell(a.after.get(k))
        );
    }
}

/// The ways the new terrain could be fitted, each scored on the run, the chosen one starred.
fn candidates(s: &mut String, a: &Added) {
    let _ = writeln!(
        s,
        "fitted as `{}`, the best of {} ways measured on this run ({} of its known stances \
         in the keep; held out: every other one of each terrain):",
        a.candidates[a.chosen].name(),
        a.candidates.len(),
        a.session_refs
    );
    // "still right": of the known stances held out, those the refitted model still decides
    // as their terrain (the table above counts the model's stored stances instead).
    s.push_str("  way             known still right           new terrain right   score\n");
    for (i, c) in a.candidates.iter().enumerate() {
        // Judged on the run's held-out known stances, or (a keep without them) on the
        // model's stored ones each left out.
        let (kept, of, on) = match c.known_kept {
            Some((k, n)) => (k, n, "of the run's"),
            None => (c.stored_known.0, c.stored_known.1, "of the stored"),
        };
        let _ = writeln!(
            s,
            "{} {:<14}  {:>3}/{:<3} {on:<13}       {:>3}/{:<3}           {:.3}",
            if i == a.chosen { "*" } else { " " },
            c.name(),
            kept,
            of,
            c.new_right.0,
            c.new_right.1,
            c.score()
        );
    }
}

/// How to deploy the model, or (known ground lost) why not to.
fn next_step(s: &mut String, a: &Added, name: &str, out_model: &Path) {
    let losses = a.known_losses();
    if losses.is_empty() {
        let _ = writeln!(
            s,
            "next: move {} to the node's model path and send it SIGHUP (it reads the model and \
             its terrains file again)",
            out_model.display()
        );
        return;
    }
    let each: Vec<String> = losses
        .iter()
        .map(|l| {
            format!(
                "{} {:.0}% right (was {:.0}%)",
                l.terrain,
                100.0 * l.after,
                100.0 * l.before
            )
        })
        .collect();
    // Said instead of the install line: the lab would otherwise deploy a model that
    // takes known ground for the new terrain.
    let _ = writeln!(
        s,
        "warning: `{name}` takes known ground: {}. Do not deploy {} as it is (it is written \
         for a look): open the groups' contact sheets (`--out DIR`) and add only the groups \
         that show one ground (`--group N`); a group of a known terrain on another foot or \
         sensor is known ground, to capture and train on, not a new terrain",
        each.join(", "),
        out_model.display()
    );
}
