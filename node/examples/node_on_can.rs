//! The terrain node on a CAN interface, embedded in a robot team's own process.
//!
//! ```text
//! cargo run --release -p presrs-node --example node_on_can -- can0 model.json
//! ```
//!
//! `model.json` comes from `presrs train`. The node hears each foot's tactile stream and
//! contact switch, and answers every step with a TerrainClass; NodeStatus is its heartbeat. An
//! interface that is missing or goes down is waited for and reopened, never a reason to exit.

use std::time::Duration;

use presrs_node::classifier::Model;
use presrs_node::{NodeConfig, NodeService};
use protocol::bus::BusSource;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let iface = args.next().unwrap_or_else(|| "can0".into());
    let model = args.next().ok_or("usage: node_on_can IFACE MODEL.json")?;
    let model = Model::load(model.as_ref())?;
    // The defaults are the paper's: 70 ms sample time, repair filter on, one foot.
    let node = NodeService::new(NodeConfig::default(), model)?;
    // Three threads: receive, pipeline (classification), send.
    let running = node.start(BusSource::Iface(iface))?;
    for _ in 0..30 {
        std::thread::sleep(Duration::from_secs(1));
        let s = running.stats();
        println!(
            "{:?}: {} frames, {} steps, {} classified",
            s.state, s.rx_frames, s.steps, s.classified
        );
    }
    // A last NodeStatus says Stopping.
    let s = running.stop();
    println!("stopped after {} steps", s.steps);
    Ok(())
}
