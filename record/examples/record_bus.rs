//! Records a CAN bus to an MCAP file that Foxglove opens: every message decoded on its own
//! channel, every pressure image as an image.
//!
//! ```text
//! cargo run --release -p presrs-record --example record_bus -- vcan0 run.mcap 10
//! ```
//!
//! The recorder listens on its own socket, beside the robot's processes, and writes off their
//! hot path; frames it cannot keep up with are dropped and counted, never waited for.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use presrs_record::{LiveRecorder, McapFile, Recorder, Sink, listen};
use protocol::bus::BusSource;
use protocol::{IdConfig, TerrainCatalog};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let iface = args.next().unwrap_or_else(|| "vcan0".into());
    let out = args.next().unwrap_or_else(|| "run.mcap".into());
    let seconds: u64 = args.next().map(|s| s.parse()).transpose()?.unwrap_or(10);
    let file: Box<dyn Sink> = Box::new(McapFile::create(out.as_ref())?);
    let recorder = LiveRecorder::start(
        Recorder::new(IdConfig::default(), TerrainCatalog::paper()),
        vec![(out.clone(), file)],
        32_768,
    )?;
    let stop = Arc::new(AtomicBool::new(false));
    let listener = listen(BusSource::Iface(iface), recorder.tap(), stop.clone())?;
    std::thread::sleep(Duration::from_secs(seconds));
    stop.store(true, Ordering::Relaxed);
    let _ = listener.join();
    // Completes the file: summary and indexes.
    let s = recorder.finish();
    println!(
        "{out}: {} messages, {} dropped",
        s.stats.messages, s.dropped
    );
    Ok(())
}
