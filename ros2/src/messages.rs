//! The ROS 2 messages as Rust values, and their CDR bytes as ROS 2 puts them on the wire and in
//! bags: a 4-byte encapsulation header (CDR, little-endian) and the fields in order, each
//! aligned to its size from the end of the header. CDR itself is the `cdr-encoding` crate's
//! (RustDDS's); the field order is [`crate::types`]'.

use serde::Serialize;

/// CDR_LE: representation id 0x0001, options 0.
const ENCAPSULATION_LE: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// Why a message could not be encoded (a bug: every value here has a CDR form).
#[derive(Debug, thiserror::Error)]
#[error("CDR encoding: {0}")]
pub struct EncodeError(String);

/// `msg` as a ROS 2 serialized message, into `out` (cleared first).
pub fn to_cdr<T: Serialize>(msg: &T, out: &mut Vec<u8>) -> Result<(), EncodeError> {
    out.clear();
    out.extend_from_slice(&ENCAPSULATION_LE);
    cdr_encoding::to_writer::<_, byteorder::LittleEndian, _>(&mut *out, msg)
        .map_err(|e| EncodeError(e.to_string()))
}

/// `builtin_interfaces/msg/Time`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Time {
    /// Seconds.
    pub sec: i32,
    /// Nanoseconds, 0..1e9.
    pub nanosec: u32,
}

impl Time {
    /// From ns on the bus's clock.
    pub fn from_ns(t_ns: u64) -> Self {
        Self {
            sec: (t_ns / 1_000_000_000).min(i32::MAX as u64) as i32,
            nanosec: (t_ns % 1_000_000_000) as u32,
        }
    }
}

/// `std_msgs/msg/Header`.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Header {
    /// When.
    pub stamp: Time,
    /// Which frame: `foot0`, `leg0`, the robot's namespace.
    pub frame_id: String,
}

/// `presrs_msgs/msg/TerrainClass`.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct TerrainClass {
    pub header: Header,
    pub foot: u8,
    pub step: u16,
    pub terrain_id: u8,
    pub terrain_name: String,
    pub confidence: f32,
    pub unknown_reason: String,
    pub damage: f32,
    pub latency_us: u32,
    pub flags: u8,
}

/// `presrs_msgs/msg/FootContact`.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct FootContact {
    pub header: Header,
    pub foot: u8,
    pub stance: bool,
    pub seq: u8,
    pub foot_timestamp_us: u32,
}

/// `presrs_msgs/msg/GaitState`.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct GaitState {
    pub header: Header,
    pub gait: u8,
    pub terrain_id: u8,
    pub terrain_name: String,
    pub omega_rad_s: f32,
    pub beta_des_rad: f32,
    pub reason: String,
    pub foot: u8,
}

/// `presrs_msgs/msg/StepState`.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct StepState {
    pub header: Header,
    pub leg: u8,
    pub speed_m_s: f32,
    pub stance_s: f32,
    pub flight_s: f32,
    pub touchdown_angle_rad: f32,
    pub liftoff_angle_rad: f32,
    pub energy_ratio: f32,
}

/// `sensor_msgs/msg/Image`.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Image {
    pub header: Header,
    pub height: u32,
    pub width: u32,
    pub encoding: String,
    pub is_bigendian: u8,
    pub step: u32,
    #[serde(with = "bytes")]
    pub data: Vec<u8>,
}

/// `sensor_msgs/msg/JointState`.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct JointState {
    pub header: Header,
    pub name: Vec<String>,
    pub position: Vec<f64>,
    pub velocity: Vec<f64>,
    pub effort: Vec<f64>,
}

/// `diagnostic_msgs/msg/KeyValue`.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct KeyValue {
    pub key: String,
    pub value: String,
}

/// `diagnostic_msgs/msg/DiagnosticStatus`.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct DiagnosticStatus {
    /// [`Level`] as its byte.
    pub level: u8,
    pub name: String,
    pub message: String,
    pub hardware_id: String,
    pub values: Vec<KeyValue>,
}

/// `diagnostic_msgs/msg/DiagnosticArray`.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct DiagnosticArray {
    pub header: Header,
    pub status: Vec<DiagnosticStatus>,
}

/// DiagnosticStatus levels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Level {
    /// `OK = 0`
    Ok = 0,
    /// `WARN = 1`
    Warn = 1,
    /// `ERROR = 2`
    Error = 2,
}

/// A `uint8[]` as its length and then its bytes in one write (serde's default writes a
/// sequence element by element; the wire bytes are the same). cdr-encoding's
/// `serialize_bytes` writes the bytes alone, so the length goes first as its own element.
mod bytes {
    use serde::ser::{Serialize, SerializeTuple, Serializer};

    struct Raw<'a>(&'a [u8]);

    impl Serialize for Raw<'_> {
        fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
            s.serialize_bytes(self.0)
        }
    }

    pub fn serialize<S: Serializer>(v: &[u8], s: S) -> Result<S::Ok, S::Error> {
        let len = u32::try_from(v.len()).map_err(serde::ser::Error::custom)?;
        let mut t = s.serialize_tuple(2)?;
        t.serialize_element(&len)?;
        t.serialize_element(&Raw(v))?;
        t.end()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_is_aligned_after_the_encapsulation() {
        let h = Header {
            stamp: Time { sec: 1, nanosec: 2 },
            frame_id: "ab".into(),
        };
        let mut out = Vec::new();
        to_cdr(&h, &mut out).unwrap();
        // header, sec, nanosec, string length 3 (with NUL), "ab\0".
        assert_eq!(
            out,
            [
                0, 1, 0, 0, 1, 0, 0, 0, 2, 0, 0, 0, 3, 0, 0, 0, b'a', b'b', 0
            ]
        );
    }

    #[test]
    fn image_bytes_are_a_length_then_the_bytes() {
        let img = Image {
            data: vec![7, 8, 9],
            ..Default::default()
        };
        let mut out = Vec::new();
        to_cdr(&img, &mut out).unwrap();
        assert_eq!(&out[out.len() - 7..], &[3, 0, 0, 0, 7, 8, 9]);
    }
}
