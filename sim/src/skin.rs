//! PreSRS as the terrain presses it: skin layers, the 44x44 TekScan array and its electronics.
//!
//! The skin (section 3 of the paper) is hard silicone over felt over the array. Under load the
//! surface meets the silicone; height differences finer than about a millimetre are resisted by
//! the stiff silicone, coarser ones by the soft felt (two scales of a Winkler foundation). The
//! foot's base is stiff: on ground softer than the felt it carries more load at its rim than at
//! its centre (a rigid punch), which is how soft ground shows at any load. The
//! felt then spreads the contact pressure before it reaches the sensels (a Gaussian blur), each
//! sensel averages the pressure over its 1.27 mm cell, and the electronics turn 0-138 kPa into
//! 8-bit counts with sensel-to-sensel gain spread, noise, a noise threshold and saturation.

use rand::Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use crate::faults::Faults;
use crate::field::{Field, normal};
use crate::terrain::{Physics, Surface};

/// Weight of the rigid-punch rim concentration on the softest ground (see `Skin::contact`).
const RIM_GAIN: f64 = 0.5;
/// The punch profile is capped short of the rim, where it diverges: at 4x the centre.
const RIM_RHO2_MAX: f64 = 1.0 - 1.0 / 16.0;

/// Frame period of the acquisition (100 Hz), µs.
pub const FRAME_PERIOD_US: u64 = 10_000;

/// Parameters of the sensor and skin model.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SkinParams {
    /// Rows of sensels.
    pub rows: usize,
    /// Columns of sensels.
    pub cols: usize,
    /// Sensel pitch, mm (TekScan 5051: 1.27).
    pub pitch_mm: f64,
    /// Fine-grid cells per sensel along each axis.
    pub oversample: usize,
    /// Pressure at full scale, kPa (0-138 kPa to 0-255).
    pub full_scale_kpa: f64,
    /// Bits per sensel.
    pub bits: u8,
    /// Felt compliance as a Winkler stiffness, kPa/mm (3 mm of 99 % void felt).
    pub felt_kpa_mm: f64,
    /// Silicone's local stiffness against sub-millimetre asperities, kPa/mm.
    pub silicone_kpa_mm: f64,
    /// Lateral spreading of pressure by the felt, mm (Gaussian sigma).
    pub felt_spread_mm: f64,
    /// Sensel gain spread after equilibration (fraction, one sigma).
    pub gain_sd: f64,
    /// Electronic noise, counts (one sigma).
    pub noise_counts: f64,
    /// Readings below this many counts read 0 (the acquisition's noise threshold).
    pub threshold_counts: f64,
}

impl Default for SkinParams {
    fn default() -> Self {
        Self {
            rows: 44,
            cols: 44,
            pitch_mm: 1.27,
            oversample: 3,
            full_scale_kpa: 138.0,
            bits: 8,
            felt_kpa_mm: 30.0,
            silicone_kpa_mm: 1000.0,
            felt_spread_mm: 0.8,
            gain_sd: 0.03,
            noise_counts: 0.4,
            threshold_counts: 1.0,
        }
    }
}

/// Where the load is applied, in sensel coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Footprint {
    /// The static platform's die: a square `margin` sensels inside the array's edge (the paper's
    /// die is 5.08 mm smaller than the sensor: 2 sensels each side).
    Die {
        /// Sensels between the die's edge and the array's.
        margin: usize,
    },
    /// The hopper's elliptical foot base, inscribed in rows `r0..r0+h` and cols `c0..c0+w`
    /// (the paper: 41 x 38 sensels, 52.1 x 48.3 mm).
    Ellipse {
        /// First row.
        r0: usize,
        /// First column.
        c0: usize,
        /// Rows spanned.
        h: usize,
        /// Columns spanned.
        w: usize,
    },
}

impl Footprint {
    /// The hopper foot of section 7.1 on a 44x44 array: the bottom 3 rows and first 6 columns lie
    /// outside the foot.
    pub const FOOT: Footprint = Footprint::Ellipse {
        r0: 0,
        c0: 6,
        h: 41,
        w: 38,
    };
    /// The static platform's die (section 5): 2 sensels inside each edge.
    pub const DIE: Footprint = Footprint::Die { margin: 2 };

    /// Squared normalised distance from the footprint's centre: 0 at the centre, 1 on its edge
    /// (the ellipse's radius; for the square die, the larger of the two axes).
    fn rho2(&self, y_sensel: f64, x_sensel: f64, rows: usize, cols: usize) -> f64 {
        match *self {
            Footprint::Die { margin } => {
                let (hy, hx) = (
                    (rows - 2 * margin) as f64 / 2.0,
                    (cols - 2 * margin) as f64 / 2.0,
                );
                let dy = (y_sensel - rows as f64 / 2.0) / hy;
                let dx = (x_sensel - cols as f64 / 2.0) / hx;
                (dy * dy).max(dx * dx)
            }
            Footprint::Ellipse { r0, c0, h, w } => {
                let (cy, cx) = (r0 as f64 + h as f64 / 2.0, c0 as f64 + w as f64 / 2.0);
                let dy = (y_sensel - cy) / (h as f64 / 2.0);
                let dx = (x_sensel - cx) / (w as f64 / 2.0);
                dy * dy + dx * dx
            }
        }
    }

    fn contains(&self, y_sensel: f64, x_sensel: f64, rows: usize, cols: usize) -> bool {
        match *self {
            Footprint::Die { margin } => {
                let m = margin as f64;
                y_sensel >= m
                    && y_sensel < (rows - margin) as f64
                    && x_sensel >= m
                    && x_sensel < (cols - margin) as f64
            }
            Footprint::Ellipse { r0, c0, h, w } => {
                let (cy, cx) = (r0 as f64 + h as f64 / 2.0, c0 as f64 + w as f64 / 2.0);
                let (dy, dx) = (
                    (y_sensel - cy) / (h as f64 / 2.0),
                    (x_sensel - cx) / (w as f64 / 2.0),
                );
                dy * dy + dx * dx <= 1.0
            }
        }
    }
}

/// A contact prepared once per press or stance: the surface split into its two scales and the
/// footprint, ready for any load.
pub struct Contact {
    lo: Vec<f32>,
    hi: Vec<f32>,
    mask: Vec<bool>,
    /// Pressure weight per fine cell (mean 1 over the footprint): the rim concentration of a
    /// stiff foot on soft ground.
    rim: Vec<f32>,
    k_lo: f64,
    k_hi: f64,
}

/// One PreSRS sensor: its fixed gain pattern, its faults and its scratch buffers.
pub struct Skin {
    /// Geometry and material.
    pub params: SkinParams,
    gain: Vec<f32>,
    /// Its faults.
    pub faults: Faults,
    pressure: Field,
    scratch: Vec<f32>,
    /// Per loaded cell: the depth below which it bears load, and its weight (see `image`).
    hinges: Vec<(f64, f64)>,
}

fn series(a: f64, b: f64) -> f64 {
    a * b / (a + b)
}

impl Skin {
    /// A sensor with `faults`; `rng` draws its gain pattern.
    pub fn new(params: SkinParams, faults: Faults, rng: &mut impl Rng) -> Self {
        let n = params.rows * params.cols;
        let g = normal(1.0, params.gain_sd);
        let gain = (0..n).map(|_| g.sample(rng).max(0.5) as f32).collect();
        let cell = params.pitch_mm / params.oversample as f64;
        let pressure = Field::zeros(
            params.rows * params.oversample,
            params.cols * params.oversample,
            cell,
        );
        Self {
            params,
            gain,
            faults,
            pressure,
            scratch: Vec::new(),
            hinges: Vec::new(),
        }
    }

    /// The sensor with serial number `serial`: its sensel gain pattern and its faults follow from
    /// the serial alone, so a dataset recorded with a sensor and a run of the robot wearing it
    /// see the same skin (a robot's model is trained on images from its own foot, as in the
    /// paper). Gains and faults come from separate streams: the damage asked for does not change
    /// the gain pattern.
    pub fn of_sensor(serial: u64, params: SkinParams, faults: crate::faults::FaultParams) -> Self {
        use rand::SeedableRng;
        let mut gain_rng = rand_chacha::ChaCha8Rng::seed_from_u64(serial ^ 0x6a17_0000_0000);
        let mut fault_rng = rand_chacha::ChaCha8Rng::seed_from_u64(serial ^ 0xfa17_0000_0000);
        let f = Faults::new(faults, params.rows, params.cols, &mut fault_rng);
        Self::new(params, f, &mut gain_rng)
    }

    /// The fine grid a surface for this sensor must have: (rows, cols, cell_mm).
    pub fn grid(&self) -> (usize, usize, f64) {
        let p = &self.params;
        (
            p.rows * p.oversample,
            p.cols * p.oversample,
            p.pitch_mm / p.oversample as f64,
        )
    }

    /// A fresh random patch of a surface under `footprint`: one static press or one stance.
    pub fn contact_on(
        &mut self,
        physics: Physics,
        footprint: Footprint,
        rng: &mut impl Rng,
    ) -> Contact {
        let (r, c, cell) = self.grid();
        let surface = physics.surface(r, c, cell, rng);
        self.contact(&surface, footprint)
    }

    /// Prepares the surface's two scales and masks the footprint.
    pub fn contact(&mut self, surface: &Surface, footprint: Footprint) -> Contact {
        let p = &self.params;
        let lo = surface.height.clone();
        let hi: Vec<f32> = match &surface.asperity {
            Some(a) => {
                let m = a.v.iter().map(|&x| x as f64).sum::<f64>() / a.v.len().max(1) as f64;
                a.v.iter().map(|&x| x - m as f32).collect()
            }
            None => vec![0.0; lo.v.len()],
        };
        let os = p.oversample as f64;
        let mask: Vec<bool> = (0..lo.rows * lo.cols)
            .map(|i| {
                let (r, c) = (i / lo.cols, i % lo.cols);
                footprint.contains((r as f64 + 0.5) / os, (c as f64 + 0.5) / os, p.rows, p.cols)
            })
            .collect();
        // A rigid base pressed into an elastic ground carries more load at its rim than at its
        // centre (the rigid punch: p ~ 1/sqrt(1 - rho^2)); pressed through soft felt onto rigid
        // ground it carries it evenly. Between the two, by how much softer the ground is than
        // the felt. This is what makes clay, grass and sand look soft to the sensor at any load.
        let soft = RIM_GAIN * p.felt_kpa_mm / (p.felt_kpa_mm + surface.stiffness_kpa_mm);
        let mut rim: Vec<f32> = (0..lo.rows * lo.cols)
            .map(|i| {
                let (r, c) = (i / lo.cols, i % lo.cols);
                let rho2 =
                    footprint.rho2((r as f64 + 0.5) / os, (c as f64 + 0.5) / os, p.rows, p.cols);
                let punch = 1.0 / (1.0 - rho2.min(RIM_RHO2_MAX)).sqrt();
                ((1.0 - soft) + soft * punch) as f32
            })
            .collect();
        let (sum, n) = rim
            .iter()
            .zip(&mask)
            .filter(|(_, m)| **m)
            .fold((0.0f64, 0usize), |(s, n), (w, _)| (s + *w as f64, n + 1));
        if n > 0 && sum > 0.0 {
            let k = (n as f64 / sum) as f32;
            rim.iter_mut().for_each(|w| *w *= k);
        }
        Contact {
            lo: lo.v,
            hi,
            mask,
            rim,
            k_lo: series(p.felt_kpa_mm, surface.stiffness_kpa_mm),
            k_hi: series(p.silicone_kpa_mm, surface.stiffness_kpa_mm),
        }
    }

    /// The image of counts for `load_n` newtons pressed through `contact`, written to `out`
    /// (`rows * cols`).
    pub fn image(&mut self, contact: &Contact, load_n: f64, rng: &mut impl Rng, out: &mut [u16]) {
        let cell_area = self.pressure.cell_mm * self.pressure.cell_mm;
        let pressure_at = |i: usize, z: f64| -> f64 {
            if !contact.mask[i] {
                return 0.0;
            }
            (contact.k_lo * (contact.lo[i] as f64 - z) + contact.k_hi * contact.hi[i] as f64)
                .max(0.0)
                * contact.rim[i] as f64
        };
        let target = load_n.max(0.0);
        if target > 0.0 {
            // The sole's depth z where the cells bear `load_n`. Each cell pushes back
            // k_lo * rim * max(0, z_i - z) (z_i: the depth where it starts to bear), so the
            // force is piecewise linear, convex and falling in z: Newton's method from a depth
            // with too much force never overshoots and is exact once in the root's segment
            // (a few passes over the cells where a 40-step bisection took about 50): `presrs lab sim
            // --log F --duration 20` 1.80 s -> 0.80 s on the host, the same images to the bit.
            // (In the vcan VM the simulator's pace is set by its loop, not by this: unchanged.)
            self.hinges.clear();
            for i in 0..contact.lo.len() {
                if contact.mask[i] && contact.rim[i] > 0.0 {
                    let z_i =
                        contact.lo[i] as f64 + contact.k_hi / contact.k_lo * contact.hi[i] as f64;
                    self.hinges.push((z_i, contact.rim[i] as f64));
                }
            }
            let depth = newton_depth(&self.hinges, contact.k_lo * cell_area / 1000.0, target);
            // No cell can bear load: every pressure 0.
            let z = depth.unwrap_or(f64::INFINITY);
            for i in 0..contact.lo.len() {
                self.pressure.v[i] = pressure_at(i, z) as f32;
            }
            self.pressure
                .blur(self.params.felt_spread_mm, &mut self.scratch);
        } else {
            self.pressure.v.fill(0.0);
        }
        let p = &self.params;
        let os = p.oversample;
        let fine_cols = p.cols * os;
        let max = ((1u32 << p.bits) - 1) as f64;
        let counts_per_kpa = max / p.full_scale_kpa;
        for r in 0..p.rows {
            for c in 0..p.cols {
                let mut acc = 0.0f64;
                for dr in 0..os {
                    for dc in 0..os {
                        acc += self.pressure.v[(r * os + dr) * fine_cols + c * os + dc] as f64;
                    }
                }
                let kpa = acc / (os * os) as f64;
                let i = r * p.cols + c;
                let n: f64 = StandardNormal.sample(rng);
                let v = kpa * counts_per_kpa * self.gain[i] as f64 * self.faults.drift_gain
                    + n * p.noise_counts;
                out[i] = if v < p.threshold_counts {
                    0
                } else {
                    v.round().min(max) as u16
                };
            }
        }
        self.faults.apply(out, max as u16, rng);
    }
}

/// The depth where cells `(z_i, rim_i)` bear `target`, the force being
/// `c * sum(rim_i * max(0, z_i - z))`; `None` when no cell can bear load (or no stiffness).
fn newton_depth(hinges: &[(f64, f64)], c: f64, target: f64) -> Option<f64> {
    if hinges.is_empty() || c.is_nan() || c <= 0.0 {
        return None;
    }
    // (force, -d force/dz) at z.
    let at = |z: f64| {
        let (mut w, mut wz) = (0.0, 0.0);
        for &(z_i, rim) in hinges {
            if z_i > z {
                w += rim;
                wz += rim * z_i;
            }
        }
        (c * (wz - w * z), c * w)
    };
    let z_top = hinges.iter().map(|h| h.0).fold(f64::MIN, f64::max);
    let mut step = 0.01;
    let mut z = z_top - step;
    while at(z).0 < target && step < 1e4 {
        step *= 2.0;
        z = z_top - step;
    }
    for _ in 0..64 {
        let (f, slope) = at(z);
        if f <= target || slope <= 0.0 {
            break;
        }
        let next = z + (f - target) / slope;
        if next <= z {
            break;
        }
        z = next;
    }
    Some(z)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::faults::FaultParams;
    use rand::SeedableRng;

    #[test]
    fn newton_finds_the_depth_bisection_finds() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for _ in 0..50 {
            let n = rng.random_range(1..400);
            let hinges: Vec<(f64, f64)> = (0..n)
                .map(|_| (rng.random::<f64>() * 2.0 - 1.0, rng.random::<f64>()))
                .collect();
            let c = 0.01 + rng.random::<f64>();
            let force = |z: f64| {
                c * hinges
                    .iter()
                    .map(|&(z_i, w)| w * (z_i - z).max(0.0))
                    .sum::<f64>()
            };
            let target = rng.random::<f64>() * 50.0 + 1e-3;
            let z = newton_depth(&hinges, c, target).unwrap();
            assert!(
                (force(z) - target).abs() <= 1e-9 * target,
                "force {} for {target}",
                force(z)
            );
        }
        assert_eq!(newton_depth(&[], 1.0, 5.0), None);
    }

    fn press(physics: Physics, footprint: Footprint, load_n: f64, seed: u64) -> Vec<u16> {
        let mut skin = Skin::of_sensor(1, SkinParams::default(), FaultParams::default());
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let contact = skin.contact_on(physics, footprint, &mut rng);
        let mut out = vec![0u16; 44 * 44];
        skin.image(&contact, load_n, &mut rng, &mut out);
        out
    }

    #[test]
    fn the_foot_presses_only_inside_its_footprint_and_more_load_reads_higher() {
        let light = press(Physics::Wood, Footprint::FOOT, 30.0, 1);
        let heavy = press(Physics::Wood, Footprint::FOOT, 90.0, 1);
        // Outside the foot (bottom 3 rows, first 6 columns) only the felt's spread and the
        // noise above threshold read anything: well under 1% of the counts.
        let outside: u64 = (0..44 * 44)
            .filter(|i| i / 44 >= 41 || i % 44 < 6)
            .map(|i| heavy[i] as u64)
            .sum();
        let sum = |v: &[u16]| v.iter().map(|&x| x as u64).sum::<u64>();
        assert!(sum(&light) > 0);
        assert!(
            outside * 100 < sum(&heavy),
            "{outside} of {} outside",
            sum(&heavy)
        );
        assert!(
            sum(&heavy) > 2 * sum(&light),
            "{} vs {}",
            sum(&heavy),
            sum(&light)
        );
        assert!(heavy.iter().all(|&v| v <= 255), "8-bit counts");
    }

    #[test]
    fn the_same_seed_renders_the_same_image_and_terrains_differ() {
        let a = press(Physics::Carpet, Footprint::DIE, 60.0, 3);
        assert_eq!(a, press(Physics::Carpet, Footprint::DIE, 60.0, 3));
        assert_ne!(a, press(Physics::Carpet, Footprint::DIE, 60.0, 4));
        assert_ne!(a, press(Physics::Wood, Footprint::DIE, 60.0, 3));
    }

    #[test]
    fn a_sensors_dead_lines_read_zero_in_its_images() {
        let faults = FaultParams {
            initial_damage_pct: 20.0,
            ..Default::default()
        };
        let mut skin = Skin::of_sensor(9, SkinParams::default(), faults);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let contact = skin.contact_on(Physics::Wood, Footprint::DIE, &mut rng);
        let mut out = vec![0u16; 44 * 44];
        skin.image(&contact, 80.0, &mut rng, &mut out);
        let f = &skin.faults;
        assert!(f.damage_pct() >= 20.0);
        for (r, _) in f.dead_rows.iter().enumerate().filter(|(_, d)| **d) {
            assert!(out[r * 44..(r + 1) * 44].iter().all(|&v| v == 0), "row {r}");
        }
        for (c, _) in f.dead_cols.iter().enumerate().filter(|(_, d)| **d) {
            assert!((0..44).all(|r| out[r * 44 + c] == 0), "col {c}");
        }
    }
}
