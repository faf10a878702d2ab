//! The DBC description of the protocol, generated from one table so it cannot drift from the
//! encoders (a test checks `presrs.dbc` against this generator, and the interop test checks the
//! encoders against Python `cantools` reading the DBC).
//!
//! Per-foot messages get one DBC message per identifier (`FootContact_F0` .. `_F7`). The FD
//! tactile message is multiplexed by `SegmentIndex`: value 0 is the header, values 1-133 are data
//! segments (extended multiplexing, `SG_MUL_VAL_`); the classic variant likewise with header
//! parts 0, 1, 2 and data from 3.

use std::fmt::Write;

use crate::ids::{IdConfig, MAX_FEET, MessageKind};
use crate::messages::{
    ANGLE_SCALE_RAD, ENERGY_RATIO_SCALE, LENGTH_SCALE_M, OMEGA_SCALE, PERCENT_SCALE,
    PHASE_TIME_SCALE_S, SPEED_SCALE_M_S, STEP_ANGLE_SCALE_RAD, TERRAIN_UNKNOWN,
};
use crate::tactile::Variant;
use crate::terrain::TerrainCatalog;

#[derive(Clone, Copy, Debug, PartialEq)]
enum Mux {
    None,
    Multiplexor,
    Value(u32),
    Range(u32, u32),
}

/// One signal of a message, as the DBC describes it (little-endian, `start` is the first bit).
#[derive(Clone, Debug)]
pub struct Signal {
    /// The DBC's name (`LegAngle`, `TerrainId`).
    pub name: String,
    /// First bit, counted from bit 0 of byte 0.
    pub start: u32,
    /// Length in bits.
    pub len: u32,
    /// Two's complement.
    pub signed: bool,
    /// Physical value per bit.
    pub factor: f64,
    /// Smallest physical value.
    pub min: f64,
    /// Largest physical value.
    pub max: f64,
    /// Physical unit (`m`, `rad`, `%`, `us`; empty for counts and ids).
    pub unit: &'static str,
    mux: Mux,
    /// The value table naming the signal's values (see [`value_table`]).
    pub values: Option<&'static str>,
}

type Sig = Signal;

impl Signal {
    /// The signal's raw integer in `data` (zero where `data` is short).
    pub fn raw(&self, data: &[u8]) -> i64 {
        let mut v = 0u64;
        for i in 0..self.len {
            let bit = self.start + i;
            let byte = data.get((bit / 8) as usize).copied().unwrap_or(0);
            v |= (((byte >> (bit % 8)) & 1) as u64) << i;
        }
        if self.signed && self.len < 64 && v & (1 << (self.len - 1)) != 0 {
            (v | (!0u64 << self.len)) as i64
        } else {
            v as i64
        }
    }

    /// The physical value in `data`: raw times factor. A factor of 1/n divides by n, so that
    /// 3 x 0.1 mrad reads 0.0003 rad, not 0.00030000000000000003.
    pub fn physical(&self, data: &[u8]) -> f64 {
        let raw = self.raw(data) as f64;
        let inv = 1.0 / self.factor;
        if self.factor < 1.0 && (inv - inv.round()).abs() < 1e-9 {
            raw / inv.round()
        } else {
            raw * self.factor
        }
    }
}

fn sig(name: &str, start: u32, len: u32, signed: bool, factor: f64, unit: &'static str) -> Sig {
    let (lo, hi) = if signed {
        (
            -(1i64 << (len - 1)) as f64,
            ((1i64 << (len - 1)) - 1) as f64,
        )
    } else {
        (0.0, ((1u64 << len) - 1) as f64)
    };
    Sig {
        name: name.to_string(),
        start,
        len,
        signed,
        factor,
        min: round(lo * factor),
        max: round(hi * factor),
        unit,
        mux: Mux::None,
        values: None,
    }
}

fn round(v: f64) -> f64 {
    (v * 1e6).round() / 1e6
}

impl Sig {
    fn mux(mut self, m: Mux) -> Self {
        self.mux = m;
        self
    }
    fn range(mut self, min: f64, max: f64) -> Self {
        self.min = min;
        self.max = max;
        self
    }
    fn values(mut self, v: &'static str) -> Self {
        self.values = Some(v);
        self
    }
}

/// The signals of `kind`'s fixed-layout messages, as in the DBC: what third-party tools name
/// and scale. For the tactile messages, the multiplexed segment layout.
pub fn signals(kind: MessageKind) -> Vec<Signal> {
    match kind {
        MessageKind::LegCommand => vec![
            sig("LegLengthSetpoint", 0, 16, false, LENGTH_SCALE_M, "m"),
            sig(
                "TouchdownAngleSetpoint",
                16,
                16,
                true,
                ANGLE_SCALE_RAD,
                "rad",
            ),
            sig("GaitId", 32, 8, false, 1.0, ""),
            sig("Phase", 40, 8, false, 1.0, "")
                .range(0.0, 1.0)
                .values("Phase"),
            sig("Sequence", 48, 8, false, 1.0, ""),
        ],
        MessageKind::FootContact => vec![
            sig("Contact", 0, 8, false, 1.0, "")
                .range(0.0, 1.0)
                .values("Phase"),
            sig("Sequence", 8, 8, false, 1.0, ""),
            sig("TimestampUs", 16, 32, false, 1.0, "us"),
        ],
        MessageKind::LegState => vec![
            sig("LegAngle", 0, 16, true, ANGLE_SCALE_RAD, "rad"),
            sig("LegLength", 16, 16, false, LENGTH_SCALE_M, "m"),
            sig("TimestampUs", 32, 32, false, 1.0, "us"),
        ],
        MessageKind::LegStatus => vec![
            sig("Mode", 0, 8, false, 1.0, "")
                .range(0.0, 6.0)
                .values("LegMode"),
            sig("Joint", 8, 8, false, 1.0, "").range(0.0, 2.0),
            sig("CommandAgeMs", 16, 16, false, 1.0, "ms"),
            sig("FaultCode", 32, 32, false, 1.0, ""),
        ],
        MessageKind::TerrainClass => vec![
            sig("Step", 0, 16, false, 1.0, ""),
            sig("TerrainId", 16, 8, false, 1.0, "").values("Terrain"),
            sig("Confidence", 24, 8, false, PERCENT_SCALE, "%").range(0.0, 100.0),
            sig("DamagePercent", 32, 8, false, PERCENT_SCALE, "%").range(0.0, 100.0),
            sig("FlagRepaired", 40, 1, false, 1.0, ""),
            sig("FlagLowConfidence", 41, 1, false, 1.0, ""),
            sig("FlagNoSample", 42, 1, false, 1.0, ""),
            sig("FlagMultiFrame", 43, 1, false, 1.0, ""),
            sig("FlagNoContact", 44, 1, false, 1.0, ""),
            sig("FlagEnergy", 45, 1, false, 1.0, ""),
            sig("UnknownReason", 46, 2, false, 1.0, "")
                .range(0.0, 3.0)
                .values("UnknownReason"),
            sig("LatencyUs", 48, 16, false, 1.0, "us"),
        ],
        MessageKind::NodeStatus => vec![
            sig("Heartbeat", 0, 8, false, 1.0, ""),
            sig("State", 8, 8, false, 1.0, "")
                .range(0.0, 7.0)
                .values("NodeState"),
            sig("ModelId", 16, 16, false, 1.0, ""),
            sig("CrcFailures", 32, 8, false, 1.0, ""),
            sig("IncompleteFrames", 40, 8, false, 1.0, ""),
            sig("BusErrors", 48, 8, false, 1.0, ""),
            sig("DamagePercent", 56, 8, false, PERCENT_SCALE, "%").range(0.0, 100.0),
        ],
        MessageKind::GaitStatus => vec![
            sig("ActiveGait", 0, 8, false, 1.0, ""),
            sig("TerrainId", 8, 8, false, 1.0, "").values("Terrain"),
            sig("Omega", 16, 16, false, OMEGA_SCALE, "rad/s"),
            sig("BetaDes", 32, 16, true, ANGLE_SCALE_RAD, "rad"),
            sig("Reason", 48, 8, false, 1.0, "")
                .range(0.0, 3.0)
                .values("GaitReason"),
            sig("Foot", 56, 8, false, 1.0, "").range(0.0, 7.0),
        ],
        MessageKind::StepState => vec![
            sig("Speed", 0, 16, true, SPEED_SCALE_M_S, "m/s"),
            sig("StanceTime", 16, 8, false, PHASE_TIME_SCALE_S, "s"),
            sig("FlightTime", 24, 8, false, PHASE_TIME_SCALE_S, "s"),
            sig("TouchdownAngle", 32, 12, true, STEP_ANGLE_SCALE_RAD, "rad"),
            sig("LiftoffAngle", 44, 12, true, STEP_ANGLE_SCALE_RAD, "rad"),
            sig("EnergyRatio", 56, 8, false, ENERGY_RATIO_SCALE, ""),
        ],
        MessageKind::TactileFrame => tactile_signals(Variant::Fd),
        MessageKind::TactileFrameClassic => tactile_signals(Variant::Classic),
    }
}

/// The multiplexed segment layout of a tactile variant: segment 0 the header, the others
/// pixels (the classic variant's CRC and timestamp in segments 1 and 2).
fn tactile_signals(variant: Variant) -> Vec<Signal> {
    match variant {
        Variant::Fd => {
            let mut v = vec![
                sig("FrameSeq", 0, 8, false, 1.0, ""),
                sig("SegmentIndex", 8, 8, false, 1.0, "").mux(Mux::Multiplexor),
                sig("Rows", 16, 8, false, 1.0, "").mux(Mux::Value(0)),
                sig("Cols", 24, 8, false, 1.0, "").mux(Mux::Value(0)),
                sig("BitsPerPixel", 32, 8, false, 1.0, "").mux(Mux::Value(0)),
                sig("SegmentCount", 40, 8, false, 1.0, "").mux(Mux::Value(0)),
                sig("Crc32", 48, 32, false, 1.0, "").mux(Mux::Value(0)),
                sig("TimestampUs", 80, 32, false, 1.0, "us").mux(Mux::Value(0)),
            ];
            for i in 0..62 {
                v.push(
                    sig(&format!("Px{i:02}"), 16 + 8 * i, 8, false, 1.0, "")
                        .mux(Mux::Range(1, Variant::Fd.max_data_segments() as u32)),
                );
            }
            v
        }
        Variant::Classic => {
            let mut v = vec![
                sig("FrameSeq", 0, 8, false, 1.0, ""),
                sig("SegmentIndex", 8, 16, false, 1.0, "").mux(Mux::Multiplexor),
                sig("Rows", 24, 8, false, 1.0, "").mux(Mux::Value(0)),
                sig("Cols", 32, 8, false, 1.0, "").mux(Mux::Value(0)),
                sig("BitsPerPixel", 40, 8, false, 1.0, "").mux(Mux::Value(0)),
                sig("SegmentCount", 48, 16, false, 1.0, "").mux(Mux::Value(0)),
                sig("Crc32", 24, 32, false, 1.0, "").mux(Mux::Value(1)),
                sig("TimestampUs", 24, 32, false, 1.0, "us").mux(Mux::Value(2)),
            ];
            for i in 0..5 {
                v.push(
                    sig(&format!("Px{i:02}"), 24 + 8 * i, 8, false, 1.0, "").mux(Mux::Range(
                        3,
                        2 + Variant::Classic.max_data_segments() as u32,
                    )),
                );
            }
            v
        }
    }
}

/// What a signal means where its name and unit do not say it (docs/protocol.md says more).
fn comment(kind: MessageKind, signal: &str) -> Option<&'static str> {
    Some(match (kind, signal) {
        (MessageKind::StepState, "Speed") => {
            "Forward speed over the hop (touchdown to touchdown), estimated by the controller from \
             the foot switch and LegState: no speed sensor."
        }
        (MessageKind::StepState, "EnergyRatio") => {
            "The body's energy (kinetic and gravitational, per unit mass) at liftoff over that at \
             touchdown: what the stance law put in (above 1) or took out; 1 in a steady gait."
        }
        (MessageKind::TerrainClass, "UnknownReason") => {
            "With TerrainId 255: the check of the stance image that called it unknown, 1 novelty \
             (unlike every known terrain), 2 load, 3 texture; 0 when a flag says why (FlagNoSample, \
             FlagNoContact, FlagEnergy)."
        }
        (MessageKind::TerrainClass, "LatencyUs") => {
            "From the kernel's receive time of the sampled frame's last segment to the decision, \
             on the node's clock: a node that was stopped or behind shows it. Saturates at \
             65535; 0 with FlagNoSample."
        }
        (MessageKind::NodeStatus, "State") => {
            "0 starting, 1 running, 2 degraded, 3 no model, 4 stopping, 5 wrong image size, \
             6 CAN controller error-passive, 7 CAN controller bus-off (from error frames)."
        }
        (MessageKind::LegStatus, "Mode") => {
            "0 waiting (nothing moved yet), 1 running, 2-4 damped stop (command timeout, driver \
             fault, driver silent), 5 stopped at exit, 6 check (reading, moving nothing)."
        }
        (MessageKind::LegStatus, "Joint") => "The joint at fault: 0 none, 1 hip, 2 length/knee.",
        (MessageKind::LegStatus, "CommandAgeMs") => {
            "Age of the last LegCommand; 65535: none yet (saturating)."
        }
        (MessageKind::LegStatus, "FaultCode") => {
            "The driver's own code: moteus fault register, ODrive axis error, MIT error byte."
        }
        (MessageKind::NodeStatus, "CrcFailures" | "IncompleteFrames") => {
            "Low 8 bits of a running total: it wraps; take differences mod 256."
        }
        (MessageKind::NodeStatus, "BusErrors") => {
            "CAN error frames heard plus failed reads and writes: low 8 bits of a running \
             total; it wraps; take differences mod 256."
        }
        _ => return None,
    })
}

fn sender(kind: MessageKind) -> &'static str {
    match kind {
        MessageKind::LegCommand | MessageKind::GaitStatus | MessageKind::StepState => "Controller",
        MessageKind::FootContact | MessageKind::TactileFrame | MessageKind::TactileFrameClassic => {
            "Foot"
        }
        MessageKind::LegState | MessageKind::LegStatus => "Leg",
        MessageKind::TerrainClass | MessageKind::NodeStatus => "Node",
    }
}

fn receivers(kind: MessageKind) -> &'static str {
    match kind {
        MessageKind::LegCommand => "Leg",
        MessageKind::TactileFrame | MessageKind::TactileFrameClassic => "Node",
        MessageKind::FootContact => "Node,Controller",
        MessageKind::LegState
        | MessageKind::LegStatus
        | MessageKind::TerrainClass
        | MessageKind::NodeStatus => "Controller",
        MessageKind::GaitStatus | MessageKind::StepState => "Node",
    }
}

fn fmt_num(v: f64) -> String {
    let s = format!("{v}");
    if s.contains('e') {
        format!("{v:.10}")
    } else {
        s
    }
}

/// The names of the DBC's value tables.
pub const VALUE_TABLES: [&str; 6] = [
    "Terrain",
    "Phase",
    "NodeState",
    "GaitReason",
    "LegMode",
    "UnknownReason",
];

/// The value table `name` (one of [`VALUE_TABLES`]): each value with its label, the catalog's
/// terrains for `Terrain`. Empty for another name.
pub fn value_table(name: &str, terrains: &TerrainCatalog) -> Vec<(u32, String)> {
    let fixed = |v: &[&str]| {
        v.iter()
            .enumerate()
            .map(|(i, l)| (i as u32, l.to_string()))
            .collect()
    };
    match name {
        "Terrain" => {
            let mut v: Vec<(u32, String)> = terrains
                .iter()
                .map(|t| (t.id() as u32, t.name().to_string()))
                .collect();
            v.push((TERRAIN_UNKNOWN as u32, "unknown".to_string()));
            v
        }
        "Phase" => fixed(&["flight", "stance"]),
        "NodeState" => fixed(&[
            "starting",
            "running",
            "degraded",
            "no_model",
            "stopping",
            "wrong_image_size",
            "error_passive",
            "bus_off",
        ]),
        "GaitReason" => fixed(&["initial", "terrain", "unknown", "node_lost"]),
        // The image checks' 2-bit codes, named as the reasons name themselves (0: none).
        "UnknownReason" => std::iter::once((0, "none".to_string()))
            .chain(
                crate::messages::UnknownReason::ALL
                    .iter()
                    .filter(|r| r.code() > 0)
                    .map(|r| (u32::from(r.code()), r.name().to_string())),
            )
            .collect(),
        "LegMode" => fixed(&[
            "waiting",
            "running",
            "command_timeout",
            "driver_fault",
            "driver_silent",
            "stopped",
            "check",
        ]),
        _ => Vec::new(),
    }
}

/// Every message of `ids` as the DBC names it: (DBC identifier, name, kind), one per foot for
/// the per-foot kinds.
fn messages(ids: &IdConfig) -> Vec<(u32, String, MessageKind)> {
    let mut msgs = Vec::new();
    for kind in MessageKind::ALL {
        let n = if kind.per_foot() { MAX_FEET } else { 1 };
        for f in 0..n {
            let raw = ids.id(kind, f);
            let dbc_id = if ids.extended { raw | 0x8000_0000 } else { raw };
            let name = if kind.per_foot() {
                format!("{}_F{f}", kind.name())
            } else {
                kind.name().to_string()
            };
            msgs.push((dbc_id, name, kind));
        }
    }
    msgs
}

/// The bus type and each message's frame format (classic or FD, standard or extended).
fn write_attributes(o: &mut String, msgs: &[(u32, String, MessageKind)], ids: &IdConfig) {
    let _ = writeln!(o, "BA_DEF_  \"BusType\" STRING ;");
    let _ = writeln!(
        o,
        "BA_DEF_ BO_  \"VFrameFormat\" ENUM  \"StandardCAN\",\"ExtendedCAN\",\"reserved\",\"J1939PG\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"StandardCAN_FD\",\"ExtendedCAN_FD\";"
    );
    let _ = writeln!(o, "BA_DEF_ BO_  \"CANFD_BRS\" ENUM  \"0\",\"1\";");
    let _ = writeln!(o, "BA_DEF_DEF_  \"BusType\" \"CAN FD\";");
    let _ = writeln!(o, "BA_DEF_DEF_  \"VFrameFormat\" \"StandardCAN\";");
    let _ = writeln!(o, "BA_DEF_DEF_  \"CANFD_BRS\" \"1\";");
    let _ = writeln!(o, "BA_ \"BusType\" \"CAN FD\";");
    for (dbc_id, _, kind) in msgs {
        let fmt = match (kind.is_fd(), ids.extended) {
            (false, false) => 0,
            (false, true) => 1,
            (true, false) => 14,
            (true, true) => 15,
        };
        let _ = writeln!(o, "BA_ \"VFrameFormat\" BO_ {dbc_id} {fmt};");
        if kind.is_fd() {
            let _ = writeln!(o, "BA_ \"CANFD_BRS\" BO_ {dbc_id} 1;");
        }
    }
}

/// The DBC text for an identifier map, with the catalog's terrains in the TerrainId value table.
pub fn generate(ids: &IdConfig, terrains: &TerrainCatalog) -> String {
    let mut o = String::new();
    let _ = writeln!(
        o,
        "VERSION \"presrs-protocol {}\"\n",
        env!("CARGO_PKG_VERSION")
    );
    let _ = writeln!(
        o,
        "NS_ :\n\tCM_\n\tBA_DEF_\n\tBA_\n\tVAL_\n\tVAL_TABLE_\n\tSG_MUL_VAL_\n"
    );
    let _ = writeln!(o, "BS_:\n");
    let _ = writeln!(o, "BU_: Controller Leg Foot Node\n");
    let tables: Vec<(&str, String)> = VALUE_TABLES
        .iter()
        .map(|&name| {
            let mut vals = String::new();
            for (v, label) in value_table(name, terrains) {
                let _ = write!(vals, " {v} \"{label}\"");
            }
            (name, vals)
        })
        .collect();
    for (name, vals) in &tables {
        let _ = writeln!(o, "VAL_TABLE_ {name}{vals};");
    }
    o.push('\n');

    let msgs = messages(ids);
    let mut vals = String::new();
    let mut muxvals = String::new();
    for (dbc_id, name, kind) in &msgs {
        let _ = writeln!(o, "BO_ {dbc_id} {name}: {} {}", kind.dlc(), sender(*kind));
        for s in signals(*kind) {
            let m = match s.mux {
                Mux::None => String::new(),
                Mux::Multiplexor => " M".to_string(),
                Mux::Value(v) => format!(" m{v}"),
                Mux::Range(a, _) => format!(" m{a}"),
            };
            let _ = writeln!(
                o,
                " SG_ {}{m} : {}|{}@1{} ({},0) [{}|{}] \"{}\" {}",
                s.name,
                s.start,
                s.len,
                if s.signed { '-' } else { '+' },
                fmt_num(s.factor),
                fmt_num(s.min),
                fmt_num(s.max),
                s.unit,
                receivers(*kind)
            );
            if let Some(t) = s.values
                && let Some((_, v)) = tables.iter().find(|(n, _)| *n == t)
            {
                let _ = writeln!(vals, "VAL_ {dbc_id} {}{v};", s.name);
            }
            if let Mux::Range(a, b) = s.mux {
                let _ = writeln!(
                    muxvals,
                    "SG_MUL_VAL_ {dbc_id} {} SegmentIndex {a}-{b};",
                    s.name
                );
            }
        }
        o.push('\n');
    }
    for (dbc_id, _, kind) in &msgs {
        for s in signals(*kind) {
            if let Some(c) = comment(*kind, &s.name) {
                let _ = writeln!(o, "CM_ SG_ {dbc_id} {} \"{c}\";", s.name);
            }
        }
    }
    o.push('\n');
    write_attributes(&mut o, &msgs, ids);
    o.push('\n');
    o.push_str(&vals);
    o.push('\n');
    o.push_str(&muxvals);
    o
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shipped_dbc_matches_generator() {
        let shipped = include_str!("../presrs.dbc");
        assert!(
            shipped == generate(&IdConfig::default(), &TerrainCatalog::paper()),
            "protocol/presrs.dbc is stale: regenerate it with `cargo run -- lab dbc --out protocol/presrs.dbc`"
        );
    }

    #[test]
    fn signals_fit_their_messages_without_overlap() {
        for kind in MessageKind::ALL {
            let sigs = signals(kind);
            for s in &sigs {
                assert!(
                    s.start + s.len <= 8 * kind.dlc() as u32,
                    "{} in {}",
                    s.name,
                    kind.name()
                );
            }
            for (i, a) in sigs.iter().enumerate() {
                for b in &sigs[i + 1..] {
                    let same_mux = match (a.mux, b.mux) {
                        (Mux::Value(x), Mux::Value(y)) => x == y,
                        (Mux::Range(..), Mux::Value(_)) | (Mux::Value(_), Mux::Range(..)) => false,
                        _ => true,
                    };
                    let overlap = a.start < b.start + b.len && b.start < a.start + a.len;
                    assert!(
                        !(same_mux && overlap),
                        "{} and {} overlap in {}",
                        a.name,
                        b.name,
                        kind.name()
                    );
                }
            }
        }
    }

    #[test]
    fn a_terrains_file_names_its_terrains_in_the_value_table() {
        let cat =
            TerrainCatalog::from_toml("[[terrain]]\nid = 20\nname = \"asphalt\"\n", "t").unwrap();
        let d = generate(&IdConfig::default(), &cat);
        let table = d
            .lines()
            .find(|l| l.starts_with("VAL_TABLE_ Terrain"))
            .unwrap_or_default();
        assert!(
            table.contains(" 11 \"grass\" 20 \"asphalt\" 255 \"unknown\""),
            "{table}"
        );
    }

    #[test]
    fn extended_ids_are_flagged() {
        let ids = IdConfig {
            extended: true,
            ..IdConfig::default()
        };
        let d = generate(&ids, &TerrainCatalog::paper());
        assert!(d.contains(&format!(
            "BO_ {} FootContact_F0: 8 Foot",
            0x100u32 | 0x8000_0000
        )));
        assert!(d.contains(&format!(
            "BA_ \"VFrameFormat\" BO_ {} 15;",
            0x600u32 | 0x8000_0000
        )));
    }
}
