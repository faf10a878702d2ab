//! The live view: the recorder's channels served over the Foxglove WebSocket protocol
//! (`foxglove.sdk.v1`, the protocol formerly named `foxglove.websocket.v1`), by the `foxglove` SDK's server on its own tokio threads.

use std::sync::Arc;

use foxglove::{Context, PartialMetadata, RawChannel, WebSocketServer, WebSocketServerHandle};

use crate::RecordError;
use crate::recorder::{Channel, Sink};

/// Foxglove's default address: the app connects to `ws://localhost:8765` unless told otherwise.
pub const DEFAULT_ADDR: &str = "127.0.0.1:8765";

/// A Foxglove WebSocket server with its own context (channels of other servers in the
/// process are not mixed in).
pub struct FoxgloveServer {
    context: Arc<Context>,
    handle: Option<WebSocketServerHandle>,
    channels: Vec<Option<Arc<RawChannel>>>,
    addr: String,
}

impl FoxgloveServer {
    /// Listens on `addr` (`host:port`; port 0 picks a free one, see [`FoxgloveServer::port`]).
    pub fn start(addr: &str) -> Result<Self, RecordError> {
        let bad = |reason: String| RecordError::Foxglove {
            addr: addr.to_string(),
            reason,
        };
        let (host, port) = addr
            .rsplit_once(':')
            .ok_or_else(|| bad("expected HOST:PORT, e.g. 127.0.0.1:8765".into()))?;
        let port: u16 = port
            .parse()
            .map_err(|_| bad(format!("port {port:?} is not a number from 0 to 65535")))?;
        let context = Context::new();
        let handle = WebSocketServer::new()
            .name("presrs")
            .context(&context)
            .bind(host.trim_matches(['[', ']']), port)
            .start_blocking()
            .map_err(|e| bad(e.to_string()))?;
        Ok(Self {
            context,
            handle: Some(handle),
            channels: Vec::new(),
            addr: addr.to_string(),
        })
    }

    /// The port it listens on.
    pub fn port(&self) -> u16 {
        self.handle.as_ref().map_or(0, |h| h.port())
    }

    /// The address it was asked to listen on.
    pub fn addr(&self) -> &str {
        &self.addr
    }
}

impl Sink for FoxgloveServer {
    fn add_channel(&mut self, index: usize, channel: &Channel) -> Result<(), RecordError> {
        let schema = foxglove::Schema::new(
            channel.schema.name.clone(),
            "jsonschema",
            channel.schema.json.clone().into_bytes(),
        );
        let ch = self
            .context
            .channel_builder(channel.topic.clone())
            .message_encoding("json")
            .schema(schema)
            .build_raw()
            .map_err(|e| RecordError::Foxglove {
                addr: self.addr.clone(),
                reason: format!("channel {}: {e}", channel.topic),
            })?;
        if self.channels.len() <= index {
            self.channels.resize(index + 1, None);
        }
        self.channels[index] = Some(ch);
        Ok(())
    }

    fn write(&mut self, index: usize, log_time_ns: u64, data: &[u8]) -> Result<(), RecordError> {
        if let Some(Some(ch)) = self.channels.get(index) {
            ch.log_with_meta(
                data,
                PartialMetadata {
                    log_time: Some(log_time_ns),
                },
            );
        }
        Ok(())
    }

    fn flush(&mut self) -> Result<(), RecordError> {
        Ok(())
    }

    fn finish(&mut self) -> Result<(), RecordError> {
        if let Some(h) = self.handle.take() {
            h.stop().wait_blocking();
        }
        Ok(())
    }
}
