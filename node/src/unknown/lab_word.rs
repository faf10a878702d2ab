//! The lab's word on which kept stances were the new ground (`presrs discover --add NAME
//! --stances SPEC`): where grouping fails or is unsure, the lab knows when the robot was on
//! the mud. Three ways to say it:
//!
//! - step ranges: `12-40` (every foot) or `0:12-40` (foot 0), several separated by commas;
//! - a labels CSV (`start_s,end_s,terrain[,foot]` in the log's timestamps, as `presrs capture
//!   --labels` reads it): its rows that name `NAME`; a stance counts by its touchdown;
//! - a file listing kept stances, one `kept.csv` file name a line (as the contact sheets and
//!   `groups.csv` name them).
//!
//! Only stances the node kept as unknown are taken: the session's known references
//! (`session/`) stay what the node decided.

use std::path::Path;

use protocol::candump::parse_seconds;

use super::discover::{DiscoverError, KeptStance, touchdown_us};

/// One of the three ways (see the module docs).
#[derive(Clone, Debug, PartialEq)]
pub enum LabWord {
    /// Step ranges, each `(foot or any, first, last)`, inclusive.
    Steps(Vec<(Option<u8>, u16, u16)>),
    /// Time ranges of the log (µs): `(start, end, foot or any)`, end exclusive.
    Times(Vec<(u64, u64, Option<u8>)>),
    /// Kept stances by file name.
    Files(Vec<String>),
}

impl LabWord {
    /// `spec` read as the module docs say: an existing `.csv` file is a labels file (its rows
    /// naming `terrain`), another existing file a list of names, else step ranges.
    pub fn parse(spec: &str, terrain: &str) -> Result<Self, DiscoverError> {
        let bad = |m: String| DiscoverError::Add(format!("--stances {spec}: {m}"));
        let path = Path::new(spec);
        if path.is_file() {
            let text = std::fs::read_to_string(path).map_err(|e| bad(e.to_string()))?;
            if spec.ends_with(".csv") {
                return labels(&text, terrain).map_err(bad);
            }
            let files: Vec<String> = text
                .lines()
                .map(str::trim)
                .filter(|l| !l.is_empty() && !l.starts_with('#'))
                .map(str::to_string)
                .collect();
            return Ok(LabWord::Files(files));
        }
        spec.split(',')
            .map(|r| step_range(r.trim()))
            .collect::<Option<Vec<_>>>()
            .map(LabWord::Steps)
            .ok_or_else(|| bad("not a file, nor step ranges like 12-40 or 0:12-40 (foot 0)".into()))
    }

    /// The indices of the unknown stances in `stances` the word names.
    pub fn select(&self, stances: &[KeptStance]) -> Vec<usize> {
        (0..stances.len())
            .filter(|&i| stances[i].known.is_none() && self.names(&stances[i]))
            .collect()
    }

    fn names(&self, s: &KeptStance) -> bool {
        let foot_ok = |f: Option<u8>| f.is_none_or(|f| f == s.foot);
        match self {
            LabWord::Steps(r) => r
                .iter()
                .any(|&(f, a, b)| foot_ok(f) && (a..=b).contains(&s.step)),
            LabWord::Times(r) => touchdown_us(&s.file)
                .is_some_and(|t| r.iter().any(|&(a, b, f)| foot_ok(f) && (a..b).contains(&t))),
            LabWord::Files(names) => names.iter().any(|n| s.file.ends_with(n.as_str())),
        }
    }

    /// What the word names, for the report: `steps 12-40`, `the labels' 2 ranges of mud`, ...
    pub fn describe(&self) -> String {
        match self {
            LabWord::Steps(r) => {
                let each: Vec<String> = r
                    .iter()
                    .map(|(f, a, b)| match f {
                        Some(f) => format!("{f}:{a}-{b}"),
                        None => format!("{a}-{b}"),
                    })
                    .collect();
                format!("steps {}", each.join(","))
            }
            LabWord::Times(r) => format!("the labels' {} time ranges", r.len()),
            LabWord::Files(f) => format!("{} named stances", f.len()),
        }
    }
}

/// `12-40` or `0:12-40` (or a single step `12`).
fn step_range(s: &str) -> Option<(Option<u8>, u16, u16)> {
    let (foot, r) = match s.split_once(':') {
        Some((f, r)) => (Some(f.trim().parse().ok()?), r),
        None => (None, s),
    };
    let (a, b) = match r.split_once('-') {
        Some((a, b)) => (a.trim().parse().ok()?, b.trim().parse().ok()?),
        None => {
            let a = r.trim().parse().ok()?;
            (a, a)
        }
    };
    (a <= b).then_some((foot, a, b))
}

/// A labels CSV's rows naming `terrain` (the new terrain need not be in any catalog yet).
fn labels(text: &str, terrain: &str) -> Result<LabWord, String> {
    let mut out = Vec::new();
    let mut names = std::collections::BTreeSet::new();
    for (i, raw) in text.lines().enumerate() {
        let l = raw.trim();
        if l.is_empty() || l.starts_with('#') || (i == 0 && l.starts_with("start")) {
            continue;
        }
        let f: Vec<&str> = l.split(',').map(str::trim).collect();
        if !(3..=4).contains(&f.len()) {
            return Err(format!(
                "line {}: want start_s,end_s,terrain[,foot], got `{l}`",
                i + 1
            ));
        }
        names.insert(f[2].to_string());
        if f[2] != terrain {
            continue;
        }
        let secs =
            |s: &str| parse_seconds(s).ok_or(format!("line {}: `{s}` is not seconds", i + 1));
        let foot = match f.get(3) {
            Some(x) if !x.is_empty() => Some(
                x.parse()
                    .map_err(|_| format!("line {}: foot `{x}`", i + 1))?,
            ),
            _ => None,
        };
        out.push((secs(f[0])?, secs(f[1])?, foot));
    }
    if out.is_empty() {
        return Err(format!(
            "no row names `{terrain}` (it names {})",
            names.into_iter().collect::<Vec<_>>().join(", ")
        ));
    }
    Ok(LabWord::Times(out))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::classifier::PressureImage;

    fn kept(file: &str, foot: u8, step: u16, known: bool) -> KeptStance {
        KeptStance {
            file: file.into(),
            foot,
            step,
            reason: if known { "known" } else { "novelty" }.into(),
            source: "r3.log".into(),
            known: known.then(|| "wood".to_string()),
            image: PressureImage::new(2, 2, 8, vec![1; 4]),
        }
    }

    #[test]
    fn the_lab_names_its_new_ground_by_steps_times_or_files() {
        let s = [
            kept("unknown/r3_f0_s00012_1700000001000000.pgm", 0, 12, false),
            kept("unknown/r3_f0_s00013_1700000001400000.pgm", 0, 13, false),
            kept(
                "session/wood/r3_f0_s00014_1700000001800000.pgm",
                0,
                14,
                true,
            ),
            kept("unknown/r3_f1_s00013_1700000001500000.pgm", 1, 13, false),
        ];
        assert_eq!(
            LabWord::parse("12-14", "mud").unwrap().select(&s),
            vec![0, 1, 3]
        );
        assert_eq!(
            LabWord::parse("0:13-20", "mud").unwrap().select(&s),
            vec![1]
        );
        assert!(LabWord::parse("twelve", "mud").is_err());
        let dir = std::env::temp_dir().join(format!("presrs-labword-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let csv = dir.join("truth.csv");
        std::fs::write(
            &csv,
            "start_s,end_s,terrain,foot\n1700000000.9,1700000001.45,mud,\n1700000001.45,1700000002,wood,\n",
        )
        .unwrap();
        let w = LabWord::parse(csv.to_str().unwrap(), "mud").unwrap();
        assert_eq!(w.select(&s), vec![0, 1]);
        let e = LabWord::parse(csv.to_str().unwrap(), "sand")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("no row names `sand`") && e.contains("mud, wood"),
            "{e}"
        );
        let list = dir.join("mine.txt");
        std::fs::write(&list, "r3_f1_s00013_1700000001500000.pgm\n").unwrap();
        assert_eq!(
            LabWord::parse(list.to_str().unwrap(), "mud")
                .unwrap()
                .select(&s),
            vec![3]
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
