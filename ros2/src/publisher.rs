//! The bridge's Zenoh session: a ROS 2 node named `presrs_bridge` in rmw_zenoh's format. A
//! liveliness token for the node and one per publisher (`ros2 node list`, `ros2 topic list`),
//! each message put on its topic's key expression with rmw_zenoh's attachment (sequence
//! number, source timestamp, publisher GID, in zenoh-ext's serialization).
//!
//! The session is a peer, as rmw_zenoh's are, without multicast scouting: it reaches the
//! router it is told (`tcp/localhost:7447`, rmw_zenohd's, by default) and listens only on
//! loopback unless the lab asks for its network. It never waits for the router: puts drop
//! while it is away (congestion control `Drop`), and Zenoh reconnects with backoff (250 ms,
//! doubling to 1 s; docs/decisions/ros2-bridge.md).

use std::collections::HashMap;
use std::path::PathBuf;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use zenoh::liveliness::LivelinessToken;
use zenoh::pubsub::Publisher;
use zenoh::qos::CongestionControl;
use zenoh::{Config, Session, Wait};
use zenoh_ext::ZSerializer;

use crate::Ros2Error;
use crate::encoder::{RosSink, RosTopic};
use crate::names::{Names, gid};

/// rmw_zenohd's address: where ROS 2 nodes on this machine find their router.
pub const DEFAULT_ROUTER: &str = "tcp/localhost:7447";

/// Where the session connects.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ZenohOptions {
    /// Routers to connect to (`tcp/HOST:7447`); empty: [`DEFAULT_ROUTER`].
    pub connect: Vec<String>,
    /// A Zenoh configuration file (JSON5): the lab's network, TLS, access control. Our
    /// settings above apply only where it says nothing.
    pub config: Option<PathBuf>,
    /// Block when a link's queue is full instead of dropping: for a simulation, whose
    /// recorder thread may wait; never for a robot.
    pub lossless: bool,
}

struct Pub {
    publisher: Publisher<'static>,
    _token: LivelinessToken,
    gid: [u8; 16],
    seq: i64,
}

/// A live Zenoh session publishing the robot's topics.
pub struct ZenohPublisher {
    session: Session,
    names: Names,
    zid: String,
    _node: LivelinessToken,
    pubs: HashMap<RosTopic, Pub>,
    next_entity: u32,
    congestion: CongestionControl,
    had_router: bool,
    router_losses: u64,
}

fn zerr(what: &str, e: impl std::fmt::Display) -> Ros2Error {
    Ros2Error::Zenoh(format!("{what}: {e}"))
}

impl ZenohPublisher {
    /// Opens the session and declares the node. Returns at once whether or not a router is
    /// there.
    pub fn open(names: Names, opts: &ZenohOptions) -> Result<Self, Ros2Error> {
        let config = config(opts)?;
        let session = zenoh::open(config)
            .wait()
            .map_err(|e| zerr("opening the session", e))?;
        let zid = session.zid().to_string();
        let node = session
            .liveliness()
            .declare_token(names.node_token(&zid))
            .wait()
            .map_err(|e| zerr("declaring the node's liveliness token", e))?;
        Ok(Self {
            session,
            names,
            zid,
            _node: node,
            pubs: HashMap::new(),
            next_entity: 1,
            congestion: if opts.lossless {
                CongestionControl::Block
            } else {
                CongestionControl::Drop
            },
            had_router: false,
            router_losses: 0,
        })
    }

    /// True while a router is connected.
    pub fn has_router(&self) -> bool {
        self.session.info().routers_zid().wait().next().is_some()
    }

    /// Waits up to `timeout` for a router (a simulation that starts publishing at once would
    /// otherwise publish its first messages to nobody). The robot's bridge does not wait.
    pub fn wait_for_router(&mut self, timeout: Duration) -> bool {
        let t0 = Instant::now();
        while t0.elapsed() < timeout {
            if self.has_router() {
                self.had_router = true;
                // The router's subscribers reach this session just after the link.
                std::thread::sleep(Duration::from_millis(300));
                return true;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        false
    }

    /// Checks the router now; returns the times it went away so far. Called about once a
    /// second (the recorder's flush), so an outage shorter than that may go uncounted.
    pub fn router_losses(&mut self) -> u64 {
        let now = self.has_router();
        if self.had_router && !now {
            self.router_losses += 1;
            tracing::warn!("Zenoh router lost: publishing resumes when it is back");
        } else if !self.had_router && now {
            tracing::info!("Zenoh router connected");
        }
        self.had_router = now;
        self.router_losses
    }

    /// Closes the session after what was put has been sent.
    pub fn close(self) {
        // Zenoh sends from its own queues; a moment lets the last batch leave before the
        // links close.
        std::thread::sleep(Duration::from_millis(200));
        let Self { session, pubs, .. } = self;
        drop(pubs);
        if let Err(e) = session.close().wait() {
            tracing::warn!("closing the Zenoh session: {e}");
        }
    }

    fn declare(&mut self, topic: RosTopic) -> Result<&mut Pub, Ros2Error> {
        let ty = topic.msg_type();
        let fq = self.names.topic(&topic.relative());
        let key = self.names.topic_key(&fq, ty);
        let entity = self.next_entity;
        self.next_entity += 1;
        let token_key = self.names.publisher_token(&self.zid, entity, &fq, ty);
        let publisher = self
            .session
            .declare_publisher(key.clone())
            .congestion_control(self.congestion)
            .wait()
            .map_err(|e| zerr(&format!("declaring the publisher on {key}"), e))?;
        let token = self
            .session
            .liveliness()
            .declare_token(token_key.clone())
            .wait()
            .map_err(|e| zerr(&format!("declaring the liveliness token {token_key}"), e))?;
        tracing::debug!(%key, "ROS 2 publisher {fq}");
        Ok(self.pubs.entry(topic).or_insert(Pub {
            publisher,
            _token: token,
            gid: gid(&token_key),
            seq: 0,
        }))
    }
}

impl RosSink for ZenohPublisher {
    fn write(&mut self, topic: RosTopic, _t_ns: u64, cdr: &[u8]) -> Result<(), Ros2Error> {
        let p = match self.pubs.contains_key(&topic) {
            true => self.pubs.get_mut(&topic),
            false => Some(self.declare(topic)?),
        };
        let Some(p) = p else {
            return Err(Ros2Error::Zenoh("a publisher vanished".into()));
        };
        p.seq += 1;
        // rmw_zenoh's attachment: sequence number, source time (ns since the epoch), GID.
        let now_ns = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos() as i64);
        let mut s = ZSerializer::new();
        s.serialize(p.seq);
        s.serialize(now_ns);
        s.serialize(p.gid);
        p.publisher
            .put(cdr.to_vec())
            .attachment(s.finish())
            .wait()
            .map_err(|e| zerr("put", e))
    }
}

fn config(opts: &ZenohOptions) -> Result<Config, Ros2Error> {
    let mut c = match &opts.config {
        Some(p) => Config::from_file(p).map_err(|e| {
            Ros2Error::Zenoh(format!(
                "--zenoh-config {}: {e} (a Zenoh JSON5 configuration file, as zenohd takes)",
                p.display()
            ))
        })?,
        None => Config::default(),
    };
    let lab_network = !opts.connect.is_empty();
    let connect: Vec<&str> = if lab_network {
        opts.connect.iter().map(String::as_str).collect()
    } else {
        vec![DEFAULT_ROUTER]
    };
    let endpoints = format!(
        "[{}]",
        connect
            .iter()
            .map(|e| format!("\"{e}\""))
            .collect::<Vec<_>>()
            .join(",")
    );
    let listen = if lab_network {
        "[\"tcp/[::]:0\"]"
    } else {
        "[\"tcp/127.0.0.1:0\"]"
    };
    let mut settings = vec![
        ("mode", "\"peer\"".to_string()),
        ("scouting/multicast/enabled", "false".into()),
        ("listen/endpoints", listen.into()),
        ("connect/timeout_ms", "0".into()),
        ("connect/exit_on_failure", "false".into()),
        (
            "connect/retry",
            "{period_init_ms: 250, period_max_ms: 1000, period_increase_factor: 2}".into(),
        ),
    ];
    if opts.config.is_none() || lab_network {
        settings.push(("connect/endpoints", endpoints));
    }
    for (key, value) in settings {
        // A config file's own settings win, but for the router given on the command line.
        if opts.config.is_some()
            && key != "connect/endpoints"
            && c.get_json(key).is_ok_and(|v| v != "null")
        {
            continue;
        }
        c.insert_json5(key, &value)
            .map_err(|e| zerr(&format!("setting {key} = {value}"), e))?;
    }
    Ok(c)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn by_default_only_loopback_and_no_multicast() {
        let c = config(&ZenohOptions::default()).unwrap();
        assert_eq!(c.get_json("scouting/multicast/enabled").unwrap(), "false");
        assert!(
            c.get_json("listen/endpoints")
                .unwrap()
                .contains("127.0.0.1")
        );
        assert!(
            c.get_json("connect/endpoints")
                .unwrap()
                .contains("localhost:7447")
        );
        let lab = config(&ZenohOptions {
            connect: vec!["tcp/10.0.0.5:7447".into()],
            config: None,
            lossless: false,
        })
        .unwrap();
        assert!(
            lab.get_json("connect/endpoints")
                .unwrap()
                .contains("10.0.0.5")
        );
    }

    #[test]
    fn a_bad_config_file_names_itself() {
        let e = config(&ZenohOptions {
            connect: vec![],
            config: Some("/nonexistent/zenoh.json5".into()),
            lossless: false,
        })
        .err()
        .unwrap();
        assert!(e.to_string().contains("/nonexistent/zenoh.json5"), "{e}");
    }
}
