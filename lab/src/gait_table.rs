//! Each gait on each ground, scored in the simulator ([`sim::gait_score`]), and the safe gait
//! chosen by measurement rather than assumed.
//!
//! The safe gait is where the controller goes on ground it does not know, so what it needs is
//! the widest margin, not the lowest speed. A gait's margin on a ground is the largest sudden
//! change of speed it survives either way ([`GaitScore::change_margin`]): a loss (a snag, a
//! patch that grips) or a gain (a push, a step down, where the ground's friction shows). The
//! safe gait is the one whose narrowest margin over the grounds
//! (its worst ground) is the widest of the gaits'. Ties within [`MARGIN_TIE`] go to the faster
//! gait. The table says too whether that gait's margin is at least every other gait's on every
//! ground, which is the stronger claim a lab may want to check before trusting it.

use controller::Gait;
use sim::gait_score::{DoesNotHop, GaitScore, ScoreOptions, score};
use sim::hopper::HopperParams;
use sim::terrain::Physics;

/// Margins closer than this (a fraction of speed) count as equal: the bisection's resolution
/// with [`ScoreOptions::default`] is 0.4% of speed.
pub const MARGIN_TIE: f64 = 0.005;

/// One gait on one ground.
#[derive(Clone, Debug)]
pub struct GaitRow {
    /// The ground's catalog name.
    pub terrain: String,
    /// The gait's id.
    pub gait: u8,
    /// Its figures, or why it could not keep hopping there.
    pub score: Result<GaitScore, DoesNotHop>,
}

/// The gait chosen for ground the controller does not know.
#[derive(Clone, Debug, PartialEq)]
pub struct SafeGait {
    /// The gait's id.
    pub gait: u8,
    /// Its narrowest margin over the grounds.
    pub narrowest_margin: f64,
    /// The ground where that margin is.
    pub narrowest_on: String,
    /// Its margin is at least every other gait's on every ground (within [`MARGIN_TIE`]).
    pub widest_everywhere: bool,
}

/// Every gait on every ground, and the safe gait.
#[derive(Clone, Debug)]
pub struct GaitTable {
    /// Gaits in the order given, grounds within each.
    pub rows: Vec<GaitRow>,
    /// None when no gait keeps hopping on every ground.
    pub safe: Option<SafeGait>,
}

/// The grounds `presrs lab gaits` scores without `--terrains`: the paper's dynamic set and
/// sand, the demo's new ground.
pub fn default_grounds() -> Vec<Physics> {
    let mut g = Physics::DYNAMIC.to_vec();
    g.push(Physics::Sand);
    g
}

/// Scores every gait on every ground.
pub fn measure(
    gaits: &[Gait],
    grounds: &[Physics],
    params: &HopperParams,
    opts: &ScoreOptions,
) -> GaitTable {
    let rows: Vec<GaitRow> = gaits
        .iter()
        .flat_map(|g| {
            grounds.iter().map(move |p| GaitRow {
                terrain: p.name().to_string(),
                gait: g.id,
                score: score(g, p.ground(), params, opts),
            })
        })
        .collect();
    let safe = safest(&rows);
    GaitTable { rows, safe }
}

/// A gait's margin on each ground, None where it does not hop.
fn margins(rows: &[GaitRow], gait: u8) -> Vec<(&str, Option<f64>)> {
    rows.iter()
        .filter(|r| r.gait == gait)
        .map(|r| {
            (
                r.terrain.as_str(),
                r.score.as_ref().ok().map(|s| s.change_margin()),
            )
        })
        .collect()
}

/// The gait whose narrowest margin is the widest (ties to the faster gait).
fn safest(rows: &[GaitRow]) -> Option<SafeGait> {
    let mut ids: Vec<u8> = rows.iter().map(|r| r.gait).collect();
    ids.dedup();
    let narrowest = |id: u8| -> Option<(f64, String, f64)> {
        let mut worst: Option<(f64, String)> = None;
        let mut speed = 0.0;
        for r in rows.iter().filter(|r| r.gait == id) {
            let s = r.score.as_ref().ok()?;
            speed += s.stride_speed_m_s;
            if worst.as_ref().is_none_or(|(m, _)| s.change_margin() < *m) {
                worst = Some((s.change_margin(), r.terrain.clone()));
            }
        }
        worst.map(|(m, t)| (m, t, speed))
    };
    let (gait, (margin, on, _)) = ids
        .iter()
        .filter_map(|&id| narrowest(id).map(|n| (id, n)))
        .reduce(|a, b| {
            let (ma, sa, mb, sb) = (a.1.0, a.1.2, b.1.0, b.1.2);
            if mb > ma + MARGIN_TIE || ((mb - ma).abs() <= MARGIN_TIE && sb > sa) {
                b
            } else {
                a
            }
        })?;
    let mine = margins(rows, gait);
    let widest_everywhere = ids.iter().filter(|&&id| id != gait).all(|&other| {
        margins(rows, other)
            .iter()
            .zip(&mine)
            .all(|((_, o), (_, m))| match (o, m) {
                (Some(o), Some(m)) => *m + MARGIN_TIE >= *o,
                (None, _) => true,
                (Some(_), None) => false,
            })
    });
    Some(SafeGait {
        gait,
        narrowest_margin: margin,
        narrowest_on: on,
        widest_everywhere,
    })
}

impl GaitTable {
    /// The table as Markdown, then the safe gait and why.
    pub fn markdown(&self) -> String {
        let mut md = String::from(
            "| ground | gait | stride speed (m/s) | cost of transport | energy ratio | stance (ms) | margin: speed loss survived | speed gain survived | grip needed |\n|---|---|---|---|---|---|---|---|---|\n",
        );
        for r in &self.rows {
            match &r.score {
                Ok(s) => md.push_str(&format!(
                    "| {} | G{} | {:.3} | {:.3} | {:.3} | {:.0} | {:.1}% | {:.1}% | {:.2} |\n",
                    r.terrain,
                    r.gait,
                    s.stride_speed_m_s,
                    s.cost_of_transport,
                    s.energy_ratio,
                    s.stance_s * 1e3,
                    s.margin * 100.0,
                    s.gain_margin * 100.0,
                    s.grip_needed
                )),
                Err(e) => md.push_str(&format!(
                    "| {} | G{} | {e} | | | | | | |\n",
                    r.terrain, r.gait
                )),
            }
        }
        md.push('\n');
        md.push_str(&self.safe_line());
        md.push('\n');
        md
    }

    /// What the safe gait is and why, in a line.
    pub fn safe_line(&self) -> String {
        match &self.safe {
            Some(s) => format!(
                "safe gait: G{} (its narrowest margin, {:.1}% on {}, is the widest of the gaits'; {})",
                s.gait,
                s.narrowest_margin * 100.0,
                s.narrowest_on,
                if s.widest_everywhere {
                    "its margin is at least every other gait's on every ground"
                } else {
                    "but another gait's margin is wider on some ground: see the table"
                }
            ),
            None => "safe gait: none (no gait keeps hopping on every ground)".into(),
        }
    }

    /// The table as JSON.
    pub fn to_json(&self) -> serde_json::Value {
        let rows: Vec<serde_json::Value> = self
            .rows
            .iter()
            .map(|r| match &r.score {
                Ok(s) => serde_json::json!({
                    "terrain": r.terrain, "gait": r.gait,
                    "stride_speed_m_s": s.stride_speed_m_s,
                    "cost_of_transport": s.cost_of_transport,
                    "energy_ratio": s.energy_ratio,
                    "stance_s": s.stance_s,
                    "margin": s.margin,
                    "gain_margin": s.gain_margin,
                    "grip_needed": s.grip_needed,
                }),
                Err(e) => serde_json::json!({"terrain": r.terrain, "gait": r.gait, "error": e.to_string()}),
            })
            .collect();
        serde_json::json!({
            "rows": rows,
            "safe_gait": self.safe.as_ref().map(|s| serde_json::json!({
                "gait": s.gait, "narrowest_margin": s.narrowest_margin,
                "narrowest_on": s.narrowest_on, "widest_everywhere": s.widest_everywhere,
            })),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(terrain: &str, gait: u8, margin: f64, speed: f64) -> GaitRow {
        GaitRow {
            terrain: terrain.into(),
            gait,
            score: Ok(GaitScore {
                stride_speed_m_s: speed,
                cost_of_transport: 0.05,
                energy_ratio: 1.0,
                stance_s: 0.17,
                margin,
                gain_margin: 0.5,
                grip_needed: 0.4,
            }),
        }
    }

    #[test]
    fn the_safe_gait_is_the_one_whose_worst_ground_is_best() {
        let rows = vec![
            row("wood", 1, 0.15, 0.4),
            row("clay", 1, 0.14, 0.4),
            row("wood", 3, 0.22, 0.9),
            row("clay", 3, 0.19, 0.9),
        ];
        let s = safest(&rows).unwrap();
        assert_eq!((s.gait, s.narrowest_on.as_str()), (3, "clay"));
        assert!(s.widest_everywhere);
        // A gait that does not hop somewhere is never the safe one.
        let mut rows = rows;
        rows[3].score = Err(DoesNotHop { gait: 3, hop: 4 });
        assert_eq!(safest(&rows).unwrap().gait, 1);
    }

    /// On the simulated hopper G3's margin is the widest on every ground the demo's robot knows
    /// and on sand, the demo's new ground; G1, the default config's safe gait (kept for the
    /// energy check, docs/decisions/safe-gait.md), the narrowest.
    #[test]
    fn g3_has_the_widest_margin_everywhere_and_g1_the_narrowest() {
        let t = measure(
            &Gait::paper_gaits(),
            &default_grounds(),
            &HopperParams::default(),
            &ScoreOptions::default(),
        );
        let safe = t.safe.clone().unwrap();
        assert_eq!(safe.gait, 3, "{}", t.markdown());
        assert!(safe.widest_everywhere, "{}", t.markdown());
        // Every gait hops everywhere, and G1 is the narrowest.
        assert!(t.rows.iter().all(|r| r.score.is_ok()), "{}", t.markdown());
        let g1 = t.rows.iter().filter(|r| r.gait == 1);
        assert!(
            g1.map(|r| r.score.as_ref().map_or(0.0, |s| s.change_margin()))
                .all(|m| m < safe.narrowest_margin),
            "{}",
            t.markdown()
        );
    }

    #[test]
    fn a_tie_goes_to_the_faster_gait_and_a_loss_somewhere_is_said() {
        let rows = vec![
            row("wood", 1, 0.300, 0.4),
            row("clay", 1, 0.150, 0.4),
            row("wood", 2, 0.200, 0.6),
            row("clay", 2, 0.152, 0.6),
        ];
        let s = safest(&rows).unwrap();
        assert_eq!(s.gait, 2);
        assert!(!s.widest_everywhere, "G1 is wider on wood");
    }
}
