//! The foot's side: cutting an image into segment frames, on the stack (no_std, no allocation).

use super::{CanFrame, Header, IdConfig, MAX_PIXELS, Variant, make_id, pixel_byte, pixel_crc};
use crate::emit::Emit;

/// Errors of [`Segmenter`].
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum SegmentError {
    #[error(
        "image of {rows}x{cols} at {bits} bits does not fit the tactile transfer (at most {MAX_PIXELS} pixels, 8 or 16 bits, {pixels} pixels given)"
    )]
    /// The image's size, depth or pixel count cannot be sent.
    BadImage {
        /// Rows given.
        rows: usize,
        /// Columns given.
        cols: usize,
        /// Bits given.
        bits: u8,
        /// Pixels given.
        pixels: usize,
    },
    /// The tactile identifier does not fit the identifier width.
    #[error("tactile identifier does not fit the configured identifier width")]
    BadId,
}

/// A borrowed image to send: geometry, depth, sampling time and row-major pixels.
#[derive(Clone, Copy, Debug)]
pub struct ImageRef<'a> {
    /// Rows of sensels.
    pub rows: usize,
    /// Columns of sensels.
    pub cols: usize,
    /// 8 or 16.
    pub bits: u8,
    /// Sender clock at sampling, µs (wrapping).
    pub timestamp_us: u32,
    /// Row-major sensel values.
    pub pixels: &'a [u16],
}

/// Cuts images into segment frames. Holds no buffers: each frame is built on the stack.
#[derive(Clone, Debug)]
pub struct Segmenter {
    /// CAN FD or classic segments.
    pub variant: Variant,
    ids: IdConfig,
}

impl Segmenter {
    /// A segmenter sending `variant` segments on `ids`.
    pub fn new(variant: Variant, ids: IdConfig) -> Self {
        Self { variant, ids }
    }

    /// Emits the frames of one image, header first, data segments in order.
    pub fn frames(
        &self,
        foot: u8,
        seq: u8,
        img: &ImageRef<'_>,
        out: &mut (impl Emit<CanFrame> + ?Sized),
    ) -> Result<(), SegmentError> {
        let ImageRef {
            rows,
            cols,
            bits,
            timestamp_us,
            pixels,
        } = *img;
        let v = self.variant;
        let n_px = rows * cols;
        let bad = SegmentError::BadImage {
            rows,
            cols,
            bits,
            pixels: pixels.len(),
        };
        if !(bits == 8 || bits == 16)
            || n_px == 0
            || n_px > MAX_PIXELS
            || pixels.len() != n_px
            || rows > 255
            || cols > 255
        {
            return Err(bad);
        }
        let n_bytes = n_px * (bits as usize / 8);
        let header = Header {
            rows: rows as u8,
            cols: cols as u8,
            bits,
            segments: v.data_segments(n_bytes) as u16,
            crc: pixel_crc(pixels, bits),
            timestamp_us,
        };
        if !header.is_valid_for(v) {
            return Err(bad);
        }
        let id = make_id(self.ids.id(v.message_kind(), foot), self.ids.extended)
            .ok_or(SegmentError::BadId)?;
        let mk = |buf: &[u8]| match v {
            Variant::Fd => CanFrame::fd(id, buf, true),
            Variant::Classic => CanFrame::classic(id, buf),
        };
        let mut buf = [0u8; 64];
        let len = v.frame_len();
        for part in 0..v.first_data_index() {
            buf[..len].fill(0);
            write_prefix(v, &mut buf, seq, part);
            encode_header(v, part, &header, &mut buf[..len]);
            out.emit(mk(&buf[..len]).ok_or(SegmentError::BadId)?);
        }
        let dps = v.data_per_segment();
        for s in 0..header.segments as usize {
            buf[..len].fill(0);
            write_prefix(v, &mut buf, seq, v.first_data_index() + s);
            let start = s * dps;
            let end = (start + dps).min(n_bytes);
            for (j, k) in (start..end).enumerate() {
                buf[v.prefix() + j] = pixel_byte(pixels, bits, k);
            }
            out.emit(mk(&buf[..len]).ok_or(SegmentError::BadId)?);
        }
        Ok(())
    }
}

pub(super) fn write_prefix(v: Variant, buf: &mut [u8], seq: u8, index: usize) {
    buf[0] = seq;
    match v {
        Variant::Fd => buf[1] = index as u8,
        Variant::Classic => buf[1..3].copy_from_slice(&(index as u16).to_le_bytes()),
    }
}

pub(super) fn encode_header(v: Variant, part: usize, h: &Header, buf: &mut [u8]) {
    match (v, part) {
        (Variant::Fd, _) => {
            buf[2] = h.rows;
            buf[3] = h.cols;
            buf[4] = h.bits;
            buf[5] = h.segments as u8;
            buf[6..10].copy_from_slice(&h.crc.to_le_bytes());
            buf[10..14].copy_from_slice(&h.timestamp_us.to_le_bytes());
        }
        (Variant::Classic, 0) => {
            buf[3] = h.rows;
            buf[4] = h.cols;
            buf[5] = h.bits;
            buf[6..8].copy_from_slice(&h.segments.to_le_bytes());
        }
        (Variant::Classic, 1) => buf[3..7].copy_from_slice(&h.crc.to_le_bytes()),
        (Variant::Classic, _) => buf[3..7].copy_from_slice(&h.timestamp_us.to_le_bytes()),
    }
}
