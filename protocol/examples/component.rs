//! A part of your own on the bus: a watchdog that reports, once a second, each foot's steps and
//! terrains and whether the node's heartbeat is there. It is a [`Component`], so the runner
//! opens the bus (and reopens it after an error), filters in the kernel, and keeps its clock.
//!
//! ```text
//! cargo run -p presrs-protocol --example component -- vcan0
//! ```

use std::sync::atomic::AtomicBool;

use presrs_protocol::bus::BusSource;
use presrs_protocol::component::{Component, Outbox, RunOptions, run};
use presrs_protocol::messages::{Message, decode};
use presrs_protocol::{IdConfig, MessageKind, Stamped, TerrainCatalog};

struct Watchdog {
    ids: IdConfig,
    catalog: TerrainCatalog,
    steps: [u32; 8],
    last: [Option<u8>; 8],
    heartbeat_us: Option<u64>,
    next_report_us: u64,
}

impl Component for Watchdog {
    fn name(&self) -> &'static str {
        "watchdog"
    }

    // Only these two kinds reach this process: never the tactile stream.
    fn filters(&self) -> Vec<(u32, u32)> {
        self.ids
            .filters(&[MessageKind::TerrainClass, MessageKind::NodeStatus])
    }

    fn on_frame(&mut self, st: &Stamped, now_us: u64, _: &mut Outbox) {
        match decode(&st.frame, &self.ids) {
            Ok(Some((foot, Message::TerrainClass(tc)))) if (foot as usize) < 8 => {
                self.steps[foot as usize] += 1;
                self.last[foot as usize] = Some(tc.terrain);
            }
            Ok(Some((_, Message::NodeStatus(_)))) => self.heartbeat_us = Some(now_us),
            _ => {}
        }
    }

    fn tick(&mut self, now_us: u64, _: &mut Outbox) {
        if now_us < self.next_report_us {
            return;
        }
        self.next_report_us = now_us + 1_000_000;
        let alive = self.heartbeat_us.is_some_and(|t| now_us - t < 500_000);
        print!("node {}", if alive { "alive" } else { "silent" });
        for (foot, (n, t)) in self.steps.iter().zip(&self.last).enumerate() {
            if let Some(t) = t {
                print!("; foot {foot}: {n} steps, {}", self.catalog.describe(*t));
            }
        }
        println!();
    }
}

fn main() {
    let iface = std::env::args().nth(1).unwrap_or_else(|| "vcan0".into());
    let mut watchdog = Watchdog {
        ids: IdConfig::default(),
        catalog: TerrainCatalog::paper(),
        steps: [0; 8],
        last: [None; 8],
        heartbeat_us: None,
        next_report_us: 0,
    };
    // Until killed (a robot's process would pass its signal flag).
    let stop = AtomicBool::new(false);
    run(
        &mut watchdog,
        &BusSource::Iface(iface),
        &RunOptions::default(),
        &stop,
    );
}
