//! The bus as ROS 2 messages: each decoded CAN message and each reassembled pressure image
//! becomes one message on its topic, CDR-encoded, for a [`RosSink`] (a Zenoh session, a
//! rosbag2 file). The one place that decides what a ROS 2 user sees; the bridge and the bag
//! writer both use it, so a bag and a live topic carry the same bytes.

use std::collections::HashMap;

use protocol::messages::{self, GaitReason, Message};
use protocol::traffic::{Heard, Traffic};
use protocol::{IdConfig, Stamped, TerrainCatalog};

use crate::Ros2Error;
use crate::messages::{self as ros, Header, Level, Time, to_cdr};
use crate::names::Names;
use crate::types::{self, MsgType};

/// A topic the bridge publishes, relative to the robot's namespace (but `/diagnostics`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum RosTopic {
    /// `footN/terrain`: `presrs_msgs/msg/TerrainClass`, one per step.
    Terrain(u8),
    /// `footN/terrain/model`: the same type, the steps a model decided on the way (`presrs mcap
    /// --ros2 --model`), beside the ones the log carried.
    ModelTerrain(u8),
    /// `footN/contact`: `presrs_msgs/msg/FootContact`.
    Contact(u8),
    /// `footN/image`: `sensor_msgs/msg/Image`, each pressure image (mono8 or mono16).
    Image(u8),
    /// `legN/joint_states`: `sensor_msgs/msg/JointState` (the leg angle, rad, and length, m).
    Joints(u8),
    /// `gait`: `presrs_msgs/msg/GaitState`.
    Gait,
    /// `legN/step`: `presrs_msgs/msg/StepState`, one per hop.
    Step(u8),
    /// `/diagnostics`: `diagnostic_msgs/msg/DiagnosticArray` (node, legs, the bridge).
    Diagnostics,
}

impl RosTopic {
    /// The name relative to the namespace (`foot0/terrain`), or absolute (`/diagnostics`).
    pub fn relative(&self) -> String {
        match *self {
            RosTopic::Terrain(f) => format!("foot{f}/terrain"),
            RosTopic::ModelTerrain(f) => format!("foot{f}/terrain/model"),
            RosTopic::Contact(f) => format!("foot{f}/contact"),
            RosTopic::Image(f) => format!("foot{f}/image"),
            RosTopic::Joints(f) => format!("leg{f}/joint_states"),
            RosTopic::Gait => "gait".into(),
            RosTopic::Step(f) => format!("leg{f}/step"),
            RosTopic::Diagnostics => "/diagnostics".into(),
        }
    }

    /// Its message type.
    pub fn msg_type(&self) -> &'static MsgType {
        match self {
            RosTopic::Terrain(_) | RosTopic::ModelTerrain(_) => &types::TERRAIN_CLASS,
            RosTopic::Contact(_) => &types::FOOT_CONTACT,
            RosTopic::Image(_) => &types::IMAGE,
            RosTopic::Joints(_) => &types::JOINT_STATE,
            RosTopic::Gait => &types::GAIT_STATE,
            RosTopic::Step(_) => &types::STEP_STATE,
            RosTopic::Diagnostics => &types::DIAGNOSTIC_ARRAY,
        }
    }
}

/// Where encoded messages go.
pub trait RosSink {
    /// One CDR message (with its encapsulation header) on `topic`, at `t_ns` on the bus's
    /// clock.
    fn write(&mut self, topic: RosTopic, t_ns: u64, cdr: &[u8]) -> Result<(), Ros2Error>;
}

/// The bridge's own health, reported in `/diagnostics` beside the node's.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BridgeHealth {
    /// Frames the bridge's queue dropped because it was behind (never waited for).
    pub dropped: u64,
    /// Messages handed to the network or file.
    pub published: u64,
    /// Times the Zenoh session lost its router (each ended by Zenoh's reconnect).
    pub router_losses: u64,
}

/// What the encoder made of the traffic.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct EncodeStats {
    /// Frames seen.
    pub frames: u64,
    /// Messages written.
    pub messages: u64,
    /// Frames with our identifiers that did not decode (not published).
    pub undecodable: u64,
    /// Frames with other identifiers (not published).
    pub foreign: u64,
}

/// Frames in, ROS 2 messages out.
pub struct Encoder {
    traffic: Traffic,
    catalog: TerrainCatalog,
    names: Names,
    hardware_id: String,
    buf: Vec<u8>,
    health: BridgeHealth,
    legs: HashMap<u8, ros::DiagnosticStatus>,
    /// Messages written.
    messages: u64,
}

impl Encoder {
    /// An encoder for traffic on `ids`, naming terrains from `catalog`, for the robot `names`.
    pub fn new(ids: IdConfig, catalog: TerrainCatalog, names: &Names) -> Self {
        let ns = names.namespace.trim_matches('/');
        Self {
            traffic: Traffic::new(ids),
            catalog,
            names: names.clone(),
            hardware_id: if ns.is_empty() {
                "presrs".into()
            } else {
                ns.into()
            },
            buf: Vec::with_capacity(8192),
            health: BridgeHealth::default(),
            legs: HashMap::new(),
            messages: 0,
        }
    }

    /// The robot's names.
    pub fn names(&self) -> &Names {
        &self.names
    }

    /// Counts so far.
    pub fn stats(&self) -> EncodeStats {
        let c = self.traffic.counts();
        EncodeStats {
            frames: c.frames,
            undecodable: c.undecodable,
            foreign: c.foreign,
            messages: self.messages,
        }
    }

    /// The bridge's health for the next `/diagnostics`.
    pub fn set_health(&mut self, h: BridgeHealth) {
        self.health = h;
    }

    /// One frame of the traffic.
    pub fn frame(&mut self, st: &Stamped, sink: &mut dyn RosSink) -> Result<(), Ros2Error> {
        let t_ns = st.t_us.saturating_mul(1000);
        let header = |frame_id: String| Header {
            stamp: Time::from_ns(t_ns),
            frame_id,
        };
        let (foot, msg) = match self.traffic.hear(st) {
            Heard::Nothing => return Ok(()),
            Heard::Message { foot, msg } => (foot, msg),
            Heard::Image { foot } => {
                let img = self.traffic.last_image();
                let mut data = Vec::new();
                let (encoding, bpp) = img.mono_bytes(&mut data);
                let m = ros::Image {
                    header: header(format!("foot{foot}")),
                    height: img.rows as u32,
                    width: img.cols as u32,
                    encoding: encoding.into(),
                    is_bigendian: 0,
                    step: img.cols as u32 * bpp,
                    data,
                };
                return self.emit(RosTopic::Image(foot), t_ns, &m, sink);
            }
        };
        match msg {
            // Whole images come as `Heard::Image`, above.
            Message::TactileSegment(_) => Ok(()),
            Message::TerrainClass(c) => {
                let m = self.terrain(header(format!("foot{foot}")), foot, &c);
                self.emit(RosTopic::Terrain(foot), t_ns, &m, sink)
            }
            Message::FootContact(c) => {
                let m = ros::FootContact {
                    header: header(format!("foot{foot}")),
                    foot,
                    stance: c.stance,
                    seq: c.seq,
                    foot_timestamp_us: c.timestamp_us,
                };
                self.emit(RosTopic::Contact(foot), t_ns, &m, sink)
            }
            Message::LegState(s) => {
                let m = ros::JointState {
                    header: header(format!("leg{foot}")),
                    name: vec![format!("leg{foot}_angle"), format!("leg{foot}_length")],
                    position: vec![s.leg_angle_rad, s.leg_length_m],
                    velocity: Vec::new(),
                    effort: Vec::new(),
                };
                self.emit(RosTopic::Joints(foot), t_ns, &m, sink)
            }
            Message::GaitStatus(g) => {
                let m = ros::GaitState {
                    header: header(self.hardware_id.clone()),
                    gait: g.gait,
                    terrain_id: g.terrain,
                    terrain_name: self.catalog.describe(g.terrain),
                    omega_rad_s: g.omega_rad_s as f32,
                    beta_des_rad: g.beta_des_rad as f32,
                    reason: gait_reason(g.reason).into(),
                    foot: g.foot,
                };
                self.emit(RosTopic::Gait, t_ns, &m, sink)
            }
            Message::NodeStatus(s) => {
                let mut status = vec![self.node_status(&s), self.bridge_status()];
                status.extend(self.legs.values().cloned());
                let m = ros::DiagnosticArray {
                    header: header(self.hardware_id.clone()),
                    status,
                };
                self.emit(RosTopic::Diagnostics, t_ns, &m, sink)
            }
            Message::LegStatus(s) => {
                let d = self.leg_status(foot, &s);
                self.legs.insert(foot, d.clone());
                let m = ros::DiagnosticArray {
                    header: header(self.hardware_id.clone()),
                    status: vec![d],
                };
                self.emit(RosTopic::Diagnostics, t_ns, &m, sink)
            }
            // The controller's set points are the leg's business; the leg's state is published.
            Message::LegCommand(_) => Ok(()),
            Message::StepState(s) => {
                let m = ros::StepState {
                    header: header(format!("leg{foot}")),
                    leg: foot,
                    speed_m_s: s.speed_m_s as f32,
                    stance_s: s.stance_s as f32,
                    flight_s: s.flight_s as f32,
                    touchdown_angle_rad: s.touchdown_angle_rad as f32,
                    liftoff_angle_rad: s.liftoff_angle_rad as f32,
                    energy_ratio: s.energy_ratio as f32,
                };
                self.emit(RosTopic::Step(foot), t_ns, &m, sink)
            }
        }
    }

    /// A step a model decided on the way (`presrs mcap --ros2 --model`): on
    /// `footN/terrain/model`, at the time it was decided, as the bus's would be.
    pub fn model_decision(
        &mut self,
        t_us: u64,
        foot: u8,
        c: &messages::TerrainClass,
        sink: &mut dyn RosSink,
    ) -> Result<(), Ros2Error> {
        let t_ns = t_us.saturating_mul(1000);
        let header = Header {
            stamp: Time::from_ns(t_ns),
            frame_id: format!("foot{foot}"),
        };
        let m = self.terrain(header, foot, c);
        self.emit(RosTopic::ModelTerrain(foot), t_ns, &m, sink)
    }

    /// A TerrainClass as its ROS 2 message; unknown ground chose no terrain, so its
    /// `confidence` is NaN (the frame's is the rejected class's posterior).
    fn terrain(&self, header: Header, foot: u8, c: &messages::TerrainClass) -> ros::TerrainClass {
        let unknown = c.terrain == messages::TERRAIN_UNKNOWN;
        ros::TerrainClass {
            header,
            foot,
            step: c.step,
            terrain_id: c.terrain,
            terrain_name: self.catalog.describe(c.terrain),
            confidence: if unknown {
                f32::NAN
            } else {
                (c.confidence_pct / 100.0) as f32
            },
            unknown_reason: c
                .unknown_reason()
                .map(|r| r.name().to_string())
                .unwrap_or_default(),
            damage: (c.damage_pct / 100.0) as f32,
            latency_us: c.latency_us,
            flags: c.flags,
        }
    }

    fn emit<T: serde::Serialize>(
        &mut self,
        topic: RosTopic,
        t_ns: u64,
        msg: &T,
        sink: &mut dyn RosSink,
    ) -> Result<(), Ros2Error> {
        to_cdr(msg, &mut self.buf)?;
        sink.write(topic, t_ns, &self.buf)?;
        self.messages += 1;
        Ok(())
    }

    fn node_status(&self, s: &messages::NodeStatus) -> ros::DiagnosticStatus {
        use messages::NodeState::*;
        let level = match s.state {
            Running => Level::Ok,
            NoModel | BusOff => Level::Error,
            Starting | Degraded | Stopping | WrongImageSize | ErrorPassive => Level::Warn,
        };
        ros::DiagnosticStatus {
            level: level as u8,
            name: format!("{}: terrain node", self.hardware_id),
            message: format!("{:?}", s.state),
            hardware_id: self.hardware_id.clone(),
            values: kv(&[
                ("heartbeat", s.heartbeat.to_string()),
                ("model_id", format!("{:04x}", s.model_id)),
                ("crc_failures", s.crc_failures.to_string()),
                ("incomplete_frames", s.incomplete_frames.to_string()),
                ("bus_errors", s.bus_errors.to_string()),
                ("damage_pct", format!("{:.1}", s.damage_pct)),
            ]),
        }
    }

    fn leg_status(&self, leg: u8, s: &messages::LegStatus) -> ros::DiagnosticStatus {
        use messages::LegMode::*;
        let level = match s.mode {
            Running | Check => Level::Ok,
            Waiting | Stopped | CommandTimeout => Level::Warn,
            DriverFault | DriverSilent => Level::Error,
        };
        ros::DiagnosticStatus {
            level: level as u8,
            name: format!("{}: leg {leg}", self.hardware_id),
            message: format!("{:?}", s.mode),
            hardware_id: self.hardware_id.clone(),
            values: kv(&[
                ("joint", s.joint.to_string()),
                ("command_age_ms", s.command_age_ms.to_string()),
                ("fault_code", s.fault_code.to_string()),
            ]),
        }
    }

    fn bridge_status(&self) -> ros::DiagnosticStatus {
        let h = self.health;
        ros::DiagnosticStatus {
            level: if h.dropped > 0 {
                Level::Warn
            } else {
                Level::Ok
            } as u8,
            name: format!("{}: ROS 2 bridge", self.hardware_id),
            message: if h.dropped > 0 {
                "dropping frames (behind the bus)".into()
            } else {
                "OK".into()
            },
            hardware_id: self.hardware_id.clone(),
            values: kv(&[
                ("dropped_frames", h.dropped.to_string()),
                ("published", h.published.to_string()),
                ("router_losses", h.router_losses.to_string()),
                (
                    "undecodable_frames",
                    self.traffic.counts().undecodable.to_string(),
                ),
            ]),
        }
    }
}

fn gait_reason(r: GaitReason) -> &'static str {
    match r {
        GaitReason::Initial => "initial",
        GaitReason::Terrain => "terrain",
        GaitReason::Unknown => "unknown",
        GaitReason::NodeLost => "node_lost",
    }
}

fn kv(pairs: &[(&str, String)]) -> Vec<ros::KeyValue> {
    pairs
        .iter()
        .map(|(k, v)| ros::KeyValue {
            key: (*k).into(),
            value: v.clone(),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use protocol::messages::{FootContact, TerrainClass};

    #[derive(Default)]
    struct Memory(Vec<(RosTopic, u64, Vec<u8>)>);
    impl RosSink for Memory {
        fn write(&mut self, topic: RosTopic, t_ns: u64, cdr: &[u8]) -> Result<(), Ros2Error> {
            self.0.push((topic, t_ns, cdr.to_vec()));
            Ok(())
        }
    }

    fn stamped(t_us: u64, m: Message, foot: u8) -> Stamped {
        Stamped {
            t_us,
            frame: m.to_frame(&IdConfig::default(), foot).unwrap(),
        }
    }

    #[test]
    fn each_message_on_its_topic_with_the_bus_time() {
        let names = Names::new(0, "robot1").unwrap();
        let mut e = Encoder::new(IdConfig::default(), TerrainCatalog::paper(), &names);
        let mut sink = Memory::default();
        let class = TerrainClass {
            step: 9,
            terrain: 2,
            confidence_pct: 80.0,
            ..Default::default()
        };
        e.frame(
            &stamped(1_500_000, Message::TerrainClass(class), 1),
            &mut sink,
        )
        .unwrap();
        let contact = FootContact {
            stance: true,
            seq: 3,
            timestamp_us: 7,
        };
        e.frame(
            &stamped(2_000_000, Message::FootContact(contact), 0),
            &mut sink,
        )
        .unwrap();
        assert_eq!(sink.0.len(), 2);
        assert_eq!(sink.0[0].0, RosTopic::Terrain(1));
        assert_eq!(sink.0[0].1, 1_500_000_000);
        // Encapsulation, then the stamp: 1 s, 500,000,000 ns.
        assert_eq!(
            &sink.0[0].2[..12],
            &[0, 1, 0, 0, 1, 0, 0, 0, 0, 0x65, 0xcd, 0x1d]
        );
        assert_eq!(sink.0[1].0, RosTopic::Contact(0));
        assert_eq!(e.stats().messages, 2);
    }

    #[test]
    fn malformed_frames_are_counted_not_published() {
        let names = Names::new(0, "").unwrap();
        let mut e = Encoder::new(IdConfig::default(), TerrainCatalog::paper(), &names);
        let mut sink = Memory::default();
        let good = stamped(0, Message::FootContact(FootContact::default()), 0);
        // Same identifier, too short.
        let short = protocol::CanFrame::classic(good.frame.id(), &[1]).unwrap();
        e.frame(
            &Stamped {
                t_us: 0,
                frame: short,
            },
            &mut sink,
        )
        .unwrap();
        let foreign =
            protocol::CanFrame::classic(protocol::frame::make_id(0x7ff, false).unwrap(), &[0; 8])
                .unwrap();
        e.frame(
            &Stamped {
                t_us: 0,
                frame: foreign,
            },
            &mut sink,
        )
        .unwrap();
        assert!(sink.0.is_empty());
        let s = e.stats();
        assert_eq!((s.undecodable, s.foreign), (1, 1));
        // The bridge's own diagnostics count them too.
        let status = e.bridge_status();
        let undecodable = status.values.iter().find(|v| v.key == "undecodable_frames");
        assert_eq!(undecodable.map(|v| v.value.as_str()), Some("1"));
    }
}
