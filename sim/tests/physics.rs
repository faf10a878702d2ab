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

/// Population standard deviation.
fn sd(v: &[f64]) -> f64 {
    let m = v.iter().sum::<f64>() / v.len() as f64;
    (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / v.len() as f64).sqrt()
}

fn in_image_sd(p: &[u16]) -> f64 {
    sd(&p.iter().map(|&v| v as f64).collect::<Vec<_>>())
}

/// Mean over `t`'s presses of `f` on the 36x36 inside the die (rows/cols 4..40).
fn per_terrain(s: &[presrs_sim::dataset::Sample], t: Terrain, f: fn(&[u16]) -> f64) -> f64 {
    let v: Vec<f64> = s
        .iter()
        .filter(|x| x.terrain == t)
        .map(|x| {
            let inner: Vec<u16> = (4..40)
                .flat_map(|r| (4..40).map(move |c| (r, c)))
                .map(|(r, c)| x.pixels[r * 44 + c])
                .collect();
            f(&inner)
        })
        .collect();
    v.iter().sum::<f64>() / v.len() as f64
}

/// Spread of the difference between a sensel and its right neighbour: the texture at one
/// sensel, with the mm-scale pattern (the backing's) mostly cancelled.
fn neighbour_sd(p: &[u16]) -> f64 {
    let d: Vec<f64> = (0..36)
        .flat_map(|r| (0..35).map(move |c| (r, c)))
        .map(|(r, c)| p[r * 36 + c] as f64 - p[r * 36 + c + 1] as f64)
        .collect();
    sd(&d)
}

#[test]
fn sandpaper_texture_at_one_sensel_grows_with_particle_size_over_a_common_backing() {
    let s = generate(&opts(Kind::Sandpaper, 10, Gait::g2(), 3));
    let terrains = Kind::Sandpaper.terrains();
    // The grains: sensel-to-sensel differences order by grit size (aluminum first). Measured:
    // 0.78, 1.35, 1.48, 1.80, 2.65 counts.
    let fine: Vec<f64> = terrains
        .iter()
        .map(|&t| per_terrain(&s, t, neighbour_sd))
        .collect();
    assert!(
        fine.windows(2).all(|w| w[0] < w[1]),
        "aluminum, 220, 150, 100, 60: {fine:?}"
    );
    // The cloth backing: every grit's image spreads well beyond aluminum's, and the finer
    // grits by about as much as each other (the same cloth), which is why a 10x10 image,
    // which keeps the spread and loses the neighbours, cannot tell them apart. Measured:
    // 0.62, 1.97, 1.89, 2.03, 2.89 counts.
    let all: Vec<f64> = terrains
        .iter()
        .map(|&t| per_terrain(&s, t, in_image_sd))
        .collect();
    assert!(all[1..].iter().all(|&x| x > 2.0 * all[0]), "{all:?}");
    assert!(
        (all[1] / all[2] - 1.0).abs() < 0.15,
        "220 against 150: {all:?}"
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

/// FNV-1a, 64 bits: a hash whose value no Rust release changes (std's hasher may).
fn fnv(h: &mut u64, bytes: &[u8]) {
    for &b in bytes {
        *h ^= b as u64;
        *h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
}

fn hash_samples(samples: &[presrs_sim::dataset::Sample]) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325;
    for s in samples {
        fnv(&mut h, s.terrain.name().as_bytes());
        fnv(&mut h, &s.load_n.to_le_bytes());
        for p in &s.pixels {
            fnv(&mut h, &p.to_le_bytes());
        }
    }
    h
}

/// The cloth backing changed the sandpaper and nothing else: every other surface's
/// images and a whole candump log of the default track are what they were before it, to the
/// bit. The hashes were taken at f062cee, before the change; a deliberate change of another
/// surface or of the skin updates them and says so in docs/results.md. The log's was updated
/// once since: the LegState sent at liftoff carries the stance's length, not the flight's.
#[test]
fn surfaces_other_than_sandpaper_render_as_before_to_the_bit() {
    let stat = generate(&opts(Kind::Static, 4, Gait::g2(), 1));
    let dynamic = generate(&opts(Kind::Dynamic, 3, Gait::g2(), 1));
    // The sandpaper set's aluminum presses draw from aluminum's own stream.
    let aluminum: Vec<_> = generate(&opts(Kind::Sandpaper, 4, Gait::g2(), 1))
        .into_iter()
        .filter(|s| s.terrain.name() == "aluminum")
        .collect();
    assert_eq!(aluminum.len(), 4);
    let mut log = 0xcbf2_9ce4_8422_2325;
    let mut frames = 0usize;
    presrs_sim::runner::record(
        presrs_sim::runner::SimConfig::default(),
        1,
        3_000_000,
        &mut |_, _| {},
        &mut |st: protocol::Stamped| {
            frames += 1;
            fnv(&mut log, &st.t_us.to_le_bytes());
            fnv(&mut log, &st.frame.raw_id().to_le_bytes());
            fnv(&mut log, st.frame.data());
        },
    );
    assert!(frames > 1000, "{frames} frames in 3 s");
    let got = [
        hash_samples(&stat),
        hash_samples(&dynamic),
        hash_samples(&aluminum),
        log,
    ];
    assert_eq!(
        got,
        [
            0x60f6_3c81_7952_d2e8,
            0x61f9_ea41_ad0c_6dd4,
            0x8af3_0575_d07a_a5d1,
            0xe33a_c679_af92_3b79
        ],
        "static, dynamic, aluminum, log: {got:#018x?}"
    );
}
