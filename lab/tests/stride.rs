//! The controller's per-hop speed estimate (`controller::stride`) against the simulator's truth:
//! the hopper runs its own gait on each dynamic terrain, and the estimator hears only what a
//! controller hears on the bus (FootContact with its bounce, LegState at 100 Hz).

use controller::stride::{StrideEstimate, StrideEstimator};
use protocol::TerrainCatalog;
use protocol::emit::Emit;
use protocol::messages::{Message, decode};
use protocol::{CanFrame, IdConfig};
use sim::runner::{SimConfig, SimRobot, Track};

/// The bus as a list.
struct Frames(Vec<CanFrame>);
impl Emit<CanFrame> for Frames {
    fn emit(&mut self, f: CanFrame) {
        self.0.push(f);
    }
}

/// Each stride's (estimate, true speed) over `seconds` of gait `gait` on `terrain`.
fn strides(terrain: &str, gait: u8, payload_kg: f64, seconds: f64) -> Vec<(StrideEstimate, f64)> {
    let text = format!("diameter_m = 2.8\n[[segments]]\nterrain = \"{terrain}\"\nlength_m = 9.0\n");
    let track = Track::from_toml(&text, "stride.toml", &TerrainCatalog::paper()).unwrap();
    let cfg = SimConfig {
        track,
        gait,
        payload_kg,
        ..SimConfig::default()
    };
    let ids = IdConfig::default();
    let mut robot = SimRobot::new(cfg, 1);
    let mut e = StrideEstimator::default();
    // The controller's debounce: an edge within the lockout of the last is a bounce.
    let lockout_us = controller::ControllerConfig::default().lockout_us;
    let (mut stance, mut last_edge) = (false, None::<u64>);
    let mut out = Vec::new();
    let mut t = 0u64;
    while (t as f64) < seconds * 1e6 {
        t += 1_000;
        let mut frames = Frames(Vec::new());
        robot.advance_to(t, &mut frames);
        for f in &frames.0 {
            match decode(f, &ids) {
                // The leg's 100 Hz reports only: a real leg does not report at the foot's edges.
                Ok(Some((0, Message::LegState(ls)))) if ls.timestamp_us % 10_000 == 0 => {
                    e.on_leg_state(ls.timestamp_us as u64, ls.leg_angle_rad, ls.leg_length_m)
                }
                Ok(Some((0, Message::FootContact(fc)))) if fc.stance != stance => {
                    let at = fc.timestamp_us as u64;
                    if last_edge.is_some_and(|l| at.saturating_sub(l) < lockout_us) {
                        continue;
                    }
                    (stance, last_edge) = (fc.stance, Some(at));
                    if fc.stance {
                        if let Some(s) = e.on_touchdown(at) {
                            // The truth of the stride that began at its touchdown: the body's
                            // travel to this touchdown over the interval (`StepTruth`).
                            if let Some(truth) = robot
                                .steps
                                .iter()
                                .find(|st| st.touchdown_us >= at.saturating_sub(2_000))
                            {
                                out.push((s, truth.speed_m_s));
                            }
                        }
                    } else {
                        e.on_liftoff(at);
                    }
                }
                _ => {}
            }
        }
    }
    assert!(robot.falls.is_empty(), "{terrain} G{gait}: fell");
    out
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Median absolute error within 5% of the true speed per gait and terrain (the first two strides
/// left out: the launch is not a gait's hop). The seed moves only the skin's noise and the
/// switch's bounce, not the hop; a payload felled the simulator's own G1 (no controller), so
/// the hopper is the default one.
#[test]
fn the_speed_estimate_is_within_five_percent_per_gait_and_terrain() {
    let mut report = Vec::new();
    for terrain in ["wood", "carpet", "clay", "grass"] {
        for gait in 1..=3u8 {
            let payload = 0.0;
            let s = strides(terrain, gait, payload, 12.0);
            assert!(
                s.len() >= 20,
                "{terrain} G{gait} +{payload} kg: {} strides",
                s.len()
            );
            let rel: Vec<f64> = s[2..]
                .iter()
                .map(|(e, v)| ((e.speed_m_s - v) / v).abs())
                .collect();
            let m = median(rel);
            // Flight keeps the body's energy: in a steady gait each stance gives back what it
            // took, so the hop's energy ratio is 1: its median within 0.02, each hop within
            // what the edge fits can tell (the liftoff's place between two 100 Hz reports).
            let ratios: Vec<f64> = s[2..].iter().map(|(e, _)| e.energy_ratio).collect();
            let energy = median(ratios.clone());
            let spread = median(ratios.iter().map(|r| (r - 1.0).abs()).collect());
            report.push(format!(
                "{terrain} G{gait} +{payload} kg: speed {:.2}%, energy ratio median {energy:.3}, each hop off 1 by {spread:.3} (median)",
                100.0 * m,
            ));
            assert!(
                m <= 0.05 && (energy - 1.0).abs() <= 0.02 && spread <= 0.05,
                "{}",
                report.join("\n")
            );
        }
    }
    eprintln!("{}", report.join("\n"));
}

/// Drops what the controller says: it listens here, the hopper runs its own laws.
struct Quiet;
impl Emit<Message> for Quiet {
    fn emit(&mut self, _: Message) {}
}

/// The controller itself measures each hop as the estimator alone does: from the bus, its
/// edges debounced and its clock its own.
#[test]
fn the_controller_reports_each_hop_within_five_percent() {
    let catalog = TerrainCatalog::paper();
    for gait in 1..=3u8 {
        let text = "diameter_m = 2.8\n[[segments]]\nterrain = \"grass\"\nlength_m = 9.0\n";
        let track = Track::from_toml(text, "stride.toml", &catalog).unwrap();
        let mut robot = SimRobot::new(
            SimConfig {
                track,
                gait,
                ..SimConfig::default()
            },
            1,
        );
        let mut c = controller::Controller::new(controller::ControllerConfig::default(), &catalog);
        let ids = IdConfig::default();
        let (mut seen, mut rel) = (None, Vec::new());
        let mut t = 0u64;
        while t < 12_000_000 {
            t += 1_000;
            let mut frames = Frames(Vec::new());
            robot.advance_to(t, &mut frames);
            for f in &frames.0 {
                if let Ok(Some((foot, m))) = decode(f, &ids) {
                    if matches!(m, Message::LegState(ls) if ls.timestamp_us % 10_000 != 0) {
                        continue;
                    }
                    c.on_message(foot, &m, t, &mut Quiet);
                }
            }
            c.tick(t, &mut Quiet);
            if let Some(s) = c.last_stride().filter(|s| Some(s.touchdown_us) != seen) {
                seen = Some(s.touchdown_us);
                let truth = robot.steps.last().map(|st| st.speed_m_s).unwrap_or(0.0);
                rel.push(((s.speed_m_s - truth) / truth).abs());
            }
        }
        assert!(rel.len() >= 20, "G{gait}: {} strides", rel.len());
        let m = median(rel.split_off(2));
        assert!(m <= 0.05, "G{gait}: median error {:.2}%", 100.0 * m);
    }
}

/// A recorded run of `gait` on `terrain`: the simulator's frames on the log's clock, with a
/// GaitStatus at the start and, as a node would send it, a TerrainClass after each touchdown
/// (the simulator's labels: the table is judged here, not the classifier). With the true
/// speed of each stride.
fn recorded_run(terrain: &str, gait: u8, seconds: f64) -> (Vec<protocol::Stamped>, Vec<f64>) {
    use protocol::messages::{GaitStatus, TerrainClass};
    let catalog = TerrainCatalog::paper();
    let text = format!("diameter_m = 2.8\n[[segments]]\nterrain = \"{terrain}\"\nlength_m = 9.0\n");
    let track = Track::from_toml(&text, "stride.toml", &catalog).unwrap();
    let id = catalog.by_name(terrain).unwrap().id();
    let mut robot = SimRobot::new(
        SimConfig {
            track,
            gait,
            ..SimConfig::default()
        },
        1,
    );
    let ids = IdConfig::default();
    let frame = |m: Message| m.to_frame(&ids, 0).unwrap();
    let gs = GaitStatus {
        gait,
        terrain: id,
        ..GaitStatus::default()
    };
    let mut log = vec![protocol::Stamped {
        t_us: 0,
        frame: frame(Message::GaitStatus(gs)),
    }];
    let mut said = 0;
    let mut t = 0u64;
    while (t as f64) < seconds * 1e6 {
        t += 1_000;
        let mut frames = Frames(Vec::new());
        robot.advance_to(t, &mut frames);
        log.extend(
            frames
                .0
                .into_iter()
                .map(|frame| protocol::Stamped { t_us: t, frame }),
        );
        while let Some(st) = robot
            .steps
            .get(said)
            .filter(|st| st.touchdown_us + 70_000 <= t)
        {
            let tc = TerrainClass {
                step: said as u16,
                terrain: id,
                ..TerrainClass::default()
            };
            log.push(protocol::Stamped {
                t_us: t,
                frame: frame(Message::TerrainClass(tc)),
            });
            let _ = st;
            said += 1;
        }
    }
    let truth = robot.steps.iter().skip(1).map(|s| s.speed_m_s).collect();
    (log, truth)
}

/// The adaptation table from recorded runs alone (`presrs lab adaptation`): each cell's median
/// within 5% of the simulator's true median speed, and the gaits on each terrain in the order
/// the truth puts them.
#[test]
fn the_adaptation_table_from_a_recording_orders_the_gaits_as_the_truth_does() {
    let catalog = TerrainCatalog::paper();
    let ids = IdConfig::default();
    for terrain in ["wood", "grass", "clay"] {
        let id = catalog.by_name(terrain).unwrap().id();
        let mut measured = Vec::new();
        for gait in 1..=3u8 {
            let (log, truth) = recorded_run(terrain, gait, 14.0);
            let strides = tools::adaptation::strides(log, &ids, &catalog);
            let cells = tools::adaptation::table(&strides);
            let cell = cells
                .get(&(id, gait))
                .copied()
                .unwrap_or_else(|| panic!("{terrain} G{gait}: {cells:?}"));
            assert!(cell.strides >= 20, "{terrain} G{gait}: {cell:?}");
            let true_median = median(truth[tools::adaptation::SETTLE_STRIDES..].to_vec());
            let err = (cell.median_m_s - true_median).abs() / true_median;
            assert!(
                err <= 0.05,
                "{terrain} G{gait}: {cell:?} against {true_median:.3} m/s"
            );
            measured.push((gait, cell.median_m_s, true_median));
            if gait == 3 {
                let md = tools::adaptation::markdown(&cells, &catalog);
                assert!(md.contains(&format!("| {terrain} |")), "{md}");
            }
        }
        let order = |key: fn(&(u8, f64, f64)) -> f64| {
            let mut v = measured.clone();
            v.sort_by(|a, b| key(a).total_cmp(&key(b)));
            v.iter().map(|m| m.0).collect::<Vec<u8>>()
        };
        assert_eq!(order(|m| m.1), order(|m| m.2), "{terrain}: {measured:?}");
        eprintln!("{terrain}: {measured:.3?}");
    }
}
