//! `presrs bridge`: the robot's bus as ROS 2 topics (beside the node, as a process of its
//! own); and the live outputs every bus command shares (`--mcap`, `--foxglove`, `--ros2`,
//! `--ros2-bag`). The encoding and publishing are [`ros2`]'s; this module wires and reports.

use std::process::ExitCode;
use std::sync::{Arc, Mutex};

use anyhow::{Context, Result};
use presrs_cli::bridge::BridgeArgs;
use protocol::bus::BusSource;
use protocol::component::Signals;
use protocol::{IdConfig, TerrainCatalog};

/// A process's live outputs: the recorder thread and what its ROS 2 output delivered.
pub struct LiveOutputs {
    pub recorder: Option<record::LiveRecorder>,
    ros2: Option<Arc<Mutex<ros2::Ros2Summary>>>,
}

impl LiveOutputs {
    /// The outputs asked for by `live` and `ros2`. `simulation`: a run with no real time to
    /// keep (the demo): it waits for its Zenoh router and never drops a message at Zenoh.
    pub fn start(
        live: &record::LiveOptions,
        ros2: &ros2::Ros2Options,
        ids: &IdConfig,
        catalog: &TerrainCatalog,
        simulation: bool,
    ) -> Result<Self> {
        let out = ros2
            .start(ids, catalog, simulation)
            .context("--ros2 / --ros2-bag")?;
        let summary = out.as_ref().map(|o| o.summary());
        let consumers: Vec<(String, Box<dyn record::FrameConsumer>)> = out
            .into_iter()
            .map(|o| {
                (
                    "ROS 2".to_string(),
                    Box::new(o) as Box<dyn record::FrameConsumer>,
                )
            })
            .collect();
        Ok(Self {
            recorder: live.start_with(ids, catalog, consumers),
            ros2: summary,
        })
    }

    /// Ends the recording and publishing; returns what ROS 2 received, per topic.
    pub fn finish(self) -> Option<ros2::Ros2Summary> {
        if let Some(r) = self.recorder {
            r.finish_logged();
        }
        let s = self.ros2?.lock().ok()?.clone();
        let total: u64 = s.published.values().sum();
        eprintln!(
            "ROS 2: {total} messages on {} topics ({} frames dropped behind the bus)",
            s.published.len(),
            s.dropped
        );
        Some(s)
    }
}

pub fn bridge(mut a: BridgeArgs) -> Result<ExitCode> {
    let cfg =
        node::NodeConfig::load_or_default(a.config.as_deref(), &a.terrains).context("--config")?;
    let catalog = cfg.catalog().context("--config terrains")?;
    a.ros2.ros2 = true;
    let signals = Signals::install()?;
    let outputs = LiveOutputs::start(
        &record::LiveOptions::default(),
        &a.ros2,
        &cfg.ids,
        &catalog,
        false,
    )?;
    let Some(recorder) = &outputs.recorder else {
        anyhow::bail!("the ROS 2 output did not start (the log says why)");
    };
    tracing::info!(iface = %a.iface, "presrs bridge: the bus as ROS 2 topics");
    // A part on the bus like every other: the runner reads every frame into the tap; the
    // recorder thread encodes and publishes.
    let listener = record::listen(
        BusSource::Iface(a.iface.clone()),
        recorder.tap(),
        signals.stop.clone(),
    )?;
    while !signals.stopping() {
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    let _ = listener.join();
    outputs.finish();
    Ok(ExitCode::SUCCESS)
}
