//! The state machine's tests: gait switching, takeover, the watchdogs, the touchdown law.

use super::*;
use crate::config::tests::fresh;
use protocol::messages::{FootContact, NodeStatus, TerrainClass};

fn tc(terrain: u8, conf: f64) -> Message {
    Message::TerrainClass(TerrainClass {
        terrain,
        confidence_pct: conf,
        ..Default::default()
    })
}

/// A switch edge stamped `foot_us` by the foot.
fn contact(stance: bool, foot_us: u64) -> Message {
    Message::FootContact(FootContact {
        stance,
        seq: 0,
        timestamp_us: foot_us as u32,
    })
}

#[test]
fn switches_in_flight_after_two_confident_steps() {
    let mut c = Controller::new(fresh(), &TerrainCatalog::paper());
    let mut out = Vec::new();
    let mut t = 0;
    let hb = Message::NodeStatus(NodeStatus::default());
    let wood = protocol::Terrain::WOOD.id();
    for step in 0..3 {
        t += 100_000;
        let before = c.gait().id;
        c.on_message(0, &hb, t, &mut out);
        c.on_message(0, &contact(true, t), t, &mut out);
        c.on_message(0, &tc(wood, 90.0), t + 70_000, &mut out);
        // in stance: no switch yet, whatever the count
        assert_eq!(c.gait().id, before, "step {step}: switched in stance");
        c.on_message(0, &contact(false, t + 140_000), t + 140_000, &mut out);
        t += 140_000;
        let expect = if step >= 1 { 3 } else { 2 };
        assert_eq!(c.gait().id, expect, "after step {step}");
    }
    assert_eq!(c.switches, 1);
    assert_eq!(c.reason(), GaitReason::Terrain);
    // A low-confidence step neither counts nor resets the gait.
    c.on_message(0, &tc(protocol::Terrain::CLAY.id(), 10.0), t, &mut out);
    assert_eq!(c.gait().id, 3);
}

/// Unknown is confirmed like a terrain (two in a row put the safe gait), and one
/// unknown step in a terrain's run neither switches nor restarts that terrain's count.
#[test]
fn an_unknown_step_is_confirmed_before_the_safe_gait() {
    // A safe gait other than wood's G3, so that the switch to it shows.
    let cfg = ControllerConfig {
        safe_gait: 1,
        ..fresh()
    };
    let mut c = Controller::new(cfg, &TerrainCatalog::paper());
    let mut out = Vec::new();
    let hb = Message::NodeStatus(NodeStatus::default());
    let wood = protocol::Terrain::WOOD.id();
    let unknown = protocol::messages::TERRAIN_UNKNOWN;
    let mut t = 0;
    let mut step = |c: &mut Controller, terrain: u8| {
        t += 240_000;
        c.on_message(0, &hb, t, &mut out);
        c.on_message(0, &contact(true, t), t, &mut out);
        c.on_message(0, &tc(terrain, 90.0), t + 70_000, &mut out);
        c.on_message(0, &contact(false, t + 140_000), t + 140_000, &mut out);
        c.gait().id
    };
    // wood, unknown, wood: wood's second step switches to G3 (the unknown between is not
    // new ground); then one unknown keeps G3, the second in a row gives the safe G1.
    assert_eq!(step(&mut c, wood), 2);
    assert_eq!(step(&mut c, unknown), 2);
    assert_eq!(step(&mut c, wood), 3);
    assert_eq!(step(&mut c, unknown), 3);
    assert_eq!(step(&mut c, unknown), 1);
    assert_eq!(c.reason(), GaitReason::Unknown);
    assert_eq!(step(&mut c, wood), 1);
    assert_eq!(step(&mut c, wood), 3);
}

#[test]
fn after_a_switch_eq5_aims_at_the_new_beta_des_in_steps() {
    let mut c = Controller::new(fresh(), &TerrainCatalog::paper());
    let mut out = Vec::new();
    let hb = Message::NodeStatus(NodeStatus::default());
    let wood = protocol::Terrain::WOOD.id();
    let ls = |angle: f64, foot_us: u64| {
        Message::LegState(protocol::messages::LegState {
            leg_angle_rad: angle,
            leg_length_m: 0.14,
            timestamp_us: foot_us as u32,
        })
    };
    let mut aims = Vec::new();
    let mut t = 0;
    for _ in 0..6 {
        t += 200_000;
        c.on_message(0, &hb, t, &mut out);
        c.on_message(0, &contact(true, t), t, &mut out);
        c.on_message(0, &tc(wood, 90.0), t + 70_000, &mut out);
        // A symmetric stance about the angle aimed at.
        c.on_message(0, &ls(-c.beta_des, t + 150_000), t + 150_000, &mut out);
        c.on_message(0, &contact(false, t + 150_000), t + 150_000, &mut out);
        aims.push((c.gait().id, (c.beta_des * 100.0).round() / 100.0));
    }
    // G2 (0.42) until the second wood step's liftoff, then G3 (0.57) in 0.05 rad steps.
    assert_eq!(
        aims,
        [
            (2, 0.42),
            (3, 0.42),
            (3, 0.47),
            (3, 0.52),
            (3, 0.57),
            (3, 0.57)
        ]
    );
}

#[test]
fn a_lab_terrain_from_the_catalog_gets_its_gait() {
    let cat = TerrainCatalog::from_toml("[[terrain]]\nid = 20\nname = \"asphalt\"\n", "t").unwrap();
    let mut cfg = fresh();
    cfg.terrain_gaits.insert("asphalt".into(), 3);
    let e = cfg.validate(&TerrainCatalog::paper()).unwrap_err();
    assert_eq!(e.key, "terrain_gaits.asphalt");
    assert!(e.message.contains("terrains file"), "{e}");
    cfg.validate(&cat).unwrap();
    let mut c = Controller::new(cfg, &cat);
    let mut out = Vec::new();
    let hb = Message::NodeStatus(NodeStatus::default());
    let mut t = 0;
    for _ in 0..2 {
        t += 100_000;
        c.on_message(0, &hb, t, &mut out);
        c.on_message(0, &contact(true, t), t, &mut out);
        c.on_message(0, &tc(20, 90.0), t + 70_000, &mut out);
        t += 140_000;
        c.on_message(0, &contact(false, t), t, &mut out);
    }
    assert_eq!(c.gait().id, 3);
    assert_eq!(c.reason(), GaitReason::Terrain);
}

/// A controller started in mid-hop listens to one step, then runs the gait whose
/// eq. (5) explains it, from the angle the leg came down at; another controller's
/// GaitStatus names the gait outright; nothing heard in `takeover_ms` is a fresh start.
#[test]
fn a_controller_started_in_mid_hop_takes_over_the_gait_the_leg_runs() {
    let leg = |angle: f64, t: u64| {
        Message::LegState(protocol::messages::LegState {
            leg_angle_rad: angle,
            leg_length_m: 0.9,
            timestamp_us: t as u32,
        })
    };
    // G3's leg: touchdown at 0.49, liftoff at 0.51 (law sign); eq. (5) with G3's
    // beta_des 0.57 and c 0.2 sends it down next at 0.51 + 0.2 (0.49 - 0.57) = 0.494.
    let g3 = Gait::g3();
    let next = laws::next_touchdown_angle(0.51, 0.49, g3.c, g3.beta_des);
    let hop = |c: &mut Controller, out: &mut Vec<Message>| {
        // (message or a tick, time): heard in mid-stance, the phase, then the liftoff (not
        // ours: nothing learned); then one whole step: touchdown, bounce, liftoff; then
        // the next touchdown.
        let events = [
            (Some(contact(true, 10_000)), 10_000),
            (Some(leg(-0.5, 60_000)), 60_000),
            (Some(contact(false, 60_000)), 60_000),
            (Some(leg(0.49, 300_000)), 300_000),
            (Some(contact(true, 300_000)), 300_000),
            (Some(contact(false, 300_400)), 300_400),
            (Some(contact(true, 300_800)), 300_800),
            (None, 350_000),
            (Some(leg(-0.51, 440_000)), 440_000),
            (Some(contact(false, 440_000)), 440_000),
            (Some(Message::NodeStatus(NodeStatus::default())), 600_000),
            (None, 600_000),
            (Some(leg(next, 680_000)), 680_000),
            (Some(contact(true, 680_000)), 680_000),
            (None, 681_000),
        ];
        for (m, t) in events {
            match m {
                Some(m) => c.on_message(0, &m, t, out),
                None => c.tick(t, out),
            }
        }
    };
    let cat = TerrainCatalog::paper();
    let mut c = Controller::new(ControllerConfig::default(), &cat);
    let mut out = Vec::new();
    c.tick(0, &mut out);
    hop(&mut c, &mut out);
    let t = c.takeover.expect("took over at the second touchdown");
    assert_eq!((t.gait, t.gait_from), (3, "touchdown law"), "{t:?}");
    assert_eq!(t.at_us, 680_000);
    assert!((t.beta_des_rad - g3.beta_des).abs() < 1e-9);
    // Silent until then; then the gait and a stance command for G3.
    let first = out
        .iter()
        .position(|m| !matches!(m, Message::GaitStatus(_)))
        .expect("commands after the takeover");
    assert!(
        matches!(out[first - 1], Message::GaitStatus(g) if g.gait == 3),
        "{out:?}"
    );
    assert!(
        matches!(out[first], Message::LegCommand(l) if l.gait == 3 && l.phase == Phase::Stance)
    );
    assert!(
        out.iter()
            .all(|m| !matches!(m, Message::GaitStatus(g) if g.gait != 3)),
        "{out:?}"
    );

    // Another controller's GaitStatus names the gait, whatever the step says.
    let mut c = Controller::new(ControllerConfig::default(), &cat);
    let mut out = Vec::new();
    let other = GaitStatus {
        gait: 1,
        terrain: protocol::Terrain::CLAY.id(),
        omega_rad_s: 6.0,
        beta_des_rad: 0.27,
        reason: GaitReason::Terrain,
        foot: 0,
    };
    c.on_message(0, &Message::GaitStatus(other), 0, &mut out);
    hop(&mut c, &mut out);
    let t = c.takeover.expect("took over");
    assert_eq!((t.gait, t.gait_from), (1, "gait status"));
    assert_eq!(c.reason(), GaitReason::Terrain);

    // No leg heard: a fresh start after takeover_ms, in the initial gait.
    let mut c = Controller::new(ControllerConfig::default(), &cat);
    let mut out = Vec::new();
    c.tick(0, &mut out);
    c.tick(1_999_000, &mut out);
    assert!(out.is_empty() && c.takeover.is_none());
    c.tick(2_000_000, &mut out);
    let t = c.takeover.expect("fresh start");
    assert_eq!(
        (t.gait, t.gait_from, t.touchdown_angle_rad),
        (2, "initial", None)
    );
    assert!(out.iter().any(|m| matches!(m, Message::LegCommand(l)
        if (l.touchdown_angle_rad - Gait::g2().beta_des).abs() < 1e-9)));
}

/// After a gap in a regular LegState stream the controller has lost the leg: it stops
/// commanding and takes it over again as at a start.
#[test]
fn a_gap_in_the_legs_reports_makes_the_controller_listen_again() {
    let mut c = Controller::new(ControllerConfig::default(), &TerrainCatalog::paper());
    let mut out = Vec::new();
    c.tick(0, &mut out);
    c.tick(2_000_000, &mut out);
    assert!(c.takeover.is_some(), "fresh start after takeover_ms");
    let ls = |t: u64| {
        Message::LegState(protocol::messages::LegState {
            leg_angle_rad: 0.3,
            leg_length_m: 0.9,
            timestamp_us: t as u32,
        })
    };
    for t in (2_000_000..2_100_000).step_by(10_000) {
        c.on_message(0, &ls(t), t, &mut out);
    }
    c.tick(2_100_000, &mut out);
    assert_eq!(c.leg_gaps, 0);
    // 300 ms of reports lost.
    c.on_message(0, &ls(2_400_000), 2_400_000, &mut out);
    assert_eq!(c.leg_gaps, 1);
    out.clear();
    c.tick(2_401_000, &mut out);
    c.tick(2_500_000, &mut out);
    assert!(out.is_empty(), "commanded a leg it lost track of: {out:?}");
}

/// A leg of motors (it says its mode in LegStatus) stops when commands stop: after a gap
/// in its reports (its bridge stalled) the controller commands on, and the foot's reports,
/// all heard, keep the phase.
#[test]
fn a_gap_in_a_motor_legs_reports_keeps_the_commands_coming() {
    let mut c = Controller::new(ControllerConfig::default(), &TerrainCatalog::paper());
    let mut out = Vec::new();
    c.tick(0, &mut out);
    c.tick(2_000_000, &mut out);
    let status = Message::LegStatus(protocol::messages::LegStatus {
        mode: protocol::messages::LegMode::Running,
        joint: 0,
        command_age_ms: 2,
        fault_code: 0,
    });
    c.on_message(0, &status, 2_000_000, &mut out);
    let ls = |t: u64| {
        Message::LegState(protocol::messages::LegState {
            leg_angle_rad: 0.3,
            leg_length_m: 0.9,
            timestamp_us: t as u32,
        })
    };
    let seq = std::cell::Cell::new(0u8);
    let fc = |stance: bool, t: u64| {
        seq.set(seq.get().wrapping_add(1));
        Message::FootContact(FootContact {
            stance,
            seq: seq.get(),
            timestamp_us: t as u32,
        })
    };
    for t in (2_000_000..2_100_000).step_by(10_000) {
        c.on_message(0, &ls(t), t, &mut out);
        c.on_message(0, &fc(false, t), t, &mut out);
    }
    c.on_message(0, &fc(true, 2_100_000), 2_100_000, &mut out);
    // The bridge silent for 300 ms; the foot's reports keep coming.
    for t in (2_110_000..2_400_000).step_by(10_000) {
        c.on_message(0, &fc(true, t), t, &mut out);
    }
    c.on_message(0, &ls(2_400_000), 2_400_000, &mut out);
    assert_eq!(c.leg_gaps, 1);
    // The phase of the first LegCommand at `t`.
    let mut phase_at = |c: &mut Controller, t: u64| {
        out.clear();
        c.tick(t, &mut out);
        match out.as_slice() {
            [Message::LegCommand(l), ..] => Some(l.phase),
            _ => None,
        }
    };
    assert_eq!(phase_at(&mut c, 2_401_000), Some(Phase::Stance));
    // The foot's reports lost for `lost` µs (`skipped` of them), a liftoff before and a
    // touchdown after.
    let lose = |c: &mut Controller, from: u64, lost: u64, skipped: u8| {
        let mut sink = |_| {};
        c.on_message(0, &fc(false, from), from, &mut sink);
        seq.set(seq.get().wrapping_add(skipped));
        c.on_message(0, &fc(true, from + lost), from + lost, &mut sink);
    };
    // 100 ms lost (longer than a stance): the phase is not known, and the stance the next
    // report says is left to the leg.
    lose(&mut c, 2_410_000, 100_000, 9);
    assert_eq!(phase_at(&mut c, 2_520_000), Some(Phase::Flight));
    // 20 ms lost (shorter than any stance): one edge at most, taken at the next report.
    lose(&mut c, 2_700_000, 20_000, 1);
    assert_eq!(phase_at(&mut c, 2_730_000), Some(Phase::Stance));
}

/// A controller started beside a leg of motors that nobody commands (its bridge waits for
/// a first command or holds its damped stop) takes the leg at once; beside one that runs
/// another controller's commands it listens as always.
#[test]
fn a_restarted_controller_commands_a_leg_of_motors_nobody_commands_at_once() {
    let status = |mode| {
        Message::LegStatus(protocol::messages::LegStatus {
            mode,
            joint: 0,
            command_age_ms: 60,
            fault_code: 0,
        })
    };
    let commands = |out: &[Message]| {
        out.iter()
            .filter(|m| matches!(m, Message::LegCommand(_)))
            .count()
    };
    for (mode, at_once) in [
        (LegMode::CommandTimeout, true),
        (LegMode::Waiting, true),
        (LegMode::Running, false),
        (LegMode::DriverFault, false),
    ] {
        let mut c = Controller::new(ControllerConfig::default(), &TerrainCatalog::paper());
        let mut out = Vec::new();
        c.tick(0, &mut out);
        c.on_message(0, &status(mode), 100_000, &mut out);
        c.tick(101_000, &mut out);
        assert_eq!(commands(&out) > 0, at_once, "{mode:?}: {out:?}");
        let t = c.takeover;
        assert_eq!(
            t.map(|t| (t.at_us, t.gait_from)),
            at_once.then_some((100_000, "initial"))
        );
        // Another foot's bridge says nothing of ours.
        let mut c = Controller::new(ControllerConfig::default(), &TerrainCatalog::paper());
        out.clear();
        c.on_message(1, &status(mode), 100_000, &mut out);
        c.tick(101_000, &mut out);
        assert_eq!(commands(&out), 0, "{mode:?} of foot 1: {out:?}");
    }
}

#[test]
fn a_heartbeat_gap_while_our_bus_was_down_is_not_a_lost_node() {
    let mut c = Controller::new(fresh(), &TerrainCatalog::paper());
    let mut out = Vec::new();
    let hb = Message::NodeStatus(NodeStatus::default());
    c.on_message(0, &hb, 100_000, &mut out);
    c.tick(200_000, &mut out);
    // Our interface was down from 0.2 s to 2.2 s; reopened, the node has a timeout again.
    c.on_bus_open(2_200_000);
    c.tick(2_250_000, &mut out);
    assert_eq!(c.reason(), GaitReason::Initial);
    c.on_message(0, &hb, 2_270_000, &mut out);
    c.tick(2_600_000, &mut out);
    assert_eq!(c.reason(), GaitReason::Initial);
    // Silent for the timeout after the reopen: lost.
    c.tick(2_771_000, &mut out);
    assert_eq!(c.reason(), GaitReason::NodeLost);
}

#[test]
fn lost_heartbeat_goes_to_the_safe_gait() {
    let mut c = Controller::new(fresh(), &TerrainCatalog::paper());
    let mut out = Vec::new();
    c.on_message(0, &Message::NodeStatus(NodeStatus::default()), 0, &mut out);
    c.tick(400_000, &mut out);
    assert_eq!(c.gait().id, 2);
    c.tick(501_000, &mut out);
    assert_eq!(
        (c.gait().id, c.reason()),
        (fresh().safe_gait, GaitReason::NodeLost)
    );
    assert_ne!(
        fresh().safe_gait,
        2,
        "the initial gait: no switch would show"
    );
    assert!(
        out.iter()
            .any(|m| matches!(m, Message::GaitStatus(g) if g.reason == GaitReason::NodeLost))
    );
}

#[test]
fn stance_commands_follow_eq4_and_bounce_is_ignored() {
    let mut c = Controller::new(fresh(), &TerrainCatalog::paper());
    let mut out = Vec::new();
    c.on_message(0, &contact(true, 1_000_000), 1_000_000, &mut out);
    c.on_message(0, &contact(false, 1_000_400), 1_000_400, &mut out); // bounce
    // The foot's 100 Hz report keeps its clock fresh.
    c.on_message(0, &contact(true, 1_060_000), 1_060_000, &mut out);
    out.clear();
    c.tick(1_070_000, &mut out);
    let g = c.gait().clone();
    let want = laws::aer_leg_length(0.07, g.zeta0, g.zeta_dev, g.omega, g.phi);
    let cmd = out.iter().find_map(|m| match m {
        Message::LegCommand(lc) => Some(*lc),
        _ => None,
    });
    let cmd = cmd.unwrap_or_default();
    assert_eq!(cmd.phase, Phase::Stance);
    assert!((cmd.leg_length_m - want).abs() < 1e-9);
}

#[test]
fn late_edges_in_a_burst_are_judged_by_the_foots_clock() {
    // No node on this bus: a long heartbeat timeout keeps the gait.
    let cfg = ControllerConfig {
        heartbeat_timeout_ms: 60_000,
        ..fresh()
    };
    let mut c = Controller::new(cfg, &TerrainCatalog::paper());
    let mut out = Vec::new();
    // A touchdown at foot time 5.000 s and its liftoff at 5.150 s, both arriving 2 ms
    // apart at our 9.000 s (the leg's frames were held up): not a bounce.
    c.on_message(0, &contact(true, 5_000_000), 9_000_000, &mut out);
    c.on_message(0, &contact(false, 5_150_000), 9_002_000, &mut out);
    assert!(!c.stance, "the liftoff was taken for bounce");
    // The next touchdown at foot time 5.400 s arrives at our 9.001 s (the clocks differ);
    // 70 ms later on our clock the stance law is at 70 ms of the foot's stance.
    c.on_message(0, &contact(true, 5_400_000), 9_001_000, &mut out);
    // The foot reports at its time 5.460 s, arriving at our 9.061 s; at our 9.071 s the
    // stance law is at 70 ms of the foot's stance.
    c.on_message(0, &contact(true, 5_460_000), 9_061_000, &mut out);
    // A LegState on the leg's own clock (another device's, seconds apart) moves nothing.
    let ls = Message::LegState(protocol::messages::LegState {
        leg_angle_rad: 0.4,
        leg_length_m: 0.14,
        timestamp_us: 1_000_000,
    });
    c.on_message(0, &ls, 9_062_000, &mut out);
    let stance_len = |c: &mut Controller, now: u64| {
        let mut out = Vec::new();
        c.next_cmd_us = 0;
        c.tick(now, &mut out);
        out.iter()
            .find_map(|m| match m {
                Message::LegCommand(lc) if lc.phase == Phase::Stance => Some(lc.leg_length_m),
                _ => None,
            })
            .unwrap_or(f64::NAN)
    };
    let g = c.gait().clone();
    let law = |t: f64| laws::aer_leg_length(t, g.zeta0, g.zeta_dev, g.omega, g.phi);
    assert!((stance_len(&mut c, 9_071_000) - law(0.07)).abs() < 1e-9);
    // The foot's reports stop: the stance law holds 20 ms past the last one (80 ms), not
    // 200 ms on.
    assert!((stance_len(&mut c, 9_261_000) - law(0.08)).abs() < 1e-9);
    // The foot's 32-bit clock wraps: an edge just after the wrap is still 100 ms later.
    let mut c = Controller::new(fresh(), &TerrainCatalog::paper());
    let before = u32::MAX as u64 - 50_000;
    c.on_message(0, &contact(true, before), 0, &mut out);
    c.on_message(0, &contact(false, before + 100_000), 100_000, &mut out);
    assert!(!c.stance, "an edge after the wrap was taken for bounce");
}

#[test]
fn a_fall_restarts_the_touchdown_law_from_beta_des() {
    let mut c = Controller::new(fresh(), &TerrainCatalog::paper());
    let mut out = Vec::new();
    let ls = |angle: f64, foot_us: u32| {
        Message::LegState(protocol::messages::LegState {
            leg_angle_rad: angle,
            leg_length_m: 0.14,
            timestamp_us: foot_us,
        })
    };
    let b = c.gait().beta_des;
    // A normal step: liftoff 0.05 rad past beta_des, eq. (5) applies.
    c.on_message(0, &ls(b, 1_000_000), 1_000_000, &mut out);
    c.on_message(0, &contact(true, 1_000_000), 1_000_000, &mut out);
    c.on_message(0, &ls(-(b + 0.05), 1_150_000), 1_150_000, &mut out);
    c.on_message(0, &contact(false, 1_150_000), 1_150_000, &mut out);
    let g = c.gait().clone();
    let law = laws::next_touchdown_angle(b + 0.05, b, g.c, g.beta_des);
    assert!((c.next_beta_td - law).abs() < 1e-12);
    assert_eq!(c.gait_resets, 0);
    // A fall: the leg swept to 1.3 rad before the foot left the ground.
    c.on_message(0, &ls(b, 1_400_000), 1_400_000, &mut out);
    c.on_message(0, &contact(true, 1_400_000), 1_400_000, &mut out);
    c.on_message(0, &ls(-1.3, 1_520_000), 1_520_000, &mut out);
    c.on_message(0, &contact(false, 1_520_000), 1_520_000, &mut out);
    assert_eq!((c.next_beta_td, c.gait_resets), (b, 1));
    // A stance of 10 ms (a stumble) is no step either.
    c.on_message(0, &contact(true, 1_800_000), 1_800_000, &mut out);
    c.on_message(0, &ls(-b, 1_810_000), 1_810_000, &mut out);
    c.on_message(0, &contact(false, 1_830_000), 1_830_000, &mut out);
    assert_eq!(c.gait_resets, 2);
}

/// Sweeping, each terrain runs the safe gait, then every other configured gait, for
/// `sweep_steps` of its steps each, then its own gait; another terrain's steps do not count
/// toward it, and a gait the config leaves out is never run.
#[test]
fn a_sweep_runs_each_configured_gait_on_each_terrain_then_its_own() {
    let mut cfg = fresh();
    cfg.sweep_steps = 3;
    cfg.gaits.retain(|g| g.id != 2);
    cfg.terrain_gaits.retain(|_, g| *g != 2);
    cfg.terrain_gaits.insert("grass".into(), 3);
    cfg.initial_gait = 1;
    cfg.safe_gait = 1;
    let catalog = TerrainCatalog::paper();
    cfg.validate(&catalog).unwrap();
    let mut c = Controller::new(cfg, &catalog);
    let mut out = Vec::new();
    let hb = Message::NodeStatus(NodeStatus::default());
    let (wood, grass) = (protocol::Terrain::WOOD.id(), protocol::Terrain::GRASS.id());
    let mut t = 0;
    let mut gaits = Vec::new();
    let mut step = |c: &mut Controller, terrain: u8| {
        t += 100_000;
        c.on_message(0, &hb, t, &mut out);
        c.on_message(0, &contact(true, t), t, &mut out);
        c.on_message(0, &tc(terrain, 90.0), t + 70_000, &mut out);
        c.on_message(0, &contact(false, t + 140_000), t + 140_000, &mut out);
        t += 140_000;
        c.gait().id
    };
    // Wood: confirmed at its second step; G1 (safe) 3 steps, G3 3 steps, then wood's own G3.
    for _ in 0..8 {
        gaits.push(step(&mut c, wood));
    }
    assert_eq!(gaits, [1, 1, 1, 1, 3, 3, 3, 3], "wood");
    // Grass starts its own sweep at the safe gait.
    let g: Vec<u8> = (0..4).map(|_| step(&mut c, grass)).collect();
    assert_eq!(g, [3, 1, 1, 1], "grass");
    assert!(!gaits.contains(&2) && !g.contains(&2));
}

/// Each hop goes on the bus at the touchdown that closes it (StepState), measured from the
/// switch and LegState: a hip that crosses its foot at 1 m/s and flies on at it.
#[test]
fn each_closed_hop_is_sent_as_a_step_state() {
    let mut c = Controller::new(fresh(), &TerrainCatalog::paper());
    let mut out = Vec::new();
    let hb = Message::NodeStatus(NodeStatus::default());
    let leg = |t: u64, angle: f64| {
        Message::LegState(protocol::messages::LegState {
            leg_angle_rad: angle,
            leg_length_m: 0.3,
            timestamp_us: t as u32,
        })
    };
    // Three stances close two hops.
    let mut t = 100_000u64;
    for _ in 0..3 {
        c.on_message(0, &hb, t, &mut out);
        c.on_message(0, &contact(true, t), t, &mut out);
        for k in 1..18u64 {
            // x = -l sin(angle) from -0.09 m at 1 m/s.
            let x = -0.09 + k as f64 * 0.01;
            c.on_message(
                0,
                &leg(t + k * 10_000, (-x / 0.3).asin()),
                t + k * 10_000,
                &mut out,
            );
        }
        c.on_message(0, &contact(false, t + 180_000), t + 180_000, &mut out);
        // The leg reports in flight too (a gap would make the phase unknown), swinging its
        // foot forward: those reports are not the stance's.
        for k in 18..34u64 {
            let angle = -0.27 + (k - 18) as f64 * 0.034;
            c.on_message(0, &leg(t + k * 10_000, angle), t + k * 10_000, &mut out);
        }
        t += 340_000;
    }
    let steps: Vec<StepState> = out
        .iter()
        .filter_map(|m| match m {
            Message::StepState(s) => Some(*s),
            _ => None,
        })
        .collect();
    assert_eq!(steps.len(), 2, "{steps:?}");
    for s in steps {
        assert!((s.speed_m_s - 1.0).abs() < 0.01, "{s:?}");
        assert!(
            (s.stance_s - 0.18).abs() < 1e-6 && (s.flight_s - 0.16).abs() < 1e-6,
            "{s:?}"
        );
    }
}
