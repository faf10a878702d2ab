//! The ROS 2 interfaces the bridge publishes: their fields (which give the RIHS01 type hash,
//! [`crate::typehash`]) and their `.msg` text (which a rosbag2 file carries as its schema).
//! Our own three are the files of `ros2/presrs_msgs/msg/`, the package a ROS 2 lab builds with
//! `colcon build`; the standard ones are copied field for field from their ROS 2 packages.

/// A field's element type (ROS 2's `type_description_interfaces/msg/FieldType` ids).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Base {
    /// Another message type, by its full name (`std_msgs/msg/Header`).
    Nested(&'static str),
    /// `bool`
    Bool,
    /// `byte`
    Byte,
    /// `uint8`
    U8,
    /// `uint16`
    U16,
    /// `int32`
    I32,
    /// `uint32`
    U32,
    /// `float32`
    F32,
    /// `float64`
    F64,
    /// `string` (unbounded)
    String,
}

impl Base {
    /// The FieldType id of a single value; an unbounded sequence adds 144.
    pub fn type_id(self) -> u8 {
        match self {
            Base::Nested(_) => 1,
            Base::U8 => 3,
            Base::U16 => 5,
            Base::I32 => 6,
            Base::U32 => 7,
            Base::F32 => 10,
            Base::F64 => 11,
            Base::Bool => 15,
            Base::Byte => 16,
            Base::String => 17,
        }
    }
}

/// One field: its name, element type, and whether it is an unbounded sequence (`T[]`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Field {
    /// The field's name.
    pub name: &'static str,
    /// Its element type.
    pub base: Base,
    /// `T[]`.
    pub sequence: bool,
}

const fn f(name: &'static str, base: Base) -> Field {
    Field {
        name,
        base,
        sequence: false,
    }
}

const fn seq(name: &'static str, base: Base) -> Field {
    Field {
        name,
        base,
        sequence: true,
    }
}

/// A message type.
#[derive(Debug, PartialEq, Eq)]
pub struct MsgType {
    /// `package/msg/Name`.
    pub name: &'static str,
    /// Its fields, in order.
    pub fields: &'static [Field],
    /// Its `.msg` definition.
    pub msg: &'static str,
}

impl MsgType {
    /// The DDS type name rmw_zenoh puts in key expressions: `pkg::msg::dds_::Name_`.
    pub fn dds_name(&self) -> String {
        let mut parts = self.name.splitn(3, '/');
        let (pkg, kind, short) = (
            parts.next().unwrap_or(""),
            parts.next().unwrap_or(""),
            parts.next().unwrap_or(""),
        );
        format!("{pkg}::{kind}::dds_::{short}_")
    }

    /// The types this one nests, directly.
    pub fn nested(&self) -> impl Iterator<Item = &'static MsgType> + '_ {
        self.fields.iter().filter_map(|f| match f.base {
            Base::Nested(n) => by_name(n),
            _ => None,
        })
    }
}

const HEADER: Base = Base::Nested("std_msgs/msg/Header");

/// `builtin_interfaces/msg/Time`.
pub static TIME: MsgType = MsgType {
    name: "builtin_interfaces/msg/Time",
    fields: &[f("sec", Base::I32), f("nanosec", Base::U32)],
    msg: "int32 sec\nuint32 nanosec\n",
};

/// `std_msgs/msg/Header`.
pub static HEADER_MSG: MsgType = MsgType {
    name: "std_msgs/msg/Header",
    fields: &[
        f("stamp", Base::Nested("builtin_interfaces/msg/Time")),
        f("frame_id", Base::String),
    ],
    msg: "builtin_interfaces/Time stamp\nstring frame_id\n",
};

/// `presrs_msgs/msg/TerrainClass`.
pub static TERRAIN_CLASS: MsgType = MsgType {
    name: "presrs_msgs/msg/TerrainClass",
    fields: &[
        f("header", HEADER),
        f("foot", Base::U8),
        f("step", Base::U16),
        f("terrain_id", Base::U8),
        f("terrain_name", Base::String),
        f("confidence", Base::F32),
        f("unknown_reason", Base::String),
        f("damage", Base::F32),
        f("latency_us", Base::U32),
        f("flags", Base::U8),
    ],
    msg: include_str!("../presrs_msgs/msg/TerrainClass.msg"),
};

/// `presrs_msgs/msg/FootContact`.
pub static FOOT_CONTACT: MsgType = MsgType {
    name: "presrs_msgs/msg/FootContact",
    fields: &[
        f("header", HEADER),
        f("foot", Base::U8),
        f("stance", Base::Bool),
        f("seq", Base::U8),
        f("foot_timestamp_us", Base::U32),
    ],
    msg: include_str!("../presrs_msgs/msg/FootContact.msg"),
};

/// `presrs_msgs/msg/GaitState`.
pub static GAIT_STATE: MsgType = MsgType {
    name: "presrs_msgs/msg/GaitState",
    fields: &[
        f("header", HEADER),
        f("gait", Base::U8),
        f("terrain_id", Base::U8),
        f("terrain_name", Base::String),
        f("omega_rad_s", Base::F32),
        f("beta_des_rad", Base::F32),
        f("reason", Base::String),
        f("foot", Base::U8),
    ],
    msg: include_str!("../presrs_msgs/msg/GaitState.msg"),
};

/// `presrs_msgs/msg/StepState`.
pub static STEP_STATE: MsgType = MsgType {
    name: "presrs_msgs/msg/StepState",
    fields: &[
        f("header", HEADER),
        f("leg", Base::U8),
        f("speed_m_s", Base::F32),
        f("stance_s", Base::F32),
        f("flight_s", Base::F32),
        f("touchdown_angle_rad", Base::F32),
        f("liftoff_angle_rad", Base::F32),
        f("energy_ratio", Base::F32),
    ],
    msg: include_str!("../presrs_msgs/msg/StepState.msg"),
};

/// `sensor_msgs/msg/Image`.
pub static IMAGE: MsgType = MsgType {
    name: "sensor_msgs/msg/Image",
    fields: &[
        f("header", HEADER),
        f("height", Base::U32),
        f("width", Base::U32),
        f("encoding", Base::String),
        f("is_bigendian", Base::U8),
        f("step", Base::U32),
        seq("data", Base::U8),
    ],
    msg: "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\n\
          uint8 is_bigendian\nuint32 step\nuint8[] data\n",
};

/// `sensor_msgs/msg/JointState`.
pub static JOINT_STATE: MsgType = MsgType {
    name: "sensor_msgs/msg/JointState",
    fields: &[
        f("header", HEADER),
        seq("name", Base::String),
        seq("position", Base::F64),
        seq("velocity", Base::F64),
        seq("effort", Base::F64),
    ],
    msg: "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\n\
          float64[] effort\n",
};

/// `diagnostic_msgs/msg/KeyValue`.
pub static KEY_VALUE: MsgType = MsgType {
    name: "diagnostic_msgs/msg/KeyValue",
    fields: &[f("key", Base::String), f("value", Base::String)],
    msg: "string key\nstring value\n",
};

/// `diagnostic_msgs/msg/DiagnosticStatus`.
pub static DIAGNOSTIC_STATUS: MsgType = MsgType {
    name: "diagnostic_msgs/msg/DiagnosticStatus",
    fields: &[
        f("level", Base::Byte),
        f("name", Base::String),
        f("message", Base::String),
        f("hardware_id", Base::String),
        seq("values", Base::Nested("diagnostic_msgs/msg/KeyValue")),
    ],
    msg: "byte OK=0\nbyte WARN=1\nbyte ERROR=2\nbyte STALE=3\nbyte level\nstring name\n\
          string message\nstring hardware_id\nKeyValue[] values\n",
};

/// `diagnostic_msgs/msg/DiagnosticArray`.
pub static DIAGNOSTIC_ARRAY: MsgType = MsgType {
    name: "diagnostic_msgs/msg/DiagnosticArray",
    fields: &[
        f("header", HEADER),
        seq(
            "status",
            Base::Nested("diagnostic_msgs/msg/DiagnosticStatus"),
        ),
    ],
    msg: "std_msgs/Header header\nDiagnosticStatus[] status\n",
};

/// Every type the bridge knows, nested ones included.
pub static ALL: [&MsgType; 11] = [
    &TIME,
    &HEADER_MSG,
    &TERRAIN_CLASS,
    &FOOT_CONTACT,
    &GAIT_STATE,
    &STEP_STATE,
    &IMAGE,
    &JOINT_STATE,
    &KEY_VALUE,
    &DIAGNOSTIC_STATUS,
    &DIAGNOSTIC_ARRAY,
];

/// The type named `name` (`pkg/msg/Name`).
pub fn by_name(name: &str) -> Option<&'static MsgType> {
    ALL.iter().copied().find(|t| t.name == name)
}

/// Every type `t` nests, at any depth, sorted by name, each once.
pub fn referenced(t: &MsgType) -> Vec<&'static MsgType> {
    let mut out: Vec<&'static MsgType> = Vec::new();
    let mut todo: Vec<&'static MsgType> = t.nested().collect();
    while let Some(n) = todo.pop() {
        if !out.iter().any(|o| o.name == n.name) {
            out.push(n);
            todo.extend(n.nested());
        }
    }
    out.sort_by_key(|t| t.name);
    out
}

/// The `ros2msg` schema of `t` as rosbag2 writes it: its own definition, then each type it
/// references after a line of 80 `=` and `MSG: pkg/Name`.
pub fn schema_text(t: &MsgType) -> String {
    let mut s = t.msg.to_string();
    for r in referenced(t) {
        s.push_str(&"=".repeat(80));
        s.push('\n');
        s.push_str("MSG: ");
        s.push_str(&r.name.replacen("/msg/", "/", 1));
        s.push('\n');
        s.push_str(r.msg);
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_nested_type_is_known_and_the_msg_files_name_the_same_fields() {
        for t in ALL {
            for f in t.fields {
                if let Base::Nested(n) = f.base {
                    assert!(by_name(n).is_some(), "{}: {n}", t.name);
                }
            }
            // Each field name appears in the .msg text, in order.
            let mut at = 0;
            for f in t.fields {
                let i = t.msg[at..]
                    .find(&format!(" {}\n", f.name))
                    .unwrap_or_else(|| panic!("{}: {} not in its .msg", t.name, f.name));
                at += i + 1;
            }
        }
    }

    #[test]
    fn dds_names_and_references() {
        assert_eq!(
            TERRAIN_CLASS.dds_name(),
            "presrs_msgs::msg::dds_::TerrainClass_"
        );
        let r: Vec<_> = referenced(&DIAGNOSTIC_ARRAY)
            .iter()
            .map(|t| t.name)
            .collect();
        assert_eq!(
            r,
            [
                "builtin_interfaces/msg/Time",
                "diagnostic_msgs/msg/DiagnosticStatus",
                "diagnostic_msgs/msg/KeyValue",
                "std_msgs/msg/Header"
            ]
        );
        assert!(schema_text(&IMAGE).contains("MSG: std_msgs/Header\n"));
    }
}
