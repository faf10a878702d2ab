#![forbid(unsafe_code)]
#![warn(missing_docs)]
//! # presrs-record: recordings people can look at
//!
//! The robot's CAN traffic as [MCAP](https://mcap.dev) files and as a live
//! [Foxglove](https://foxglove.dev) view: every decoded message on its own channel per foot
//! (`/foot0/contact`, `/foot0/terrain`, `/leg0/state`, `/node/status`, `/gait`), JSON with the
//! DBC's signal names and units, and every reassembled pressure image as a `foxglove.RawImage`.
//!
//! - [`Recorder`] turns stamped frames into channel messages for a [`Sink`];
//! - [`McapFile`] is a sink writing an MCAP file; [`FoxgloveServer`] (feature `foxglove`)
//!   serves the same channels over the Foxglove WebSocket protocol;
//! - [`read::read_json`] reads a recording back (for plots without Foxglove);
//! - [`LiveRecorder`] records off the hot path: a process offers its frames to a
//!   [`LiveTap`] (a [`protocol::bus::Tap`]) that never blocks, and a writer thread does the
//!   decoding and writing; when it falls behind, frames are dropped and counted.
//!
//! ```
//! use presrs_record::{McapFile, Recorder};
//! use protocol::{IdConfig, Stamped, TerrainCatalog, messages::*};
//! let path = std::env::temp_dir().join("presrs-record-doc.mcap");
//! let mut file = McapFile::create(&path).unwrap();
//! let mut rec = Recorder::new(IdConfig::default(), TerrainCatalog::paper());
//! let contact = Message::FootContact(FootContact { stance: true, seq: 1, timestamp_us: 0 });
//! let frame = contact.to_frame(&IdConfig::default(), 0).unwrap();
//! rec.frame(&Stamped { t_us: 1_000, frame }, &mut file).unwrap();
//! use presrs_record::Sink;
//! file.finish().unwrap();
//! assert_eq!(rec.stats().messages, 1);
//! ```

use std::path::{Path, PathBuf};

#[cfg(feature = "foxglove")]
mod foxglove_server;
mod live;
mod mcap_file;
pub mod read;
mod recorder;
pub mod schema;

#[cfg(feature = "foxglove")]
pub use foxglove_server::{DEFAULT_ADDR, FoxgloveServer};
pub use live::{
    FrameConsumer, LIVE_QUEUE, LiveOptions, LiveRecorder, LiveSummary, LiveTap, listen,
};
pub use mcap_file::McapFile;
pub use recorder::{Channel, RecordStats, Recorder, SimTruth, Sink, Topic};

/// Why a recording could not be written.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// The file system refused.
    #[error("{}: {source}{}", path.display(), io_hint(source))]
    Io {
        /// The recording's path.
        path: PathBuf,
        /// What the OS said.
        source: std::io::Error,
    },
    /// The MCAP writer refused (not an I/O error).
    #[error("{}: MCAP writer: {source}", path.display())]
    Mcap {
        /// The recording's path.
        path: PathBuf,
        /// What the writer said.
        source: mcap::McapError,
    },
    /// Written to after it was finished.
    #[error("{}: the recording is already finished", path.display())]
    Finished {
        /// The recording's path.
        path: PathBuf,
    },
    /// The live view could not start.
    #[error("Foxglove server on {addr}: {reason}")]
    Foxglove {
        /// The address asked for.
        addr: String,
        /// Why not.
        reason: String,
    },
    /// The recorder's thread could not start.
    #[error("starting the recorder thread: {0}")]
    Spawn(std::io::Error),
    /// An output of another encoding (the ROS 2 bridge) failed.
    #[error("{0}")]
    Output(String),
    /// A bug in the recorder; please report it.
    #[error("recorder: {0}")]
    Internal(&'static str),
}

impl RecordError {
    fn mcap(path: &Path, e: mcap::McapError) -> Self {
        match e {
            mcap::McapError::Io(source) => RecordError::Io {
                path: path.to_path_buf(),
                source,
            },
            source => RecordError::Mcap {
                path: path.to_path_buf(),
                source,
            },
        }
    }
}

fn io_hint(e: &std::io::Error) -> &'static str {
    use std::io::ErrorKind::*;
    match e.kind() {
        StorageFull => " (the disk is full: free space, or record to another disk)",
        PermissionDenied | ReadOnlyFilesystem => {
            " (not writable: record to a path you may write, e.g. under your home)"
        }
        NotFound => " (its folder does not exist: create it or pick another path)",
        IsADirectory => " (a folder: give a file name ending in .mcap)",
        _ => "",
    }
}
