//! An MCAP file as a [`Sink`], written with the `mcap` crate: chunked, with message and chunk
//! indexes and a summary, so tools seek by time without reading the whole file.

use std::collections::HashMap;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use crate::RecordError;
use crate::recorder::{Channel, Sink};

/// Chunk size: about 0.4 s of one foot's images and messages as JSON. A chunk is the unit that
/// survives a killed process (each is written whole), so smaller loses less; the indexes cost
/// about 100 bytes per chunk and channel.
const CHUNK_BYTES: u64 = 256 * 1024;

/// An MCAP file being written.
pub struct McapFile {
    path: PathBuf,
    writer: Option<mcap::Writer<BufWriter<File>>>,
    schemas: HashMap<String, u16>,
    /// Per recorder channel index: the file's channel id and its last sequence number.
    channels: Vec<(u16, u32)>,
}

impl McapFile {
    /// Creates (or truncates) `path`. The error names the path and what to do.
    pub fn create(path: &Path) -> Result<Self, RecordError> {
        let io = |source| RecordError::Io {
            path: path.to_path_buf(),
            source,
        };
        let file = File::create(path).map_err(io)?;
        let opts = mcap::WriteOptions::new()
            .compression(None)
            .profile("")
            .library(concat!("presrs ", env!("CARGO_PKG_VERSION")))
            .chunk_size(Some(CHUNK_BYTES))
            // Buffered chunks: each reaches the file whole, never as a header patched later,
            // so a SIGKILL leaves every chunk written so far readable.
            .disable_seeking(true);
        let writer = opts
            .create(BufWriter::with_capacity(64 * 1024, file))
            .map_err(|e| RecordError::mcap(path, e))?;
        Ok(Self {
            path: path.to_path_buf(),
            writer: Some(writer),
            schemas: HashMap::new(),
            channels: Vec::new(),
        })
    }

    /// The file's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    fn writer(&mut self) -> Result<&mut mcap::Writer<BufWriter<File>>, RecordError> {
        self.writer.as_mut().ok_or(RecordError::Finished {
            path: self.path.clone(),
        })
    }
}

impl Sink for McapFile {
    fn add_channel(&mut self, index: usize, channel: &Channel) -> Result<(), RecordError> {
        let path = self.path.clone();
        let schema_id = match self.schemas.get(&channel.schema.name) {
            Some(&id) => id,
            None => {
                let id = self
                    .writer()?
                    .add_schema(
                        &channel.schema.name,
                        "jsonschema",
                        channel.schema.json.as_bytes(),
                    )
                    .map_err(|e| RecordError::mcap(&path, e))?;
                self.schemas.insert(channel.schema.name.clone(), id);
                id
            }
        };
        let id = self
            .writer()?
            .add_channel(schema_id, &channel.topic, "json", &Default::default())
            .map_err(|e| RecordError::mcap(&path, e))?;
        if self.channels.len() <= index {
            self.channels.resize(index + 1, (0, 0));
        }
        self.channels[index] = (id, 0);
        Ok(())
    }

    fn write(&mut self, index: usize, log_time_ns: u64, data: &[u8]) -> Result<(), RecordError> {
        let Some((channel_id, seq)) = self.channels.get_mut(index) else {
            return Err(RecordError::Internal("a message on a channel never added"));
        };
        *seq = seq.wrapping_add(1);
        let header = mcap::records::MessageHeader {
            channel_id: *channel_id,
            sequence: *seq,
            log_time: log_time_ns,
            publish_time: log_time_ns,
        };
        let path = self.path.clone();
        self.writer()?
            .write_to_known_channel(&header, data)
            .map_err(|e| RecordError::mcap(&path, e))
    }

    fn flush(&mut self) -> Result<(), RecordError> {
        let path = self.path.clone();
        self.writer()?
            .flush()
            .map_err(|e| RecordError::mcap(&path, e))
    }

    fn finish(&mut self) -> Result<(), RecordError> {
        let Some(mut w) = self.writer.take() else {
            return Ok(());
        };
        w.finish().map_err(|e| RecordError::mcap(&self.path, e))?;
        let mut inner = w.into_inner();
        inner.flush().map_err(|source| RecordError::Io {
            path: self.path.clone(),
            source,
        })?;
        let file = inner.into_inner().map_err(|e| RecordError::Io {
            path: self.path.clone(),
            source: e.into_error(),
        })?;
        file.sync_all().map_err(|source| RecordError::Io {
            path: self.path.clone(),
            source,
        })
    }
}

impl Drop for McapFile {
    fn drop(&mut self) {
        if self.writer.is_some()
            && let Err(e) = self.finish()
        {
            tracing::error!("{e}");
        }
    }
}
