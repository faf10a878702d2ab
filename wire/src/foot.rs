//! The foot's side of the protocol, for its microcontroller: switch reports and images, sent
//! through any [`embedded_can::blocking::Can`] driver. `no_std`, no allocation.
//!
//! A foot board runs a 100 Hz loop: read the micro-switch, sample the tactile array, and call
//! [`Foot::tick`] with both and its clock. That sends what `docs/protocol.md` asks of a foot:
//! a `FootContact` every tick (100 Hz keeps the node's view of the foot's clock moving, which
//! lets it decide a step whose later images were lost) and the image as one header and 32 data
//! segments on CAN FD, both stamped with the same µs clock, so the node judges the stance and the
//! image's place in it by the foot's time, never by arrival time. Edges are not debounced here:
//! the node debounces (a switch's bounce is information the node's rule is built for).
//!
//! ```
//! use presrs_wire::{foot::Foot, ids::IdConfig, tactile::{ImageRef, Variant}, CanFrame};
//! # struct Sink(Vec<CanFrame>);
//! # impl embedded_can::blocking::Can for Sink {
//! #     type Frame = CanFrame;
//! #     type Error = core::convert::Infallible;
//! #     fn transmit(&mut self, f: &CanFrame) -> Result<(), Self::Error> { self.0.push(*f); Ok(()) }
//! #     fn receive(&mut self) -> Result<CanFrame, Self::Error> { unreachable!() }
//! # }
//! let mut foot = Foot::new(Sink(Vec::new()), 0, IdConfig::default(), Variant::Fd);
//! let pixels = [0u16; 44 * 44];
//! let image = ImageRef { rows: 44, cols: 44, bits: 8, timestamp_us: 10_000, pixels: &pixels };
//! foot.tick(true, 10_000, Some(&image)).unwrap();
//! assert_eq!(foot.can().0.len(), 1 + 33); // one FootContact, one header, 32 data segments
//! ```

use embedded_can::Frame as _;

use crate::frame::CanFrame;
use crate::ids::IdConfig;
use crate::messages::{FootContact, Message};
use crate::tactile::{ImageRef, SegmentError, Segmenter, Variant};

/// Why a foot could not send.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum FootError<E: core::fmt::Debug> {
    /// The CAN driver refused a frame (bus off, no FD support, ...).
    #[error("the CAN driver refused a frame: {0:?}")]
    Can(E),
    /// The image cannot be sent (size, depth or pixel count).
    #[error(transparent)]
    Image(#[from] SegmentError),
    /// The foot number or identifier map gives an identifier outside the configured width.
    #[error("foot {0}'s identifier does not fit the configured identifier width")]
    BadId(u8),
    /// The driver's frame type cannot carry a frame of this length (an FD image segment on a
    /// classic-only driver: use [`Variant::Classic`]).
    #[error(
        "the CAN driver's frame type cannot carry {0} data bytes (a classic-only driver: use the classic tactile variant)"
    )]
    FrameTooLong(usize),
}

/// One foot's sender: its switch reports and tactile images through the driver `C`.
pub struct Foot<C> {
    can: C,
    foot: u8,
    ids: IdConfig,
    segmenter: Segmenter,
    contact_seq: u8,
    image_seq: u8,
}

impl<C: embedded_can::blocking::Can> Foot<C>
where
    C::Error: core::fmt::Debug,
{
    /// Foot number `foot` (0..8) on `ids`, images as `variant` segments.
    pub fn new(can: C, foot: u8, ids: IdConfig, variant: Variant) -> Self {
        Self {
            can,
            foot,
            segmenter: Segmenter::new(variant, ids.clone()),
            ids,
            contact_seq: 0,
            image_seq: 0,
        }
    }

    /// The driver (for its statistics, or to take it back).
    pub fn can(&mut self) -> &mut C {
        &mut self.can
    }

    /// One period of the foot's loop: the switch state as `FootContact`, then the image sampled
    /// at this tick, if any (its `timestamp_us` is the sample time on the same clock as `now_us`).
    pub fn tick(
        &mut self,
        stance: bool,
        now_us: u32,
        image: Option<&ImageRef<'_>>,
    ) -> Result<(), FootError<C::Error>> {
        self.contact(stance, now_us)?;
        if let Some(img) = image {
            self.image(img)?;
        }
        Ok(())
    }

    /// Gives the driver back.
    pub fn into_inner(self) -> C {
        self.can
    }

    /// Sends one `FootContact` (call it every tick, or at least on each edge).
    pub fn contact(&mut self, stance: bool, now_us: u32) -> Result<(), FootError<C::Error>> {
        let msg = Message::FootContact(FootContact {
            stance,
            seq: self.contact_seq,
            timestamp_us: now_us,
        });
        self.contact_seq = self.contact_seq.wrapping_add(1);
        let frame = msg
            .to_frame(&self.ids, self.foot)
            .ok_or(FootError::BadId(self.foot))?;
        send(&mut self.can, &frame)
    }

    /// Sends one image: a header segment and its data segments, in order. Nothing is buffered:
    /// each segment is built on the stack and handed to the driver before the next.
    pub fn image(&mut self, img: &ImageRef<'_>) -> Result<(), FootError<C::Error>> {
        let seq = self.image_seq;
        self.image_seq = self.image_seq.wrapping_add(1);
        let mut failed = None;
        let (can, foot) = (&mut self.can, self.foot);
        self.segmenter.frames(foot, seq, img, &mut |f: CanFrame| {
            if failed.is_none()
                && let Err(e) = send(can, &f)
            {
                failed = Some(e);
            }
        })?;
        failed.map_or(Ok(()), Err)
    }
}

/// Converts our frame to the driver's frame type (FD when longer than 8 bytes, as
/// `embedded_can::Frame::new` builds it for drivers that support FD) and transmits it.
fn send<C: embedded_can::blocking::Can>(
    can: &mut C,
    frame: &CanFrame,
) -> Result<(), FootError<C::Error>>
where
    C::Error: core::fmt::Debug,
{
    let f = C::Frame::new(frame.id(), frame.data()).ok_or(FootError::FrameTooLong(frame.len()))?;
    can.transmit(&f).map_err(FootError::Can)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::messages::decode;
    use crate::tactile::Reassembler;

    #[derive(Debug, PartialEq, Eq)]
    struct BusOff;
    impl embedded_can::Error for BusOff {
        fn kind(&self) -> embedded_can::ErrorKind {
            embedded_can::ErrorKind::Other
        }
    }

    /// Takes 40 frames, then is bus-off.
    struct Sink(Vec<CanFrame>);
    impl embedded_can::blocking::Can for Sink {
        type Frame = CanFrame;
        type Error = BusOff;
        fn transmit(&mut self, f: &CanFrame) -> Result<(), Self::Error> {
            if self.0.len() >= 40 {
                return Err(BusOff);
            }
            self.0.push(*f);
            Ok(())
        }
        fn receive(&mut self) -> Result<CanFrame, Self::Error> {
            Err(BusOff)
        }
    }

    #[test]
    fn what_a_foot_sends_reassembles_and_decodes() {
        let ids = IdConfig::default();
        let mut foot = Foot::new(Sink(Vec::new()), 3, ids.clone(), Variant::Fd);
        let pixels: Vec<u16> = (0..44 * 44).map(|i| (i % 251) as u16).collect();
        let img = ImageRef {
            rows: 44,
            cols: 44,
            bits: 8,
            timestamp_us: 70_000,
            pixels: &pixels,
        };
        foot.tick(true, 70_000, Some(&img)).unwrap();
        let frames = std::mem::take(&mut foot.can().0);
        assert_eq!(frames.len(), 34);
        let contact = decode(&frames[0], &ids).unwrap();
        assert_eq!(
            contact,
            Some((
                3,
                Message::FootContact(FootContact {
                    stance: true,
                    seq: 0,
                    timestamp_us: 70_000
                })
            ))
        );
        let mut r = Reassembler::new(100_000);
        let mut got = None;
        for (i, f) in frames[1..].iter().enumerate() {
            let (kind, foot_no) = ids.lookup(f.raw_id(), false).unwrap();
            assert_eq!((kind, f.is_fd()), (crate::MessageKind::TactileFrame, true));
            if let Some(im) = r.push(Variant::Fd, foot_no, f.data(), i as u64) {
                got = Some((im.foot, im.timestamp_us, im.pixels().to_vec()));
            }
        }
        assert_eq!(got, Some((3, 70_000, pixels.clone())));
        // A second tick: the counters move on.
        foot.contact(false, 80_000).unwrap();
        let Some((_, Message::FootContact(c))) = decode(&foot.can().0[0], &ids).unwrap() else {
            panic!("not a FootContact")
        };
        assert_eq!((c.stance, c.seq), (false, 1));
    }

    #[test]
    fn a_driver_error_stops_the_image_and_is_returned() {
        let mut foot = Foot::new(Sink(Vec::new()), 0, IdConfig::default(), Variant::Fd);
        let pixels = [7u16; 44 * 44];
        let img = ImageRef {
            rows: 44,
            cols: 44,
            bits: 8,
            timestamp_us: 0,
            pixels: &pixels,
        };
        foot.image(&img).unwrap();
        assert_eq!(foot.image(&img), Err(FootError::Can(BusOff)));
        assert_eq!(foot.can().0.len(), 40);
        let bad = ImageRef {
            rows: 44,
            cols: 45,
            ..img
        };
        assert!(matches!(foot.image(&bad), Err(FootError::Image(_))));
    }
}
