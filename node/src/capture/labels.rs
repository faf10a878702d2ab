//! Which terrain each step stood on: a labels file of time ranges, or one terrain for the whole run.

use super::{CaptureError, Path, Skip, Terrain, TerrainCatalog, io, parse_seconds};

/// One range of a labels file: steps whose touchdown and sample both fall in `[start, end)`
/// (the log's clock, µs) on `foot` (any foot when `None`) are `terrain`.
#[derive(Clone, Debug, PartialEq)]
pub struct LabelRange {
    /// Start, µs on the log's clock.
    pub start_us: u64,
    /// End (exclusive).
    pub end_us: u64,
    /// The terrain.
    pub terrain: Terrain,
    /// The foot it applies to; all feet when `None`.
    pub foot: Option<u8>,
}

/// How steps get their terrain.
#[derive(Clone, Debug)]
pub enum Labelling {
    /// Every step is this terrain (`--label`).
    All(Terrain),
    /// Time ranges (`--labels`), for a run that crosses terrains.
    Ranges(Vec<LabelRange>),
}

/// Parses a labels CSV: `start_s,end_s,terrain[,foot]` per line, in the log's own timestamps
/// (seconds, as `candump -L` prints them). A header line, blank lines and `#` comments are
/// allowed. Terrains must be in `catalog`; ranges of one foot must not overlap.
pub fn parse_labels(
    text: &str,
    origin: &str,
    catalog: &TerrainCatalog,
) -> Result<Vec<LabelRange>, CaptureError> {
    let bad = |line: usize, reason: String| CaptureError::Labels {
        path: origin.to_string(),
        line,
        reason,
    };
    let mut out: Vec<(usize, LabelRange)> = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = i + 1;
        let l = raw.trim();
        if l.is_empty() || l.starts_with('#') || (line == 1 && l.starts_with("start")) {
            continue;
        }
        let f: Vec<&str> = l.split(',').map(str::trim).collect();
        if !(3..=4).contains(&f.len()) {
            return Err(bad(
                line,
                format!(
                    "`{l}` has {} fields; want start_s,end_s,terrain[,foot]",
                    f.len()
                ),
            ));
        }
        let secs = |s: &str, what: &str| {
            parse_seconds(s).ok_or_else(|| {
                bad(
                    line,
                    format!(
                        "{what} `{s}` is not a time in seconds (as candump -L prints it, e.g. 1700000000.250000)"
                    ),
                )
            })
        };
        let (start_us, end_us) = (secs(f[0], "start_s")?, secs(f[1], "end_s")?);
        if end_us <= start_us {
            return Err(bad(
                line,
                format!("end_s {} is not after start_s {}", f[1], f[0]),
            ));
        }
        let terrain = catalog.known(f[2]).map_err(|e| bad(line, e.to_string()))?;
        let foot = match f.get(3) {
            None | Some(&"") => None,
            Some(s) => Some(
                s.parse::<u8>()
                    .ok()
                    .filter(|&n| n < protocol::ids::MAX_FEET)
                    .ok_or_else(|| bad(line, format!("foot `{s}` is not 0..7")))?,
            ),
        };
        let r = LabelRange {
            start_us,
            end_us,
            terrain,
            foot,
        };
        if let Some((other, _)) = out.iter().find(|(_, o)| {
            (o.foot.is_none() || r.foot.is_none() || o.foot == r.foot)
                && o.start_us < r.end_us
                && r.start_us < o.end_us
        }) {
            return Err(bad(
                line,
                format!("overlaps the range of line {other}: a step there would have two terrains"),
            ));
        }
        out.push((line, r));
    }
    if out.is_empty() {
        return Err(bad(
            0,
            "no ranges: want lines start_s,end_s,terrain[,foot]".into(),
        ));
    }
    Ok(out.into_iter().map(|(_, r)| r).collect())
}

impl Labelling {
    /// A command's `--label NAME` (every step that terrain) or else `--labels FILE` (a CSV of
    /// time ranges, [`parse_labels`]); errors name the option and the fix.
    pub fn from_args(
        label: Option<&str>,
        labels: Option<&Path>,
        catalog: &TerrainCatalog,
    ) -> Result<Self, CaptureError> {
        match (label, labels) {
            (Some(name), _) => {
                catalog
                    .known(name)
                    .map(Labelling::All)
                    .map_err(|e| CaptureError::Label {
                        name: name.to_string(),
                        reason: e.to_string(),
                    })
            }
            (None, Some(p)) => {
                let text = std::fs::read_to_string(p).map_err(|e| io("read", p, e))?;
                Ok(Labelling::Ranges(parse_labels(
                    &text,
                    &p.display().to_string(),
                    catalog,
                )?))
            }
            (None, None) => Err(CaptureError::NoLabels),
        }
    }

    /// The terrain of a step on `foot` from `t0` (touchdown) to `t1` (sample), log clock.
    pub fn label(&self, foot: u8, t0: u64, t1: u64) -> Result<Terrain, Skip> {
        let ranges = match self {
            Labelling::All(t) => return Ok(*t),
            Labelling::Ranges(r) => r,
        };
        let find = |t: u64| {
            ranges
                .iter()
                .position(|r| r.foot.is_none_or(|f| f == foot) && r.start_us <= t && t < r.end_us)
        };
        match (find(t0), find(t1)) {
            (Some(a), Some(b)) if a == b => Ok(ranges[a].terrain),
            (None, None) => Err(Skip::Unlabelled),
            _ => Err(Skip::SpansLabels),
        }
    }
}
