//! Where the bridge's messages go on Zenoh, in rmw_zenoh's format (its `docs/design.md` and
//! `liveliness_utils.cpp`): the topic key expression `<domain>/<topic>/<DDS type>/<RIHS01>`,
//! the liveliness tokens `@ros2_lv/...` by which `ros2 node list` and `ros2 topic list` see a
//! node and its publishers, and each publisher's GID (XXH3-128 of its token).

use crate::typehash::rihs01;
use crate::types::MsgType;

/// rmw_zenoh's admin space for liveliness tokens.
pub const ADMIN_SPACE: &str = "@ros2_lv";

/// The ROS 2 node name the bridge appears as.
pub const NODE_NAME: &str = "presrs_bridge";

/// A publisher's QoS as rmw_zenoh writes it in a token: reliable, volatile, keep-last 10, no
/// deadline, lifespan or liveliness lease (rmw's default profile, depth written out).
pub const QOS: &str = "::,10:,:,:,,";

/// One robot on one ROS domain.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Names {
    /// `ROS_DOMAIN_ID`.
    pub domain: u32,
    /// `/robot1`, or empty for none.
    pub namespace: String,
}

/// A namespace that ROS 2 would refuse (`--namespace`).
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
#[error(
    "--namespace `{0}`: a ROS 2 namespace is letters, digits and `_` in `/`-separated parts, \
     not starting with a digit (e.g. robot1 or lab/robot1)"
)]
pub struct BadNamespace(pub String);

impl Names {
    /// `namespace` as given on the command line (`robot1`, `/robot1`, `lab/robot1`, or empty).
    pub fn new(domain: u32, namespace: &str) -> Result<Self, BadNamespace> {
        let trimmed = namespace.trim_matches('/');
        if !trimmed.is_empty() {
            let ok = trimmed.split('/').all(|part| {
                !part.is_empty()
                    && !part.starts_with(|c: char| c.is_ascii_digit())
                    && part.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
            });
            if !ok {
                return Err(BadNamespace(namespace.to_string()));
            }
        }
        Ok(Self {
            domain,
            namespace: if trimmed.is_empty() {
                String::new()
            } else {
                format!("/{trimmed}")
            },
        })
    }

    /// The fully qualified topic name: `relative` under the namespace (`foot0/terrain` ->
    /// `/robot1/foot0/terrain`); an absolute name (`/diagnostics`) stays as it is, as ROS 2
    /// resolves it.
    pub fn topic(&self, relative: &str) -> String {
        if relative.starts_with('/') {
            relative.to_string()
        } else {
            format!("{}/{relative}", self.namespace)
        }
    }

    /// The key expression a topic's messages are put on.
    pub fn topic_key(&self, fq_topic: &str, t: &MsgType) -> String {
        format!(
            "{}/{}/{}/{}",
            self.domain,
            fq_topic.trim_matches('/'),
            t.dds_name(),
            rihs01(t)
        )
    }

    /// The node's liveliness token, for the session `zid`.
    pub fn node_token(&self, zid: &str) -> String {
        format!(
            "{ADMIN_SPACE}/{}/{zid}/0/0/NN/%/{}/{NODE_NAME}",
            self.domain,
            mangle(&self.namespace)
        )
    }

    /// Publisher `entity`'s liveliness token.
    pub fn publisher_token(&self, zid: &str, entity: u32, fq_topic: &str, t: &MsgType) -> String {
        format!(
            "{ADMIN_SPACE}/{}/{zid}/0/{entity}/MP/%/{}/{NODE_NAME}/{}/{}/{}/{QOS}",
            self.domain,
            mangle(&self.namespace),
            mangle(fq_topic),
            t.dds_name(),
            rihs01(t)
        )
    }
}

/// A name as one key-expression chunk: `/` becomes `%`; empty is `%`.
fn mangle(name: &str) -> String {
    if name.is_empty() {
        "%".into()
    } else {
        name.replace('/', "%")
    }
}

/// A publisher's GID, as rmw_zenoh makes it: XXH3-128 of its liveliness token, low 64 bits
/// then high, each little-endian.
pub fn gid(token: &str) -> [u8; 16] {
    let h = xxhash_rust::xxh3::xxh3_128(token.as_bytes());
    let mut g = [0u8; 16];
    g[..8].copy_from_slice(&(h as u64).to_le_bytes());
    g[8..].copy_from_slice(&((h >> 64) as u64).to_le_bytes());
    g
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::types;

    #[test]
    fn keys_and_tokens_in_rmw_zenoh_format() {
        let n = Names::new(0, "robot1").unwrap();
        let topic = n.topic("foot0/terrain");
        assert_eq!(topic, "/robot1/foot0/terrain");
        assert_eq!(n.topic("/diagnostics"), "/diagnostics");
        let key = n.topic_key(&topic, &types::TERRAIN_CLASS);
        assert!(
            key.starts_with("0/robot1/foot0/terrain/presrs_msgs::msg::dds_::TerrainClass_/RIHS01_"),
            "{key}"
        );
        assert_eq!(
            n.node_token("abc"),
            "@ros2_lv/0/abc/0/0/NN/%/%robot1/presrs_bridge"
        );
        let t = n.publisher_token("abc", 3, &topic, &types::TERRAIN_CLASS);
        assert!(t.starts_with(
            "@ros2_lv/0/abc/0/3/MP/%/%robot1/presrs_bridge/%robot1%foot0%terrain/presrs_msgs::msg::dds_::TerrainClass_/RIHS01_"
        ));
        assert!(t.ends_with("/::,10:,:,:,,"));
        let root = Names::new(7, "").unwrap();
        assert_eq!(root.topic("gait"), "/gait");
        assert_eq!(
            root.node_token("z"),
            "@ros2_lv/7/z/0/0/NN/%/%/presrs_bridge"
        );
    }

    #[test]
    fn bad_namespaces_are_refused_with_the_rule() {
        for bad in ["1robot", "robot-1", "a//b", "robot 1"] {
            let e = Names::new(0, bad).unwrap_err();
            assert!(e.to_string().contains("letters, digits"), "{bad}");
        }
        assert_eq!(
            Names::new(0, "/lab/robot_2/").unwrap().namespace,
            "/lab/robot_2"
        );
    }

    #[test]
    fn gids_differ_per_token() {
        assert_ne!(gid("a"), gid("b"));
        assert_eq!(gid("a"), gid("a"));
    }
}
