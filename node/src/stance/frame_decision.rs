//! One frame's decision: crop, repair (per image, or from the foot's line history with the
//! model refitted to its dead lines, [`super::adapt`]) and the classifier's decision, with a
//! multi-frame stance's sums. The pipeline calls it for the sampled frame, or for every frame
//! of a multi-frame stance.

use super::adapt::Refitter;
use super::{Counters, Foot};
use crate::classifier::{Classifier, Decision};
use crate::config::{NodeConfig, RepairMode};

/// What a decision adapts with: the config (repair mode, refit mode), the refitter and the
/// counters it counts refits in.
pub(super) struct Adaptation<'a> {
    pub cfg: &'a NodeConfig,
    pub refitter: &'a mut Refitter,
    pub counters: &'a mut Counters,
}

/// What a multi-frame decision keeps of a frame: its log posteriors added to the stance's
/// sum, and (for the frame nearest the sample time) the checks' verdict for each class.
pub(super) struct FrameSums<'a> {
    pub sum_lp: &'a mut Vec<f64>,
    pub verdicts: Option<&'a mut Vec<Option<crate::unknown::Reason>>>,
}

/// Crop, repair and decision for one frame (the foot's `best`). Returns the decision and
/// whether any line was filled; `observe` feeds the frame to the stance history (once per
/// stance); `sums` (multi-frame) gets the decision's log posteriors and verdicts. With history
/// repair, a model refitted to the foot's current dead lines decides. An image without contact
/// is neither learned from nor repaired.
pub(super) fn decide_frame(
    cls: &mut Classifier,
    foot: u8,
    f: &mut Foot,
    (rows, cols): (usize, usize),
    observe: bool,
    sums: Option<FrameSums<'_>>,
    ctx: Adaptation<'_>,
) -> Option<(Decision, bool)> {
    let Adaptation {
        cfg,
        refitter,
        counters,
    } = ctx;
    cls.prepare(&f.best[..f.best_len], rows, cols).ok()?;
    // Measured once here: the decisions below skip the check.
    if !cls.in_contact() {
        return Some((Decision::NO_CONTACT, false));
    }
    let add = |sums: Option<FrameSums<'_>>, c: &mut Classifier| {
        if let Some(s) = sums {
            for (a, b) in s.sum_lp.iter_mut().zip(c.log_posteriors()) {
                *a += b;
            }
            if let Some(v) = s.verdicts {
                c.verdicts_per_class(v);
            }
        }
    };
    let repaired = match cfg.repair {
        RepairMode::None => false,
        RepairMode::PerImage => cls.repair_work() > 0,
        RepairMode::History => {
            if observe {
                f.health.observe(cls.work_mut(), cfg.dead_after_stances);
                refitter.request(cfg.refit, foot, f, counters);
            }
            if let Some(a) = f.adapted.as_mut().filter(|a| a.fits(&f.health)) {
                a.cls.work_mut().copy_from_slice(cls.work_mut());
                let repaired = f.health.repair(a.cls.work_mut()) > 0;
                let d = a.cls.decide_in_contact();
                add(sums, &mut a.cls);
                return Some((d, repaired));
            }
            f.health.repair(cls.work_mut()) > 0
        }
    };
    let d = cls.decide_in_contact();
    add(sums, cls);
    Some((d, repaired))
}
