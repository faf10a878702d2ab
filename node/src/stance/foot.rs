//! One foot's stance state: its switch, the stance's candidate image (single frame) or summed
//! posteriors (multi-frame), its line health and refit, its image clock and energy balance.
//! The pipeline ([`super::StancePipeline`]) owns one per foot and drives it.

use super::adapt::Adapted;
use super::debounce::Switch;
use super::timing::ImageClock;
use crate::health::LineHealth;
use crate::unknown::Reason;
use crate::unknown::energy::Balance;

/// One foot's stance state.
pub(super) struct Foot {
    pub(super) switch: Switch,
    pub(super) touchdown_us: u32,
    /// The touchdown on the receiver's clock ([`super::Decided::touchdown_us`]).
    pub(super) touchdown_rx_us: u64,
    pub(super) decided: bool,
    pub(super) step: u16,
    /// Single frame: the best candidate so far (|dt - sample| in µs) and its pixels.
    pub(super) best_err: Option<u32>,
    pub(super) best_rx_us: u64,
    /// The best candidate's pixels (the first `best_len`), geometry and sample time.
    pub(super) best: Vec<u16>,
    pub(super) best_len: usize,
    pub(super) best_shape: (u8, u8, u8),
    pub(super) best_ts: u32,
    /// Multi-frame: summed log-posteriors (one per class of the model) and frames used.
    pub(super) sum_lp: Vec<f64>,
    pub(super) used: u32,
    /// Multi-frame: how near the sample time the nearest frame so far was (|dt - sample| in
    /// µs), and its verdict for each class: the checks were calibrated on images at the sample
    /// time, so that frame's verdict on the class the summed posterior decides is the step's.
    pub(super) sample_err: Option<u32>,
    pub(super) sample_verdicts: Vec<Option<Reason>>,
    /// An image of this stance was looked at and showed no contact.
    pub(super) no_contact: bool,
    /// A line of this stance's frames was filled.
    pub(super) repaired: bool,
    pub(super) health: LineHealth,
    /// The model refitted to this foot's dead lines, used while they are still the dead lines.
    pub(super) adapted: Option<Adapted>,
    /// The dead lines a refit was last asked for (pending, done or failed): asked once per set.
    pub(super) asked: Option<(Vec<bool>, Vec<bool>)>,
    /// When this foot's images come, on its clock and on the receiver's.
    pub(super) clock: ImageClock,
    /// The last frame heard from this foot: its receive time and the foot's timestamp in it,
    /// so [`super::StancePipeline::tick`] can tell the foot's time from the receiver's.
    pub(super) heard: Option<(u64, u32)>,
    /// The last FootContact's receive time and timestamp: the foot's clock against the
    /// receiver's without an image's transfer time (an image is received whole some ms after
    /// its sample time), to put a touchdown on the receiver's clock.
    pub(super) contact_heard: Option<(u64, u32)>,
    /// The hop's energy balance over this foot's stances.
    pub(super) balance: Balance,
    /// Capture mode: per offset of [`super::FRAME_OFFSETS_MS`], the image nearest it so far (|dt -
    /// offset| in µs) and its pixels (empty outside capture).
    pub(super) frames: Vec<(Option<u32>, Vec<u16>)>,
}

impl Foot {
    /// Keeps `img` as the stance's candidate image.
    pub(super) fn keep(&mut self, img: &protocol::tactile::TactileImage, rx_us: u64) {
        let n = img.len();
        self.best[..n].copy_from_slice(img.pixels());
        self.best_len = n;
        self.best_shape = (img.rows, img.cols, img.bits);
        self.best_ts = img.timestamp_us;
        self.best_rx_us = rx_us;
    }

    pub(super) fn new(input: usize, classes: usize, health: LineHealth) -> Self {
        Self {
            switch: Switch::default(),
            touchdown_us: 0,
            touchdown_rx_us: 0,
            decided: true,
            step: 0,
            best_err: None,
            best_rx_us: 0,
            best: vec![0; input],
            best_len: input,
            best_shape: (0, 0, 8),
            best_ts: 0,
            sum_lp: vec![0.0; classes],
            used: 0,
            sample_err: None,
            sample_verdicts: vec![None; classes],
            no_contact: false,
            repaired: false,
            health,
            adapted: None,
            asked: None,
            clock: ImageClock::default(),
            heard: None,
            contact_heard: None,
            balance: Balance::default(),
            frames: Vec::new(),
        }
    }
}
