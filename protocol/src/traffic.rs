//! Listening to a bus's traffic: each frame decoded against the configured identifiers, tactile
//! segments reassembled into whole pressure images, and every frame counted as heard, foreign
//! (another identifier) or undecodable. The recorder (MCAP, Foxglove) and the ROS 2 bridge both
//! listen this way; one type keeps their counts meaning the same.

use crate::frame::Stamped;
use crate::ids::IdConfig;
use crate::messages::{self, Message};
use crate::tactile::{Reassembler, TactileImage};

/// What one frame brought.
#[derive(Debug)]
pub enum Heard {
    /// A message (not a tactile segment) from `foot` (0 for messages not per foot).
    Message {
        /// The sending foot, or 0.
        foot: u8,
        /// The decoded message.
        msg: Message,
    },
    /// A segment that completed a pressure image of `foot`: [`Traffic::last_image`].
    Image {
        /// The foot the image is from.
        foot: u8,
    },
    /// Nothing to act on: a segment of an image not yet whole, or a frame counted as foreign
    /// or undecodable.
    Nothing,
}

/// Frames counted by a [`Traffic`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TrafficCounts {
    /// Frames heard.
    pub frames: u64,
    /// Frames with our identifiers that did not decode.
    pub undecodable: u64,
    /// Frames with other identifiers.
    pub foreign: u64,
}

/// Frames in, messages and whole images out.
pub struct Traffic {
    ids: IdConfig,
    reassembler: Reassembler,
    counts: TrafficCounts,
}

impl Traffic {
    /// Listens for traffic on `ids`.
    pub fn new(ids: IdConfig) -> Self {
        Self {
            ids,
            reassembler: Reassembler::default(),
            counts: TrafficCounts::default(),
        }
    }

    /// Counts so far.
    pub fn counts(&self) -> TrafficCounts {
        self.counts
    }

    /// The image the last [`Heard::Image`] completed.
    pub fn last_image(&self) -> &TactileImage {
        self.reassembler.last_image()
    }

    /// One frame of the traffic.
    pub fn hear(&mut self, st: &Stamped) -> Heard {
        self.counts.frames += 1;
        let (foot, msg) = match messages::decode(&st.frame, &self.ids) {
            Ok(Some(m)) => m,
            Ok(None) => {
                self.counts.foreign += 1;
                return Heard::Nothing;
            }
            Err(_) => {
                self.counts.undecodable += 1;
                return Heard::Nothing;
            }
        };
        match msg {
            Message::TactileSegment(variant) => {
                match self
                    .reassembler
                    .push(variant, foot, st.frame.data(), st.t_us)
                {
                    Some(_) => Heard::Image { foot },
                    None => Heard::Nothing,
                }
            }
            msg => {
                let foot = if msg.kind().per_foot() { foot } else { 0 };
                Heard::Message { foot, msg }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::{CanFrame, make_id};
    use crate::ids::MessageKind;
    use crate::tactile::{ImageRef, Segmenter, Variant};

    fn at(frame: CanFrame, t_us: u64) -> Stamped {
        Stamped { frame, t_us }
    }

    #[test]
    fn counts_foreign_and_undecodable_frames_and_hands_over_whole_images() {
        let ids = IdConfig::default();
        let mut t = Traffic::new(ids.clone());
        let foreign = CanFrame::classic(make_id(0x7FF, false).unwrap(), &[1, 2]).unwrap();
        assert!(matches!(t.hear(&at(foreign, 1)), Heard::Nothing));
        // Our identifier, one byte where FootContact has eight.
        let id = make_id(ids.id(MessageKind::FootContact, 2), ids.extended).unwrap();
        let short = CanFrame::classic(id, &[1]).unwrap();
        assert!(matches!(t.hear(&at(short, 2)), Heard::Nothing));
        let pixels: Vec<u16> = (0..44 * 44).map(|i| (i % 200) as u16).collect();
        let mut frames = Vec::new();
        let img = ImageRef {
            rows: 44,
            cols: 44,
            bits: 8,
            timestamp_us: 5,
            pixels: &pixels,
        };
        Segmenter::new(Variant::Classic, ids)
            .frames(3, 7, &img, &mut frames)
            .unwrap();
        let n = frames.len();
        let mut whole = Vec::new();
        for (i, f) in frames.into_iter().enumerate() {
            match t.hear(&at(f, 10 + i as u64)) {
                Heard::Image { foot } => whole.push((i, foot)),
                Heard::Nothing => {}
                Heard::Message { .. } => panic!("a segment is not a message"),
            }
        }
        assert_eq!(whole, [(n - 1, 3)], "one image, at its last segment");
        assert_eq!(t.last_image().pixels(), &pixels[..]);
        let c = t.counts();
        assert_eq!((c.frames, c.foreign, c.undecodable), (n as u64 + 2, 1, 1));
    }
}
