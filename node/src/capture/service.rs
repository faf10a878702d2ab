//! Capture as a part on the bus (`presrs capture --iface`): a [`Component`] that writes each
//! labelled step to a [`CaptureSet`] as it comes.

use super::{Capture, CaptureError, CaptureSet, CapturedStep, Component, Outbox, Path, Stamped};

/// A capture filling a training set, as a part on the bus ([`Component`]): `presrs capture
/// --iface` runs it with the one runner; a log is fed to it frame by frame
/// ([`CaptureService::feed`]). The first write error stops it ([`Component::done`]);
/// everything written before stays written.
pub struct CaptureService {
    /// The stance logic and the labels.
    pub capture: Capture,
    /// Where captured steps go.
    pub set: CaptureSet,
    /// The name the manifest keys steps by.
    pub source: String,
    /// The write error that stopped it, if one did.
    pub failed: Option<CaptureError>,
    last_t: u64,
}

impl CaptureService {
    /// A capture into `set`, keying steps by `source`.
    pub fn new(capture: Capture, set: CaptureSet, source: String) -> Self {
        Self {
            capture,
            set,
            source,
            failed: None,
            last_t: 0,
        }
    }

    /// One frame with its time (a log's, or the bus's receive time).
    pub fn feed(&mut self, st: &Stamped) {
        self.last_t = st.t_us;
        let (set, source, failed) = (&mut self.set, &self.source, &mut self.failed);
        self.capture
            .feed(st, &mut |c| keep(set, source, failed, &c));
    }
}

impl CaptureService {
    /// Feeds a log's records until the capture is done (a `--replay`).
    pub fn replay<R: std::borrow::Borrow<protocol::candump::LogRecord>>(
        &mut self,
        records: impl IntoIterator<Item = R>,
    ) {
        for r in records {
            self.feed(&r.borrow().stamped);
            if self.failed.is_some() {
                break;
            }
        }
        self.finish();
    }

    /// Writes the steps the capture still holds (the run ended before their next touchdown).
    pub fn finish(&mut self) {
        let (set, source, failed) = (&mut self.set, &self.source, &mut self.failed);
        self.capture.finish(&mut |c| keep(set, source, failed, &c));
    }

    /// `presrs capture --json`'s object: what was read, written and skipped, and why it
    /// stopped if it did; `out` names the set's folder.
    pub fn report_json(&self, out: &Path) -> serde_json::Value {
        let (c, pc, set) = (
            self.capture.counts(),
            self.capture.pipeline().counters,
            &self.set,
        );
        serde_json::json!({
            "source": self.source, "out": out, "frames": pc.frames, "images": pc.images,
            "steps": c.steps, "written": set.written, "duplicates": set.duplicates,
            "no_image": c.no_image, "blank": c.blank, "unlabelled": c.unlabelled,
            "spans_labels": c.spans_labels, "per_terrain": set.written_per_terrain,
            "per_gait": set.written_per_gait.iter().map(|(g, n)| (crate::gait_status::gait_name(*g), *n))
                .collect::<std::collections::BTreeMap<_, _>>(),
            "set_total": set.len(), "error": self.failed.as_ref().map(|e| e.to_string()),
        })
    }

    /// The same for a person: the counts on a first line, what was written and skipped below.
    pub fn report(&self, out: &Path) -> String {
        let (c, set) = (self.capture.counts(), &self.set);
        let terrains: Vec<String> = set
            .written_per_terrain
            .iter()
            .map(|(t, n)| format!("{t} {n}"))
            .collect();
        let gaits: Vec<String> = set
            .written_per_gait
            .iter()
            .map(|(g, n)| format!("{} {n}", crate::gait_status::gait_name(*g)))
            .collect();
        format!(
            "capture of {}: {} steps, {} written, {} already in the set; {} holds {} steps\n  \
             written per terrain: {}\n  by gait at touchdown: {}\n  skipped: {} without an \
             image in the stance, {} blank, {} outside every label, {} spanning two labels",
            self.source,
            c.steps,
            set.written,
            set.duplicates,
            out.display(),
            set.len(),
            if terrains.is_empty() {
                "none".into()
            } else {
                terrains.join(", ")
            },
            if gaits.is_empty() {
                "none".into()
            } else {
                gaits.join(", ")
            },
            c.no_image,
            c.blank,
            c.unlabelled,
            c.spans_labels,
        )
    }
}

pub(super) fn keep(
    set: &mut CaptureSet,
    source: &str,
    failed: &mut Option<CaptureError>,
    c: &CapturedStep,
) {
    if failed.is_none()
        && let Err(e) = set.add(c, source)
    {
        *failed = Some(e);
    }
}

impl Component for CaptureService {
    fn name(&self) -> &'static str {
        "capture"
    }

    /// Every frame, as the node sees them: a lab's foot may send what the node reads under
    /// any ids its config gives.
    fn filters(&self) -> Vec<(u32, u32)> {
        Vec::new()
    }

    fn on_frame(&mut self, st: &Stamped, _: u64, _: &mut Outbox) {
        self.feed(st);
    }

    /// The bus went quiet: steps whose nearer images can no longer come are decided, on the
    /// clock of the last frame's receive time (the bus's, not this process's).
    fn tick(&mut self, _: u64, _: &mut Outbox) {
        let (set, source, failed) = (&mut self.set, &self.source, &mut self.failed);
        self.capture
            .tick(self.last_t, &mut |c| keep(set, source, failed, &c));
    }

    fn stop(&mut self, _: u64, _: &mut Outbox) {
        self.finish();
    }

    fn done(&self) -> bool {
        self.failed.is_some()
    }
}
