//! A recorded bus turned into a recording: a candump log's frames on [`record`]'s channels or
//! in a ROS 2 bag ([`ros2`]), with the decisions a model makes of them beside what the robot's
//! node said.

use std::borrow::Borrow;

use node::{NodeService, Output};
use protocol::candump::LogRecord;
use protocol::messages::TerrainClass;
use record::{RecordError, Recorder, Sink};

/// Every record of a candump log into `rec`'s channels on `out`; with a `node`, the node's own
/// decisions on the log's clock (one record at a time, as `presrs node --replay` makes them)
/// recorded beside them as model TerrainClass. A sink that fails ends it (nothing is dropped
/// silently).
pub fn log_to_recording<R: Borrow<LogRecord>>(
    records: impl IntoIterator<Item = R>,
    node: Option<&mut NodeService>,
    rec: &mut Recorder,
    out: &mut dyn Sink,
) -> Result<(), RecordError> {
    with_decisions(
        records,
        node,
        &mut (rec, out),
        |(rec, out), st| rec.frame(st, *out),
        |(rec, out), t, foot, class| rec.model_decision(t, foot, class, *out),
    )
}

/// [`log_to_recording`] for a ROS 2 bag: the log's frames through `enc` into `bag`, and with a
/// `node` its decisions on `footN/terrain/model` (`presrs mcap --ros2 --model`).
pub fn log_to_bag<R: Borrow<LogRecord>>(
    records: impl IntoIterator<Item = R>,
    node: Option<&mut NodeService>,
    enc: &mut ros2::Encoder,
    bag: &mut ros2::RosBag,
) -> Result<(), ros2::Ros2Error> {
    with_decisions(
        records,
        node,
        &mut (enc, bag),
        |(enc, bag), st| enc.frame(st, *bag),
        |(enc, bag), t, foot, class| enc.model_decision(t, foot, class, *bag),
    )
}

/// Each record to `frame`; with a `node`, each decision it makes of the records so far (on the
/// log's clock, as `presrs node --replay` makes them) to `decided`, after the record; both
/// write through `out`.
fn with_decisions<R: Borrow<LogRecord>, O, E>(
    records: impl IntoIterator<Item = R>,
    mut node: Option<&mut NodeService>,
    out: &mut O,
    frame: impl Fn(&mut O, &protocol::Stamped) -> Result<(), E>,
    decided: impl Fn(&mut O, u64, u8, &TerrainClass) -> Result<(), E>,
) -> Result<(), E> {
    let mut made = Vec::new();
    for r in records {
        let st = &r.borrow().stamped;
        frame(out, st)?;
        if let Some(node) = node.as_deref_mut() {
            node.replay(std::iter::once(st), &mut |(t, o): (u64, Output)| {
                if let Output::Class { foot, class, .. } = o {
                    made.push((t, foot, class));
                }
            });
            for (t, foot, class) in made.drain(..) {
                decided(out, t, foot, &class)?;
            }
        }
    }
    Ok(())
}
