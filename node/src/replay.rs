//! A candump log through the node on the log's own clock (`presrs node --replay`), and the
//! lines in which the node's TerrainClass stream is printed.
//!
//! Each record's time ticks the node before the record is processed, as a live node's clock
//! would have: a step whose sample deadline passed between two records is decided at the later
//! record's time, as it would have been live at the next frame.

use std::fmt;

use protocol::TerrainCatalog;
use protocol::emit::Emit;
use std::borrow::Borrow;

use protocol::candump::LogRecord;
use protocol::messages::TerrainClass;
use protocol::tactile::ReassemblyStats;

use crate::gait_status::{GaitCount, describe_counts};
use crate::service::{NodeService, Output};
use crate::stance::Counters;

/// What a replay did: the records read and what the node made of them.
#[derive(Clone, Debug, PartialEq)]
pub struct ReplaySummary {
    /// Records replayed.
    pub frames: usize,
    /// From the first record's time to the last's, µs.
    pub span_us: u64,
    /// The node's counters after the log.
    pub counters: Counters,
    /// Its tactile reassembly's.
    pub reassembly: ReassemblyStats,
    /// Per terrain of the model that has a return map: its stances judged by the energy check
    /// and those outside the map. Empty for a model without maps.
    pub energy: Vec<EnergyTally>,
    /// Steps and unknowns per gait in force when each was decided (the log's GaitStatus), in
    /// gait order, steps before any GaitStatus last. Empty when the log has no GaitStatus.
    pub gaits: Vec<GaitCount>,
    /// The gaits the model was trained in (`Model::gaits`), when it says.
    pub model_gaits: Option<Vec<u8>>,
}

pub use crate::unknown::energy::EnergyTally;

impl fmt::Display for ReplaySummary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (c, r) = (&self.counters, &self.reassembly);
        write!(
            f,
            "replayed {} frames ({:.1} s): {} steps, {} classified, {} without a sample, {} \
             without contact{}\n  unknown by reason: {}\n  {} images, {} CRC failures, {} \
             incomplete, {} undecodable frames",
            self.frames,
            self.span_us as f64 * 1e-6,
            c.steps,
            c.classified,
            c.no_sample,
            c.no_contact,
            // A step whose stance the log ends in is counted, not decided.
            match c
                .steps
                .saturating_sub(c.classified + c.no_sample + c.no_contact)
            {
                0 => String::new(),
                n => format!(", {n} still in stance at the log's end"),
            },
            c.unknown_by_reason,
            r.delivered,
            r.crc_failures,
            r.incomplete,
            c.decode_errors
        )?;
        if !self.energy.is_empty() {
            write!(f, "\n  energy check, stances outside their terrain's map:")?;
            for (i, t) in self.energy.iter().enumerate() {
                let sep = if i == 0 { " " } else { ", " };
                write!(f, "{sep}{} {}/{}", t.terrain, t.outside, t.judged)?;
            }
        }
        if !self.gaits.is_empty() {
            let by_gait = describe_counts(&self.gaits, self.model_gaits.as_deref());
            write!(f, "\n  unknown by gait: {by_gait}")?;
        }
        Ok(())
    }
}

/// Replays `records` through `node`, handing each decision ([`Output::Class`]: foot, decision,
/// the gait in force, the log's last GaitStatus) to `out` with its log time. The records stream: a
/// [`protocol::candump::LogFile`]'s or a slice's.
pub fn replay_log<R: Borrow<LogRecord>>(
    node: &mut NodeService,
    records: impl IntoIterator<Item = R>,
    out: &mut (impl Emit<(u64, Output)> + ?Sized),
) -> ReplaySummary {
    let (mut frames, mut span) = (0, None::<(u64, u64)>);
    // The gaits counted from this replay's decisions alone, as the node counts since it began.
    let before = node.gait_tally().clone();
    for r in records {
        let st = &r.borrow().stamped;
        frames += 1;
        span = Some(span.map_or((st.t_us, st.t_us), |(a, _)| (a, st.t_us)));
        node.replay(std::iter::once(st), &mut |(t_us, o): (u64, Output)| {
            if matches!(o, Output::Class { .. }) {
                out.emit((t_us, o));
            }
        });
    }
    let gaits = node.gait_tally().since(&before).counts();
    ReplaySummary {
        frames,
        span_us: span.map_or(0, |(a, b)| b.saturating_sub(a)),
        counters: node.counters(),
        reassembly: node.reassembly_stats(),
        energy: node.energy_tally(),
        gaits,
        model_gaits: node.model().and_then(|m| m.gaits.clone()),
    }
}

/// Why [`replay_file`] stopped.
#[derive(Debug, thiserror::Error)]
pub enum ReplayFileError {
    /// The log cannot be read, or changed while it was replayed.
    #[error(transparent)]
    Log(#[from] protocol::candump::LogFileError),
    /// The step table cannot be written.
    #[error("step table {}: {source}", path.display())]
    Table {
        /// The table's file.
        path: std::path::PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The decisions cannot be written (their output closed).
    #[error("writing the decisions: {0}")]
    Out(std::io::Error),
}

/// `presrs node --replay`: the log at `log`, checked to its end before the first decision,
/// through `node`; each decision a line to `out` ([`class_line`], or [`class_json`] with
/// `json`) and each step a row of the step table at `table` when given.
pub fn replay_file(
    node: &mut NodeService,
    log: &std::path::Path,
    json: bool,
    table: Option<&std::path::Path>,
    mut truth: Option<&mut crate::truth::TruthTally>,
    out: &mut dyn std::io::Write,
) -> Result<ReplaySummary, ReplayFileError> {
    use std::io::Write;
    let file = protocol::candump::LogFile::check(log)?;
    let mut records = file.records()?;
    let catalog = node.catalog().clone();
    let table_err = |path: &std::path::Path| {
        let path = path.to_path_buf();
        move |source| ReplayFileError::Table { path, source }
    };
    let mut rows = match table {
        Some(p) => {
            let f = std::fs::File::create(p).map_err(table_err(p))?;
            let mut w = std::io::BufWriter::new(f);
            writeln!(w, "{}", crate::step_table::HEADER).map_err(table_err(p))?;
            Some(w)
        }
        None => None,
    };
    // The first write error of each output, kept: the replay's closure cannot return one.
    let (mut row_err, mut out_err) = (None, None);
    let summary = replay_log(node, &mut records, &mut |(t_us, o)| {
        if let (Some(w), Some(row)) = (rows.as_mut(), crate::step_table::StepRow::of(t_us, &o))
            && row_err.is_none()
            && let Err(e) = writeln!(w, "{}", row.to_csv(&catalog))
        {
            row_err = Some(e);
        }
        let Output::Class {
            foot,
            class,
            gait,
            touchdown_us,
        } = o
        else {
            return;
        };
        if let Some(t) = truth.as_deref_mut() {
            t.add(foot, touchdown_us, &class);
        }
        let line = if json {
            class_json(t_us, foot, &class, gait, &catalog).to_string()
        } else {
            class_line(t_us, foot, &class, &catalog)
        };
        if out_err.is_none()
            && let Err(e) = writeln!(out, "{line}")
        {
            out_err = Some(e);
        }
    });
    records.finish()?;
    if let Some(e) = out_err {
        return Err(ReplayFileError::Out(e));
    }
    if let (Some(p), Some(mut w)) = (table, rows) {
        row_err
            .map_or_else(|| w.flush(), Err)
            .map_err(table_err(p))?;
    }
    Ok(summary)
}

/// One TerrainClass as a line for people: time (s), foot, step, terrain name, confidence
/// (`-` for unknown ground: no terrain was chosen, and the rejected class's posterior would
/// read as certainty), damage and flags, as on the bus and named (the unknown reason first).
pub fn class_line(t_us: u64, foot: u8, tc: &TerrainClass, catalog: &TerrainCatalog) -> String {
    use protocol::messages::flags;
    let named = [
        (flags::REPAIRED, "repaired"),
        (flags::LOW_CONFIDENCE, "low confidence"),
        (flags::MULTI_FRAME, "multi-frame"),
    ];
    let notes: Vec<&str> = (tc.unknown_reason().map(|r| r.name()).into_iter())
        .chain(
            named
                .iter()
                .filter(|(b, _)| tc.flags & b != 0)
                .map(|(_, n)| *n),
        )
        .collect();
    format!(
        "{:.6} foot {foot} step {:5} {:<13} {:>6}  damage {:4.1}%  flags 0x{:02X}{}",
        t_us as f64 * 1e-6,
        tc.step,
        catalog.describe(tc.terrain),
        confidence_text(tc),
        tc.damage_pct,
        tc.flags,
        match notes.is_empty() {
            true => String::new(),
            false => format!("  ({})", notes.join(", ")),
        }
    )
}

/// The chosen terrain's confidence for people (`87.5%`), `-` for an unknown step.
pub fn confidence_text(tc: &TerrainClass) -> String {
    match known_confidence(tc) {
        Some(c) => format!("{c:.1}%"),
        None => "-".to_string(),
    }
}

/// The chosen terrain's posterior, %, or `None` for an unknown step: the TerrainClass frame
/// carries the best class's posterior even when the checks rejected it, which no output for
/// people shows as the step's confidence.
pub fn known_confidence(tc: &TerrainClass) -> Option<f64> {
    (tc.terrain != protocol::messages::TERRAIN_UNKNOWN).then_some(tc.confidence_pct)
}

/// One TerrainClass as a JSON object: every field of the message, the terrain also by name;
/// `confidence_pct` is `null` for an unknown step ([`known_confidence`]). `gait` is the gait
/// in force (`null` before any GaitStatus).
pub fn class_json(
    t_us: u64,
    foot: u8,
    tc: &TerrainClass,
    gait: Option<u8>,
    catalog: &TerrainCatalog,
) -> serde_json::Value {
    serde_json::json!({
        "t_us": t_us, "foot": foot, "step": tc.step, "terrain": catalog.describe(tc.terrain),
        "terrain_id": tc.terrain, "confidence_pct": known_confidence(tc),
        "damage_pct": tc.damage_pct, "flags": tc.flags, "latency_us": tc.latency_us,
        "unknown_reason": tc.unknown_reason().map(|r| r.name()), "gait": gait,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tc(terrain: u8) -> TerrainClass {
        TerrainClass {
            step: 7,
            terrain,
            confidence_pct: 91.5,
            damage_pct: 2.0,
            flags: 0x04,
            latency_us: 1234,
        }
    }

    #[test]
    fn the_summary_counts_unknowns_per_gait_and_names_a_gait_the_model_never_saw() {
        let tally = |gait, steps, unknown| GaitCount {
            gait,
            steps,
            unknown,
        };
        let mut s = ReplaySummary {
            frames: 10,
            span_us: 1_000_000,
            counters: Counters::default(),
            reassembly: ReassemblyStats::default(),
            energy: vec![],
            gaits: vec![
                tally(Some(1), 40, 1),
                tally(Some(3), 20, 7),
                tally(None, 1, 0),
            ],
            model_gaits: Some(vec![1, 2]),
        };
        let line = s.to_string();
        assert!(
            line.ends_with(
                "\n  unknown by gait: G1 1/40, G3 7/20 (the model was not trained in it), \
                 no GaitStatus 0/1"
            ),
            "{line}"
        );
        // A model that does not say which gaits it knows: counts only.
        s.model_gaits = None;
        assert!(!s.to_string().contains("not trained"), "{s}");
        s.gaits.clear();
        assert!(!s.to_string().contains("by gait"), "{s}");
    }

    #[test]
    fn lines_name_the_terrain_and_keep_every_field() {
        let cat = TerrainCatalog::paper();
        let line = class_line(1_500_000, 1, &tc(0), &cat);
        assert!(line.starts_with("1.500000 foot 1 step     7 "), "{line}");
        assert!(
            line.contains(" 91.5%") && line.ends_with("flags 0x04"),
            "{line}"
        );
        let mut repaired = tc(0);
        repaired.flags =
            protocol::messages::flags::REPAIRED | protocol::messages::flags::LOW_CONFIDENCE;
        let line = class_line(0, 0, &repaired, &cat);
        assert!(
            line.ends_with("flags 0x03  (repaired, low confidence)"),
            "{line}"
        );
        let unknown = class_line(0, 0, &tc(protocol::messages::TERRAIN_UNKNOWN), &cat);
        assert!(unknown.contains(&cat.describe(0xFF)), "{unknown}");
        let v = class_json(1_500_000, 1, &tc(0), Some(2), &cat);
        assert_eq!(v["gait"], 2);
        assert!(class_json(0, 0, &tc(0), None, &cat)["gait"].is_null());
        assert_eq!(v["terrain"], cat.describe(0));
        assert_eq!(v["terrain_id"], 0);
        assert_eq!(v["latency_us"], 1234);
        assert_eq!(v["step"], 7);
    }
}
