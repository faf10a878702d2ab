//! A rosbag2 directory that `ros2 bag play` and `rosbags` read: one MCAP file with profile
//! `ros2`, a `ros2msg` schema per type and `cdr` messages (the bridge's bytes), and the
//! `metadata.yaml` beside it (rosbag2 format version 9, as ROS 2 Jazzy's `ros2 bag record`
//! writes it, with each topic's offered QoS: the bridge's publisher profile, [`QOS_PROFILE`]).
//! The YAML is written by hand: it is a fixed shape of numbers and names, not worth a YAML
//! crate.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use crate::Ros2Error;
use crate::encoder::{RosSink, RosTopic};
use crate::names::Names;
use crate::typehash::rihs01;
use crate::types::schema_text;

/// The ROS 2 distribution the bag's format and the bridge's wire format follow.
pub const ROS_DISTRO: &str = "jazzy";

/// The QoS every topic of the bridge is offered with, as rosbag2 (format 9) lists it: the one
/// [`crate::names::QOS`] writes in rmw_zenoh's tokens (reliable, volatile, keep-last 10, and
/// rmw's infinite durations for the rest). Indented by `indent` spaces, without a line end.
pub fn qos_profile_yaml(indent: usize) -> String {
    // rmw's "infinite" duration (RMW_DURATION_INFINITE), for deadline, lifespan and lease.
    const INFINITE: [&str; 2] = ["    sec: 9223372036", "    nsec: 854775807"];
    let mut lines = vec![
        "- history: keep_last",
        "  depth: 10",
        "  reliability: reliable",
        "  durability: volatile",
    ];
    for d in ["  deadline:", "  lifespan:"] {
        lines.push(d);
        lines.extend(INFINITE);
    }
    lines.push("  liveliness: automatic");
    lines.push("  liveliness_lease_duration:");
    lines.extend(INFINITE);
    lines.push("  avoid_ros_namespace_conventions: false");
    let p = " ".repeat(indent);
    lines
        .iter()
        .map(|l| format!("{p}{l}"))
        .collect::<Vec<_>>()
        .join("\n")
}

struct Topic {
    channel: u16,
    name: String,
    ty: &'static str,
    hash: String,
    count: u64,
}

/// A rosbag2 being written; [`RosBag::finish`] completes it.
pub struct RosBag {
    dir: PathBuf,
    file_name: String,
    names: Names,
    writer: Option<mcap::Writer<BufWriter<File>>>,
    schemas: BTreeMap<&'static str, u16>,
    topics: BTreeMap<RosTopic, Topic>,
    first_ns: Option<u64>,
    last_ns: u64,
    messages: u64,
}

impl RosBag {
    /// Creates the directory `dir` (which must not exist, as with `ros2 bag record -o`) for the
    /// robot `names`.
    pub fn create(dir: &Path, names: Names) -> Result<Self, Ros2Error> {
        if dir.exists() {
            return Err(Ros2Error::BagExists(dir.to_path_buf()));
        }
        let io = |source| Ros2Error::Io {
            path: dir.to_path_buf(),
            source,
        };
        std::fs::create_dir_all(dir).map_err(io)?;
        let stem = dir
            .file_name()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "bag".into());
        let file_name = format!("{stem}_0.mcap");
        let path = dir.join(&file_name);
        let file = File::create(&path).map_err(|source| Ros2Error::Io {
            path: path.clone(),
            source,
        })?;
        let writer = mcap::WriteOptions::new()
            .compression(None)
            .profile("ros2")
            .library(concat!("presrs ", env!("CARGO_PKG_VERSION")))
            .create(BufWriter::with_capacity(64 * 1024, file))
            .map_err(|e| Ros2Error::mcap(&path, e))?;
        Ok(Self {
            dir: dir.to_path_buf(),
            file_name,
            names,
            writer: Some(writer),
            schemas: BTreeMap::new(),
            topics: BTreeMap::new(),
            first_ns: None,
            last_ns: 0,
            messages: 0,
        })
    }

    /// Messages written so far.
    pub fn messages(&self) -> u64 {
        self.messages
    }

    fn mcap_path(&self) -> PathBuf {
        self.dir.join(&self.file_name)
    }

    fn add_topic(&mut self, topic: RosTopic) -> Result<u16, Ros2Error> {
        let path = self.mcap_path();
        let ty = topic.msg_type();
        let Some(w) = self.writer.as_mut() else {
            return Err(Ros2Error::Finished(path));
        };
        let schema = match self.schemas.get(ty.name) {
            Some(&id) => id,
            None => {
                let id = w
                    .add_schema(ty.name, "ros2msg", schema_text(ty).as_bytes())
                    .map_err(|e| Ros2Error::mcap(&path, e))?;
                self.schemas.insert(ty.name, id);
                id
            }
        };
        let name = self.names.topic(&topic.relative());
        let hash = rihs01(ty);
        let metadata = BTreeMap::from([
            ("offered_qos_profiles".to_string(), qos_profile_yaml(0)),
            ("topic_type_hash".to_string(), hash.clone()),
        ]);
        let channel = w
            .add_channel(schema, &name, "cdr", &metadata)
            .map_err(|e| Ros2Error::mcap(&path, e))?;
        self.topics.insert(
            topic,
            Topic {
                channel,
                name,
                ty: ty.name,
                hash,
                count: 0,
            },
        );
        Ok(channel)
    }

    /// Writes the MCAP summary and `metadata.yaml`. Called once; a bag not finished has no
    /// `metadata.yaml` (rosbag2's `ros2 bag reindex` can rebuild it).
    pub fn finish(&mut self) -> Result<(), Ros2Error> {
        let path = self.mcap_path();
        let Some(mut w) = self.writer.take() else {
            return Ok(());
        };
        w.finish().map_err(|e| Ros2Error::mcap(&path, e))?;
        drop(w);
        let yaml = self.metadata_yaml();
        let meta = self.dir.join("metadata.yaml");
        std::fs::write(&meta, yaml).map_err(|source| Ros2Error::Io { path: meta, source })
    }

    fn metadata_yaml(&self) -> String {
        let start = self.first_ns.unwrap_or(0);
        let duration = self.last_ns.saturating_sub(start);
        let mut y = String::new();
        y.push_str("rosbag2_bagfile_information:\n  version: 9\n  storage_identifier: mcap\n");
        y.push_str(&format!(
            "  duration:\n    nanoseconds: {duration}\n  starting_time:\n    \
             nanoseconds_since_epoch: {start}\n  message_count: {}\n  topics_with_message_count:\n",
            self.messages
        ));
        for t in self.topics.values() {
            y.push_str(&format!(
                "    - topic_metadata:\n        name: \"{}\"\n        type: \"{}\"\n        \
                 serialization_format: cdr\n        offered_qos_profiles:\n{}\n        \
                 type_description_hash: \"{}\"\n      message_count: {}\n",
                t.name,
                t.ty,
                qos_profile_yaml(10),
                t.hash,
                t.count
            ));
        }
        y.push_str(&format!(
            "  compression_format: \"\"\n  compression_mode: \"\"\n  relative_file_paths:\n    \
             - \"{f}\"\n  files:\n    - path: \"{f}\"\n      starting_time:\n        \
             nanoseconds_since_epoch: {start}\n      duration:\n        nanoseconds: {duration}\n      \
             message_count: {}\n  custom_data: ~\n  ros_distro: {ROS_DISTRO}\n",
            self.messages,
            f = self.file_name
        ));
        y
    }
}

/// `stamped` frames (a candump log's) into a new rosbag2 at `dir`: the messages the bridge
/// would have published for `names`, decoded with `ids` and named from `catalog`.
pub fn write_bag(
    stamped: impl IntoIterator<Item = protocol::Stamped>,
    ids: protocol::IdConfig,
    catalog: protocol::TerrainCatalog,
    names: Names,
    dir: &Path,
) -> Result<crate::EncodeStats, Ros2Error> {
    let mut bag = RosBag::create(dir, names.clone())?;
    let mut enc = crate::Encoder::new(ids, catalog, &names);
    for st in stamped {
        enc.frame(&st, &mut bag)?;
    }
    bag.finish()?;
    Ok(enc.stats())
}

impl RosSink for RosBag {
    fn write(&mut self, topic: RosTopic, t_ns: u64, cdr: &[u8]) -> Result<(), Ros2Error> {
        let channel = match self.topics.get(&topic) {
            Some(t) => t.channel,
            None => self.add_topic(topic)?,
        };
        let path = self.mcap_path();
        let Some(t) = self.topics.get_mut(&topic) else {
            return Err(Ros2Error::Finished(path));
        };
        t.count += 1;
        let sequence = t.count as u32;
        let Some(w) = self.writer.as_mut() else {
            return Err(Ros2Error::Finished(path));
        };
        // Bag readers expect time to go forward; the bus's stamps can cross by microseconds.
        let t_ns = t_ns.max(self.last_ns);
        let header = mcap::records::MessageHeader {
            channel_id: channel,
            sequence,
            log_time: t_ns,
            publish_time: t_ns,
        };
        w.write_to_known_channel(&header, cdr)
            .map_err(|e| Ros2Error::mcap(&path, e))?;
        self.first_ns.get_or_insert(t_ns);
        self.last_ns = t_ns;
        self.messages += 1;
        Ok(())
    }
}

impl Drop for RosBag {
    fn drop(&mut self) {
        if self.writer.is_some()
            && let Err(e) = self.finish()
        {
            tracing::error!("{e}");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bag_has_its_mcap_and_metadata_and_refuses_an_existing_dir() {
        let dir = std::env::temp_dir().join(format!("presrs-bag-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let mut bag = RosBag::create(&dir, Names::new(0, "r1").unwrap()).unwrap();
        bag.write(RosTopic::Gait, 5, &[0, 1, 0, 0, 1]).unwrap();
        bag.write(RosTopic::Gait, 9, &[0, 1, 0, 0, 2]).unwrap();
        bag.finish().unwrap();
        let meta = std::fs::read_to_string(dir.join("metadata.yaml")).unwrap();
        assert!(meta.contains("name: \"/r1/gait\""), "{meta}");
        assert!(meta.contains("message_count: 2"));
        assert!(meta.contains("duration:\n    nanoseconds: 4"));
        let name = dir.file_name().unwrap().to_string_lossy().into_owned();
        assert!(dir.join(format!("{name}_0.mcap")).exists());
        let e = RosBag::create(&dir, Names::new(0, "").unwrap())
            .err()
            .unwrap();
        assert!(e.to_string().contains("already exists"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
