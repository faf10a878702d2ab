//! JSON schemas of the recorded channels: one per CAN message, made from the DBC's table of
//! signals (the same names and units as `presrs.dbc`), `foxglove.RawImage` for pressure
//! images, and the simulator's ground truth.

use std::fmt::Write;

use protocol::MessageKind;
use protocol::dbc::{Signal, signals};

/// A channel's schema: its name (`presrs.TerrainClass`, `foxglove.RawImage`) and JSON Schema text.
#[derive(Clone, Debug, PartialEq)]
pub struct Schema {
    /// Schema name, as tools show it.
    pub name: String,
    /// JSON Schema (draft 2020-12) of the messages.
    pub json: String,
}

/// The JSON key of the label of a signal with a value table: `TerrainId` -> `Terrain`,
/// `State` -> `StateName`.
pub fn label_key(signal: &str) -> String {
    match signal.strip_suffix("Id") {
        Some(base) if !base.is_empty() => base.to_string(),
        _ => format!("{signal}Name"),
    }
}

/// Whether a signal's physical values are whole numbers (written as JSON integers).
pub(crate) fn is_integer(s: &Signal) -> bool {
    s.factor == 1.0
}

fn describe(s: &Signal) -> String {
    let mut d = format!(
        "DBC signal {}: bits {}..{}, {}, {} per bit",
        s.name,
        s.start,
        s.start + s.len - 1,
        if s.signed { "signed" } else { "unsigned" },
        s.factor
    );
    if !s.unit.is_empty() {
        let _ = write!(d, ", unit {}", s.unit);
    }
    d
}

/// Extra property the live node adds to its NodeStatus channel.
pub const RECORDING_DROPPED: &str = "RecordingDropped";

/// A TerrainClass of unknown ground (TerrainId 255) chose no terrain: its `Confidence` is
/// recorded as `null`, and the frame's value (the posterior of the class the checks
/// rejected) under this name, so that no plot reads it as the step's certainty.
pub const REJECTED_CONFIDENCE: &str = "RejectedConfidence";

/// The schema of a fixed-layout message, `None` for the tactile segments (recorded as images).
pub fn message(kind: MessageKind) -> Option<Schema> {
    if matches!(
        kind,
        MessageKind::TactileFrame | MessageKind::TactileFrameClassic
    ) {
        return None;
    }
    let mut props = serde_json::Map::new();
    let mut required = Vec::new();
    for s in signals(kind) {
        let mut p = serde_json::Map::new();
        let ty = if is_integer(&s) { "integer" } else { "number" };
        p.insert("type".into(), ty.into());
        p.insert("description".into(), describe(&s).into());
        p.insert("minimum".into(), s.min.into());
        p.insert("maximum".into(), s.max.into());
        if !s.unit.is_empty() {
            p.insert("unit".into(), s.unit.into());
        }
        if let Some(table) = s.values {
            props.insert(
                label_key(&s.name),
                serde_json::json!({
                    "type": "string",
                    "description": format!("{}'s label in the DBC's {table} value table", s.name),
                }),
            );
        }
        if kind == MessageKind::TerrainClass && s.name == "Confidence" {
            p.insert("type".into(), serde_json::json!(["number", "null"]));
            p.insert(
                "description".into(),
                format!(
                    "{}; null for unknown ground (TerrainId 255): no terrain was chosen, and the \
                     frame's value is in {REJECTED_CONFIDENCE}",
                    describe(&s)
                )
                .into(),
            );
            props.insert(
                REJECTED_CONFIDENCE.into(),
                serde_json::json!({
                    "type": "number",
                    "unit": s.unit,
                    "description": "unknown ground only: the posterior of the class the unknown-ground checks rejected (the frame's Confidence)",
                }),
            );
        }
        required.push(serde_json::Value::from(s.name.clone()));
        props.insert(s.name.clone(), p.into());
    }
    if kind == MessageKind::NodeStatus {
        props.insert(
            RECORDING_DROPPED.into(),
            serde_json::json!({
                "type": "integer",
                "description": "Live recordings only: frames the recorder dropped so far because it was behind (not on the bus)",
            }),
        );
    }
    let schema = serde_json::json!({
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": format!("presrs.{}", kind.name()),
        "description": format!("CAN message {} as decoded by presrs (names and units of presrs.dbc)", kind.name()),
        "type": "object",
        "properties": props,
        "required": required,
    });
    Some(Schema {
        name: format!("presrs.{}", kind.name()),
        json: schema.to_string(),
    })
}

/// Foxglove's `foxglove.RawImage` in its JSON form (`data` base64).
pub fn raw_image() -> Schema {
    let schema = serde_json::json!({
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "foxglove.RawImage",
        "description": "A raw image",
        "type": "object",
        "properties": {
            "timestamp": {
                "type": "object",
                "title": "time",
                "properties": {
                    "sec": {"type": "integer", "minimum": 0},
                    "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999}
                },
                "description": "Timestamp of image"
            },
            "frame_id": {"type": "string", "description": "Frame of reference for the image."},
            "width": {"type": "integer", "minimum": 0, "description": "Image width"},
            "height": {"type": "integer", "minimum": 0, "description": "Image height"},
            "encoding": {"type": "string", "description": "Encoding of the raw image data"},
            "step": {"type": "integer", "minimum": 0, "description": "Byte length of a single row"},
            "data": {"type": "string", "contentEncoding": "base64", "description": "Raw image data"}
        }
    });
    Schema {
        name: "foxglove.RawImage".into(),
        json: schema.to_string(),
    }
}

/// The simulator's ground truth per leg (only in simulated runs).
pub fn sim_truth() -> Schema {
    let schema = serde_json::json!({
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "presrs.SimTruth",
        "description": "What the simulator knows and the robot does not: the hopper's speed and position and the terrain under it",
        "type": "object",
        "properties": {
            "SpeedMps": {"type": "number", "unit": "m/s", "description": "forward speed of the hopper"},
            "PositionM": {"type": "number", "unit": "m", "description": "distance along the track"},
            "TerrainId": {"type": "integer", "description": "true terrain under the hopper"},
            "Terrain": {"type": "string", "description": "its name"},
            "Gait": {"type": "integer", "description": "gait the leg runs (1..3 for G1..G3)"},
            "Falls": {"type": "integer", "description": "falls so far"}
        },
        "required": ["SpeedMps", "PositionM", "TerrainId", "Terrain", "Gait", "Falls"]
    });
    Schema {
        name: "presrs.SimTruth".into(),
        json: schema.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_fixed_message_has_a_schema_naming_the_dbc_signals_and_units() {
        for kind in MessageKind::ALL {
            let Some(s) = message(kind) else {
                assert!(matches!(
                    kind,
                    MessageKind::TactileFrame | MessageKind::TactileFrameClassic
                ));
                continue;
            };
            let v: serde_json::Value = serde_json::from_str(&s.json).unwrap();
            for sig in signals(kind) {
                let p = &v["properties"][&sig.name];
                assert!(p.is_object(), "{} lacks {}", s.name, sig.name);
                if !sig.unit.is_empty() {
                    assert_eq!(p["unit"], sig.unit);
                }
            }
        }
        let leg = message(MessageKind::LegState).unwrap();
        assert!(leg.json.contains("\"LegAngle\"") && leg.json.contains("\"rad\""));
    }

    #[test]
    fn labels_drop_an_id_suffix_or_add_name() {
        assert_eq!(label_key("TerrainId"), "Terrain");
        assert_eq!(label_key("State"), "StateName");
        assert_eq!(label_key("Id"), "IdName");
    }
}
