//! The gait the simulator holds when no controller is on the bus: the controller crate's laws
//! with one fixed gait, run inside the simulator.

use controller::{Gait, laws};

use crate::hopper::LegCommands;

/// Eq. (4) in stance and eq. (5) at every liftoff, for one gait.
#[derive(Clone, Debug)]
pub struct FixedGait {
    /// The gait held.
    pub gait: Gait,
    /// Touchdown angle for the coming touchdown, rad.
    pub beta_td: f64,
    /// Touchdown angle of the last touchdown, rad.
    pub last_beta_td: f64,
}

impl FixedGait {
    /// Commands for `gait`.
    pub fn new(gait: Gait) -> Self {
        let b = gait.beta_des;
        Self {
            gait,
            beta_td: b,
            last_beta_td: b,
        }
    }

    /// Eq. (5) at liftoff.
    pub fn on_liftoff(&mut self, beta_lo: f64) {
        let g = &self.gait;
        let next = laws::next_touchdown_angle(beta_lo, self.last_beta_td, g.c, g.beta_des);
        // The leg's range of motion.
        self.beta_td = next.clamp(0.0, 1.0);
    }

    /// At touchdown with the leg at `beta`, rad: the stance law restarts.
    pub fn on_touchdown(&mut self, beta: f64) {
        self.last_beta_td = beta;
    }

    /// Changes the gait from the next stance on.
    pub fn set_gait(&mut self, gait: Gait) {
        self.gait = gait;
    }
}

impl LegCommands for FixedGait {
    fn stance_length(&mut self, t: f64) -> f64 {
        let g = &self.gait;
        laws::aer_leg_length(t, g.zeta0, g.zeta_dev, g.omega, g.phi)
    }
    fn flight_length(&self) -> f64 {
        let g = &self.gait;
        laws::aer_leg_length(0.0, g.zeta0, g.zeta_dev, g.omega, g.phi)
    }
    fn touchdown_angle(&self) -> f64 {
        self.beta_td
    }
}
