//! Terrain surfaces as the foot's skin meets them: a height field under the sensor (mm, on the
//! fine grid), the terrain's local stiffness, and its bulk stiffness under the hopper.
//!
//! Every sample is a fresh random patch (stones, needles and particles placed anew), so no two
//! samples are alike. The physical reasoning per surface is in the comments of
//! [`Physics::surface`]; how the skin turns a surface into pressure is in `skin.rs`. The
//! sandpapers are grains ([`Physics::grit_diameter_mm`]) on a cloth backing whose relief
//! ([`BACKING_RELIEF_MM`]) is what makes the paper's resolution experiment come out as it does.

use std::f64::consts::PI;

use rand::Rng;
use rand_distr::{Distribution, Poisson};
use serde::{Deserialize, Serialize};

pub use protocol::terrain::Terrain;

use crate::field::{Field, normal};
use crate::hopper::Ground;

/// The simulator's model of each surface of the paper's three experiments. A [`Terrain`]
/// (the catalog's) picks its model by name ([`Physics::of`]); nothing depends on this enum's
/// order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Physics {
    /// Polished aluminium plate.
    Aluminum,
    /// Loose sand.
    Sand,
    /// Pine needles.
    PineNeedles,
    /// Gravel.
    Gravel,
    /// Sandpaper, grit 220.
    Sandpaper220,
    /// Sandpaper, grit 150.
    Sandpaper150,
    /// Sandpaper, grit 100.
    Sandpaper100,
    /// Sandpaper, grit 60.
    Sandpaper60,
    /// Wood board.
    Wood,
    /// Carpet.
    Carpet,
    /// Clay.
    Clay,
    /// Grass.
    Grass,
}

/// A catalog terrain the simulator has no model for.
#[derive(Debug, thiserror::Error, Clone, Copy, PartialEq, Eq)]
#[error(
    "the simulator cannot simulate terrain `{0}` (id {id}): it models the paper's twelve \
     (aluminum, sand, pine_needles, gravel, sandpaper_220/150/100/60, wood, carpet, clay, grass); \
     record this terrain on the robot instead (docs/deploy.md)", id = .0.id()
)]
pub struct CannotSimulate(pub Terrain);

/// A terrain patch under the sensor.
pub struct Surface {
    /// Height of the surface at the felt's scale (a millimetre and up), mm; higher touches first.
    pub height: Field,
    /// Sub-millimetre asperities (mm about their mean) that the hard silicone rides on rather
    /// than wrapping: the only way features far below the sensor pitch reach the sensels.
    pub asperity: Option<Field>,
    /// Local stiffness of the terrain itself, kPa/mm (in series with the skin).
    pub stiffness_kpa_mm: f64,
}

impl Physics {
    /// Every surface the simulator has.
    pub const ALL: [Physics; 12] = [
        Physics::Aluminum,
        Physics::Sand,
        Physics::PineNeedles,
        Physics::Gravel,
        Physics::Sandpaper220,
        Physics::Sandpaper150,
        Physics::Sandpaper100,
        Physics::Sandpaper60,
        Physics::Wood,
        Physics::Carpet,
        Physics::Clay,
        Physics::Grass,
    ];
    /// Section 4: the static set.
    pub const STATIC: [Physics; 4] = [
        Physics::Aluminum,
        Physics::Sand,
        Physics::PineNeedles,
        Physics::Gravel,
    ];
    /// Section 5: the sandpaper set.
    pub const SANDPAPER: [Physics; 5] = [
        Physics::Aluminum,
        Physics::Sandpaper220,
        Physics::Sandpaper150,
        Physics::Sandpaper100,
        Physics::Sandpaper60,
    ];
    /// Section 7: the dynamic set.
    pub const DYNAMIC: [Physics; 4] = [
        Physics::Wood,
        Physics::Carpet,
        Physics::Clay,
        Physics::Grass,
    ];

    /// The terrain this models (the paper's catalog entry of the same name).
    pub fn terrain(self) -> Terrain {
        match self {
            Physics::Aluminum => Terrain::ALUMINUM,
            Physics::Sand => Terrain::SAND,
            Physics::PineNeedles => Terrain::PINE_NEEDLES,
            Physics::Gravel => Terrain::GRAVEL,
            Physics::Sandpaper220 => Terrain::SANDPAPER_220,
            Physics::Sandpaper150 => Terrain::SANDPAPER_150,
            Physics::Sandpaper100 => Terrain::SANDPAPER_100,
            Physics::Sandpaper60 => Terrain::SANDPAPER_60,
            Physics::Wood => Terrain::WOOD,
            Physics::Carpet => Terrain::CARPET,
            Physics::Clay => Terrain::CLAY,
            Physics::Grass => Terrain::GRASS,
        }
    }

    /// The model of a catalog terrain, chosen by its name; an error for a terrain (a lab's
    /// own, say) that the simulator has no physics for.
    pub fn of(terrain: Terrain) -> Result<Physics, CannotSimulate> {
        Ok(match terrain.name() {
            "aluminum" => Physics::Aluminum,
            "sand" => Physics::Sand,
            "pine_needles" => Physics::PineNeedles,
            "gravel" => Physics::Gravel,
            "sandpaper_220" => Physics::Sandpaper220,
            "sandpaper_150" => Physics::Sandpaper150,
            "sandpaper_100" => Physics::Sandpaper100,
            "sandpaper_60" => Physics::Sandpaper60,
            "wood" => Physics::Wood,
            "carpet" => Physics::Carpet,
            "clay" => Physics::Clay,
            "grass" => Physics::Grass,
            _ => return Err(CannotSimulate(terrain)),
        })
    }

    /// The paper's name of the terrain this models.
    pub fn name(self) -> &'static str {
        self.terrain().name()
    }

    /// Aluminum-oxide particle diameter of a sandpaper, mm (the paper's Table 2).
    pub fn grit_diameter_mm(self) -> Option<f64> {
        match self {
            Physics::Sandpaper220 => Some(0.058),
            Physics::Sandpaper150 => Some(0.082),
            Physics::Sandpaper100 => Some(0.129),
            Physics::Sandpaper60 => Some(0.260),
            _ => None,
        }
    }

    /// Friction of the foot's silicone sole on this ground (docs/decisions/ground-physics.md).
    pub fn friction(self) -> f64 {
        match self {
            Physics::Aluminum => 0.6,
            Physics::Wood => 0.8,
            Physics::Gravel => 0.65,
            Physics::Sandpaper220
            | Physics::Sandpaper150
            | Physics::Sandpaper100
            | Physics::Sandpaper60 => 1.0,
            Physics::Carpet => 0.9,
            Physics::Clay => 0.8,
            Physics::Grass => 0.8,
            Physics::Sand => 0.65,
            Physics::PineNeedles => 0.55,
        }
    }

    /// The ground under the hopper: bulk stiffness and damping in series with the leg.
    pub fn ground(self) -> Ground {
        let (stiffness, damping) = match self {
            // Rigid for a 2 kg hopper.
            Physics::Aluminum | Physics::Wood | Physics::Gravel => (2e5, 5.0),
            Physics::Sandpaper220
            | Physics::Sandpaper150
            | Physics::Sandpaper100
            | Physics::Sandpaper60 => (2e5, 5.0),
            // Low-pile carpet on a hard floor: some give, some loss.
            Physics::Carpet => (3e4, 40.0),
            // Semi-moist clay: soft and lossy (it deforms plastically).
            Physics::Clay => (1.5e4, 120.0),
            // Thick grass: soft and springy.
            Physics::Grass => (8e3, 15.0),
            Physics::Sand => (1e4, 150.0),
            Physics::PineNeedles => (1.2e4, 60.0),
        };
        Ground {
            stiffness,
            damping,
            friction: self.friction(),
        }
    }

    /// A fresh random patch of this surface on a `rows x cols` grid of `cell_mm` cells.
    pub fn surface(self, rows: usize, cols: usize, cell_mm: f64, rng: &mut impl Rng) -> Surface {
        let w = cols as f64 * cell_mm;
        let h = rows as f64 * cell_mm;
        let mut asperity = None;
        let (height, stiffness_kpa_mm) = match self {
            Physics::Aluminum => {
                // Polished plate: a slight tilt against the die and sub-micron roughness.
                asperity = Some(Field::random_smooth(rows, cols, cell_mm, 0.0005, 0.2, rng));
                (plate(rows, cols, cell_mm, 0.0, rng), 1e6)
            }
            Physics::Sand => {
                // Dry beach sand settles under the die: mm-scale mottling of the bed and grains
                // of 0.1-0.5 mm, on a bed far softer than the skin.
                let mut f = Field::random_smooth(rows, cols, cell_mm, 0.12, 3.0, rng);
                let grains = Field::random_smooth(rows, cols, cell_mm, 0.05, 0.2, rng);
                f.add(&grains);
                (f, 12.0)
            }
            Physics::PineNeedles => (strands(&NEEDLES, rows, cols, cell_mm, w, h, rng), 60.0),
            Physics::Gravel => (stones(rows, cols, cell_mm, w, h, rng), 1e5),
            Physics::Sandpaper220
            | Physics::Sandpaper150
            | Physics::Sandpaper100
            | Physics::Sandpaper60 => {
                let d = self.grit_diameter_mm().unwrap_or(0.1);
                asperity = Some(grit(rows, cols, cell_mm, d, rng));
                let mut f = plate(rows, cols, cell_mm, 0.0, rng);
                f.add(&backing(rows, cols, cell_mm, rng));
                (f, 1e5)
            }
            Physics::Wood => (wood(rows, cols, cell_mm, w, rng), 2e3),
            Physics::Carpet => (carpet(rows, cols, cell_mm, rng), 1000.0),
            Physics::Clay => (clay(rows, cols, cell_mm, w, h, rng), 15.0),
            Physics::Grass => {
                // Thick grass: many blades 3-6 mm wide lying in random directions at several
                // heights; the foot presses the top layer.
                (strands(&BLADES, rows, cols, cell_mm, w, h, rng), 20.0)
            }
        };
        Surface {
            height,
            asperity,
            stiffness_kpa_mm,
        }
    }
}

/// Planed wood's height field (the [`Physics::Wood`] surface).
fn wood(rows: usize, cols: usize, cell_mm: f64, w: f64, rng: &mut impl Rng) -> Field {
    // Planed pine: grain ridges about 2-4 mm apart (earlywood/latewood), a few
    // microns to tens of microns high, along the plank; now and then a plank seam.
    let mut f = plate(rows, cols, cell_mm, 0.002, rng);
    let angle = rng.random_range(-0.15..0.15f64) + PI / 2.0;
    let period = rng.random_range(2.0..4.0);
    let phase = rng.random_range(0.0..1.0);
    let (s, c) = angle.sin_cos();
    let seam = rng.random_bool(0.3).then(|| rng.random_range(0.2..0.8) * w);
    for r in 0..rows {
        for col in 0..cols {
            let (y, x) = f.pos(r, col);
            let u = x * c + y * s;
            let ring = (u / period + phase).fract();
            let mut z = if ring < 0.3 { 0.03 } else { 0.0 };
            if seam.is_some_and(|sx| (x - sx).abs() < 0.6) {
                z -= 0.5;
            }
            f.v[r * cols + col] += z as f32;
        }
    }
    f
}

/// Loop-pile carpet's height field (the [`Physics::Carpet`] surface).
fn carpet(rows: usize, cols: usize, cell_mm: f64, rng: &mut impl Rng) -> Field {
    // Loop pile: tufts on a square gauge of 3.6 mm. One carpet: the gauge varies only
    // by manufacturing tolerance, the orientation and offset by where the foot lands
    // (a gauge drawn anew per stance made every step a different carpet). The loops
    // are far stiffer than the skin's felt, so each presses through as a bump the
    // sensor can see.
    let mut f = Field::zeros(rows, cols, cell_mm);
    let gauge = rng.random_range(3.5..3.7);
    let (oy, ox) = (rng.random_range(0.0..gauge), rng.random_range(0.0..gauge));
    let angle: f64 = rng.random_range(-0.2..0.2);
    let (s, c) = angle.sin_cos();
    let jitter = normal(0.0, 0.08);
    for r in 0..rows {
        for col in 0..cols {
            let (y, x) = f.pos(r, col);
            let (u, v) = (x * c + y * s + ox, -x * s + y * c + oy);
            let du = (u / gauge).fract() - 0.5;
            let dv = (v / gauge).fract() - 0.5;
            let r2 = (du * du + dv * dv) * gauge * gauge;
            let tuft = 1.2 * (-r2 / (2.0 * 0.6f64.powi(2))).exp();
            f.v[r * cols + col] = (tuft + jitter.sample(rng)) as f32;
        }
    }
    f
}

/// Clay dirt's height field (the [`Physics::Clay`] surface).
fn clay(rows: usize, cols: usize, cell_mm: f64, w: f64, h: f64, rng: &mut impl Rng) -> Field {
    // Semi-moist clay dirt: a soft, mostly conforming bed with clods and a few
    // embedded pebbles, and drying cracks.
    let mut f = Field::random_smooth(rows, cols, cell_mm, 0.25, 5.0, rng);
    let clods = Field::random_smooth(rows, cols, cell_mm, 0.10, 1.0, rng);
    f.add(&clods);
    for _ in 0..rng.random_range(1..4) {
        let (cy, cx, rad) = (
            rng.random_range(0.0..h),
            rng.random_range(0.0..w),
            rng.random_range(1.0..2.5),
        );
        bump(&mut f, cy, cx, rad, 0.6);
    }
    if rng.random_bool(0.5) {
        let (y0, a) = (rng.random_range(0.0..h), rng.random_range(0.0..PI));
        crack(&mut f, y0, a, 0.8, -1.0);
    }
    f
}

/// A flat plate with a random tilt and waviness `rough_mm` (over about 2 mm).
fn plate(rows: usize, cols: usize, cell_mm: f64, rough_mm: f64, rng: &mut impl Rng) -> Field {
    let mut f = Field::random_smooth(rows, cols, cell_mm, rough_mm, 2.0, rng);
    let (gy, gx) = (
        rng.random_range(-4e-4..4e-4f64),
        rng.random_range(-4e-4..4e-4f64),
    );
    for r in 0..rows {
        for c in 0..cols {
            let (y, x) = f.pos(r, c);
            f.v[r * cols + c] += (gy * y + gx * x) as f32;
        }
    }
    f
}

fn bump(f: &mut Field, cy: f64, cx: f64, rad: f64, height: f64) {
    for r in 0..f.rows {
        for c in 0..f.cols {
            let (y, x) = f.pos(r, c);
            let d2 = (y - cy).powi(2) + (x - cx).powi(2);
            if d2 < rad * rad {
                let z = height * (1.0 - d2 / (rad * rad)).sqrt();
                let i = r * f.cols + c;
                f.v[i] = f.v[i].max(z as f32);
            }
        }
    }
}

fn crack(f: &mut Field, y0: f64, angle: f64, width: f64, depth: f64) {
    let (s, c) = angle.sin_cos();
    for r in 0..f.rows {
        for col in 0..f.cols {
            let (y, x) = f.pos(r, col);
            let d = ((y - y0) * c - x * s).abs();
            if d < width / 2.0 {
                f.v[r * f.cols + col] += depth as f32;
            }
        }
    }
}

/// Dolomite gravel of 10-50 mm stones: rounded tops at different heights, so under a flat foot
/// only the highest few carry the load.
fn stones(rows: usize, cols: usize, cell_mm: f64, w: f64, h: f64, rng: &mut impl Rng) -> Field {
    let mut f = Field::zeros(rows, cols, cell_mm);
    f.v.fill(-20.0);
    // Enough stones to cover the patch and its surroundings.
    let n = rng.random_range(6..12);
    for _ in 0..n {
        let size = rng.random_range(10.0..50.0f64);
        let (cy, cx) = (
            rng.random_range(-10.0..h + 10.0),
            rng.random_range(-10.0..w + 10.0),
        );
        // Radius of curvature of the top: about half the stone, flattened stones more.
        let radius = size * rng.random_range(0.4..0.9);
        let top = rng.random_range(0.0..4.0) + 0.05 * size;
        for r in 0..rows {
            for c in 0..cols {
                let (y, x) = f.pos(r, c);
                let d2 = (y - cy).powi(2) + (x - cx).powi(2);
                let z = top - d2 / (2.0 * radius);
                let i = r * cols + c;
                f.v[i] = f.v[i].max(z as f32);
            }
        }
    }
    f
}

/// A loose pile of long thin things (needles, blades) as cylinders at random heights.
struct Strands {
    /// Height of the gaps between strands, mm.
    background: f32,
    count: std::ops::Range<usize>,
    length_mm: std::ops::Range<f64>,
    thickness_mm: std::ops::Range<f64>,
    /// `None`: any direction; `Some(s)`: within `s` rad of a common direction.
    spread: Option<f64>,
    base_mm: std::ops::Range<f64>,
    /// Largest slope along a strand (they sag and twist).
    slope: f64,
}

/// Dry pine needles: cylinders 0.8-1.5 mm thick and 20-60 mm long in a loose random pile.
const NEEDLES: Strands = Strands {
    background: -6.0,
    count: 35..60,
    length_mm: 20.0..60.0,
    thickness_mm: 0.8..1.5,
    spread: None,
    base_mm: -4.0..0.0,
    slope: 0.03,
};

/// Thick grass: flat blades 3-6 mm wide, 30-80 mm long, in several layers. A lawn is combed by
/// the mower and the wind, so blades share a loose main direction; a blade is flat with a
/// raised midrib, modelled as a wide, low cylinder.
const BLADES: Strands = Strands {
    background: -8.0,
    count: 40..70,
    length_mm: 30.0..80.0,
    thickness_mm: 3.0..6.0,
    spread: Some(0.6),
    base_mm: -5.0..0.0,
    slope: 0.05,
};

fn strands(
    spec: &Strands,
    rows: usize,
    cols: usize,
    cell_mm: f64,
    w: f64,
    h: f64,
    rng: &mut impl Rng,
) -> Field {
    let mut f = Field::zeros(rows, cols, cell_mm);
    f.v.fill(spec.background);
    let n = rng.random_range(spec.count.clone());
    let main = spec.spread.map(|_| rng.random_range(0.0..PI));
    for _ in 0..n {
        let len = rng.random_range(spec.length_mm.clone());
        let thickness = rng.random_range(spec.thickness_mm.clone());
        let (cy, cx) = (
            rng.random_range(-10.0..h + 10.0),
            rng.random_range(-10.0..w + 10.0),
        );
        let a = match (main, spec.spread) {
            (Some(m), Some(s)) => m + rng.random_range(-s..s),
            _ => rng.random_range(0.0..PI),
        };
        let base = rng.random_range(spec.base_mm.clone());
        let slope = rng.random_range(-spec.slope..spec.slope);
        segment(&mut f, cy, cx, a, len, thickness / 2.0, base, slope);
    }
    f
}

/// Adds a cylinder of radius `rad` lying along a segment to the height field (max).
#[allow(clippy::too_many_arguments)]
fn segment(f: &mut Field, cy: f64, cx: f64, a: f64, len: f64, rad: f64, base: f64, slope: f64) {
    let (s, c) = a.sin_cos();
    for r in 0..f.rows {
        for col in 0..f.cols {
            let (y, x) = f.pos(r, col);
            let (dy, dx) = (y - cy, x - cx);
            let along = dx * c + dy * s;
            if along.abs() > len / 2.0 {
                continue;
            }
            let across = (-dx * s + dy * c).abs();
            if across < rad {
                let z = base + slope * along + rad + (rad * rad - across * across).sqrt();
                let i = r * f.cols + col;
                f.v[i] = f.v[i].max(z as f32);
            }
        }
    }
}

/// Relief of a sandpaper's cloth backing at the felt's scale, mm (one sigma).
///
/// The paper's sandpaper is "aluminum oxide particles adhered to a fabric backing". A woven
/// cloth laid on the platform's table is not flat at the scale of a few sensels: its yarns
/// (about 0.2-0.5 mm thick) cross over each other, the make coat only partly levels them, and
/// a sheet cut from a roll keeps the cockle of its weave and its cure. Its thickness tolerance,
/// tens of microns, is this relief. Features under about 2 mm are lost in the felt's spread
/// (a sinusoid of 2 mm period keeps 4 % through the 0.8 mm blur), so what the sensor sees is
/// the relief over several millimetres: 50 um over about 2 mm ([`BACKING_CORR_MM`]).
///
/// It is the same cloth under every grit, so it adds the same mm-scale pressure pattern to
/// every grit's image: a 50 um crest presses the felt 1.5 kPa more (30 kPa/mm), 40 % of the
/// 3.9 kPa of a 10 N press. Under a fine grit the skin follows it; under 60 grit the
/// tallest grains, whose spread in height (about 40 um) the stiff silicone reads 33 times
/// harder than the felt, carry the load and mask it. What is left to tell two grits apart is
/// then the grains' texture at one to two sensels, which a 40x40 image resolves and a 10x10
/// one (5.08 mm pitch) aliases into the backing's pattern: the paper's section 5.
///
/// The value is an estimate of the cloth's relief; measured: docs/decisions/sandpaper-backing-relief.md.
pub const BACKING_RELIEF_MM: f64 = 0.05;
/// Correlation length of the backing's relief (the Gaussian smoothing of white noise), mm.
pub const BACKING_CORR_MM: f64 = 2.0;

/// The cloth backing's relief ([`BACKING_RELIEF_MM`]): a smooth random field, fresh per press
/// (the die lands on another part of the sheet).
fn backing(rows: usize, cols: usize, cell_mm: f64, rng: &mut impl Rng) -> Field {
    Field::random_smooth(rows, cols, cell_mm, BACKING_RELIEF_MM, BACKING_CORR_MM, rng)
}

/// Sandpaper: aluminum-oxide particles of diameter `d` mm bonded in resin, about 0.45/d^2
/// particles per mm^2 (an open-to-closed coat). Each cell's height is its highest particle tip;
/// far below the sensor pitch, so only the statistics of many particles reach a sensel.
fn grit(rows: usize, cols: usize, cell_mm: f64, d: f64, rng: &mut impl Rng) -> Field {
    let mut f = Field::zeros(rows, cols, cell_mm);
    let lambda = 0.45 * cell_mm * cell_mm / (d * d);
    let count = Poisson::new(lambda).ok();
    let tip = normal(0.5 * d, 0.15 * d);
    // Resin bed: about 35 % of the particle height.
    let bed = 0.35 * d;
    for x in f.v.iter_mut() {
        let n = count.as_ref().map_or(1.0, |p| p.sample(rng)) as usize;
        let mut top = bed;
        for _ in 0..n {
            top = top.max(tip.sample(rng));
        }
        *x += top as f32;
    }
    f
}
