//! Property tests of tactile reassembly over random segment streams: loss, duplication,
//! reordering, interleaved feet and garbage. 100k streams per property by default
//! (`PROPTEST_CASES` overrides).

use std::collections::HashMap;

use presrs_wire::CanFrame;
use presrs_wire::ids::IdConfig;
use presrs_wire::tactile::{ImageRef, Reassembler, Segmenter, Variant};
use proptest::prelude::*;
use rand::rngs::StdRng;
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};

struct Sent {
    foot: u8,
    seq: u8,
    rows: u8,
    cols: u8,
    bits: u8,
    pixels: Vec<u16>,
}

/// (foot, payload, image index or None for garbage)
type Seg = (u8, Vec<u8>, Option<usize>);

fn cases() -> u32 {
    std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(100_000)
}

fn make_images(rng: &mut StdRng, n: usize) -> Vec<Sent> {
    let mut next_seq = [0u8; 4];
    (0..n)
        .map(|_| {
            let foot = rng.random_range(0..4u8);
            let seq = next_seq[foot as usize];
            next_seq[foot as usize] += 1;
            let rows = rng.random_range(1..=14u8);
            let cols = rng.random_range(1..=14u8);
            let bits = if rng.random_bool(0.5) { 8 } else { 16 };
            let max = if bits == 8 { 255 } else { 65535 };
            let pixels = (0..rows as usize * cols as usize)
                .map(|_| rng.random_range(0..=max))
                .collect();
            Sent {
                foot,
                seq,
                rows,
                cols,
                bits,
                pixels,
            }
        })
        .collect()
}

fn segments(v: Variant, img: &Sent) -> Vec<Vec<u8>> {
    let mut out = Vec::new();
    Segmenter::new(v, IdConfig::default())
        .frames(
            img.foot,
            img.seq,
            &ImageRef {
                rows: img.rows as usize,
                cols: img.cols as usize,
                bits: img.bits,
                timestamp_us: 77,
                pixels: &img.pixels,
            },
            &mut |f: CanFrame| out.push(f.data().to_vec()),
        )
        .unwrap();
    out
}

/// Per foot, each image's segments shuffled, lost and duplicated; feet interleaved at random.
fn stream(
    rng: &mut StdRng,
    v: Variant,
    imgs: &[Sent],
    loss: f64,
    dup: f64,
) -> (Vec<Seg>, Vec<bool>) {
    let mut per_foot: HashMap<u8, Vec<Seg>> = HashMap::new();
    let mut complete = Vec::new();
    for (i, img) in imgs.iter().enumerate() {
        let mut segs = segments(v, img);
        segs.shuffle(rng);
        let mut all_there = true;
        let q = per_foot.entry(img.foot).or_default();
        for s in segs {
            if rng.random_bool(loss) {
                all_there = false;
                continue;
            }
            q.push((img.foot, s.clone(), Some(i)));
            if rng.random_bool(dup) {
                q.push((img.foot, s, Some(i)));
            }
        }
        complete.push(all_there);
    }
    let mut queues: Vec<std::collections::VecDeque<Seg>> =
        per_foot.into_values().map(Into::into).collect();
    let mut out = Vec::new();
    while queues.iter().any(|q| !q.is_empty()) {
        let live: Vec<usize> = (0..queues.len())
            .filter(|&i| !queues[i].is_empty())
            .collect();
        let k = live[rng.random_range(0..live.len())];
        if let Some(s) = queues[k].pop_front() {
            out.push(s);
        }
    }
    (out, complete)
}

fn check(v: Variant, imgs: &[Sent], segs: &[Seg]) -> Result<Vec<usize>, TestCaseError> {
    let mut r = Reassembler::new(1_000_000);
    let mut delivered = Vec::new();
    for (t, (foot, payload, _)) in segs.iter().enumerate() {
        if let Some(img) = r.push(v, *foot, payload, t as u64 * 10) {
            let i = imgs
                .iter()
                .position(|s| s.foot == img.foot && s.seq == img.seq);
            let Some(i) = i else {
                return Err(TestCaseError::fail(format!(
                    "delivered an image never sent: foot {} seq {}",
                    img.foot, img.seq
                )));
            };
            let s = &imgs[i];
            prop_assert_eq!((img.rows, img.cols, img.bits), (s.rows, s.cols, s.bits));
            prop_assert_eq!(img.pixels(), &s.pixels[..], "wrong pixels delivered");
            delivered.push(i);
        }
    }
    Ok(delivered)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: cases(), failure_persistence: None, ..ProptestConfig::default() })]

    /// Loss, duplication, reordering within an image, interleaved feet, wrong-length garbage and
    /// garbage for feet the bus does not have: every image that arrived whole is delivered exactly
    /// once, nothing else is delivered, nothing panics.
    #[test]
    fn complete_images_delivered_exactly(seed in any::<u64>(), n in 1usize..6, loss in 0.0f64..0.3, dup in 0.0f64..0.3, fd in any::<bool>(), garbage in 0usize..6) {
        let v = if fd { Variant::Fd } else { Variant::Classic };
        let mut rng = StdRng::seed_from_u64(seed);
        let imgs = make_images(&mut rng, n);
        let (mut segs, complete) = stream(&mut rng, v, &imgs, loss, dup);
        for _ in 0..garbage {
            let at = rng.random_range(0..=segs.len());
            let len = if rng.random_bool(0.5) { rng.random_range(0..v.frame_len()) } else { v.frame_len() };
            let foot = if len == v.frame_len() { rng.random_range(8..=255u8) } else { rng.random_range(0..4u8) };
            let payload: Vec<u8> = (0..len).map(|_| rng.random()).collect();
            segs.insert(at, (foot, payload, None));
        }
        let delivered = check(v, &imgs, &segs)?;
        for (i, whole) in complete.iter().enumerate() {
            let times = delivered.iter().filter(|&&d| d == i).count();
            if *whole {
                prop_assert_eq!(times, 1, "complete image {} delivered {} times", i, times);
            } else {
                prop_assert_eq!(times, 0, "image {} with lost segments was delivered", i);
            }
        }
    }

    /// Adversarial garbage on our own identifiers (any bytes, any foot, colliding sequence
    /// numbers): no panic, and whatever is delivered is exactly an image that was sent.
    #[test]
    fn garbage_never_yields_a_wrong_image(seed in any::<u64>(), n in 1usize..4, garbage in 1usize..20, fd in any::<bool>()) {
        let v = if fd { Variant::Fd } else { Variant::Classic };
        let mut rng = StdRng::seed_from_u64(seed);
        let imgs = make_images(&mut rng, n);
        let (mut segs, _) = stream(&mut rng, v, &imgs, 0.05, 0.1);
        for _ in 0..garbage {
            let at = rng.random_range(0..=segs.len());
            let mut payload: Vec<u8> = (0..v.frame_len()).map(|_| rng.random()).collect();
            // Often aim at a real image: its seq, a plausible index.
            if rng.random_bool(0.7) && !imgs.is_empty() {
                let s = &imgs[rng.random_range(0..imgs.len())];
                payload[0] = s.seq;
                payload[1] = rng.random_range(0..6);
                if v == Variant::Classic { payload[2] = 0; }
                segs.insert(at, (s.foot, payload, None));
            } else {
                segs.insert(at, (rng.random_range(0..8), payload, None));
            }
        }
        check(v, &imgs, &segs)?;
    }
}
