//! CAN traffic to channels: each decoded message as JSON on its own topic, each reassembled
//! pressure image as a `foxglove.RawImage`. The [`Recorder`] decides what goes where; a
//! [`Sink`] (an MCAP file, a Foxglove WebSocket server) stores or serves it.

use std::collections::HashMap;
use std::fmt::Write;

use base64::Engine;

use protocol::dbc::{Signal, signals, value_table};
use protocol::messages::TerrainClass;
use protocol::tactile::TactileImage;
use protocol::traffic::{Heard, Traffic};
use protocol::{IdConfig, MessageKind, Stamped, TerrainCatalog};

use crate::RecordError;
use crate::schema::{self, Schema};

/// Where a message goes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Topic {
    /// A fixed-layout CAN message; `foot` is 0 for the node's and controller's messages.
    Message(MessageKind, u8),
    /// A foot's reassembled pressure images.
    Image(u8),
    /// TerrainClass computed while recording by a node with a model (`presrs mcap --model`).
    ModelTerrain(u8),
    /// The simulator's ground truth for a leg.
    SimTruth(u8),
}

impl Topic {
    /// The topic's name: `/foot0/contact`, `/leg0/state`, `/node/status`, `/gait`, ...
    pub fn name(&self) -> String {
        match *self {
            Topic::Message(kind, f) => match kind {
                MessageKind::FootContact => format!("/foot{f}/contact"),
                MessageKind::TerrainClass => format!("/foot{f}/terrain"),
                MessageKind::LegState => format!("/leg{f}/state"),
                MessageKind::LegCommand => format!("/leg{f}/command"),
                MessageKind::LegStatus => format!("/leg{f}/status"),
                MessageKind::NodeStatus => "/node/status".into(),
                MessageKind::GaitStatus => "/gait".into(),
                MessageKind::StepState => format!("/leg{f}/step"),
                MessageKind::TactileFrame | MessageKind::TactileFrameClassic => {
                    format!("/foot{f}/image")
                }
            },
            Topic::Image(f) => format!("/foot{f}/image"),
            Topic::ModelTerrain(f) => format!("/foot{f}/terrain/model"),
            Topic::SimTruth(f) => format!("/sim/leg{f}"),
        }
    }

    fn schema(&self) -> Schema {
        match *self {
            Topic::Message(kind, _) => schema::message(kind).unwrap_or_else(schema::raw_image),
            Topic::Image(_) => schema::raw_image(),
            Topic::ModelTerrain(_) => {
                schema::message(MessageKind::TerrainClass).unwrap_or_else(schema::raw_image)
            }
            Topic::SimTruth(_) => schema::sim_truth(),
        }
    }
}

/// A channel as a sink sees it: topic, JSON encoding, schema.
#[derive(Clone, Debug, PartialEq)]
pub struct Channel {
    /// Topic name.
    pub topic: String,
    /// Its schema.
    pub schema: Schema,
}

/// Where channels and their messages go. Message data is JSON; times are ns since the Unix
/// epoch (or since the log's start, for logs that start at 0).
pub trait Sink: Send {
    /// A channel's first message follows; `index` is dense from 0, in order of first use.
    fn add_channel(&mut self, index: usize, channel: &Channel) -> Result<(), RecordError>;
    /// One message on channel `index`.
    fn write(&mut self, index: usize, log_time_ns: u64, data: &[u8]) -> Result<(), RecordError>;
    /// Makes what is written so far readable by others (an MCAP file: closes the chunk).
    fn flush(&mut self) -> Result<(), RecordError>;
    /// Completes the recording (an MCAP file: summary and indexes). Called once.
    fn finish(&mut self) -> Result<(), RecordError>;
}

/// The simulator's truth for one leg at one moment.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SimTruth {
    /// Forward speed, m/s.
    pub speed_m_s: f64,
    /// Distance along the track, m.
    pub position_m: f64,
    /// True terrain under the hopper.
    pub terrain: u8,
    /// The gait the leg runs.
    pub gait: u8,
    /// Falls so far.
    pub falls: u32,
}

/// What a recording holds, and what it left out.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct RecordStats {
    /// Frames seen.
    pub frames: u64,
    /// Messages written (decoded messages, images, model decisions, truth).
    pub messages: u64,
    /// Pressure images written.
    pub images: u64,
    /// TerrainClass written from the model (`/footN/terrain/model`).
    pub model_decisions: u64,
    /// Frames with our identifiers that did not decode (not recorded).
    pub undecodable: u64,
    /// Frames with other identifiers (not recorded).
    pub foreign: u64,
    /// Messages whose time was earlier than the one before, written at that one's time.
    pub reordered: u64,
}

impl std::fmt::Display for RecordStats {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} messages ({} images, {} model TerrainClass); {} undecodable and {} foreign \
             frames not recorded",
            self.messages, self.images, self.model_decisions, self.undecodable, self.foreign
        )
    }
}

/// Decodes frames into channels for one [`Sink`]. Listens for itself ([`Traffic`]): the
/// recording sees every image the traffic carries, whatever the node made of it.
pub struct Recorder {
    traffic: Traffic,
    catalog: TerrainCatalog,
    channels: HashMap<Topic, usize>,
    signals: HashMap<MessageKind, Vec<Signal>>,
    labels: HashMap<&'static str, Vec<(u32, String)>>,
    buf: String,
    bytes: Vec<u8>,
    last_ns: u64,
    recording_dropped: Option<u64>,
    stats: RecordStats,
}

impl Recorder {
    /// A recorder for traffic on `ids`, naming terrains from `catalog`.
    pub fn new(ids: IdConfig, catalog: TerrainCatalog) -> Self {
        let signals = MessageKind::ALL.iter().map(|&k| (k, signals(k))).collect();
        let labels = protocol::dbc::VALUE_TABLES
            .iter()
            .map(|&t| (t, value_table(t, &catalog)))
            .collect();
        Self {
            traffic: Traffic::new(ids),
            catalog,
            channels: HashMap::new(),
            signals,
            labels,
            buf: String::with_capacity(4096),
            bytes: Vec::with_capacity(4096),
            last_ns: 0,
            recording_dropped: None,
            stats: RecordStats::default(),
        }
    }

    /// Counts so far.
    pub fn stats(&self) -> RecordStats {
        let c = self.traffic.counts();
        RecordStats {
            frames: c.frames,
            undecodable: c.undecodable,
            foreign: c.foreign,
            ..self.stats
        }
    }

    /// Live recordings: the recorder's own drop count, added to NodeStatus messages.
    pub fn set_recording_dropped(&mut self, dropped: u64) {
        self.recording_dropped = Some(dropped);
    }

    /// One frame of the traffic.
    pub fn frame(&mut self, st: &Stamped, sink: &mut dyn Sink) -> Result<(), RecordError> {
        let t_ns = st.t_us.saturating_mul(1000);
        match self.traffic.hear(st) {
            Heard::Image { foot } => self.image(foot, t_ns, sink),
            Heard::Message { foot, msg } => {
                let kind = msg.kind();
                self.json_message(kind, st.frame.data())?;
                self.emit(Topic::Message(kind, foot), t_ns, sink)
            }
            Heard::Nothing => Ok(()),
        }
    }

    /// A TerrainClass decided while recording (by a node with a model), on `/footN/terrain/model`.
    pub fn model_decision(
        &mut self,
        t_us: u64,
        foot: u8,
        class: &TerrainClass,
        sink: &mut dyn Sink,
    ) -> Result<(), RecordError> {
        let t_ns = t_us.saturating_mul(1000);
        self.json_message(MessageKind::TerrainClass, &class.encode())?;
        self.stats.model_decisions += 1;
        self.emit(Topic::ModelTerrain(foot), t_ns, sink)
    }

    /// The simulator's truth for leg `foot`.
    pub fn sim_truth(
        &mut self,
        t_us: u64,
        foot: u8,
        truth: &SimTruth,
        sink: &mut dyn Sink,
    ) -> Result<(), RecordError> {
        let b = &mut self.buf;
        b.clear();
        let _ = write!(
            b,
            "{{\"SpeedMps\":{},\"PositionM\":{},\"TerrainId\":{},\"Terrain\":",
            finite(truth.speed_m_s),
            finite(truth.position_m),
            truth.terrain
        );
        json_string(b, &self.catalog.describe(truth.terrain));
        let _ = write!(b, ",\"Gait\":{},\"Falls\":{}}}", truth.gait, truth.falls);
        self.emit(Topic::SimTruth(foot), t_us.saturating_mul(1000), sink)
    }

    /// Writes the message in `self.buf` on `topic`, adding the channel on first use.
    fn emit(&mut self, topic: Topic, t_ns: u64, sink: &mut dyn Sink) -> Result<(), RecordError> {
        let next = self.channels.len();
        let index = *self.channels.entry(topic).or_insert(next);
        if index == next {
            sink.add_channel(
                index,
                &Channel {
                    topic: topic.name(),
                    schema: topic.schema(),
                },
            )?;
        }
        // One clock per recording, but two threads' frames can cross by microseconds on a live
        // node: readers expect time to go forward.
        let t_ns = if t_ns < self.last_ns {
            self.stats.reordered += 1;
            self.last_ns
        } else {
            t_ns
        };
        self.last_ns = t_ns;
        sink.write(index, t_ns, self.buf.as_bytes())?;
        self.stats.messages += 1;
        Ok(())
    }

    /// `self.buf` = the message as JSON: each DBC signal's physical value by its DBC name, and
    /// each value-table signal's label.
    fn json_message(&mut self, kind: MessageKind, data: &[u8]) -> Result<(), RecordError> {
        let b = &mut self.buf;
        b.clear();
        b.push('{');
        let Some(sigs) = self.signals.get(&kind) else {
            return Err(RecordError::Internal("a message kind without signals"));
        };
        // Unknown ground chose no terrain: its confidence is not the step's (schema.rs).
        let unknown = kind == MessageKind::TerrainClass
            && sigs
                .iter()
                .find(|s| s.name == "TerrainId")
                .is_some_and(|s| s.raw(data) == i64::from(protocol::messages::TERRAIN_UNKNOWN));
        let mut rejected = None;
        for (i, s) in sigs.iter().enumerate() {
            if i > 0 {
                b.push(',');
            }
            let _ = write!(b, "\"{}\":", s.name);
            if unknown && s.name == "Confidence" {
                b.push_str("null");
                rejected = Some(finite(s.physical(data)));
            } else if schema::is_integer(s) {
                let _ = write!(b, "{}", s.raw(data));
            } else {
                let _ = write!(b, "{}", finite(s.physical(data)));
            }
            if let Some(table) = s.values {
                let v = s.raw(data);
                let label = self
                    .labels
                    .get(table)
                    .and_then(|t| t.iter().find(|(k, _)| *k as i64 == v))
                    .map(|(_, l)| l.as_str());
                let _ = write!(b, ",\"{}\":", schema::label_key(&s.name));
                match label {
                    Some(l) => json_string(b, l),
                    None => {
                        let _ = write!(b, "\"{v}\"");
                    }
                }
            }
        }
        if let Some(c) = rejected {
            let _ = write!(b, ",\"{}\":{c}", schema::REJECTED_CONFIDENCE);
        }
        if kind == MessageKind::NodeStatus
            && let Some(n) = self.recording_dropped
        {
            let _ = write!(b, ",\"{}\":{n}", schema::RECORDING_DROPPED);
        }
        b.push('}');
        Ok(())
    }

    /// The reassembler's last image as a `foxglove.RawImage` on `/footN/image`.
    fn image(&mut self, foot: u8, t_ns: u64, sink: &mut dyn Sink) -> Result<(), RecordError> {
        let img: &TactileImage = self.traffic.last_image();
        let bytes = &mut self.bytes;
        // Foxglove reads mono16 little-endian.
        let (encoding, bpp) = img.mono_bytes(bytes);
        let b = &mut self.buf;
        b.clear();
        let _ = write!(
            b,
            "{{\"timestamp\":{{\"sec\":{},\"nsec\":{}}},\"frame_id\":\"foot{foot}\",\"width\":{},\"height\":{},\"encoding\":\"{encoding}\",\"step\":{},\"data\":\"",
            t_ns / 1_000_000_000,
            t_ns % 1_000_000_000,
            img.cols,
            img.rows,
            img.cols as usize * bpp as usize
        );
        base64::engine::general_purpose::STANDARD.encode_string(bytes.as_slice(), b);
        b.push_str("\"}");
        self.stats.images += 1;
        self.emit(Topic::Image(foot), t_ns, sink)
    }
}

/// JSON has no NaN or infinity; the decoders never produce them, but a caller's truth might.
fn finite(v: f64) -> f64 {
    if v.is_finite() { v } else { 0.0 }
}

fn json_string(b: &mut String, s: &str) {
    b.push('"');
    for c in s.chars() {
        match c {
            '"' => b.push_str("\\\""),
            '\\' => b.push_str("\\\\"),
            c if (c as u32) < 0x20 => {
                let _ = write!(b, "\\u{:04x}", c as u32);
            }
            c => b.push(c),
        }
    }
    b.push('"');
}

#[cfg(test)]
mod tests {
    use super::*;
    use protocol::messages::{
        FootContact, GaitReason, GaitStatus, LegState, Message, NodeState, NodeStatus,
        TERRAIN_UNKNOWN,
    };
    use protocol::tactile::{ImageRef, Segmenter, Variant};

    /// Keeps what it is given.
    #[derive(Default)]
    pub(crate) struct Memory {
        pub channels: Vec<Channel>,
        pub messages: Vec<(usize, u64, String)>,
    }

    impl Sink for Memory {
        fn add_channel(&mut self, index: usize, channel: &Channel) -> Result<(), RecordError> {
            assert_eq!(index, self.channels.len());
            self.channels.push(channel.clone());
            Ok(())
        }
        fn write(&mut self, index: usize, t: u64, data: &[u8]) -> Result<(), RecordError> {
            self.messages
                .push((index, t, String::from_utf8(data.to_vec()).unwrap()));
            Ok(())
        }
        fn flush(&mut self) -> Result<(), RecordError> {
            Ok(())
        }
        fn finish(&mut self) -> Result<(), RecordError> {
            Ok(())
        }
    }

    fn stamped(t_us: u64, m: Message, foot: u8) -> Stamped {
        Stamped {
            t_us,
            frame: m.to_frame(&IdConfig::default(), foot).unwrap(),
        }
    }

    fn json(m: &Memory, topic: &str) -> Vec<serde_json::Value> {
        let i = m.channels.iter().position(|c| c.topic == topic).unwrap();
        m.messages
            .iter()
            .filter(|(c, _, _)| *c == i)
            .map(|(_, _, s)| serde_json::from_str(s).unwrap())
            .collect()
    }

    #[test]
    fn messages_are_json_with_the_dbc_names_physical_values_and_labels() {
        let mut r = Recorder::new(IdConfig::default(), TerrainCatalog::paper());
        let mut m = Memory::default();
        let leg = LegState {
            leg_angle_rad: -0.1234,
            leg_length_m: 0.3,
            timestamp_us: 77,
        };
        r.frame(&stamped(10, Message::LegState(leg), 2), &mut m)
            .unwrap();
        let gait = GaitStatus {
            gait: 3,
            terrain: 0,
            omega_rad_s: 12.5,
            beta_des_rad: 0.57,
            reason: GaitReason::Terrain,
            foot: 0,
        };
        r.frame(&stamped(20, Message::GaitStatus(gait), 0), &mut m)
            .unwrap();
        let status = NodeStatus {
            heartbeat: 9,
            state: NodeState::Running,
            ..Default::default()
        };
        r.set_recording_dropped(4);
        r.frame(&stamped(30, Message::NodeStatus(status), 0), &mut m)
            .unwrap();
        let l = &json(&m, "/leg2/state")[0];
        assert_eq!(l["LegAngle"], -0.1234);
        assert_eq!(l["LegLength"], 0.3);
        assert_eq!(l["TimestampUs"], 77);
        let g = &json(&m, "/gait")[0];
        assert_eq!(g["ActiveGait"], 3);
        assert_eq!(g["Omega"], 12.5);
        assert_eq!(g["ReasonName"], "terrain");
        assert_eq!(g["Terrain"], TerrainCatalog::paper().describe(0));
        let s = &json(&m, "/node/status")[0];
        assert_eq!(s["StateName"], "running");
        assert_eq!(s["RecordingDropped"], 4);
        assert_eq!(m.messages[0].1, 10_000, "log time in ns");
        assert_eq!(m.channels[0].schema.name, "presrs.LegState");
        // A known step's confidence is the frame's; unknown ground's is null, the frame's value
        // kept as the rejected class's.
        let tc = |terrain| TerrainClass {
            step: 4,
            terrain,
            confidence_pct: 90.0,
            damage_pct: 0.0,
            flags: 0,
            latency_us: 0,
        };
        r.frame(&stamped(40, Message::TerrainClass(tc(0)), 1), &mut m)
            .unwrap();
        r.frame(
            &stamped(50, Message::TerrainClass(tc(TERRAIN_UNKNOWN)), 1),
            &mut m,
        )
        .unwrap();
        let t = json(&m, "/foot1/terrain");
        assert_eq!(
            (t[0]["Confidence"].as_f64(), t[0].get("RejectedConfidence")),
            (Some(90.0), None)
        );
        assert!(t[1]["Confidence"].is_null(), "{}", t[1]);
        assert_eq!(t[1]["RejectedConfidence"], 90.0);
        let schema: serde_json::Value =
            serde_json::from_str(&schema::message(MessageKind::TerrainClass).unwrap().json)
                .unwrap();
        assert_eq!(schema["properties"]["Confidence"]["type"][1], "null");
    }

    #[test]
    fn a_complete_image_is_one_raw_image_and_a_broken_one_none() {
        let ids = IdConfig::default();
        let mut r = Recorder::new(ids.clone(), TerrainCatalog::paper());
        let mut m = Memory::default();
        let px: Vec<u16> = (0..44 * 44).map(|i| (i % 251) as u16).collect();
        let img = ImageRef {
            rows: 44,
            cols: 44,
            bits: 8,
            timestamp_us: 5,
            pixels: &px,
        };
        let seg = Segmenter::new(Variant::Fd, ids);
        let mut frames = Vec::new();
        seg.frames(1, 0, &img, &mut frames).unwrap();
        for (i, f) in frames.iter().enumerate() {
            r.frame(
                &Stamped {
                    t_us: 100 + i as u64,
                    frame: *f,
                },
                &mut m,
            )
            .unwrap();
        }
        // The same image again without its third segment: never completes.
        for (i, f) in frames.iter().enumerate().filter(|(i, _)| *i != 2) {
            r.frame(
                &Stamped {
                    t_us: 200 + i as u64,
                    frame: *f,
                },
                &mut m,
            )
            .unwrap();
        }
        let images = json(&m, "/foot1/image");
        assert_eq!(images.len(), 1);
        let i = &images[0];
        assert_eq!(
            (i["width"].as_u64(), i["height"].as_u64()),
            (Some(44), Some(44))
        );
        assert_eq!(i["encoding"], "mono8");
        assert_eq!(i["frame_id"], "foot1");
        let data = i["data"].as_str().unwrap();
        assert_eq!(data.len(), 44 * 44 / 3 * 4 + 4, "base64 of 1936 bytes");
        assert!(data.starts_with("AAECAwQF"), "0,1,2,3,4,5 in base64");
        assert_eq!(r.stats().images, 1);
    }

    #[test]
    fn a_16_bit_image_is_mono16_little_endian() {
        let ids = IdConfig::default();
        let mut r = Recorder::new(ids.clone(), TerrainCatalog::paper());
        let mut m = Memory::default();
        let px: Vec<u16> = (0..16 * 12).map(|i| 0x0100 * i as u16 + 7).collect();
        let img = ImageRef {
            rows: 12,
            cols: 16,
            bits: 16,
            timestamp_us: 0,
            pixels: &px,
        };
        let mut frames = Vec::new();
        Segmenter::new(Variant::Fd, ids)
            .frames(0, 3, &img, &mut frames)
            .unwrap();
        for f in frames {
            r.frame(&Stamped { t_us: 9, frame: f }, &mut m).unwrap();
        }
        let i = &json(&m, "/foot0/image")[0];
        assert_eq!(i["encoding"], "mono16");
        assert_eq!(
            (i["width"].as_u64(), i["height"].as_u64()),
            (Some(16), Some(12))
        );
        assert_eq!(i["step"], 32, "two bytes per pixel");
        // Pixels 7, 0x0107, 0x0207 little-endian: 07 00 07 01 07 02 -> "BwAHAQcC".
        assert!(i["data"].as_str().unwrap().starts_with("BwAHAQcC"));
    }

    #[test]
    fn foreign_and_malformed_frames_are_counted_not_recorded() {
        let ids = IdConfig::default();
        let mut r = Recorder::new(ids.clone(), TerrainCatalog::paper());
        let mut m = Memory::default();
        let good = stamped(1, Message::FootContact(FootContact::default()), 0);
        let mut bad = good;
        bad.frame =
            protocol::CanFrame::classic(good.frame.id(), &[7, 0, 0, 0, 0, 0, 0, 0]).unwrap();
        let foreign = Stamped {
            t_us: 2,
            frame: protocol::CanFrame::classic(
                protocol::frame::make_id(0x7FF, false).unwrap(),
                &[1],
            )
            .unwrap(),
        };
        for f in [good, bad, foreign] {
            r.frame(&f, &mut m).unwrap();
        }
        let s = r.stats();
        assert_eq!((s.messages, s.undecodable, s.foreign), (1, 1, 1));
        assert_eq!(
            s.to_string(),
            "1 messages (0 images, 0 model TerrainClass); 1 undecodable and 1 foreign frames \
             not recorded"
        );
    }

    #[test]
    fn time_never_goes_back() {
        let mut r = Recorder::new(IdConfig::default(), TerrainCatalog::paper());
        let mut m = Memory::default();
        for t in [5, 3, 9] {
            r.frame(
                &stamped(t, Message::FootContact(FootContact::default()), 0),
                &mut m,
            )
            .unwrap();
        }
        let t: Vec<u64> = m.messages.iter().map(|x| x.1).collect();
        assert_eq!(t, [5000, 5000, 9000]);
        assert_eq!(r.stats().reordered, 1);
    }
}
