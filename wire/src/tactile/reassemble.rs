//! The receiver's side: images rebuilt from segments that may be lost, duplicated, reordered,
//! interleaved between feet or garbage; buffers allocated once.

use alloc::boxed::Box;
use alloc::vec;
use alloc::vec::Vec;

use super::{BITMAP_WORDS, Header, MAX_BYTES, ReassemblyStats, TactileImage, Variant};
use crate::ids::MAX_FEET;

#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(super) enum SlotState {
    Empty,
    Assembling,
    /// Delivered or failed: absorbs late duplicates of the same image.
    Done,
    /// Timed out unfinished (counted once as incomplete): absorbs the image's late segments
    /// for another timeout, so that they do not start a second assembly of it, which would be
    /// abandoned and counted again (a slow transfer counted two per image).
    Abandoned,
}

#[derive(Clone, Debug)]
pub(super) struct Slot {
    state: SlotState,
    seq: u8,
    first_rx_us: u64,
    /// Header fields received so far; bit i = header part i (classic has three parts).
    header_parts: u8,
    header: Header,
    bits: [u64; BITMAP_WORDS],
    /// Distinct data segments received whose index is within the header's count.
    n_data: usize,
    buf: Vec<u8>,
}

impl Slot {
    fn new() -> Self {
        Self {
            state: SlotState::Empty,
            seq: 0,
            first_rx_us: 0,
            header_parts: 0,
            header: Header::default(),
            bits: [0; BITMAP_WORDS],
            n_data: 0,
            buf: Vec::new(),
        }
    }

    fn start(&mut self, seq: u8, rx_us: u64) {
        self.state = SlotState::Assembling;
        self.seq = seq;
        self.first_rx_us = rx_us;
        self.header_parts = 0;
        self.header = Header::default();
        self.bits = [0; BITMAP_WORDS];
        self.n_data = 0;
    }

    fn test_and_set(&mut self, i: usize) -> bool {
        let (w, b) = (i / 64, i % 64);
        let was = self.bits[w] & (1 << b) != 0;
        self.bits[w] |= 1 << b;
        was
    }
}

/// Rebuilds tactile images from segments; see the module docs. Two assembly slots per foot, so a
/// late segment of the previous image does not destroy the image being received.
pub struct Reassembler {
    slots: Vec<[Slot; 2]>,
    out: Box<TactileImage>,
    timeout_us: u64,
    stats: ReassemblyStats,
}

impl Default for Reassembler {
    fn default() -> Self {
        Self::new(100_000)
    }
}

impl Reassembler {
    /// `timeout_us`: an image not completed this long after its first segment is abandoned
    /// (and its sequence number may be reused).
    pub fn new(timeout_us: u64) -> Self {
        let mut slots = Vec::with_capacity(MAX_FEET as usize);
        for _ in 0..MAX_FEET {
            let mut pair = [Slot::new(), Slot::new()];
            for s in &mut pair {
                s.buf = vec![0; MAX_BYTES];
            }
            slots.push(pair);
        }
        Self {
            slots,
            out: Box::default(),
            timeout_us,
            stats: ReassemblyStats::default(),
        }
    }

    /// Counters since creation.
    pub fn stats(&self) -> ReassemblyStats {
        self.stats
    }

    /// The image the last successful [`Reassembler::push`] returned.
    pub fn last_image(&self) -> &TactileImage {
        &self.out
    }

    /// Feeds one segment's payload (the frame's data) received at `rx_us`. Returns the image
    /// when this segment completed one that checks.
    pub fn push(
        &mut self,
        variant: Variant,
        foot: u8,
        payload: &[u8],
        rx_us: u64,
    ) -> Option<&TactileImage> {
        if payload.len() != variant.frame_len() {
            self.stats.bad_length += 1;
            return None;
        }
        if foot >= MAX_FEET {
            self.stats.out_of_range += 1;
            return None;
        }
        let seq = payload[0];
        let index = variant.index(payload);
        let stats = &mut self.stats;
        let pair = &mut self.slots[foot as usize];
        age(pair, rx_us, self.timeout_us, stats);
        let slot = &mut pair[slot_for(pair, seq, rx_us, stats)];
        match slot.state {
            SlotState::Done => {
                stats.duplicates += 1;
                return None;
            }
            SlotState::Abandoned => {
                stats.late += 1;
                return None;
            }
            _ => {}
        }
        let taken = if index < variant.first_data_index() {
            absorb_header(variant, index, payload, slot, stats)
        } else {
            absorb_data(variant, index, payload, slot, stats)
        };
        if !taken
            || slot.header_parts != full_header(variant)
            || slot.n_data != slot.header.segments as usize
        {
            return None;
        }
        // Complete: check the CRC over exactly the header's byte count.
        slot.state = SlotState::Done;
        let n = slot.header.n_bytes();
        if crc32fast::hash(&slot.buf[..n]) != slot.header.crc {
            stats.crc_failures += 1;
            return None;
        }
        deliver(&mut self.out, slot, foot, seq, rx_us);
        stats.delivered += 1;
        Some(&*self.out)
    }
}

/// Ages a foot's two slots at `rx_us`: an assembly past the timeout is abandoned (counted
/// incomplete), a finished or abandoned one is freed later.
fn age(pair: &mut [Slot; 2], rx_us: u64, timeout: u64, stats: &mut ReassemblyStats) {
    for s in pair.iter_mut() {
        let age = rx_us.saturating_sub(s.first_rx_us);
        s.state = match s.state {
            SlotState::Assembling if age > timeout => {
                stats.incomplete += 1;
                SlotState::Abandoned
            }
            SlotState::Done if age > timeout => SlotState::Empty,
            SlotState::Abandoned if age > 2 * timeout => SlotState::Empty,
            s => s,
        };
    }
}

/// The slot of image `seq`: the one holding it, else a new one (an empty slot first, then a
/// finished one, then the older assembly, counted incomplete).
fn slot_for(pair: &mut [Slot; 2], seq: u8, rx_us: u64, stats: &mut ReassemblyStats) -> usize {
    if let Some(i) = pair
        .iter()
        .position(|s| s.state != SlotState::Empty && s.seq == seq)
    {
        return i;
    }
    let rank = |s: &Slot| match s.state {
        SlotState::Empty => (0, 0),
        SlotState::Abandoned | SlotState::Done => (1, s.first_rx_us),
        SlotState::Assembling => (2, s.first_rx_us),
    };
    let i = if rank(&pair[0]) <= rank(&pair[1]) {
        0
    } else {
        1
    };
    if pair[i].state == SlotState::Assembling {
        stats.incomplete += 1;
    }
    pair[i].start(seq, rx_us);
    i
}

/// Takes one data segment into the slot. False when it is dropped (out of range or a
/// duplicate).
fn absorb_data(
    v: Variant,
    index: usize,
    payload: &[u8],
    slot: &mut Slot,
    stats: &mut ReassemblyStats,
) -> bool {
    let d = index - v.first_data_index();
    let limit = if slot.header_parts == full_header(v) {
        slot.header.segments as usize
    } else {
        v.max_data_segments()
    };
    if d >= limit {
        stats.out_of_range += 1;
        return false;
    }
    if slot.test_and_set(index) {
        stats.duplicates += 1;
        return false;
    }
    let dps = v.data_per_segment();
    let start = d * dps;
    let end = (start + dps).min(MAX_BYTES);
    slot.buf[start..end].copy_from_slice(&payload[v.prefix()..v.prefix() + (end - start)]);
    if slot.header_parts == full_header(v) {
        slot.n_data += 1;
    }
    true
}

/// A complete, checked slot's pixels into `out`.
fn deliver(out: &mut TactileImage, slot: &Slot, foot: u8, seq: u8, rx_us: u64) {
    let h = slot.header;
    let n = h.n_bytes();
    out.foot = foot;
    out.seq = seq;
    out.rows = h.rows;
    out.cols = h.cols;
    out.bits = h.bits;
    out.timestamp_us = h.timestamp_us;
    out.completed_us = rx_us;
    let n_px = h.rows as usize * h.cols as usize;
    if h.bits == 8 {
        for (p, b) in out.pixels[..n_px].iter_mut().zip(&slot.buf[..n]) {
            *p = *b as u16;
        }
    } else {
        for (p, b) in out.pixels[..n_px]
            .iter_mut()
            .zip(slot.buf[..n].chunks_exact(2))
        {
            *p = u16::from_le_bytes([b[0], b[1]]);
        }
    }
}

pub(super) const fn full_header(v: Variant) -> u8 {
    match v {
        Variant::Fd => 0b1,
        Variant::Classic => 0b111,
    }
}

/// Takes one header segment into the slot. False when it is dropped (duplicate or bad).
pub(super) fn absorb_header(
    v: Variant,
    part: usize,
    p: &[u8],
    slot: &mut Slot,
    stats: &mut ReassemblyStats,
) -> bool {
    let mut h = slot.header;
    match (v, part) {
        (Variant::Fd, _) => {
            h = Header {
                rows: p[2],
                cols: p[3],
                bits: p[4],
                segments: p[5] as u16,
                crc: u32::from_le_bytes([p[6], p[7], p[8], p[9]]),
                timestamp_us: u32::from_le_bytes([p[10], p[11], p[12], p[13]]),
            }
        }
        (Variant::Classic, 0) => {
            h.rows = p[3];
            h.cols = p[4];
            h.bits = p[5];
            h.segments = u16::from_le_bytes([p[6], p[7]]);
        }
        (Variant::Classic, 1) => h.crc = u32::from_le_bytes([p[3], p[4], p[5], p[6]]),
        (Variant::Classic, _) => h.timestamp_us = u32::from_le_bytes([p[3], p[4], p[5], p[6]]),
    }
    let bit = 1u8 << part;
    if slot.header_parts & bit != 0 {
        if h == slot.header {
            stats.duplicates += 1;
        } else {
            // Two different headers for one image: trust neither.
            stats.bad_header += 1;
            slot.state = SlotState::Done;
        }
        return false;
    }
    if (v == Variant::Fd || part == 0) && !h.is_valid_for(v) {
        stats.bad_header += 1;
        slot.state = SlotState::Done;
        return false;
    }
    slot.header = h;
    slot.header_parts |= bit;
    if slot.header_parts == full_header(v) {
        // Segments that came before the header: count those inside the image, forget the rest.
        let first = v.first_data_index();
        let last = first + h.segments as usize;
        let mut n = 0;
        for i in first..last {
            if slot.bits[i / 64] & (1 << (i % 64)) != 0 {
                n += 1;
            }
        }
        for i in last..BITMAP_WORDS * 64 {
            if slot.bits[i / 64] & (1 << (i % 64)) != 0 {
                slot.bits[i / 64] &= !(1 << (i % 64));
                stats.out_of_range += 1;
            }
        }
        slot.n_data = n;
    }
    true
}
