//! The unknown-terrain section: leave one class out per source, judged on a fresh run, over seeds.

use super::open_set_seeds::{
    OptionSpreads, open_set_by_gait, open_set_options, open_set_options_separable, open_set_spread,
};
use super::{Crop, FOOT_CROP, Kind, Report, ReportError, STATIC_CROP, pct};
use std::fmt::Write;

/// The open-set section's sources for `seed`: the lab's and extra sets (the seed draws the
/// split), then without `--data` the simulated ones (the seed also draws their runs).
pub(super) fn open_set_sources(ctx: &Report, seed: u64) -> Vec<crate::open_set::OpenSetSource> {
    use crate::open_set::OpenSetSource;
    use crate::study::dataset_on;
    use node::classifier::train::TrainOptions;
    let n = open_set_images(ctx);
    let models = ctx.open_set_models.options();
    let opts = |crop: Crop, normalize_load: bool| TrainOptions {
        crop: crop.into(),
        normalize_load,
        seed,
        ..models.clone()
    };
    let mut sources: Vec<OpenSetSource> = Vec::new();
    for u in ctx.user.iter().chain(&ctx.extra) {
        // Whether the images were scaled to one load changes what a class is (a person, not
        // a person at a speed): the table says so.
        let scaled = if u.normalize_load {
            " (load-normalised)"
        } else {
            ""
        };
        sources.push(OpenSetSource::from_runs(
            format!("`{}`{scaled}", u.dir.display()),
            &u.set,
            opts(u.crop, u.normalize_load),
        ));
    }
    if ctx.user.is_none() {
        let (g1, g2, g3) = (
            controller::Gait::g1(),
            controller::Gait::g2(),
            controller::Gait::g3(),
        );
        for (what, kind, crop, norm, gaits) in [
            (
                "simulator, static",
                Kind::Static,
                STATIC_CROP,
                false,
                vec![&g2],
            ),
            (
                "simulator, sandpaper",
                Kind::Sandpaper,
                STATIC_CROP,
                false,
                vec![&g2],
            ),
            (
                "simulator, dynamic (G1-G3)",
                Kind::Dynamic,
                FOOT_CROP,
                // Not pinned: `train` measures whether load normalisation pays here.
                false,
                vec![&g1, &g2, &g3],
            ),
        ] {
            let s = seed + 40;
            // Run i: sensor serial 1 + i, its own seed; the dynamic runs hop every gait
            // (a third of the stances each), as the demo's model is trained.
            let run = |i: u64, m: usize| {
                let mut t = dataset_on(kind, m / gaits.len(), gaits[0].clone(), s + i, 1 + i);
                for (j, g) in gaits.iter().enumerate().skip(1) {
                    let u = dataset_on(
                        kind,
                        m / gaits.len(),
                        (*g).clone(),
                        s + i + 10 * j as u64,
                        1 + i,
                    );
                    t.images.extend(u.images);
                    t.labels.extend(u.labels);
                    t.runs.extend(u.runs);
                    t.gaits.extend(u.gaits);
                }
                t
            };
            sources.push(OpenSetSource {
                name: what.to_string(),
                train: run(0, n),
                calibration: Some(run(1, n / 2)),
                fresh: Some(run(2, n / 2)),
                opts: opts(crop, norm),
            });
        }
    }
    sources
}

/// Images per terrain in a simulated open-set source's training run (half that in the others).
pub(super) fn open_set_images(ctx: &Report) -> usize {
    if ctx.quick { 30 } else { 60 }
}

/// The section's heading and what its tables measure.
fn open_set_intro(ctx: &Report, n: usize, rate: f64) -> String {
    let mut md = String::from("## Unknown terrain: leave one class out, judged on a fresh run\n\n");
    let _ = writeln!(
        md,
        "Per source, each class in turn is left out of training; the model ({split}, \
         rejection calibrated to `--unknown-rate {rate}`{texture}) then classifies every \
         image of the left-out class and the known classes' images of a **fresh run** (one the \
         model was neither trained nor calibrated on). The simulated sources are three runs on \
         three sensors (serials 1, 2, 3; seeds {s0}-{s2}; {n} images per terrain to train on, \
         {h} in each other run): train on the first, calibrate on the second, judge on the \
         third; a lab's set is split by the runs of its capture manifest (per class: the last \
         run is the fresh one, the one before it calibrates). Each model is trained as `presrs \
         train` trains without flags: it chooses its unknown-ground checks (novelty score, load \
         normalisation, PCA dimensions, load and texture bands) by leaving each of its known \
         classes out in turn on its training and calibration runs \
         (node/src/training/choice.rs; docs/decisions/unknown-choice.md).\n\n\
         *AUROC*: how well a score separates the left-out class from the fresh known images, \
         whatever the threshold (1 perfect, 0.5 chance): ours, the Parzen density of earlier \
         models, and the plain nearest-neighbour distance in the model's PCA space (the ceiling \
         a simple distance reaches). *Left-out unknown*: share of the left-out class called \
         unknown (target at least 80%). *Fresh known unknown*: share of the fresh run's known \
         images called unknown (target at most 3%); in brackets, those of them the model took for \
         another terrain: called unknown, they cost no accuracy and spare the robot that \
         terrain's gait (the rest, images it had right, are the rejection's cost: the gap \
         between the next two columns). *Known right*: fresh known images \
         classified right with the rejection on and off (target: within 2 points). \
         *Calibration check*: the share of the calibration run's images called unknown.\n\n\
         The simulated sandpaper has lain on a cloth backing (see Resolution): \
         the backing's pattern is the same under every grit, so the two finest grits, 220 and \
         150, now pass for each other as they do in the paper's 10x10 images, and a left-out \
         fine grit is taken for its neighbour (their nearest-neighbour AUROC below is the \
         ceiling). Before it (f062cee, seed 1) this source scored a mean AUROC of 0.991 and \
         98.0% of a left-out grit unknown.\n",
        s0 = ctx.seed + 40,
        s2 = ctx.seed + 42,
        h = n / 2,
        split = ctx.open_set_models.describe_split(),
        texture = if ctx.open_set_models.check_texture {
            ", with the texture check of `train --check-texture`"
        } else {
            ""
        },
    );
    md
}

/// Leave-one-class-out per source (the simulator's static, sandpaper and dynamic sets, each in
/// three runs on three sensors; the lab's own set and any extra sources, split by their runs):
/// how much of a class the model never saw is called unknown, and how much of a fresh run of
/// the known ones; with `open_set_seeds` above 1, the spread of the means over
/// that many seeds.
pub(super) fn open_set(ctx: &Report) -> Result<String, ReportError> {
    use crate::open_set::{OpenSetMeans, SeedSpread, leave_one_class_out};
    let rate = ctx.open_set_models.options().unknown_rate;
    let n = open_set_images(ctx);
    let sources = open_set_sources(ctx, ctx.seed);
    let mut spreads: Vec<SeedSpread> = vec![SeedSpread::default(); sources.len()];
    let mut md = open_set_intro(ctx, n, rate);
    let _ = writeln!(
        md,
        "| source | calibrated on | AUROC: ours | density (before) | nearest neighbour | left-out unknown | fresh known unknown (taken for another terrain) | known right: rejection on | off | calibration check |"
    );
    let _ = writeln!(md, "|---|---|---|---|---|---|---|---|---|---|");
    let mut detail = String::from(
        "\nPer left-out class: *checks* is what `train` chose on the other classes (its `--unknown-checks` list).\n\n| source | left out | checks | AUROC: ours | density | nearest neighbour | left-out unknown | fresh known unknown (another terrain) | known right (on / off) |\n|---|---|---|---|---|---|---|---|---|\n",
    );
    // Per source: each single option fixed instead of chosen, over the same seeds.
    let mut options: Vec<OptionSpreads> = Vec::new();
    for src in &sources {
        let per = crate::open_set::single_options(src)?
            .into_iter()
            .map(|(c, rows)| {
                let mut s = SeedSpread::default();
                s.push_rows(ctx.seed, rows);
                (c, s)
            })
            .collect();
        options.push(per);
    }
    for (src, spread) in sources.iter().zip(&mut spreads) {
        let rows = leave_one_class_out(src)?;
        let m = OpenSetMeans::of(&rows);
        spread.push_rows(ctx.seed, rows.clone());
        let r = &m.row;
        let cal = match (&src.calibration, &src.fresh) {
            (Some(c), _) => format!("another run ({} images)", c.images.len()),
            (None, Some(_)) => "the training run (margin)".into(),
            (None, None) => "the training run (margin); no fresh run: known images are the training run's unused ones".into(),
        };
        let _ = writeln!(
            md,
            "| {} | {cal} | **{:.3}** ({:.2}-{:.2}) | {:.3} | {:.3} | **{}** | **{}** ({}) | {} | {} | {} |",
            src.name,
            r.auroc,
            m.auroc_range.0,
            m.auroc_range.1,
            r.density_auroc,
            r.nn_auroc,
            pct(r.unknown_held_out),
            pct(r.unknown_known),
            pct(r.unknown_known_misclassified),
            pct(r.known_accuracy),
            pct(r.known_accuracy_open),
            pct(r.calibration_unknown),
        );
        for x in &rows {
            let _ = writeln!(
                detail,
                "| {} | {} | `{}` | {:.3} | {:.3} | {:.3} | {} | {} ({}) | {} / {} |",
                src.name,
                x.held_out,
                x.checks,
                x.auroc,
                x.density_auroc,
                x.nn_auroc,
                pct(x.unknown_held_out),
                pct(x.unknown_known),
                pct(x.unknown_known_misclassified),
                pct(x.known_accuracy),
                pct(x.known_accuracy_open),
            );
        }
    }
    md.push_str(&detail);
    if ctx.open_set_seeds > 1 {
        let last = ctx.seed + ctx.open_set_seeds - 1;
        for seed in ctx.seed + 1..=last {
            let seed_sources = open_set_sources(ctx, seed);
            for ((src, spread), opts) in seed_sources.iter().zip(&mut spreads).zip(&mut options) {
                spread.push_rows(seed, leave_one_class_out(src)?);
                for ((_, s), (_, rows)) in
                    opts.iter_mut().zip(crate::open_set::single_options(src)?)
                {
                    s.push_rows(seed, rows);
                }
            }
        }
        let names: Vec<&str> = sources.iter().map(|s| s.name.as_str()).collect();
        md.push_str(&open_set_spread(&names, &spreads, ctx.seed, last));
    }
    let names: Vec<&str> = sources.iter().map(|s| s.name.as_str()).collect();
    md.push_str(&open_set_by_gait(&names, &spreads));
    md.push_str(&open_set_options(&names, &spreads, &options));
    md.push_str(&open_set_options_separable(&names, &spreads, &options));
    Ok(md)
}
