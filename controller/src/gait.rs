//! Gaits `G_i(omega, phi, c, beta_des)` and their parameters (section 6 and 7.1 of the paper).

use protocol::config::Invalid;
use serde::{Deserialize, Serialize};

/// One gait: the parameters of eqs. (4) and (5).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Gait {
    /// Gait number on the bus (1..=3 for the paper's G1..G3).
    pub id: u8,
    /// Recirculation frequency omega of eq. (4), rad/s.
    pub omega: f64,
    /// Desired touchdown angle beta_des of eq. (5), rad (see [`crate::laws`] for the convention).
    pub beta_des: f64,
    /// Recirculation phase phi of eq. (4), rad.
    #[serde(default = "default_phi")]
    pub phi: f64,
    /// Weight c of eq. (5); regulates speed for 0 < c < 2 (see [`crate::laws`]).
    #[serde(default = "default_c")]
    pub c: f64,
    /// Rest leg length zeta0, m.
    #[serde(default = "default_zeta0")]
    pub zeta0: f64,
    /// Recirculation amplitude zeta_dev, m.
    #[serde(default = "default_zeta_dev")]
    pub zeta_dev: f64,
}

/// Leg lengthens through stance (minimum at touchdown): the recirculation puts energy in.
pub fn default_phi() -> f64 {
    std::f64::consts::FRAC_PI_2
}
/// Default leg-length amplitude c of eq. (4), m (fraction of the rest length).
pub fn default_c() -> f64 {
    0.2
}
/// Default mean leg compression zeta_0 of eq. (4).
pub fn default_zeta0() -> f64 {
    0.15
}
/// Default allowed deviation of zeta before the touchdown law corrects.
pub fn default_zeta_dev() -> f64 {
    0.01
}

impl Gait {
    fn paper(id: u8, omega: f64, beta_des: f64) -> Self {
        Self {
            id,
            omega,
            beta_des,
            phi: default_phi(),
            c: default_c(),
            zeta0: default_zeta0(),
            zeta_dev: default_zeta_dev(),
        }
    }
    /// G1 (6.0 rad/s, 0.27 rad).
    pub fn g1() -> Self {
        Self::paper(1, 6.0, 0.27)
    }
    /// G2 (6.5 rad/s, 0.42 rad).
    pub fn g2() -> Self {
        Self::paper(2, 6.5, 0.42)
    }
    /// G3 (7.0 rad/s, 0.57 rad).
    pub fn g3() -> Self {
        Self::paper(3, 7.0, 0.57)
    }
    /// The paper's three gaits.
    pub fn paper_gaits() -> Vec<Self> {
        vec![Self::g1(), Self::g2(), Self::g3()]
    }
    /// The paper's gait by name ("G1", "g2", "3").
    pub fn by_name(name: &str) -> Option<Self> {
        match name.trim_start_matches(['G', 'g']) {
            "1" => Some(Self::g1()),
            "2" => Some(Self::g2()),
            "3" => Some(Self::g3()),
            _ => None,
        }
    }

    /// Checks every field against its allowed range; the error names the field (under `path`,
    /// e.g. `gaits[0]`) and the range.
    pub fn validate(&self, path: &str) -> Result<(), Invalid> {
        let check = |name: &str, v: f64, lo: f64, hi: f64| {
            if v.is_finite() && v >= lo && v <= hi {
                Ok(())
            } else {
                Err(Invalid::new(
                    format!("{path}.{name}"),
                    format!("{path}.{name} = {v} is outside the allowed range {lo}..={hi}"),
                ))
            }
        };
        if self.id == 0 {
            return Err(Invalid::new(
                format!("{path}.id"),
                format!("{path}.id = 0: gait ids start at 1"),
            ));
        }
        check("omega", self.omega, 0.1, 100.0)?;
        check("beta_des", self.beta_des, 0.0, 1.2)?;
        check(
            "phi",
            self.phi,
            -std::f64::consts::TAU,
            std::f64::consts::TAU,
        )?;
        check("c", self.c, 0.01, 1.99)?;
        check("zeta0", self.zeta0, 0.05, 2.0)?;
        check("zeta_dev", self.zeta_dev, 0.0, self.zeta0 * 0.5)?;
        Ok(())
    }
}

/// The paper's gait by name, as [`Gait::by_name`] (for command-line options: `--fixed-gait G1`).
impl std::str::FromStr for Gait {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        Self::by_name(s).ok_or_else(|| format!("`{s}` is not a gait: expected G1, G2 or G3"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_gait_parses_by_its_papers_name_and_nothing_else() {
        assert_eq!("G3".parse::<Gait>(), Ok(Gait::g3()));
        assert_eq!("g1".parse::<Gait>(), Ok(Gait::g1()));
        let e = "G4".parse::<Gait>().unwrap_err();
        assert!(e.contains("G4") && e.contains("G1, G2 or G3"), "{e}");
    }

    #[test]
    fn paper_gaits_are_valid_and_named() {
        for g in Gait::paper_gaits() {
            g.validate("gaits").unwrap();
        }
        assert_eq!(Gait::by_name("G2").unwrap().omega, 6.5);
        assert!(Gait::by_name("G7").is_none());
    }

    #[test]
    fn validation_names_the_field_and_range() {
        let mut g = Gait::g1();
        g.c = -0.5;
        let e = g.validate("gaits[0]").unwrap_err();
        assert_eq!(e.key, "gaits[0].c");
        assert!(e.message.contains("0.01..=1.99"), "{e}");
    }
}
