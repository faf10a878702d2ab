//! `leg.toml`: the leg's geometry, its two joints and their drivers, the impedance, rates and
//! timeouts. Every check names the key at fault.
//!
//! ```toml
//! foot = 0
//! rate_hz = 500              # commands to the motors, and LegState
//! command_timeout_ms = 50    # no LegCommand for this long: damped stop
//! reply_timeout_ms = 50      # a driver silent this long: damped stop, its fault named
//! motor_iface = "can1"       # the motors' own bus (default: the one LegCommand comes on)
//!
//! [kinematics]
//! type = "prismatic"         # or "two-link" with thigh_m, shank_m, knee_sign
//! min_length_m = 0.06
//! max_length_m = 0.20
//!
//! [impedance]
//! stance_stiffness_n_per_m = 1000.0   # the AER law's leg spring
//! stance_damping_n_s_per_m = 2.0
//! flight_stiffness_n_per_m = 1000.0
//! flight_damping_n_s_per_m = 20.0
//! hip_stiffness_nm_per_rad = 20.0     # holds the touchdown angle in flight; 0 in stance
//! hip_damping_nm_s_per_rad = 0.5
//!
//! [hip]
//! driver = "mit"             # "moteus", "odrive" or "mit"
//! id = 1
//! mit_model = "AK80-6-V1.1"
//!
//! [length]                   # the screw, belt or rack; the knee of a two-link leg
//! driver = "mit"
//! id = 2
//! metres_per_turn = 0.5     # prismatic only: leg length per turn of the joint
//! mit_model = "AK80-6-V1.1"
//! ```

use std::f64::consts::TAU;
use std::path::Path;

use protocol::IdConfig;
use protocol::config::{ConfigFileError, Invalid};
use serde::{Deserialize, Serialize};

use crate::driver::mit::{Mit, Ranges};
use crate::driver::moteus::Moteus;
use crate::driver::odrive::Odrive;
use crate::driver::{BusId, Driver};
use crate::kinematics::Kinematics;

mod validate;

/// The protocol a joint's driver speaks.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DriverKind {
    /// mjbots moteus (CAN FD).
    Moteus,
    /// ODrive CANSimple.
    Odrive,
    /// MIT mini-cheetah protocol.
    Mit,
}

impl DriverKind {
    /// Every protocol.
    pub const ALL: [DriverKind; 3] = [DriverKind::Moteus, DriverKind::Odrive, DriverKind::Mit];

    /// Its name in configs and on the command line ("moteus", "odrive", "mit").
    pub fn name(self) -> &'static str {
        match self {
            DriverKind::Moteus => "moteus",
            DriverKind::Odrive => "odrive",
            DriverKind::Mit => "mit",
        }
    }
}

impl std::str::FromStr for DriverKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Self::ALL
            .into_iter()
            .find(|k| k.name() == s)
            .ok_or_else(|| format!("{s:?}: one of moteus, odrive, mit"))
    }
}

/// One joint: its driver and how the driver's shaft maps to the joint.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointConfig {
    /// The protocol.
    pub driver: Option<DriverKind>,
    /// CAN id (moteus 1..127, ODrive node 0..63, MIT 1..255).
    pub id: Option<u8>,
    /// Driver shaft turns per joint turn (a gearbox after the driver's output).
    #[serde(default = "one")]
    pub gear_ratio: f64,
    /// +1, or -1 when the driver's positive turns the joint negative.
    #[serde(default = "one")]
    pub direction: f64,
    /// The joint coordinate (rad; m for a prismatic leg's length) where the driver reads 0.
    #[serde(default)]
    pub zero_offset: f64,
    /// Prismatic leg's length joint: leg metres per turn of the joint.
    pub metres_per_turn: Option<f64>,
    /// MIT: a known model's ranges (`Ranges::MODELS`).
    pub mit_model: Option<String>,
    /// MIT: explicit ranges instead of a model.
    pub mit_ranges: Option<Ranges>,
    /// MIT: the id replies come on.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub mit_master_id: u8,
    /// moteus: its configured `servo.pid_position.kp`, N m/rev (the scales' 1.0).
    pub moteus_kp: Option<f64>,
    /// moteus: its configured `servo.pid_position.kd`, N m s/rev.
    pub moteus_kd: Option<f64>,
    /// moteus: the source id the bridge sends from (replies come back to it).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub moteus_source: u8,
}

fn one() -> f64 {
    1.0
}

/// A written config leaves out the other protocols' keys at their default (`presrs leg
/// --example moteus` said `mit_master_id = 0`, which a moteus leg has no use for).
fn is_zero(x: &u8) -> bool {
    *x == 0
}

/// The leg's spring and the hip's hold.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Impedance {
    /// The leg spring in stance (eq. 4's spring), N/m.
    pub stance_stiffness_n_per_m: f64,
    /// Leg damping in stance, N s/m.
    pub stance_damping_n_s_per_m: f64,
    /// The leg's length hold in flight, N/m.
    pub flight_stiffness_n_per_m: f64,
    /// Leg damping in flight, N s/m.
    pub flight_damping_n_s_per_m: f64,
    /// The hip's hold on the touchdown angle in flight, N m/rad (0 in stance: the leg sweeps).
    pub hip_stiffness_nm_per_rad: f64,
    /// Hip damping, N m s/rad (also the hip's damped stop).
    pub hip_damping_nm_s_per_rad: f64,
    /// Leg damping in the damped stop, N s/m.
    pub stop_damping_n_s_per_m: f64,
}

impl Default for Impedance {
    fn default() -> Self {
        // The simulated hopper's leg (sim::HopperParams: 1 kN/m, 2 N s/m).
        Self {
            stance_stiffness_n_per_m: 1000.0,
            stance_damping_n_s_per_m: 2.0,
            flight_stiffness_n_per_m: 1000.0,
            flight_damping_n_s_per_m: 20.0,
            hip_stiffness_nm_per_rad: 20.0,
            hip_damping_nm_s_per_rad: 0.5,
            stop_damping_n_s_per_m: 20.0,
        }
    }
}

/// The whole file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LegConfig {
    /// The foot (leg) whose LegCommand this leg follows.
    #[serde(default)]
    pub foot: u8,
    /// Commands to the motors and LegState, Hz.
    #[serde(default = "default_rate")]
    pub rate_hz: f64,
    /// No LegCommand for this long: the damped stop, ms.
    #[serde(default = "default_timeout")]
    pub command_timeout_ms: u64,
    /// A driver silent this long: the damped stop, ms.
    #[serde(default = "default_timeout")]
    pub reply_timeout_ms: u64,
    /// The motors' own bus; `None`: the bus LegCommand comes on.
    pub motor_iface: Option<String>,
    /// The leg's geometry.
    pub kinematics: Kinematics,
    /// Spring and damping.
    #[serde(default)]
    pub impedance: Impedance,
    /// The hip joint.
    pub hip: JointConfig,
    /// The length joint: a prismatic leg's screw or belt, a two-link leg's knee.
    pub length: JointConfig,
    /// Our identifiers (for the collision check on a shared bus).
    #[serde(default)]
    pub ids: IdConfig,
}

fn default_rate() -> f64 {
    500.0
}
fn default_timeout() -> u64 {
    50
}

/// A joint's mapping between its coordinate and its driver's shaft.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JointMap {
    /// Driver rad per joint unit (rad, or m for a prismatic length), with the direction.
    pub scale: f64,
    /// The joint coordinate at the driver's zero.
    pub zero: f64,
}

impl JointMap {
    /// Driver position for a joint coordinate.
    pub fn to_driver(&self, x: f64) -> f64 {
        self.scale * (x - self.zero)
    }
    /// Joint coordinate for a driver position.
    pub fn to_joint(&self, p: f64) -> f64 {
        p / self.scale + self.zero
    }
    /// A joint stiffness (per joint unit) at the driver: `k / scale^2`.
    pub fn stiffness_to_driver(&self, k: f64) -> f64 {
        k / (self.scale * self.scale)
    }
}

impl LegConfig {
    /// A prismatic hopper leg on two motors of `kind`, with ids that share a bus with ours
    /// (the simulator's `--leg KIND` without a file; examples/leg.toml is the MIT one):
    /// MIT ids 1 and 2, moteus 3 and 4 (its replies on 0x300 and 0x400), ODrive nodes 1 and 2
    /// (0x020-0x05F).
    pub fn example(kind: DriverKind) -> Self {
        let joint = |n: u8| match kind {
            DriverKind::Mit => format!("driver = \"mit\"\nid = {n}\nmit_model = \"AK80-6-V1.1\"\n"),
            DriverKind::Moteus => format!(
                "driver = \"moteus\"\nid = {}\nmoteus_kp = 200.0\nmoteus_kd = 5.0\n",
                n + 2
            ),
            DriverKind::Odrive => format!("driver = \"odrive\"\nid = {n}\n"),
        };
        let text = format!(
            "[kinematics]\ntype = \"prismatic\"\nmin_length_m = 0.06\nmax_length_m = 0.20\n\
             [hip]\n{}[length]\n{}metres_per_turn = 0.5\nzero_offset = 0.06\n",
            joint(1),
            joint(2)
        );
        match Self::from_text(&text, "example") {
            Ok(c) => c,
            // The three examples are checked by a unit test; this cannot be reached.
            Err(e) => unreachable!("the {kind:?} example leg is invalid: {e}"),
        }
    }

    /// The config as a TOML file.
    pub fn to_toml(&self) -> Result<String, toml::ser::Error> {
        toml::to_string(self)
    }

    /// Every joint's driver is `kind`.
    pub fn speaks(&self, kind: DriverKind) -> bool {
        self.hip.driver == Some(kind) && self.length.driver == Some(kind)
    }

    /// Reads and checks a leg config (TOML, or JSON by extension).
    pub fn from_file(path: &Path) -> Result<Self, ConfigFileError> {
        let (text, name) = protocol::config::read_text(path)?;
        Self::from_text(&text, &name)
    }

    /// The leg a process runs on `kind`'s motors: the file's (whose drivers must both speak
    /// `kind`), or the built-in prismatic leg on that protocol's motors ([`Self::example`]).
    pub fn for_driver(kind: DriverKind, path: Option<&Path>) -> Result<Self, ConfigFileError> {
        let Some(p) = path else {
            return Ok(Self::example(kind));
        };
        let c = Self::from_file(p)?;
        if !c.speaks(kind) {
            let name = |d: Option<DriverKind>| d.map_or("none", DriverKind::name);
            return Err(ConfigFileError::Invalid {
                path: p.display().to_string(),
                source: Invalid::new(
                    "driver",
                    format!(
                        "driver: the joints' drivers are {} (hip) and {} (length), not {} on \
                         both as asked; give the leg's protocol or another file",
                        name(c.hip.driver),
                        name(c.length.driver),
                        kind.name()
                    ),
                ),
            });
        }
        Ok(c)
    }

    /// Parses and checks a config's text; `name` names it in errors.
    pub fn from_text(text: &str, name: &str) -> Result<Self, ConfigFileError> {
        let c: Self = protocol::config::parse(text, name)?;
        c.validate()
            .map_err(|e| ConfigFileError::invalid(name, e))?;
        Ok(c)
    }

    fn joint(&self, which: usize) -> (&'static str, &JointConfig) {
        if which == 0 {
            ("hip", &self.hip)
        } else {
            ("length", &self.length)
        }
    }

    /// The joint's coordinate-to-driver map (`which`: 0 hip, 1 length joint).
    pub fn map(&self, which: usize) -> JointMap {
        let (_, j) = self.joint(which);
        let per_unit = match (which, &self.kinematics) {
            (1, Kinematics::Prismatic { .. }) => TAU / j.metres_per_turn.unwrap_or(1.0),
            _ => 1.0,
        };
        JointMap {
            scale: j.direction.signum() * j.gear_ratio * per_unit,
            zero: j.zero_offset,
        }
    }

    /// The joint's driver (`which`: 0 hip, 1 length joint); the config must be valid.
    pub fn driver(&self, which: usize) -> Driver {
        let (_, j) = self.joint(which);
        let id = j.id.unwrap_or(0);
        match j.driver.unwrap_or(DriverKind::Mit) {
            DriverKind::Moteus => Driver::Moteus(Moteus::new(
                id,
                j.moteus_source,
                j.moteus_kp.unwrap_or(0.0),
                j.moteus_kd.unwrap_or(0.0),
                self.command_timeout_ms as f64 * 1e-3,
            )),
            DriverKind::Odrive => Driver::Odrive(Odrive::new(id)),
            DriverKind::Mit => {
                Driver::Mit(Mit::new(id, j.mit_master_id, self.mit_ranges_of(which)))
            }
        }
    }

    /// An MIT joint's ranges (`which`: 0 hip, 1 length joint); the config must be valid (the
    /// check refuses an MIT joint without them: the fallback is never used then).
    pub fn mit_ranges_of(&self, which: usize) -> Ranges {
        let (_, j) = self.joint(which);
        self.mit_ranges(j).unwrap_or(Ranges {
            p_max: 12.5,
            v_max: 50.0,
            kp_max: 500.0,
            kd_max: 5.0,
            t_max: 18.0,
        })
    }

    fn mit_ranges(&self, j: &JointConfig) -> Option<Ranges> {
        j.mit_ranges
            .or_else(|| j.mit_model.as_deref().and_then(Ranges::of_model))
    }

    /// The largest stiffness and damping the length joint's driver must give over the
    /// workspace (N m/rad, N m s/rad at the driver).
    pub fn length_gains_needed(&self) -> (f64, f64) {
        let imp = &self.impedance;
        let k = imp
            .stance_stiffness_n_per_m
            .max(imp.flight_stiffness_n_per_m);
        let b = imp
            .stance_damping_n_s_per_m
            .max(imp.flight_damping_n_s_per_m)
            .max(imp.stop_damping_n_s_per_m);
        let (lo, hi) = self.kinematics.length_range();
        let m = self.map(1);
        let mut g2: f64 = 0.0;
        for i in 0..=50 {
            let l = lo + (hi - lo) * i as f64 / 50.0;
            let q = self.kinematics.inverse(l, 0.0).joints;
            g2 = g2.max(self.kinematics.length_gain(q).powi(2));
        }
        (m.stiffness_to_driver(k * g2), m.stiffness_to_driver(b * g2))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_leg_file_for_another_protocol_is_refused_naming_its_drivers() {
        let path = std::env::temp_dir().join(format!("presrs-leg-{}.toml", std::process::id()));
        std::fs::write(&path, MIT_PRISMATIC).unwrap();
        assert!(LegConfig::for_driver(DriverKind::Mit, Some(&path)).is_ok());
        let e = LegConfig::for_driver(DriverKind::Moteus, Some(&path)).unwrap_err();
        std::fs::remove_file(&path).ok();
        let msg = e.to_string();
        assert!(
            msg.contains("mit (hip) and mit (length), not moteus"),
            "{msg}"
        );
        assert!(msg.contains(&path.display().to_string()), "{msg}");
        // Without a file: the protocol's example leg.
        let c = LegConfig::for_driver(DriverKind::Odrive, None).unwrap();
        assert!(c.speaks(DriverKind::Odrive));
    }

    pub(crate) const MIT_PRISMATIC: &str = r#"
foot = 0
[kinematics]
type = "prismatic"
min_length_m = 0.06
max_length_m = 0.20
[hip]
driver = "mit"
id = 1
mit_model = "AK80-6-V1.1"
[length]
driver = "mit"
id = 2
metres_per_turn = 0.5
mit_model = "AK80-6-V1.1"
"#;

    fn refused(text: &str) -> String {
        match LegConfig::from_text(text, "leg.toml") {
            Ok(_) => panic!("accepted:\n{text}"),
            Err(e) => e.to_string(),
        }
    }

    #[test]
    fn coarse_mit_gains_are_said_and_the_example_has_none() {
        let c =
            LegConfig::from_text(include_str!("../../../examples/leg.toml"), "leg.toml").unwrap();
        assert_eq!(c.quantisation_warnings(), Vec::<String>::new());
        let coarse = include_str!("../../../examples/leg.toml")
            .replace("metres_per_turn = 0.5", "metres_per_turn = 0.25");
        let c = LegConfig::from_text(&coarse, "leg.toml").unwrap();
        let w = c.quantisation_warnings();
        assert!(
            w.iter()
                .any(|w| w.starts_with("impedance.stance_damping_n_s_per_m")),
            "{w:?}"
        );
    }

    #[test]
    fn the_built_in_examples_are_valid() {
        for k in DriverKind::ALL {
            let c = LegConfig::example(k);
            assert!(c.speaks(k));
            c.validate().unwrap();
            // Printed (`presrs leg --example`) and read back, the same leg.
            let text = c.to_toml().unwrap();
            let back = LegConfig::from_text(&text, "example.toml").unwrap();
            assert_eq!(back, c);
            // Only the keys of the leg's own protocol.
            for other in ["mit_", "moteus_"] {
                let own = matches!(
                    (k, other),
                    (DriverKind::Mit, "mit_") | (DriverKind::Moteus, "moteus_")
                );
                assert_eq!(text.contains(other), own, "{k:?}: {text}");
            }
        }
    }

    #[test]
    fn the_shipped_example_is_valid() {
        let c = LegConfig::from_text(
            include_str!("../../../examples/leg.toml"),
            "examples/leg.toml",
        )
        .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(c.rate_hz, 500.0);
    }

    #[test]
    fn the_example_is_valid_and_maps_joints() {
        let c = LegConfig::from_text(MIT_PRISMATIC, "leg.toml").unwrap();
        let m = c.map(1);
        // 0.5 m per turn: 1 cm of leg is 0.02 turns.
        assert!((m.to_driver(0.01) - 0.02 * TAU).abs() < 1e-12);
        assert!((m.to_joint(m.to_driver(0.137)) - 0.137).abs() < 1e-12);
        let (kp, _) = c.length_gains_needed();
        // 1000 N/m through 0.5 m/turn: 1000 * (0.5 / 2 pi)^2 N m/rad.
        assert!((kp - 1000.0 * (0.5 / TAU).powi(2)).abs() < 1e-9);
    }

    #[test]
    fn bad_configs_are_refused_naming_the_key() {
        let e = refused(&MIT_PRISMATIC.replace("id = 2\n", ""));
        assert!(e.contains("length.id") && e.contains("no CAN id"), "{e}");
        let two_link = MIT_PRISMATIC
            .replace(
                "type = \"prismatic\"",
                "type = \"two-link\"\nthigh_m = 0.0\nshank_m = 0.1\nknee_sign = 1.0",
            )
            .replace("metres_per_turn = 0.5\n", "");
        let e = refused(&two_link);
        assert!(e.contains("kinematics.thigh_m"), "{e}");
        let e = refused(&MIT_PRISMATIC.replace(
            "foot = 0",
            "foot = 0\n[impedance]\nhip_stiffness_nm_per_rad = 900.0",
        ));
        assert!(
            e.contains("impedance.hip_stiffness_nm_per_rad") && e.contains("kp_max"),
            "{e}"
        );
        let e = refused(&MIT_PRISMATIC.replace("id = 2", "id = 1"));
        assert!(
            e.contains("length.id") && e.contains("two joints on one id"),
            "{e}"
        );
        let e = refused(&MIT_PRISMATIC.replace("AK80-6-V1.1\"\n[length]", "AK99\"\n[length]"));
        assert!(e.contains("hip.mit_model"), "{e}");
        let e = refused(&MIT_PRISMATIC.replace("metres_per_turn = 0.5\n", ""));
        assert!(e.contains("length.metres_per_turn"), "{e}");
        let e = refused(&MIT_PRISMATIC.replace(
            "[hip]\ndriver = \"mit\"\nid = 1",
            "[hip]\ndriver = \"odrive\"\nid = 8",
        ));
        assert!(
            e.contains("hip.id") && e.contains("FootContact") && e.contains("0x100"),
            "{e}"
        );
        let e = refused(&MIT_PRISMATIC.replace("foot = 0", "foot = 0\nrate_hz = 5000"));
        assert!(e.contains("rate_hz"), "{e}");
        let e = refused(&MIT_PRISMATIC.replace("foot = 0", "foot = 0\nbogus = 1"));
        assert!(e.contains("bogus"), "{e}");
    }

    #[test]
    fn a_colliding_driver_is_fine_on_its_own_bus() {
        let own = MIT_PRISMATIC
            .replace("foot = 0", "foot = 0\nmotor_iface = \"can1\"")
            .replace(
                "[hip]\ndriver = \"mit\"\nid = 1",
                "[hip]\ndriver = \"odrive\"\nid = 8",
            );
        LegConfig::from_text(&own, "leg.toml").unwrap();
    }

    #[test]
    fn moteus_stiffness_over_its_configured_kp_is_refused() {
        let m = MIT_PRISMATIC
            .replace("[hip]\ndriver = \"mit\"\nid = 1\nmit_model = \"AK80-6-V1.1\"", "[hip]\ndriver = \"moteus\"\nid = 3\nmoteus_kp = 200.0\nmoteus_kd = 2.0")
            .replace("foot = 0", "foot = 0\n[impedance]\nhip_stiffness_nm_per_rad = 20.0\nhip_damping_nm_s_per_rad = 0.1");
        LegConfig::from_text(&m, "leg.toml").unwrap();
        let e = refused(
            &m.replace(
                "hip_stiffness_nm_per_rad = 20.0",
                "hip_stiffness_nm_per_rad = 9.0",
            )
            .replace("moteus_kp = 200.0", "moteus_kp = 10.0"),
        );
        assert!(
            e.contains("impedance.hip_stiffness_nm_per_rad") && e.contains("servo.pid_position.kp"),
            "{e}"
        );
    }
}
