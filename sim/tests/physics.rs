//! The simulator's promises: determinism, distinct surfaces, plausible hopping.

use controller::Gait;
use presrs_sim::dataset::{Kind, Options, generate};
use presrs_sim::terrain::Terrain;

fn opts(kind: Kind, n: usize, gait: Gait, seed: u64) -> Options {
    Options {
        kind,
        n: Some(n),
        gait,
        damage_pct: 0.0,
        sensor: presrs_sim::DEFAULT_SENSOR,
        seed,
    }
}

#[test]
fn same_seed_same_output_other_seed_other_output() {
    let a = generate(&opts(Kind::Static, 3, Gait::g2(), 7));
    let b = generate(&opts(Kind::Static, 3, Gait::g2(), 7));
    let c = generate(&opts(Kind::Static, 3, Gait::g2(), 8));
    assert!(a.iter().zip(&b).all(|(x, y)| x.pixels == y.pixels));
    assert!(a.iter().zip(&c).any(|(x, y)| x.pixels != y.pixels));
    // no two samples alike
    assert!(a.windows(2).all(|w| w[0].pixels != w[1].pixels));
}

fn in_image_sd(p: &[u16]) -> f64 {
    let m = p.iter().map(|&v| v as f64).sum::<f64>() / p.len() as f64;
    (p.iter().map(|&v| (v as f64 - m).powi(2)).sum::<f64>() / p.len() as f64).sqrt()
}

#[test]
fn sandpaper_roughness_grows_with_particle_size() {
    // Inside the die only (rows/cols 4..40), the mean in-image spread orders by grit size.
    let s = generate(&opts(Kind::Sandpaper, 10, Gait::g2(), 3));
    let spread = |t: Terrain| {
        let v: Vec<f64> = s
            .iter()
            .filter(|x| x.terrain == t)
            .map(|x| {
                let inner: Vec<u16> = (4..40)
                    .flat_map(|r| (4..40).map(move |c| (r, c)))
                    .map(|(r, c)| x.pixels[r * 44 + c])
                    .collect();
                in_image_sd(&inner)
            })
            .collect();
        v.iter().sum::<f64>() / v.len() as f64
    };
    let order: Vec<f64> = Kind::Sandpaper.terrains().into_iter().map(spread).collect();
    assert!(
        order.windows(2).all(|w| w[0] < w[1]),
        "aluminum, 220, 150, 100, 60: {order:?}"
    );
}

#[test]
fn static_presses_carry_the_platform_load() {
    let s = generate(&opts(Kind::Static, 5, Gait::g2(), 4));
    for x in &s {
        // 10 N over the sensels: counts * 138/255 kPa * 1.613 mm^2 each.
        let n: f64 = x
            .pixels
            .iter()
            .map(|&v| v as f64 * 138.0 / 255.0 * 1.27 * 1.27 / 1000.0)
            .sum();
        assert!(
            (7.0..13.0).contains(&n),
            "{}: {n:.1} N read back",
            x.terrain
        );
        // gravel loads a few stones, sand spreads: zero fraction tells them apart
    }
    let zeros = |t: Terrain| {
        s.iter()
            .filter(|x| x.terrain == t)
            .map(|x| x.pixels[..].iter().filter(|&&v| v == 0).count())
            .sum::<usize>()
    };
    assert!(zeros(Terrain::GRAVEL) > 3 * zeros(Terrain::SAND));
}

#[test]
fn stance_times_and_speeds_in_documented_ranges() {
    for g in Gait::paper_gaits() {
        let s = generate(&opts(Kind::Dynamic, 15, g.clone(), 5));
        for t in Kind::Dynamic.terrains() {
            let of: Vec<_> = s.iter().filter(|x| x.terrain == t).collect();
            assert_eq!(of.len(), 15, "G{} {t}: every stance sampled", g.id);
            let stance = of.iter().map(|x| x.stance_s).sum::<f64>() / 15.0;
            let speed = of.iter().map(|x| x.speed_m_s).sum::<f64>() / 15.0;
            let load = of.iter().map(|x| x.load_n).fold(0.0, f64::max);
            assert!(
                (0.14..0.21).contains(&stance),
                "G{} {t}: stance {stance}",
                g.id
            );
            assert!((0.3..1.5).contains(&speed), "G{} {t}: speed {speed}", g.id);
            assert!((20.0..200.0).contains(&load), "G{} {t}: load {load}", g.id);
        }
        // faster gaits run faster on every terrain (Table 3's ordering)
    }
    // The paper's premise for one classifier across gaits: the frame at 70 ms carries about the
    // same load whatever the gait.
    let mean_load = |g: Gait, t: Terrain| {
        let s = generate(&opts(Kind::Dynamic, 15, g, 7));
        let of: Vec<_> = s
            .iter()
            .filter(|x| x.terrain == t)
            .map(|x| x.load_n)
            .collect();
        of.iter().sum::<f64>() / of.len() as f64
    };
    for t in Kind::Dynamic.terrains() {
        let l2 = mean_load(Gait::g2(), t);
        for g in [Gait::g1(), Gait::g3()] {
            let l = mean_load(g.clone(), t);
            assert!(
                (l / l2 - 1.0).abs() < 0.05,
                "{t}: load at 70 ms G{} {l:.1} N vs G2 {l2:.1} N",
                g.id
            );
        }
    }
    let speed = |g: Gait| {
        let s = generate(&opts(Kind::Dynamic, 10, g, 6));
        s.iter().map(|x| x.speed_m_s).sum::<f64>() / s.len() as f64
    };
    let (v1, v2, v3) = (speed(Gait::g1()), speed(Gait::g2()), speed(Gait::g3()));
    assert!(v1 < v2 && v2 < v3, "{v1} {v2} {v3}");
}
