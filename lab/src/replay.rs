//! A recorded bus turned into a recording: a candump log's frames on [`record`]'s channels,
//! with the decisions a model makes of them beside what the robot's node said.

use std::borrow::Borrow;

use node::{NodeService, Output};
use protocol::candump::LogRecord;
use record::{RecordError, Recorder, Sink};

/// Every record of a candump log into `rec`'s channels on `out`; with a `node`, the node's own
/// decisions on the log's clock (one record at a time, as `presrs node --replay` makes them)
/// recorded beside them as model TerrainClass. A sink that fails ends it (nothing is dropped
/// silently).
pub fn log_to_recording<R: Borrow<LogRecord>>(
    records: impl IntoIterator<Item = R>,
    mut node: Option<&mut NodeService>,
    rec: &mut Recorder,
    out: &mut dyn Sink,
) -> Result<(), RecordError> {
    let mut decided = Vec::new();
    for r in records {
        let st = &r.borrow().stamped;
        rec.frame(st, out)?;
        if let Some(node) = node.as_deref_mut() {
            node.replay(std::iter::once(st), &mut |(t, o): (u64, Output)| {
                if let Output::Class { foot, class, .. } = o {
                    decided.push((t, foot, class));
                }
            });
            for (t, foot, class) in decided.drain(..) {
                rec.model_decision(t, foot, &class, out)?;
            }
        }
    }
    Ok(())
}
