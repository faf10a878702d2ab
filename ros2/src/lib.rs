#![forbid(unsafe_code)]
#![warn(missing_docs)]
//! # presrs-ros2: the robot in ROS 2, without ROS on the robot
//!
//! The bus's messages as ROS 2 topics: published on Zenoh in rmw_zenoh's wire format (so every
//! ROS 2 node on the same Zenoh router sees them, `ros2 topic echo` included) and written as
//! rosbag2 directories (`ros2 bag play`). Per robot namespace: `footN/terrain`
//! (`presrs_msgs/msg/TerrainClass`, with the unknown reason), `footN/contact`, `footN/image`
//! (`sensor_msgs/msg/Image`), `legN/joint_states`, `gait`, and `/diagnostics`.
//!
//! - [`Encoder`] turns stamped CAN frames into CDR messages for a [`RosSink`];
//! - [`ZenohPublisher`] (feature `zenoh`) and [`RosBag`] are the sinks;
//! - [`Ros2Output`] runs them on a live recorder's writer thread, off the robot's hot path
//!   (the tap drops and counts frames when the network or disk is behind; the bridge
//!   reports its drops in `/diagnostics`);
//! - [`types`] and [`typehash`] describe the interfaces and compute their RIHS01 hashes.
//!
//! Our message definitions are the ROS 2 package `ros2/presrs_msgs` (`colcon build` it on
//! the ROS side). docs/ros2.md is the page for a ROS 2 lab.

use std::path::{Path, PathBuf};

mod bag;
mod encoder;
// Their fields are the `.msg` files' (`types`), documented there.
#[allow(missing_docs)]
pub mod messages;
pub mod names;
mod options;
mod output;
#[cfg(feature = "zenoh")]
mod publisher;
pub mod typehash;
pub mod types;

pub use bag::{RosBag, write_bag};
pub use encoder::{BridgeHealth, EncodeStats, Encoder, RosSink, RosTopic};
pub use names::{BadNamespace, Names};
pub use options::Ros2Options;
pub use output::{Ros2Output, Ros2Summary};
#[cfg(feature = "zenoh")]
pub use publisher::{DEFAULT_ROUTER, ZenohOptions, ZenohPublisher};

/// Why a ROS 2 output failed.
#[derive(Debug, thiserror::Error)]
pub enum Ros2Error {
    /// A message could not be encoded (a bug).
    #[error(transparent)]
    Encode(#[from] messages::EncodeError),
    /// The file system refused.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// What the OS said.
        source: std::io::Error,
    },
    /// The MCAP writer refused.
    #[error("{}: MCAP writer: {source}", path.display())]
    Mcap {
        /// The bag's MCAP file.
        path: PathBuf,
        /// What the writer said.
        source: mcap::McapError,
    },
    /// A bag directory that exists already.
    #[error(
        "{}: already exists (a rosbag2 directory is created new, as `ros2 bag record -o` does: \
         remove it or pick another name)",
        .0.display()
    )]
    BagExists(PathBuf),
    /// Written to after it was finished.
    #[error("{}: the bag is already finished", .0.display())]
    Finished(PathBuf),
    /// The Zenoh session could not start or a declaration failed.
    #[error("Zenoh: {0}")]
    Zenoh(String),
    /// The namespace is not a ROS 2 namespace.
    #[error(transparent)]
    Namespace(#[from] BadNamespace),
    /// Asked for the live bridge in a build without it.
    #[error(
        "this presrs was built without the `zenoh` feature: the live ROS 2 bridge is not in \
         it (rosbag2 files are: --ros2-bag DIR)"
    )]
    NoZenoh,
}

impl Ros2Error {
    fn mcap(path: &Path, e: mcap::McapError) -> Self {
        match e {
            mcap::McapError::Io(source) => Ros2Error::Io {
                path: path.to_path_buf(),
                source,
            },
            source => Ros2Error::Mcap {
                path: path.to_path_buf(),
                source,
            },
        }
    }
}
