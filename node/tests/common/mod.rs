//! What the node crate's test binaries share: synthetic stance images.

use presrs_node::classifier::PressureImage;
use rand::Rng;

/// 44x44 image of a texture: `period` sets the contact-patch spacing, `fill` the contact
/// fraction, with random placement, load and noise.
pub fn texture(rng: &mut impl Rng, period: usize, fill: f64) -> PressureImage {
    let (dy, dx) = (rng.random_range(0..period), rng.random_range(0..period));
    let load = rng.random_range(0.8..1.2);
    let px = (0..44 * 44)
        .map(|i| {
            let (r, c) = (i / 44 + dy, i % 44 + dx);
            let on = ((r % period) as f64) < fill * period as f64
                && ((c % period) as f64) < fill * period as f64;
            let v: f64 = if on { 150.0 * load } else { 10.0 * load } + rng.random_range(-8.0..8.0);
            v.clamp(0.0, 255.0) as u16
        })
        .collect();
    PressureImage::new(44, 44, 8, px)
}
