#![forbid(unsafe_code)]
#![warn(missing_docs)]
//! # presrs-sim: the simulated hopper and foot
pub mod dataset;
pub mod faults;
pub mod field;
pub mod fixed_gait;
pub mod foot_model;
pub mod gait_score;
pub mod hopper;
pub mod runner;
pub mod service;
pub mod skin;
pub mod terrain;

/// Changes whenever the simulator's output for a given seed changes (hopper parameters, terrain
/// textures, skin), so that models trained and cached from simulated data can tell they are stale.
/// 5: the sandpapers' cloth backing.
pub const SIM_VERSION: u32 = 5;

/// The serial number of the simulated foot sensor when none is given: datasets and simulated
/// runs use the same sensor unless told otherwise, as a real robot's training data comes from
/// its own foot. (Foot `i` of a multi-legged run wears sensor `serial + i`.)
pub const DEFAULT_SENSOR: u64 = 1;

/// The simulated hopper's foot and its sensor, as a process's options give them (with the
/// `clap` feature, those options themselves: `--gait`, `--damage`, `--sensor`).
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "clap", derive(clap::Args))]
pub struct FootOptions {
    /// Hopper gait (the dynamic set's; the one `sim` holds without a controller): G1, G2 or G3.
    #[cfg_attr(feature = "clap", arg(long, default_value = "G2"))]
    pub gait: String,
    /// Sensor damage from the start, percent of sensels on dead rows and columns (eq. 6).
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 0.0))]
    pub damage: f64,
    /// Serial number of the simulated sensor (`sim`'s foot i wears serial + i): its gain pattern
    /// and faults. `dataset` and `sim` share the default, so a model trained on one fits the other.
    #[cfg_attr(feature = "clap", arg(long, default_value_t = DEFAULT_SENSOR))]
    pub sensor: u64,
}

impl Default for FootOptions {
    fn default() -> Self {
        Self {
            gait: "G2".into(),
            damage: 0.0,
            sensor: DEFAULT_SENSOR,
        }
    }
}

/// A [`FootOptions`] value that cannot be simulated, named as the option that gave it.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum FootError {
    /// Not one of the paper's gaits.
    #[error("--gait {0}: expected G1, G2 or G3")]
    Gait(String),
    /// Not a percentage.
    #[error("--damage {0}: expected a percentage in 0..=100")]
    Damage(f64),
    /// Not a payload the hopper can carry.
    #[error(
        "--payload {0}: expected kilograms in 0..={MAX_PAYLOAD_KG} (the body is 2.0 kg; 0 carries nothing)"
    )]
    Payload(f64),
}

/// The most payload a simulated hopper carries, kg: as much again as its body. At that its
/// stance lasts sqrt(2) times as long (the spring's period), far past the sample time.
pub const MAX_PAYLOAD_KG: f64 = 2.0;

/// A payload (`--payload KG`) checked to lie in 0..=[`MAX_PAYLOAD_KG`].
pub fn check_payload(kg: f64) -> Result<f64, FootError> {
    if (0.0..=MAX_PAYLOAD_KG).contains(&kg) {
        Ok(kg)
    } else {
        Err(FootError::Payload(kg))
    }
}

impl FootOptions {
    /// The gait, and the damage checked.
    pub fn checked(&self) -> Result<(controller::Gait, f64), FootError> {
        let gait = controller::Gait::by_name(&self.gait)
            .ok_or_else(|| FootError::Gait(self.gait.clone()))?;
        Ok((gait, check_damage(self.damage)?))
    }
}

/// A damage percentage (`--damage PCT`) checked to lie in 0..=100.
pub fn check_damage(pct: f64) -> Result<f64, FootError> {
    if (0.0..=100.0).contains(&pct) {
        Ok(pct)
    } else {
        Err(FootError::Damage(pct))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn foot_options_name_the_option_that_is_wrong() {
        assert_eq!(
            FootOptions::default().checked().map(|(g, d)| (g.id, d)),
            Ok((2, 0.0))
        );
        let bad = FootOptions {
            gait: "G4".into(),
            ..Default::default()
        };
        assert_eq!(bad.checked().err(), Some(FootError::Gait("G4".into())));
        assert_eq!(check_damage(100.5), Err(FootError::Damage(100.5)));
        assert!(FootError::Damage(-1.0).to_string().contains("0..=100"));
    }
}
