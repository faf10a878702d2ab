//! Segmented transfer of tactile pressure images.
//!
//! A pressure image (rows x cols, 8 or 16 bits per pixel, rows concatenated, 16-bit pixels
//! little-endian) is sent as one *header* segment and N *data* segments, all on the foot's
//! `TactileFrame` identifier. Every segment starts with the frame sequence number (so segments of
//! different images never mix) and its segment index (0 is the header). The header carries the
//! geometry, the number of data segments, a CRC-32 of the pixel bytes and the sender timestamp,
//! so a receiver can check it got exactly the image that was sent.
//!
//! | variant | frame | prefix | header | pixel bytes per data segment | 44x44x8 bit |
//! |---|---|---|---|---|---|
//! | [`Variant::Fd`] | CAN FD, 64 bytes, BRS | seq u8, index u8 | index 0 | 62 | 1 + 32 frames |
//! | [`Variant::Classic`] | classic, 8 bytes | seq u8, index u16 | indexes 0, 1, 2 | 5 | 3 + 388 frames |
//!
//! [`Reassembler`] rebuilds images from segments that may be lost, duplicated, reordered,
//! interleaved between feet, or garbage. It never panics, never delivers an image whose CRC,
//! length or geometry does not check, and counts every kind of drop in [`ReassemblyStats`].

use crate::frame::{CanFrame, make_id};
use crate::ids::{IdConfig, MessageKind};

/// Largest image the transfer accepts (64 x 64 pixels): enough for the 44x44 PreSRS array, and
/// it bounds the receive buffers, which are allocated once.
pub const MAX_PIXELS: usize = 4096;
/// Largest pixel payload in bytes (16-bit pixels).
pub const MAX_BYTES: usize = MAX_PIXELS * 2;
const BITMAP_WORDS: usize = 32; // 2048 segment indexes: enough for the classic variant

/// Frame layout of the segmented transfer.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Variant {
    /// CAN FD, 64-byte frames with bit-rate switch: the default.
    Fd,
    /// Classic CAN, 8-byte frames: for buses without FD (too slow for 100 Hz full images).
    Classic,
}

impl Variant {
    /// Bytes on the bus per segment.
    pub const fn frame_len(self) -> usize {
        match self {
            Variant::Fd => 64,
            Variant::Classic => 8,
        }
    }
    const fn prefix(self) -> usize {
        match self {
            Variant::Fd => 2,
            Variant::Classic => 3,
        }
    }
    /// Pixel bytes per data segment.
    pub const fn data_per_segment(self) -> usize {
        self.frame_len() - self.prefix()
    }
    /// Index of the first data segment (header segments come before it).
    pub const fn first_data_index(self) -> usize {
        match self {
            Variant::Fd => 1,
            Variant::Classic => 3,
        }
    }
    /// Most data segments an image can have: bounded by the index field (FD), the receive
    /// bitmap (classic) and the largest image.
    pub fn max_data_segments(self) -> usize {
        let by_field = match self {
            Variant::Fd => 255,
            Variant::Classic => BITMAP_WORDS * 64 - 3,
        };
        by_field.min(MAX_BYTES.div_ceil(self.data_per_segment()))
    }
    /// Data segments needed for `n_bytes` pixel bytes.
    pub fn data_segments(self, n_bytes: usize) -> usize {
        n_bytes.div_ceil(self.data_per_segment())
    }
    /// Frames on the bus for one image (header and data).
    pub fn frames_per_image(self, rows: usize, cols: usize, bits: u8) -> usize {
        self.first_data_index() + self.data_segments(rows * cols * (bits as usize / 8))
    }
    /// The message kind (and so the identifier) of this variant's segments.
    pub fn message_kind(self) -> MessageKind {
        match self {
            Variant::Fd => MessageKind::TactileFrame,
            Variant::Classic => MessageKind::TactileFrameClassic,
        }
    }
    #[cfg(feature = "alloc")]
    fn index(self, p: &[u8]) -> usize {
        match self {
            Variant::Fd => p[1] as usize,
            Variant::Classic => u16::from_le_bytes([p[1], p[2]]) as usize,
        }
    }
}

/// Image geometry and integrity data, as carried by the header segment(s).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct Header {
    /// Rows of sensels.
    pub rows: u8,
    /// Columns of sensels.
    pub cols: u8,
    /// 8 or 16.
    pub bits: u8,
    /// Number of data segments.
    pub segments: u16,
    /// CRC-32 (IEEE) of the pixel bytes.
    pub crc: u32,
    /// Sender clock at the image's sampling, µs (wrapping).
    pub timestamp_us: u32,
}

impl Header {
    fn n_bytes(&self) -> usize {
        self.rows as usize * self.cols as usize * (self.bits as usize / 8)
    }

    fn is_valid_for(&self, v: Variant) -> bool {
        (self.bits == 8 || self.bits == 16)
            && self.rows > 0
            && self.cols > 0
            && (self.rows as usize * self.cols as usize) <= MAX_PIXELS
            && self.segments as usize == v.data_segments(self.n_bytes())
            && self.segments as usize <= v.max_data_segments()
    }
}

/// A reassembled pressure image.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TactileImage {
    /// The foot that sent it.
    pub foot: u8,
    /// The sender's image counter (wrapping).
    pub seq: u8,
    /// Rows of sensels.
    pub rows: u8,
    /// Columns of sensels.
    pub cols: u8,
    /// Bits per sensel (8 or 16).
    pub bits: u8,
    /// Sender timestamp (µs, wrapping) from the header.
    pub timestamp_us: u32,
    /// Receive time of the segment that completed the image (µs, the bus's clock).
    pub completed_us: u64,
    /// Row-major pixels; only the first `rows * cols` are meaningful.
    pub pixels: [u16; MAX_PIXELS],
}

impl Default for TactileImage {
    fn default() -> Self {
        Self {
            foot: 0,
            seq: 0,
            rows: 0,
            cols: 0,
            bits: 8,
            timestamp_us: 0,
            completed_us: 0,
            pixels: [0; MAX_PIXELS],
        }
    }
}

impl TactileImage {
    /// Number of sensels.
    pub fn len(&self) -> usize {
        self.rows as usize * self.cols as usize
    }
    /// No sensels.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// The meaningful pixels, row-major.
    pub fn pixels(&self) -> &[u16] {
        &self.pixels[..self.len()]
    }

    /// The pixels as a viewer's image bytes, into `out` (cleared): `mono8` for 8-bit images,
    /// `mono16` little-endian otherwise. Returns the encoding and the bytes per pixel. The
    /// MCAP recording and the ROS 2 image both show them so.
    #[cfg(feature = "alloc")]
    pub fn mono_bytes(&self, out: &mut alloc::vec::Vec<u8>) -> (&'static str, u32) {
        out.clear();
        if self.bits == 8 {
            out.extend(self.pixels().iter().map(|&p| p as u8));
            ("mono8", 1)
        } else {
            for &p in self.pixels() {
                out.extend_from_slice(&p.to_le_bytes());
            }
            ("mono16", 2)
        }
    }
}

/// Writes pixel `i`'s bytes into the transfer's byte stream.
#[inline]
fn pixel_byte(pixels: &[u16], bits: u8, k: usize) -> u8 {
    if bits == 8 {
        pixels[k].min(255) as u8
    } else {
        pixels[k / 2].to_le_bytes()[k % 2]
    }
}

/// CRC-32 of an image's pixel bytes, as the header carries it.
pub fn pixel_crc(pixels: &[u16], bits: u8) -> u32 {
    let mut h = crc32fast::Hasher::new();
    let mut chunk = [0u8; 64];
    let n = pixels.len() * (bits as usize / 8);
    let mut k = 0;
    while k < n {
        let m = (n - k).min(chunk.len());
        for (j, c) in chunk[..m].iter_mut().enumerate() {
            *c = pixel_byte(pixels, bits, k + j);
        }
        h.update(&chunk[..m]);
        k += m;
    }
    h.finalize()
}

#[cfg(feature = "alloc")]
mod reassemble;
mod segment;

#[cfg(feature = "alloc")]
pub use reassemble::Reassembler;
pub use segment::{ImageRef, SegmentError, Segmenter};

/// Drop counters of the reassembler. Each segment or image that is not delivered is counted once
/// under the reason it was dropped.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct ReassemblyStats {
    /// Images delivered.
    pub delivered: u64,
    /// Images whose pixels did not match the header's CRC-32.
    pub crc_failures: u64,
    /// Images abandoned unfinished: a newer image replaced them, or they timed out. One per
    /// image.
    pub incomplete: u64,
    /// Segments of an image already abandoned, arriving within a further timeout (ignored).
    pub late: u64,
    /// Segments received twice (ignored; the first copy is kept).
    pub duplicates: u64,
    /// Segments whose frame length is not the variant's (64 FD, 8 classic).
    pub bad_length: u64,
    /// Headers with impossible geometry, or contradicting an earlier header of the same image.
    pub bad_header: u64,
    /// Data segments with an index beyond the image, or feet beyond the bus's 8.
    pub out_of_range: u64,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(rows: usize, cols: usize, bits: u8, salt: u16) -> Vec<u16> {
        let max = if bits == 8 { 255 } else { 65535 };
        (0..rows * cols)
            .map(|i| {
                ((i as u32)
                    .wrapping_mul(2654435761)
                    .wrapping_add(salt as u32)
                    % (max + 1)) as u16
            })
            .collect()
    }

    fn frames(
        v: Variant,
        foot: u8,
        seq: u8,
        rows: usize,
        cols: usize,
        bits: u8,
        px: &[u16],
    ) -> Vec<CanFrame> {
        let mut out = Vec::new();
        Segmenter::new(v, IdConfig::default())
            .frames(
                foot,
                seq,
                &ImageRef {
                    rows,
                    cols,
                    bits,
                    timestamp_us: 1234,
                    pixels: px,
                },
                &mut out,
            )
            .unwrap();
        out
    }

    #[test]
    fn frame_counts_match_the_docs() {
        assert_eq!(Variant::Fd.frames_per_image(44, 44, 8), 33);
        assert_eq!(Variant::Classic.frames_per_image(44, 44, 8), 391);
        assert_eq!(Variant::Fd.frames_per_image(44, 44, 16), 64);
        let px = image(44, 44, 8, 1);
        assert_eq!(frames(Variant::Fd, 0, 0, 44, 44, 8, &px).len(), 33);
    }

    #[test]
    fn round_trip_both_variants_and_depths() {
        for v in [Variant::Fd, Variant::Classic] {
            for bits in [8, 16] {
                let px = image(44, 44, bits, 7);
                let mut r = Reassembler::default();
                let fr = frames(v, 5, 42, 44, 44, bits, &px);
                let mut got = None;
                for (i, f) in fr.iter().enumerate() {
                    assert_eq!(f.is_fd(), v == Variant::Fd);
                    if let Some(img) = r.push(v, 5, f.data(), i as u64) {
                        got = Some(img.clone());
                    }
                }
                let img = got.expect("delivered");
                assert_eq!(
                    (img.rows, img.cols, img.bits, img.seq, img.foot),
                    (44, 44, bits, 42, 5)
                );
                assert_eq!(img.timestamp_us, 1234);
                assert_eq!(img.pixels(), &px[..]);
                assert_eq!(r.stats().delivered, 1);
            }
        }
    }

    #[test]
    fn reordered_header_last_and_duplicates() {
        let px = image(10, 7, 16, 3);
        let mut fr = frames(Variant::Fd, 0, 1, 10, 7, 16, &px);
        fr.rotate_left(1); // header last
        let dup = fr[0];
        fr.insert(1, dup);
        let mut r = Reassembler::default();
        let n = fr
            .iter()
            .filter(|f| r.push(Variant::Fd, 0, f.data(), 0).is_some())
            .count();
        assert_eq!(n, 1);
        assert_eq!(r.stats().duplicates, 1);
    }

    #[test]
    fn corrupted_pixel_fails_crc() {
        let px = image(44, 44, 8, 9);
        let fr = frames(Variant::Fd, 0, 1, 44, 44, 8, &px);
        let mut r = Reassembler::default();
        for (i, f) in fr.iter().enumerate() {
            let mut d = f.data().to_vec();
            if i == 5 {
                d[10] ^= 0x40;
            }
            assert!(r.push(Variant::Fd, 0, &d, 0).is_none());
        }
        assert_eq!(r.stats().crc_failures, 1);
        assert_eq!(r.stats().delivered, 0);
    }

    /// Stats after 40 images on `variant`, each sent over `span_us`, with the segments
    /// `drop(image, segment)` lost; a segment of a 41st image long after flushes the timeouts.
    fn stream(
        variant: Variant,
        timeout_us: u64,
        span_us: u64,
        drop: impl Fn(u8, usize) -> bool,
    ) -> ReassemblyStats {
        let px = image(44, 44, 8, 9);
        let mut r = Reassembler::new(timeout_us);
        for k in 0..40u8 {
            let fr = frames(variant, 0, k, 44, 44, 8, &px);
            let n = fr.len() as u64;
            for (i, f) in fr.iter().enumerate() {
                if !drop(k, i) {
                    r.push(
                        variant,
                        0,
                        f.data(),
                        k as u64 * 100_000 + i as u64 * span_us / n,
                    );
                }
            }
        }
        let last = frames(variant, 0, 40, 44, 44, 8, &px);
        r.push(variant, 0, last[0].data(), 10_000_000);
        r.stats()
    }

    #[test]
    fn each_dropped_image_counts_once_as_incomplete() {
        for variant in [Variant::Fd, Variant::Classic] {
            // A middle segment, a header, the second half: three images lost.
            let s = stream(variant, 100_000, 9_000, |k, i| {
                (k == 10 && i == 7) || (k == 20 && i == 0) || (k == 30 && i > 20)
            });
            assert_eq!((s.delivered, s.incomplete), (37, 3), "{variant:?}: {s:?}");
            // Every transfer (52 ms) slower than the timeout (30 ms): each image abandoned
            // once, its late segments ignored (they used to start a second assembly: 79).
            let s = stream(variant, 30_000, 52_000, |_, _| false);
            assert_eq!((s.delivered, s.incomplete), (0, 40), "{variant:?}: {s:?}");
            assert!(s.late > 0);
        }
    }

    #[test]
    fn new_frame_replaces_abandoned_one_and_counts_it() {
        let px = image(44, 44, 8, 9);
        let a = frames(Variant::Fd, 0, 1, 44, 44, 8, &px);
        let b = frames(Variant::Fd, 0, 2, 44, 44, 8, &px);
        let c = frames(Variant::Fd, 0, 3, 44, 44, 8, &px);
        let mut r = Reassembler::default();
        for f in &a[..10] {
            r.push(Variant::Fd, 0, f.data(), 0);
        }
        for f in &b[..10] {
            r.push(Variant::Fd, 0, f.data(), 0);
        }
        let mut ok = 0;
        for f in &c {
            ok += r.push(Variant::Fd, 0, f.data(), 0).is_some() as usize;
        }
        assert_eq!(ok, 1);
        assert_eq!(r.stats().incomplete, 1);
        // The late rest of b still completes b: two slots per foot.
        for f in &b[10..] {
            ok += r.push(Variant::Fd, 0, f.data(), 1).is_some() as usize;
        }
        assert_eq!(ok, 2);
    }

    #[test]
    fn timeout_abandons_and_bad_inputs_are_counted() {
        let px = image(4, 4, 8, 1);
        let fr = frames(Variant::Fd, 0, 1, 4, 4, 8, &px);
        let mut r = Reassembler::new(100);
        r.push(Variant::Fd, 0, fr[0].data(), 0);
        r.push(Variant::Fd, 0, fr[1].data(), 1000);
        assert_eq!(r.stats().incomplete, 1);
        assert!(r.push(Variant::Fd, 0, &[0; 8], 0).is_none());
        assert_eq!(r.stats().bad_length, 1);
        let mut h = fr[0].data().to_vec();
        h[4] = 12; // 12 bits per pixel
        h[0] = 9;
        r.push(Variant::Fd, 0, &h, 2000);
        assert_eq!(r.stats().bad_header, 1);
        assert!(r.push(Variant::Fd, 9, fr[0].data(), 0).is_none());
        assert_eq!(r.stats().out_of_range, 1);
    }

    #[test]
    fn segmenter_rejects_bad_images() {
        let s = Segmenter::new(Variant::Fd, IdConfig::default());
        let e = s
            .frames(
                0,
                0,
                &ImageRef {
                    rows: 65,
                    cols: 65,
                    bits: 8,
                    timestamp_us: 0,
                    pixels: &vec![0; 65 * 65],
                },
                &mut |_: CanFrame| {},
            )
            .unwrap_err();
        assert!(e.to_string().contains("at most 4096 pixels"));
        assert!(
            s.frames(
                0,
                0,
                &ImageRef {
                    rows: 2,
                    cols: 2,
                    bits: 12,
                    timestamp_us: 0,
                    pixels: &[0; 4]
                },
                &mut |_: CanFrame| {}
            )
            .is_err()
        );
        assert!(
            s.frames(
                0,
                0,
                &ImageRef {
                    rows: 2,
                    cols: 2,
                    bits: 8,
                    timestamp_us: 0,
                    pixels: &[0; 3]
                },
                &mut |_: CanFrame| {}
            )
            .is_err()
        );
    }
}
