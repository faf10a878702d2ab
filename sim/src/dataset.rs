//! The paper's three datasets, generated: static presses (section 4.1), sandpaper presses
//! (section 5) and dynamic stances on the hopper (section 7.1).

use controller::Gait;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::faults::FaultParams;
use crate::fixed_gait::FixedGait;
use crate::hopper::{Event, Hopper, HopperParams};
use crate::skin::{Footprint, Skin, SkinParams};
use crate::terrain::{Physics, Terrain};

/// The static load of the test platform, N (section 4.1).
pub const STATIC_LOAD_N: f64 = 10.0;
/// When the dynamic image is taken, s after touchdown (section 7.1).
pub const STANCE_SAMPLE_S: f64 = 0.07;
/// Sensor frame period, s (100 Hz).
pub const FRAME_PERIOD_S: f64 = crate::skin::FRAME_PERIOD_US as f64 * 1e-6;

/// Which experiment.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum Kind {
    /// Presses of the static platform on aluminum, sand, pine needles and gravel (section 4).
    Static,
    /// Presses on the four sandpaper grits and polished aluminum (section 5).
    Sandpaper,
    /// Hopper stances on the four dynamic terrains (section 7).
    Dynamic,
}

impl Kind {
    /// The surfaces of this experiment.
    pub fn physics(self) -> &'static [Physics] {
        match self {
            Kind::Static => &Physics::STATIC,
            Kind::Sandpaper => &Physics::SANDPAPER,
            Kind::Dynamic => &Physics::DYNAMIC,
        }
    }

    /// The set's terrains, in the paper's order.
    pub fn terrains(self) -> Vec<Terrain> {
        self.physics().iter().map(|p| p.terrain()).collect()
    }

    /// The paper's sample count for a terrain (Table 4 for the dynamic set).
    pub fn default_count(self, terrain: Physics, gait: u8) -> usize {
        match self {
            Kind::Static => 100,
            Kind::Sandpaper => 50,
            Kind::Dynamic => {
                let row = match gait {
                    1 => [72, 43, 119, 69],
                    3 => [71, 76, 102, 86],
                    _ => [60, 65, 113, 85],
                };
                let i = Physics::DYNAMIC
                    .iter()
                    .position(|t| *t == terrain)
                    .unwrap_or(0);
                row[i]
            }
        }
    }
}

/// One generated image with what produced it.
#[derive(Clone, Debug)]
pub struct Sample {
    /// The terrain pressed.
    pub terrain: Terrain,
    /// Rows of sensels.
    pub rows: usize,
    /// Columns of sensels.
    pub cols: usize,
    /// Row-major counts.
    pub pixels: Vec<u16>,
    /// Load on the sensor when the image was taken, N.
    pub load_n: f64,
    /// Dynamic set: stance duration (s) and forward speed (m/s) of the step.
    pub stance_s: f64,
    /// Forward speed of the step, m/s (dynamic set).
    pub speed_m_s: f64,
}

/// Options for [`generate`].
#[derive(Clone, Debug)]
pub struct Options {
    /// Which experiment.
    pub kind: Kind,
    /// Images per terrain; `None`: the paper's counts.
    pub n: Option<usize>,
    /// The gait the hopper runs (dynamic set).
    pub gait: Gait,
    /// Sensor damage from the start, percent of sensels (eq. 6).
    pub damage_pct: f64,
    /// Serial of the sensor that records the images (see [`Skin::of_sensor`]).
    pub sensor: u64,
    /// Seed: the same options give the same images.
    pub seed: u64,
}

/// Generates a dataset, terrain by terrain.
pub fn generate(opts: &Options) -> Vec<Sample> {
    let mut out = Vec::new();
    // One sensor for every terrain, as in the paper: its sensel gain pattern and its damage are
    // the same under every surface. (A sensor per terrain would let the classifier learn the
    // sensor instead of the terrain.)
    let faults = FaultParams {
        initial_damage_pct: opts.damage_pct,
        ..Default::default()
    };
    let mut skin = Skin::of_sensor(opts.sensor, SkinParams::default(), faults);
    for (ti, &terrain) in opts.kind.physics().iter().enumerate() {
        // One stream per terrain, so a class's samples do not depend on the others' counts.
        let mut rng = ChaCha8Rng::seed_from_u64(opts.seed ^ ((ti as u64 + 1) << 32));
        let n = opts
            .n
            .unwrap_or_else(|| opts.kind.default_count(terrain, opts.gait.id));
        match opts.kind {
            Kind::Static | Kind::Sandpaper => {
                for _ in 0..n {
                    out.push(press(
                        &mut skin,
                        terrain,
                        STATIC_LOAD_N,
                        Footprint::DIE,
                        &mut rng,
                    ));
                }
            }
            Kind::Dynamic => out.extend(stances(&mut skin, terrain, &opts.gait, n, &mut rng)),
        }
    }
    out
}

/// One static press of a fresh patch of `terrain`.
pub fn press(
    skin: &mut Skin,
    terrain: Physics,
    load_n: f64,
    fp: Footprint,
    rng: &mut impl Rng,
) -> Sample {
    let contact = skin.contact_on(terrain, fp, rng);
    let (rows, cols) = (skin.params.rows, skin.params.cols);
    let mut pixels = vec![0; rows * cols];
    skin.image(&contact, load_n, rng, &mut pixels);
    Sample {
        terrain: terrain.terrain(),
        rows,
        cols,
        pixels,
        load_n,
        stance_s: 0.0,
        speed_m_s: 0.0,
    }
}

/// `n` hopper stances on `terrain` in `gait`, each on a fresh patch, imaged at the sensor frame
/// nearest 70 ms after touchdown. The hopper runs 20 settling steps first.
pub fn stances(
    skin: &mut Skin,
    terrain: Physics,
    gait: &Gait,
    n: usize,
    rng: &mut impl Rng,
) -> Vec<Sample> {
    let mut out = Vec::with_capacity(n);
    let ground = terrain.ground();
    let mut hopper = Hopper::launch(HopperParams::default(), gait);
    let mut cmd = FixedGait::new(gait.clone());
    let phase = rng.random_range(0.0..FRAME_PERIOD_S);
    let (rows, cols) = (skin.params.rows, skin.params.cols);
    let mut steps = 0usize;
    let mut last_td: Option<(f64, f64)> = None;
    // A sample's stance time is known at its liftoff: the hopper goes on until the last one's.
    // (It stopped at the last image, which then read a stance of 0 s, and the first sample's
    // speed read 0, its previous touchdown being a settling step: `presrs lab dataset dynamic`'s
    // means were low by one sample in n.)
    let done = |out: &[Sample]| out.len() >= n && out.last().is_none_or(|s| s.stance_s > 0.0);
    while !done(&out) && steps < 20 + 4 * n {
        match hopper.advance(1.0, ground, &mut cmd) {
            Some(Event::Touchdown { t, beta, .. }) => {
                cmd.on_touchdown(beta);
                steps += 1;
                let x0 = hopper.x;
                if steps <= 20 || out.len() >= n {
                    // Settling, or the last sample's stance ended in a fall: no image here.
                    last_td = Some((t, x0));
                    if out.len() >= n {
                        break;
                    }
                    continue;
                }
                let k = ((t + STANCE_SAMPLE_S - phase) / FRAME_PERIOD_S).round();
                let t_frame = phase + k * FRAME_PERIOD_S;
                match hopper.advance(t_frame - t, ground, &mut cmd) {
                    None => {
                        let contact = skin.contact_on(terrain, Footprint::FOOT, rng);
                        let mut pixels = vec![0; rows * cols];
                        let load = hopper.foot_load();
                        skin.image(&contact, load, rng, &mut pixels);
                        let speed = last_td.map_or(0.0, |(t0, x)| (x0 - x) / (t - t0));
                        out.push(Sample {
                            terrain: terrain.terrain(),
                            rows,
                            cols,
                            pixels,
                            load_n: load,
                            stance_s: 0.0,
                            speed_m_s: speed,
                        });
                    }
                    Some(Event::Liftoff { beta, .. }) => cmd.on_liftoff(beta),
                    Some(_) => break,
                }
                last_td = Some((t, x0));
            }
            Some(Event::Liftoff { t, beta, .. }) => {
                cmd.on_liftoff(beta);
                if let Some(s) = out.last_mut().filter(|s| s.stance_s == 0.0)
                    && let Some((t0, _)) = last_td
                {
                    s.stance_s = t - t0;
                }
            }
            Some(Event::Fell { .. }) => {
                // Restart the run; a fall is a hopper problem, not a sensor one.
                hopper = Hopper::launch(HopperParams::default(), gait);
                cmd = FixedGait::new(gait.clone());
                last_td = None;
            }
            None => {}
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_dynamic_sample_has_its_stance_time_and_speed() {
        let s = generate(&Options {
            kind: Kind::Dynamic,
            n: Some(4),
            gait: Gait::g2(),
            damage_pct: 0.0,
            sensor: 1,
            seed: 7,
        });
        assert_eq!(s.len(), 16);
        for x in &s {
            // G2's stances last 0.16-0.19 s and it hops at 0.35-1.0 m/s (hopper.rs).
            assert!((0.12..0.25).contains(&x.stance_s), "{x:?}");
            assert!((0.2..1.2).contains(&x.speed_m_s), "{x:?}");
        }
    }
}
