//! A step's touchdown time on the log's clock, whatever the foot switch does: any bounce at
//! touchdown and liftoff, a sender clock based anywhere (near 2^32 µs too), the clock wrapping
//! mid-stance, images stamped at their sample time and received whole a few ms later. Every
//! step is decided once, and its touchdown lies within 5 ms of the true one (the bounce's span).
//!
//! `node --replay --csv`, `--truth`, `--keep-unknown` and MCAP all take the step's time from
//! [`presrs_node::stance::Decided::touchdown_us`], which these streams check.

use presrs_node::NodeConfig;
use presrs_node::stance::{Decided, StancePipeline};
use proptest::prelude::*;
use protocol::messages::{FootContact, Message};
use protocol::tactile::{ImageRef, Segmenter, Variant};
use protocol::{CanFrame, IdConfig, Stamped};

/// One step of the stream: its stance and flight, and the switch's bounce edges (µs after the
/// touchdown and after the liftoff).
#[derive(Clone, Debug)]
struct Step {
    stance_ms: u64,
    flight_ms: u64,
    td_bounce: Vec<u64>,
    lo_bounce: Vec<u64>,
}

fn step() -> impl Strategy<Value = Step> {
    // Bounce edges within 3 ms (each 200-900 µs apart), 0 to 5 of them, as micro-switches do.
    let bounce = || prop::collection::vec(200u64..900, 0..=5);
    (150u64..450, 60u64..200, bounce(), bounce()).prop_map(|(s, f, td, lo)| Step {
        stance_ms: s,
        flight_ms: f,
        td_bounce: td,
        lo_bounce: lo,
    })
}

/// The log a foot board puts on the bus for `steps`, with its sender clock at `base` µs at
/// the log's start, images every 10 ms from `phase_us`; and each true touchdown, log time.
fn stream(steps: &[Step], base: u32, phase_us: u64, seg_gap_us: u64) -> (Vec<Stamped>, Vec<u64>) {
    let ids = IdConfig::default();
    let t0 = 1_700_000_000_000_000u64; // log time of the sender's `base`
    let clk = |t: u64| base.wrapping_add((t - t0) as u32);
    // The switch's edges, in log time, and the stance intervals.
    let mut edges: Vec<(u64, bool)> = Vec::new();
    let mut truth = Vec::new();
    let mut stances = Vec::new();
    let mut t = t0 + 50_000;
    for s in steps {
        let (td, lo) = (t, t + s.stance_ms * 1000);
        truth.push(td);
        stances.push((td, lo));
        for (at, bounce, closed) in [(td, &s.td_bounce, true), (lo, &s.lo_bounce, false)] {
            edges.push((at, closed));
            // The contact flips at each bounce edge and settles where it began.
            let (mut e, mut state) = (at, closed);
            for gap in bounce {
                e += gap;
                state = !state;
                edges.push((e, state));
            }
            if state != closed {
                edges.push((e + 300, closed));
            }
        }
        t = lo + s.flight_ms * 1000;
    }
    let end = t + 100_000;
    let state_at = |x: u64| {
        edges
            .iter()
            .take_while(|(te, _)| *te <= x)
            .last()
            .is_some_and(|e| e.1)
    };
    let mut out = Vec::new();
    let contact = |stance: bool, t: u64, seq: u8| Stamped {
        t_us: t + 150,
        frame: Message::FootContact(FootContact {
            stance,
            seq,
            timestamp_us: clk(t),
        })
        .to_frame(&ids, 0)
        .expect("a FootContact encodes"),
    };
    let mut seq = 0u8;
    for &(te, v) in &edges {
        seq = seq.wrapping_add(1);
        out.push(contact(v, te, seq));
    }
    let mut tick = t0 + 3_000;
    while tick < end {
        seq = seq.wrapping_add(1);
        out.push(contact(state_at(tick), tick, seq));
        tick += 10_000;
    }
    // Images on the array's 10 ms grid, stamped at their sample time; in flight near-blank.
    let seg = Segmenter::new(Variant::Fd, ids.clone());
    let mut ts = t0 + phase_us;
    let mut img_seq = 0u8;
    while ts < end {
        let loaded = stances.iter().any(|&(a, b)| (a..b).contains(&ts));
        let px: Vec<u16> = (0..44 * 44)
            .map(|i| if loaded { 40 + (i % 7) as u16 * 20 } else { 0 })
            .collect();
        let img = ImageRef {
            rows: 44,
            cols: 44,
            bits: 8,
            timestamp_us: clk(ts),
            pixels: &px,
        };
        let mut k = 0u64;
        seg.frames(0, img_seq, &img, &mut |f: CanFrame| {
            out.push(Stamped {
                t_us: ts + 300 + k * seg_gap_us,
                frame: f,
            });
            k += 1;
        })
        .expect("a 44x44 image segments");
        img_seq = img_seq.wrapping_add(1);
        ts += 10_000;
    }
    out.sort_by_key(|s| s.t_us);
    (out, truth)
}

/// Every step decided once, its touchdown within 10 ms of the truth.
fn check(steps: &[Step], base: u32, phase_us: u64, seg_gap_us: u64) -> Result<(), TestCaseError> {
    let (frames, truth) = stream(steps, base, phase_us, seg_gap_us);
    let mut p = StancePipeline::new(NodeConfig::default(), None);
    let mut said: Vec<Decided> = Vec::new();
    for f in &frames {
        p.on_frame(f, &mut |d: Decided| said.push(d));
        p.tick(f.t_us, &mut |d: Decided| said.push(d));
    }
    prop_assert_eq!(said.len(), truth.len(), "one decision per step");
    for (k, (d, &td)) in said.iter().zip(&truth).enumerate() {
        // The debounced edge is the bounce's last (at most 4.8 ms after the first here), put on
        // the log's clock by the switch report (received 150 µs after it was sent).
        let err = d.touchdown_us.abs_diff(td);
        prop_assert!(
            err <= 5_000,
            "step {}: touchdown {} µs from the truth (clock base {})",
            k,
            err,
            base
        );
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn touchdown_on_the_log_clock_whatever_the_switch_does(
        steps in prop::collection::vec(step(), 1..8),
        base in any::<u32>(),
        phase_us in 0u64..10_000,
        seg_gap_us in 100u64..200,
    ) {
        check(&steps, base, phase_us, seg_gap_us)?;
    }

    #[test]
    fn the_sender_clock_wraps_mid_stance(
        steps in prop::collection::vec(step(), 2..6),
        before_wrap_ms in 0u32..1_500,
        phase_us in 0u64..10_000,
    ) {
        // The clock wraps within the first steps: at most 1.5 s after the log starts.
        let base = u32::MAX - before_wrap_ms * 1000;
        check(&steps, base, phase_us, 150)?;
    }
}

#[test]
fn a_bouncing_switch_with_images_received_after_their_sample_time() {
    // The case the emulator's streams showed: 4 bounce edges within 3 ms of each touchdown, an
    // image sampled just before it and received just after.
    let step = Step {
        stance_ms: 250,
        flight_ms: 100,
        td_bounce: vec![400, 700, 600, 800],
        lo_bounce: vec![500, 500],
    };
    for phase_us in (0..10_000).step_by(500) {
        check(&vec![step.clone(); 5], 123_456_789, phase_us, 150)
            .map_err(|e| TestCaseError::fail(format!("phase {phase_us}: {e}")))
            .unwrap();
    }
}
