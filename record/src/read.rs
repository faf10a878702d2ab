//! Reading a recording back: the messages of an MCAP file written by [`crate::McapFile`]
//! (or any MCAP file with JSON channels), for plots and checks without Foxglove.

use std::path::Path;

use base64::Engine;

use crate::RecordError;

/// One message of a recording.
#[derive(Clone, Debug, PartialEq)]
pub struct Recorded {
    /// Its topic.
    pub topic: String,
    /// Log time, ns.
    pub log_time_ns: u64,
    /// The message, parsed.
    pub json: serde_json::Value,
}

/// Every JSON message of the MCAP file at `path`, in file order (a file cut short by a kill
/// reads up to its last whole chunk). Channels in other encodings are skipped.
pub fn read_json(path: &Path) -> Result<Vec<Recorded>, RecordError> {
    let bytes = std::fs::read(path).map_err(|source| RecordError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let stream = mcap::MessageStream::new(&bytes).map_err(|e| RecordError::mcap(path, e))?;
    let mut out = Vec::new();
    for m in stream {
        let m = match m {
            Ok(m) => m,
            // The torn end of a killed recording: what came before stands.
            Err(_) if !out.is_empty() => break,
            Err(e) => return Err(RecordError::mcap(path, e)),
        };
        if m.channel.message_encoding != "json" {
            continue;
        }
        let Ok(json) = serde_json::from_slice(&m.data) else {
            continue;
        };
        out.push(Recorded {
            topic: m.channel.topic.clone(),
            log_time_ns: m.log_time,
            json,
        });
    }
    Ok(out)
}

/// Standard base64, padding optional on reading: a `foxglove.RawImage`'s `data`, as any JSON
/// writer may have padded it.
const BASE64: base64::engine::GeneralPurpose = base64::engine::GeneralPurpose::new(
    &base64::alphabet::STANDARD,
    base64::engine::GeneralPurposeConfig::new()
        .with_decode_padding_mode(base64::engine::DecodePaddingMode::Indifferent),
);

/// A `foxglove.RawImage` message's mono8 pixels: (width, height, row-major bytes); `None` for
/// another encoding or a malformed message.
pub fn mono8_image(json: &serde_json::Value) -> Option<(usize, usize, Vec<u8>)> {
    if json["encoding"] != "mono8" {
        return None;
    }
    let (w, h) = (
        json["width"].as_u64()? as usize,
        json["height"].as_u64()? as usize,
    );
    let px = BASE64.decode(json["data"].as_str()?).ok()?;
    (px.len() == w * h).then_some((w, h, px))
}
