//! The node's decisions as a table a colleague opens in a spreadsheet: one CSV row per step
//! and foot (`presrs node --replay LOG --csv FILE`, and live `presrs node --csv FILE`).
//!
//! | column | what |
//! |---|---|
//! | `foot` | the foot that stepped |
//! | `step` | the foot's step counter as the bus carries it (TerrainClass `Step`) and `capture`'s manifest numbers it: the first touchdown the node saw is step 1 |
//! | `touchdown_s` | the debounced touchdown, on the log's clock (its timestamps, seconds) |
//! | `decision_s` | when the node decided the step, on the same clock |
//! | `terrain` | the catalog's name, `unknown` for unknown ground |
//! | `unknown_reason` | why it is unknown (`novelty`, `load`, `texture`, `energy`, `no_sample`, `no_contact`), empty when known |
//! | `confidence_pct` | the chosen terrain's posterior, %; empty for an unknown step: no terrain was chosen |
//! | `gait` | the gait in force when it was decided (`G2`), empty before the log's first GaitStatus |
//!
//! Terrain names are `[a-z0-9_]+` (the catalog refuses others) and every other field a
//! number, so the rows need no quoting and are written without a CSV crate.
//!
//! Live, the rows go to a writer thread through a bounded queue ([`StepLog`]): the node's
//! thread never waits on the disk; a row the queue cannot take is dropped and counted.

use std::io::Write;
use std::path::{Path, PathBuf};

use protocol::TerrainCatalog;
use protocol::candump::format_seconds;
use protocol::messages::{TERRAIN_UNKNOWN, TerrainClass};

use crate::service::output::Output;

/// The header line.
pub const HEADER: &str =
    "foot,step,touchdown_s,decision_s,terrain,unknown_reason,confidence_pct,gait";

/// One step's row: what the node decided and when.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepRow {
    /// The foot.
    pub foot: u8,
    /// The decision as the bus carries it.
    pub class: TerrainClass,
    /// Touchdown, µs on the log's (receiver's) clock.
    pub touchdown_us: u64,
    /// Decision, µs on the same clock.
    pub decided_us: u64,
    /// The gait in force.
    pub gait: Option<u8>,
}

impl StepRow {
    /// The row of a node output decided at `t_us` (`None` for a NodeStatus).
    pub fn of(t_us: u64, o: &Output) -> Option<Self> {
        match *o {
            Output::Class {
                foot,
                class,
                gait,
                touchdown_us,
            } => Some(Self {
                foot,
                class,
                touchdown_us,
                decided_us: t_us,
                gait,
            }),
            Output::Status(_) => None,
        }
    }

    /// The row as CSV, without its line end.
    pub fn to_csv(&self, catalog: &TerrainCatalog) -> String {
        let c = &self.class;
        let known = c.terrain != TERRAIN_UNKNOWN;
        format!(
            "{},{},{},{},{},{},{},{}",
            self.foot,
            c.step,
            format_seconds(self.touchdown_us),
            format_seconds(self.decided_us),
            catalog.describe(c.terrain),
            c.unknown_reason().map_or("", |r| r.name()),
            if known {
                format!("{:.1}", c.confidence_pct)
            } else {
                String::new()
            },
            self.gait.map_or(String::new(), |g| format!("G{g}")),
        )
    }
}

/// A step table being written live: rows in through [`StepLog::sender`], written on a thread
/// of their own.
pub struct StepLog {
    tx: Option<crossbeam_channel::Sender<StepRow>>,
    dropped: std::sync::Arc<std::sync::atomic::AtomicU64>,
    writer: Option<std::thread::JoinHandle<Result<u64, StepLogError>>>,
    path: PathBuf,
}

/// A step table that could not be written (the error names the file).
#[derive(Debug, thiserror::Error)]
#[error("step table {path}: {source} (give --csv a path in a folder you can write)")]
pub struct StepLogError {
    /// The file.
    pub path: PathBuf,
    /// Why.
    #[source]
    pub source: std::io::Error,
}

/// Rows the live queue holds: about a minute of eight feet stepping at 3 Hz.
const QUEUE: usize = 1024;

/// What a live node hands each decided step to: never blocks (a full queue drops the row and
/// counts it).
#[derive(Clone)]
pub struct StepSender {
    tx: crossbeam_channel::Sender<StepRow>,
    dropped: std::sync::Arc<std::sync::atomic::AtomicU64>,
}

impl StepSender {
    /// Offers `row` to the writer; a full queue drops it.
    #[inline]
    pub fn offer(&self, row: StepRow) {
        if self.tx.try_send(row).is_err() {
            self.dropped
                .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        }
    }
}

impl StepLog {
    /// Creates `path` (the header written at once, so a bad path is an error before the node
    /// starts) and the thread that writes the rows, naming terrains from `catalog`.
    pub fn create(path: &Path, catalog: TerrainCatalog) -> Result<Self, StepLogError> {
        let err = |source| StepLogError {
            path: path.to_path_buf(),
            source,
        };
        let file = std::fs::File::create(path).map_err(err)?;
        let mut w = std::io::BufWriter::new(file);
        writeln!(w, "{HEADER}")
            .and_then(|_| w.flush())
            .map_err(err)?;
        let (tx, rx) = crossbeam_channel::bounded::<StepRow>(QUEUE);
        let p = path.to_path_buf();
        let writer = std::thread::Builder::new()
            .name("step-table".into())
            .spawn(move || {
                let mut rows = 0u64;
                for r in rx {
                    writeln!(w, "{}", r.to_csv(&catalog))
                        // Each row reaches the file as it comes: a table of a run that is
                        // killed holds every step up to then.
                        .and_then(|_| w.flush())
                        .map_err(|source| StepLogError {
                            path: p.clone(),
                            source,
                        })?;
                    rows += 1;
                }
                Ok(rows)
            })
            .map_err(err)?;
        Ok(Self {
            tx: Some(tx),
            dropped: Default::default(),
            writer: Some(writer),
            path: path.to_path_buf(),
        })
    }

    /// The handle a node offers its rows to.
    pub fn sender(&self) -> Option<StepSender> {
        Some(StepSender {
            tx: self.tx.clone()?,
            dropped: self.dropped.clone(),
        })
    }

    /// Closes the queue once every sender is gone, waits for the rows and returns how many were
    /// written and how many dropped.
    pub fn finish(mut self) -> Result<(u64, u64), StepLogError> {
        drop(self.tx.take());
        let written = match self.writer.take().map(|h| h.join()) {
            Some(Ok(r)) => r?,
            Some(Err(_)) => {
                return Err(StepLogError {
                    path: self.path.clone(),
                    source: std::io::Error::other("the writer thread panicked"),
                });
            }
            None => 0,
        };
        Ok((
            written,
            self.dropped.load(std::sync::atomic::Ordering::Relaxed),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use protocol::messages::UnknownReason;

    fn row(terrain: u8, flags: u8, gait: Option<u8>) -> StepRow {
        StepRow {
            foot: 1,
            class: TerrainClass {
                step: 12,
                terrain,
                confidence_pct: 87.5,
                damage_pct: 0.0,
                flags,
                latency_us: 0,
            },
            touchdown_us: 1_700_000_001_250_000,
            decided_us: 1_700_000_001_320_500,
            gait,
        }
    }

    #[test]
    fn a_row_names_its_terrain_and_an_unknown_one_has_no_confidence() {
        let cat = TerrainCatalog::paper();
        let known = row(0, 0, Some(2)).to_csv(&cat);
        assert_eq!(
            known,
            format!(
                "1,12,1700000001.250000,1700000001.320500,{},,87.5,G2",
                cat.describe(0)
            )
        );
        let unknown = row(TERRAIN_UNKNOWN, UnknownReason::Novelty.flag_bits(), None);
        assert_eq!(
            unknown.to_csv(&cat),
            "1,12,1700000001.250000,1700000001.320500,unknown,novelty,,"
        );
        assert_eq!(
            HEADER.split(',').count(),
            known.split(',').count(),
            "as many columns as the header"
        );
    }

    #[test]
    fn the_live_table_holds_every_row_offered_and_counts_what_it_dropped() {
        let dir = std::env::temp_dir().join(format!("presrs-steps-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("steps.csv");
        let log = StepLog::create(&path, TerrainCatalog::paper()).unwrap();
        let s = log.sender().unwrap();
        for _ in 0..5 {
            s.offer(row(0, 0, None));
        }
        drop(s);
        assert_eq!(log.finish().unwrap(), (5, 0));
        let text = std::fs::read_to_string(&path).unwrap();
        assert_eq!(text.lines().count(), 6);
        assert_eq!(text.lines().next(), Some(HEADER));
        let bad = StepLog::create(&dir.join("no/such/dir/steps.csv"), TerrainCatalog::paper());
        assert!(bad.err().unwrap().to_string().contains("no/such/dir"));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
