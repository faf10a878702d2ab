//! The leg bridge embedded in a robot team's own process: LegCommand from the bus to the
//! motor drivers of a leg config, LegState and LegStatus back.
//!
//! ```text
//! presrs leg --example moteus > leg.toml     # then set ids, gear ratios, zero offsets
//! cargo run --release -p presrs-leg --example leg_bridge -- can0 leg.toml 60
//! ```
//!
//! Runs for the given seconds (a robot's process would stop it on its own signal). Nothing
//! moves before the first LegCommand; a command older than `command_timeout_ms`, a driver
//! fault or a silent driver puts every joint in the damped stop; at the end every motor is
//! left stopped. An interface that is missing or goes down is waited for and reopened.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use presrs_leg::LegConfig;
use protocol::bus::BusSource;

fn main() -> std::process::ExitCode {
    match bridge() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("leg_bridge: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn bridge() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let iface = args.next().unwrap_or_else(|| "can0".into());
    let config = args
        .next()
        .ok_or("usage: leg_bridge IFACE LEG.toml [SECONDS]")?;
    let seconds: u64 = args.next().map_or(Ok(60), |s| s.parse())?;
    // Checked key by key: a wrong key is an error naming it, never a motor moved on a guess.
    let cfg = LegConfig::from_file(config.as_ref())?;
    let stop = AtomicBool::new(false);
    let counters = std::thread::scope(|s| {
        s.spawn(|| {
            std::thread::sleep(Duration::from_secs(seconds));
            stop.store(true, Ordering::Relaxed);
        });
        // `check = false`: command the joints (true reads them and moves nothing: bring-up).
        // Time scale 1: the robot's clock is the wall clock.
        presrs_leg::bridge::run(cfg, false, &BusSource::Iface(iface), 1.0, &stop)
    });
    println!(
        "{} LegCommands, {} joint commands, {} periods in the damped stop, {} malformed replies",
        counters.commands,
        counters.joint_commands,
        counters.stopped_periods,
        counters.malformed_replies
    );
    Ok(())
}
