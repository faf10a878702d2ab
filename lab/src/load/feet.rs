//! The feet the bench plays: the stance images, the fixed schedule, the frame each step's
//! decision must come from.

use super::{
    CanFrame, FRAME_US, FootContact, IdConfig, ImageRef, LoadError, Message, SAMPLE_US, SIDE,
    STANCE_US, STEP_US, Segmenter, Variant,
};
use protocol::emit::Emit;

/// Eight G2 stance images per dynamic terrain from the simulator's skin, with their terrain ids.
pub fn image_pool() -> Vec<(u8, Vec<u16>)> {
    sim::dataset::generate(&sim::dataset::Options {
        kind: sim::dataset::Kind::Dynamic,
        n: Some(8),
        gait: controller::Gait::g2(),
        damage_pct: 0.0,
        sensor: sim::DEFAULT_SENSOR,
        seed: 99,
    })
    .into_iter()
    .filter(|s| s.rows == SIDE && s.cols == SIDE)
    .map(|s| (s.terrain.id(), s.pixels))
    .collect()
}

/// One foot's schedule: touchdown, liftoff and frame times on the foot clock (µs from start).
pub(super) struct Foot {
    id: u8,
    td: u64,
    lo: u64,
    frame: u64,
    /// This foot's frame grid: frames at `offset + k * FRAME_US`.
    offset: u64,
    in_stance: bool,
    step: u16,
    contact_seq: u8,
    image_seq: u8,
    /// Time of this stance's sampled frame, and the image shown in this stance.
    sampled: Option<u64>,
    image: usize,
}

/// The frame the node should classify for a step: sent whole by the event that returned it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Sampled {
    /// The foot.
    pub foot: u8,
    /// The step (the TerrainClass's step counter).
    pub step: u16,
    /// The frame's time on the foot clock, µs.
    pub t_us: u64,
    /// The true terrain id of the stance.
    pub terrain: u8,
}

/// `n` feet on the fixed schedule, in time order.
pub struct Feet {
    pub(super) feet: Vec<Foot>,
    images: Vec<(u8, Vec<u16>)>,
    blank: Vec<u16>,
    seg: Segmenter,
    pub(super) ids: IdConfig,
}

impl Feet {
    /// `n` feet (1..=[`protocol::ids::MAX_FEET`]) showing `images` (44x44, with terrain ids).
    pub fn new(n: u8, images: Vec<(u8, Vec<u16>)>, ids: IdConfig) -> Result<Self, LoadError> {
        if !(1..=protocol::ids::MAX_FEET).contains(&n) {
            return Err(LoadError::Feet(n));
        }
        if images.is_empty() || images.iter().any(|(_, p)| p.len() != SIDE * SIDE) {
            return Err(LoadError::NoImages);
        }
        let k = n as u64;
        let feet = (0..n)
            .map(|f| {
                let i = f as u64;
                Foot {
                    id: f,
                    td: 200_000 + i * STEP_US / k + 3_300,
                    lo: u64::MAX,
                    frame: 1_000 + i * FRAME_US / k,
                    offset: 1_000 + i * FRAME_US / k,
                    in_stance: false,
                    step: 0,
                    contact_seq: 0,
                    image_seq: 0,
                    sampled: None,
                    image: f as usize,
                }
            })
            .collect();
        Ok(Self {
            feet,
            images,
            blank: vec![0; SIDE * SIDE],
            seg: Segmenter::new(Variant::Fd, ids.clone()),
            ids,
        })
    }

    /// The next event's time on the foot clock, µs.
    pub fn next_us(&self) -> u64 {
        self.feet
            .iter()
            .map(|f| f.td.min(f.lo).min(f.frame))
            .min()
            .unwrap_or(u64::MAX)
    }

    /// Emits the next event's frames (a FootContact, or an image's segments) and says whether
    /// that image was its stance's sampled frame.
    pub fn emit(&mut self, out: &mut dyn Emit<CanFrame>) -> Result<Option<Sampled>, LoadError> {
        let t = self.next_us();
        let Some(f) = self
            .feet
            .iter_mut()
            .find(|f| f.td.min(f.lo).min(f.frame) == t)
        else {
            return Ok(None);
        };
        if t == f.td || t == f.lo {
            let touchdown = t == f.td;
            if touchdown {
                f.in_stance = true;
                f.step = f.step.wrapping_add(1);
                f.lo = t + STANCE_US;
                f.td = t + STEP_US;
                f.image = (f.image + 7) % self.images.len();
                // The frame nearest 70 ms after touchdown, on this foot's frame grid.
                let k = ((t + SAMPLE_US - f.offset) as f64 / FRAME_US as f64).round() as u64;
                f.sampled = Some(f.offset + k * FRAME_US);
            } else {
                f.in_stance = false;
                f.lo = u64::MAX;
            }
            f.contact_seq = f.contact_seq.wrapping_add(1);
            let m = Message::FootContact(FootContact {
                stance: touchdown,
                seq: f.contact_seq,
                timestamp_us: t as u32,
            });
            if let Some(frame) = m.to_frame(&self.ids, f.id) {
                out.emit(frame);
            }
            return Ok(None);
        }
        f.frame += FRAME_US;
        f.image_seq = f.image_seq.wrapping_add(1);
        let (terrain, pixels) = if f.in_stance {
            let (id, px) = &self.images[f.image];
            (*id, px.as_slice())
        } else {
            (0, self.blank.as_slice())
        };
        let img = ImageRef {
            rows: SIDE,
            cols: SIDE,
            bits: 8,
            timestamp_us: t as u32,
            pixels,
        };
        self.seg.frames(f.id, f.image_seq, &img, out)?;
        Ok((f.sampled == Some(t)).then_some(Sampled {
            foot: f.id,
            step: f.step,
            t_us: t,
            terrain,
        }))
    }
}
