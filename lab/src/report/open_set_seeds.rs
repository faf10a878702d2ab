//! The open-set report's tables over several seeds: each source's spread, its mean with a 95%
//! interval, the targets where they apply, the fresh run's unknowns per gait, and the
//! default against one option fixed by hand (over every class, then the separable ones).
//! `open_set.rs` runs the experiment and writes the first seed's tables.

use std::fmt::Write as _;

use super::pct;
use crate::open_set::SeedSpread;

/// Each single option's spread over the seeds, for one source.
pub(super) type OptionSpreads = Vec<(
    node::classifier::options::Candidate,
    crate::open_set::SeedSpread,
)>;

/// The default (`train` choosing its checks on the known classes) against the best single
/// option fixed instead, and the plain nearest neighbour's AUROC, per source: means over the
/// seeds run, the default's left-out share also at its median and worst seed.
pub(super) fn open_set_options(
    names: &[&str],
    default: &[crate::open_set::SeedSpread],
    options: &[OptionSpreads],
) -> String {
    let seeds = match default.first().map(|s| s.seeds.as_slice()) {
        Some([a, .., b]) => format!("seeds {a}-{b}"),
        Some([a]) => format!("seed {a}"),
        _ => return String::new(),
    };
    let mut md = format!(
        "\nThe default against one option fixed by hand ({seeds}, means over the seeds; every \
         class counted). *Default*: `train` as it runs without flags, choosing its checks on \
         the known classes (the per-class table above names its choice). *Best single \
         option*: of {}, each fixed in place of the choice, the one with the largest AUROC. \
         *Left-out*: the default's share at its median and worst seed beside the mean.\n\n\
         | source | default: AUROC | left-out unknown (median, worst seed) | fresh known unknown \
         | best single option | its AUROC | its left-out | its fresh known | nearest neighbour AUROC |\n\
         |---|---|---|---|---|---|---|---|---|\n",
        crate::open_set::SINGLE_OPTIONS
            .iter()
            .map(|c| format!("`{c}`"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    for ((name, d), opts) in names.iter().zip(default).zip(options) {
        let held = d.of(|r| r.unknown_held_out);
        let best = opts.iter().max_by(|a, b| {
            a.1.of(|r| r.auroc)
                .mean
                .total_cmp(&b.1.of(|r| r.auroc).mean)
        });
        let Some((c, b)) = best else { continue };
        let _ = writeln!(
            md,
            "| {name} | **{:.3}** | **{}** ({}, {}) | **{}** | `{c}` | {:.3} | {} | {} | {:.3} |",
            d.of(|r| r.auroc).mean,
            pct(held.mean),
            pct(held.median),
            pct(held.min),
            pct(d.of(|r| r.unknown_known).mean),
            b.of(|r| r.auroc).mean,
            pct(b.of(|r| r.unknown_held_out).mean),
            pct(b.of(|r| r.unknown_known).mean),
            d.of(|r| r.nn_auroc).mean,
        );
    }
    md
}

/// The same comparison on the classes a score separates at all (see [`open_set_judged`]),
/// where the targets hold: the default's AUROC against the best single option's and
/// the nearest neighbour's, and its left-out share's worst seed against its median. Each
/// target is named met or by how much it is missed.
pub(super) fn open_set_options_separable(
    names: &[&str],
    default: &[crate::open_set::SeedSpread],
    options: &[OptionSpreads],
) -> String {
    if !default.iter().any(SeedSpread::has_rows) {
        return String::new();
    }
    let mut md = String::from(
        "\nThe same on the separable classes (the table above names those left out): the \
         issue's targets there are an AUROC at least the best single option's and the nearest \
         neighbour's, at least 80% of a left-out class found, and the worst seed's left-out \
         share within 20 points of its median. The best single option is the one with the \
         largest AUROC on these classes.\n\n\
         | source | default: AUROC | left-out unknown (median, worst seed) | the worst seed's least-found class (its checks) | best single option | its AUROC | its left-out | nearest neighbour AUROC | targets |\n\
         |---|---|---|---|---|---|---|---|---|\n",
    );
    for ((name, d), opts) in names.iter().zip(default).zip(options) {
        let except: Vec<String> = d.inseparable().into_iter().map(|(n, _, _)| n).collect();
        let auroc = d.of_classes(&except, |r| r.auroc).mean;
        let held = d.of_classes(&except, |r| r.unknown_held_out);
        let nn = d.of_classes(&except, |r| r.nn_auroc).mean;
        let best = opts
            .iter()
            .map(|(c, s)| (c, s.of_classes(&except, |r| r.auroc).mean, s))
            .max_by(|a, b| a.1.total_cmp(&b.1));
        let Some((c, best_auroc, b)) = best else {
            continue;
        };
        let mut verdict = Vec::new();
        for (what, short) in [
            ("AUROC >= best single", best_auroc - auroc),
            ("AUROC >= nearest neighbour", nn - auroc),
        ] {
            verdict.push(if short > 0.0 {
                format!("{what}: {short:.3} short")
            } else {
                format!("{what}: met")
            });
        }
        verdict.push(if held.mean < 0.8 {
            format!("left-out >= 80%: {} short", pct(0.8 - held.mean))
        } else {
            "left-out >= 80%: met".to_string()
        });
        let gap = 100.0 * (held.median - held.min);
        verdict.push(if gap > 20.0 {
            format!("worst seed within 20 points: {gap:.1} points")
        } else {
            format!("worst seed within 20 points: met ({gap:.1})")
        });
        let least = d
            .least_found(&except)
            .map(|(seed, r)| {
                format!(
                    "seed {seed}: {} {} (`{}`)",
                    r.held_out,
                    pct(r.unknown_held_out),
                    r.checks
                )
            })
            .unwrap_or_default();
        let _ = writeln!(
            md,
            "| {name} | **{auroc:.3}** | **{}** ({}, {}) | {least} | `{c}` | {best_auroc:.3} | {} | {nn:.3} | {} |",
            pct(held.mean),
            pct(held.median),
            pct(held.min),
            pct(b.of_classes(&except, |r| r.unknown_held_out).mean),
            verdict.join("; "),
        );
    }
    md
}

/// The fresh run's known images called unknown per gait they touched down in, for the sources
/// whose images carry two or more gaits (a simulated gait, a capture manifest's `gait`: for
/// SpeedPP2D the walking speed), pooled over the left-out classes and the seeds run: where the
/// cost of the rejection falls. Empty when no source has two gaits.
pub(super) fn open_set_by_gait(names: &[&str], spreads: &[crate::open_set::SeedSpread]) -> String {
    let pooled: Vec<(&str, Vec<node::gait_status::GaitCount>)> = names
        .iter()
        .zip(spreads)
        .map(|(name, s)| {
            let rows = s.means.iter().map(|m| &m.known_by_gait);
            (*name, crate::open_set::pool_gait_counts(rows))
        })
        .filter(|(_, v)| v.len() >= 2)
        .collect();
    if pooled.is_empty() {
        return String::new();
    }
    let mut md = format!(
        "
Fresh known images called unknown, by the gait they touched down in (pooled over \
         the left-out classes and {}; each image counts once per model that judged it): \
         whether the rejection's cost gathers in one gait.\n\n| source | by gait |\n|---|---|\n",
        match spreads.first().map(|s| s.seeds.as_slice()) {
            Some([a, .., b]) => format!("seeds {a}-{b}"),
            Some([a]) => format!("seed {a}"),
            _ => String::new(),
        }
    );
    for (name, v) in pooled {
        let cells: Vec<String> = v
            .iter()
            .map(|c| {
                format!(
                    "{} {} ({}/{})",
                    node::gait_status::gait_name(c.gait),
                    pct(c.unknown as f64 / c.steps.max(1) as f64),
                    c.unknown,
                    c.steps
                )
            })
            .collect();
        let _ = writeln!(md, "| {name} | {} |", cells.join(", "));
    }
    md
}

/// The spread table: each source's means over seeds `first`-`last`, median (range), and the
/// seeds that miss a target of issue 25.
pub(super) fn open_set_spread(
    names: &[&str],
    spreads: &[crate::open_set::SeedSpread],
    first: u64,
    last: u64,
) -> String {
    use crate::open_set::Spread;
    let p = |s: Spread| format!("{} ({}-{})", pct(s.median), pct(s.min), pct(s.max));
    let mut md = format!(
        "\nOver seeds {first}-{last} (each seed draws another split and, for the simulated \
         sources, other runs): the median of each source's mean, its lowest and highest, and \
         the seeds that miss a target (left-out unknown below 80%, which the classes that pass \
         for each other miss on every seed; fresh known unknown above 3%; the rejection's cost, \
         the accuracy gap, above 2 points).\n\n\
         | source | AUROC | left-out unknown | fresh known unknown | of them another terrain | accuracy gap, points | seeds off target |\n\
         |---|---|---|---|---|---|---|\n"
    );
    for (name, s) in names.iter().zip(spreads) {
        let auroc = s.of(|m| m.auroc);
        let gap = s.of(|m| 100.0 * (m.known_accuracy_open - m.known_accuracy));
        let mut off = Vec::new();
        for (what, seeds) in [
            ("left-out", s.missing(|m| m.unknown_held_out < 0.8)),
            ("fresh", s.missing(|m| m.unknown_known > 0.03)),
            (
                "gap",
                s.missing(|m| m.known_accuracy_open - m.known_accuracy > 0.02),
            ),
        ] {
            if !seeds.is_empty() {
                let list: Vec<String> = seeds.iter().map(u64::to_string).collect();
                off.push(format!("{what}: {}", list.join(", ")));
            }
        }
        let _ = writeln!(
            md,
            "| {name} | {:.3} ({:.3}-{:.3}) | {} | {} | {} | {:.1} ({:.1}-{:.1}) | {} |",
            auroc.median,
            auroc.min,
            auroc.max,
            p(s.of(|m| m.unknown_held_out)),
            p(s.of(|m| m.unknown_known)),
            p(s.of(|m| m.unknown_known_misclassified)),
            gap.median,
            gap.min,
            gap.max,
            if off.is_empty() {
                "none".to_string()
            } else {
                off.join("; ")
            },
        );
    }
    let _ = write!(
        md,
        "\nThe same seeds' mean, with its 95% interval (Student's t over the seeds): the rate a \
         lab can expect over its runs, where the table above gives how far one run lands. A \
         run's count is small (one image of 150 is 0.7 points), so a single run can miss a \
         target that the expected rate meets; the last column names the targets that the mean \
         misses, and those whose interval reaches past them.\n\n\
         | source | left-out unknown | fresh known unknown | of them another terrain | accuracy gap, points | targets |\n\
         |---|---|---|---|---|---|\n"
    );
    for (name, s) in names.iter().zip(spreads) {
        let out = s.of(|m| m.unknown_held_out);
        let fresh = s.of(|m| m.unknown_known);
        let gap = s.of(|m| m.known_accuracy_open - m.known_accuracy);
        let mut verdict = Vec::new();
        for (what, missed, reaches) in [
            ("left-out", out.mean < 0.8, out.interval().0 < 0.8),
            ("fresh", fresh.mean > 0.03, fresh.interval().1 > 0.03),
            ("gap", gap.mean > 0.02, gap.interval().1 > 0.02),
        ] {
            if missed {
                verdict.push(format!("{what} missed"));
            } else if reaches {
                verdict.push(format!("{what} met, interval reaches past"));
            }
        }
        let _ = writeln!(
            md,
            "| {name} | {} | {} | {} | {} | {} |",
            ci(out, true),
            ci(fresh, true),
            ci(s.of(|m| m.unknown_known_misclassified), true),
            ci(gap, false),
            if verdict.is_empty() {
                "all met".to_string()
            } else {
                verdict.join("; ")
            },
        );
    }
    md.push_str(&open_set_judged(names, spreads));
    md
}

/// A mean over seeds and its 95% interval in percent (points when not a `share`): a share's
/// interval is clamped to 0-100%, which the t interval does not know.
pub(super) fn ci(s: crate::open_set::Spread, share: bool) -> String {
    let (mut lo, mut hi) = s.interval();
    if share {
        (lo, hi) = (lo.max(0.0), hi.min(1.0));
    }
    let unit = if share { "%" } else { "" };
    format!(
        "{:.1}{unit} ({:.1}-{:.1})",
        100.0 * s.mean,
        100.0 * lo,
        100.0 * hi
    )
}

/// The issue's targets where they apply: its AUROC and left-out targets hold "where the
/// classes are separable at all", so classes that no measured score separates are named and
/// left out of those two; the fresh run's unknowns are split into the images the model had
/// right (the rejection's cost: the accuracy gap) and those it had wrong. Empty without rows.
pub(super) fn open_set_judged(names: &[&str], spreads: &[crate::open_set::SeedSpread]) -> String {
    use crate::open_set::SEPARABLE_AUROC;
    if !spreads.iter().any(SeedSpread::has_rows) {
        return String::new();
    }
    let mut md = format!(
        "
The targets where they apply. The AUROC and left-out targets hold \"where the classes \
         are separable at all\": a left-out class counts as separable when a score measured \
         here separates it, our score's or the plain nearest neighbour's mean AUROC over the \
         seeds reaching {SEPARABLE_AUROC}. The classes neither reaches are named with both \
         (no distance in these features finds them) and left out of those two columns. Of a \
         fresh run's known images called unknown, those the model had right are the \
         rejection's cost (the accuracy gap, target 2 points): a robot sent to the safe gait on \
         ground it would have named; the rest it had wrong, and unknown sends them to the safe \
         gait instead of a wrong terrain's. Means over the seeds, 95% interval.\n\n\
         | source | not separable (AUROC ours / nearest neighbour) | AUROC, separable classes | left-out unknown, separable classes | fresh known unknown | of them it had right (the cost), points | targets |\n\
         |---|---|---|---|---|---|---|\n"
    );
    for (name, s) in names.iter().zip(spreads) {
        let hard = s.inseparable();
        let except: Vec<String> = hard.iter().map(|(n, _, _)| n.clone()).collect();
        let auroc = s.of_classes(&except, |r| r.auroc);
        let out = s.of_classes(&except, |r| r.unknown_held_out);
        let fresh = s.of(|m| m.unknown_known);
        let cost = s.of(|m| m.known_accuracy_open - m.known_accuracy);
        let mut verdict = Vec::new();
        for (what, missed, reaches) in [
            ("AUROC", auroc.mean < 0.9, auroc.interval().0 < 0.9),
            ("left-out", out.mean < 0.8, out.interval().0 < 0.8),
            ("cost", cost.mean > 0.02, cost.interval().1 > 0.02),
            ("fresh (all)", fresh.mean > 0.03, fresh.interval().1 > 0.03),
        ] {
            verdict.push(if missed {
                format!("{what} missed")
            } else if reaches {
                format!("{what} met (interval reaches past)")
            } else {
                format!("{what} met")
            });
        }
        let hard_s = if hard.is_empty() {
            "none".to_string()
        } else {
            hard.iter()
                .map(|(n, a, b)| format!("{n} ({a:.2} / {b:.2})"))
                .collect::<Vec<_>>()
                .join(", ")
        };
        let _ = writeln!(
            md,
            "| {name} | {hard_s} | {:.3} ({:.3}-{:.3}) | {} | {} | {} | {} |",
            auroc.mean,
            auroc.interval().0,
            auroc.interval().1.min(1.0),
            ci(out, true),
            ci(fresh, true),
            ci(cost, false),
            verdict.join("; "),
        );
    }
    md
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn the_spread_table_gives_median_and_range_and_the_seeds_off_target() {
        use crate::open_set::{SeedSpread, mean_row as row};
        let mut s = SeedSpread::default();
        s.push(4, row(0.02, 0.98));
        s.push(5, row(0.04, 0.96));
        s.push(6, row(0.01, 0.985));
        let md = open_set_spread(&["src"], &[s], 4, 6);
        assert!(md.contains("Over seeds 4-6"), "{md}");
        assert!(
            md.contains("| src | 0.990 (0.990-0.990) | 90.0% (90.0%-90.0%) | 2.0% (1.0%-4.0%) |"),
            "{md}"
        );
        assert!(md.contains("| fresh: 5; gap: 5 |"), "{md}");
        // Fresh 2.0, 4.0, 1.0: mean 2.33, sd 1.53, t(2) 4.303: 2.3 (-1.5-6.1), a share: from 0.
        assert!(
            md.contains("| src | 90.0% (90.0-90.0) | 2.3% (0.0-6.1) | 0.0% (0.0-0.0) |"),
            "{md}"
        );
        assert!(
            md.contains("| fresh met, interval reaches past; gap met, interval reaches past |"),
            "{md}"
        );
        let mut bad = SeedSpread::default();
        bad.push(1, row(0.05, 0.9));
        bad.push(2, row(0.05, 0.9));
        let md = open_set_spread(&["src"], &[bad], 1, 2);
        assert!(md.contains("| fresh missed; gap missed |"), "{md}");
    }

    #[test]
    fn the_separable_table_leaves_out_the_inseparable_class_and_names_each_target() {
        use crate::open_set::{SINGLE_OPTIONS, SeedSpread, mean_row};
        let row = |class: &str, auroc, nn_auroc, held| {
            let mut r = mean_row(0.02, 0.98);
            r.held_out = class.into();
            r.auroc = auroc;
            r.nn_auroc = nn_auroc;
            r.unknown_held_out = held;
            r
        };
        let (mut d, mut o) = (SeedSpread::default(), SeedSpread::default());
        for (seed, held) in [(1, 0.9), (2, 0.6)] {
            // "b" is found by no score: out of every column, however it scores.
            d.push_rows(
                seed,
                vec![row("a", 0.99, 0.9, held), row("b", 0.6, 0.5, 0.0)],
            );
            o.push_rows(
                seed,
                vec![row("a", 0.995, 0.9, 0.5), row("b", 0.99, 0.5, 1.0)],
            );
        }
        let c = SINGLE_OPTIONS[0];
        let md = open_set_options_separable(&["src"], &[d], &[vec![(c, o)]]);
        let want = format!(
            "| src | **0.990** | **75.0%** (75.0%, 60.0%) | seed 2: a 60.0% (``) | `{c}` | 0.995 | \
             50.0% | 0.900 | \
             AUROC >= best single: 0.005 short; AUROC >= nearest neighbour: met; \
             left-out >= 80%: 5.0% short; worst seed within 20 points: met (15.0) |"
        );
        assert!(md.contains(&want), "{md}");
        assert_eq!(
            open_set_options_separable(&["src"], &[SeedSpread::default()], &[vec![]]),
            ""
        );
    }

    #[test]
    fn the_gait_table_pools_seeds_and_skips_sources_of_one_gait() {
        use crate::open_set::{SeedSpread, mean_row as row};
        let g = |gait, steps, unknown| node::gait_status::GaitCount {
            gait: Some(gait),
            steps,
            unknown,
        };
        let (mut two, mut one) = (SeedSpread::default(), SeedSpread::default());
        for (seed, unknown) in [(3, 1), (4, 3)] {
            let mut r = row(0.02, 0.98);
            r.known_by_gait = vec![g(1, 50, unknown), g(3, 50, 0)];
            two.push(seed, r);
            let mut r = row(0.02, 0.98);
            r.known_by_gait = vec![g(2, 100, 1)];
            one.push(seed, r);
        }
        let md = open_set_by_gait(&["walk", "press"], &[two, one]);
        assert!(md.contains("seeds 3-4;"), "{md}");
        assert!(
            md.contains("| walk | G1 4.0% (4/100), G3 0.0% (0/100) |"),
            "{md}"
        );
        assert!(!md.contains("press"), "{md}");
        assert_eq!(open_set_by_gait(&["press"], &[SeedSpread::default()]), "");
    }
}
