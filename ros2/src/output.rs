//! The ROS 2 outputs of a running process: the [`Encoder`] and its sinks (a Zenoh session, a
//! rosbag2) as one [`record::FrameConsumer`] on the live recorder's writer thread, so the
//! robot's threads only copy each frame into a bounded queue. A sink that fails is logged
//! and dropped; the other goes on.

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};

use protocol::Stamped;
use record::{FrameConsumer, RecordError};

use crate::encoder::{BridgeHealth, Encoder, RosSink, RosTopic};
use crate::{Ros2Error, RosBag};

#[cfg(feature = "zenoh")]
type Zenoh = crate::ZenohPublisher;
#[cfg(not(feature = "zenoh"))]
type Zenoh = std::convert::Infallible;

/// What the outputs delivered.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Ros2Summary {
    /// Messages handed to Zenoh (or the bag), per topic name.
    pub published: BTreeMap<String, u64>,
    /// Frames the tap dropped (the outputs were behind).
    pub dropped: u64,
    /// Outputs that failed, with their error.
    pub failed: Vec<String>,
}

/// The encoder with its sinks.
pub struct Ros2Output {
    encoder: Encoder,
    sinks: Sinks,
    /// The tap's drops as of the last frame, and the router's losses as of the last flush.
    dropped: u64,
    router_losses: u64,
    summary: Arc<Mutex<Ros2Summary>>,
}

struct Sinks {
    zenoh: Option<Zenoh>,
    bag: Option<RosBag>,
    names: crate::Names,
    published: BTreeMap<RosTopic, u64>,
    total: u64,
    failed: Vec<String>,
}

impl RosSink for Sinks {
    fn write(&mut self, topic: RosTopic, t_ns: u64, cdr: &[u8]) -> Result<(), Ros2Error> {
        #[cfg(feature = "zenoh")]
        if let Some(z) = self.zenoh.as_mut()
            && let Err(e) = z.write(topic, t_ns, cdr)
        {
            tracing::error!("ROS 2 on Zenoh stopped: {e}; the robot goes on without it");
            self.failed.push(e.to_string());
            self.zenoh = None;
        }
        if let Some(b) = self.bag.as_mut()
            && let Err(e) = b.write(topic, t_ns, cdr)
        {
            tracing::error!("rosbag2 stopped: {e}; the robot goes on without it");
            self.failed.push(e.to_string());
            self.bag = None;
        }
        *self.published.entry(topic).or_default() += 1;
        self.total += 1;
        Ok(())
    }
}

impl Ros2Output {
    /// The encoder and whichever sinks are given.
    pub fn new(encoder: Encoder, zenoh: Option<Zenoh>, bag: Option<RosBag>) -> Self {
        let names = encoder.names().clone();
        Self {
            encoder,
            sinks: Sinks {
                zenoh,
                bag,
                names,
                published: BTreeMap::new(),
                total: 0,
                failed: Vec::new(),
            },
            dropped: 0,
            router_losses: 0,
            summary: Arc::default(),
        }
    }

    /// A handle that reads what was delivered once the recorder has finished.
    pub fn summary(&self) -> Arc<Mutex<Ros2Summary>> {
        self.summary.clone()
    }

    fn alive(&self) -> bool {
        self.sinks.zenoh.is_some() || self.sinks.bag.is_some()
    }
}

impl FrameConsumer for Ros2Output {
    fn frame(&mut self, frame: &Stamped, dropped: u64) -> Result<(), RecordError> {
        self.dropped = dropped;
        self.encoder.set_health(BridgeHealth {
            dropped,
            published: self.sinks.total,
            router_losses: self.router_losses,
        });
        self.encoder
            .frame(frame, &mut self.sinks)
            .map_err(|e| RecordError::Output(format!("ROS 2: {e}")))?;
        if self.alive() {
            Ok(())
        } else {
            Err(RecordError::Output("ROS 2: every output failed".into()))
        }
    }

    fn flush(&mut self) -> Result<(), RecordError> {
        #[cfg(feature = "zenoh")]
        if let Some(z) = self.sinks.zenoh.as_mut() {
            self.router_losses = z.router_losses();
        }
        Ok(())
    }

    fn finish(&mut self) -> Result<(), RecordError> {
        let mut result = Ok(());
        if let Some(mut b) = self.sinks.bag.take()
            && let Err(e) = b.finish()
        {
            result = Err(RecordError::Output(format!("rosbag2: {e}")));
        }
        #[cfg(feature = "zenoh")]
        if let Some(z) = self.sinks.zenoh.take() {
            z.close();
        }
        let published: BTreeMap<String, u64> = self
            .sinks
            .published
            .iter()
            .map(|(t, n)| (self.sinks.names.topic(&t.relative()), *n))
            .collect();
        tracing::info!(
            messages = published.values().sum::<u64>(),
            "ROS 2 outputs closed"
        );
        if let Ok(mut s) = self.summary.lock() {
            s.published = published;
            s.dropped = self.dropped;
            s.failed = self.sinks.failed.clone();
        }
        result
    }
}
