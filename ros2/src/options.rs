//! The ROS 2 outputs as a process's options (`--ros2`, `--ros2-bag DIR`, `--namespace`,
//! `--domain`, `--zenoh-connect`, `--zenoh-config`), the same on every command that runs a
//! bus: `presrs bridge`, `demo`, `node`, `sim`.

use std::path::PathBuf;
use std::time::Duration;

use protocol::{IdConfig, TerrainCatalog};

use crate::{Names, Ros2Error, Ros2Output};

/// Where the robot's ROS 2 messages go.
#[derive(Clone, Debug, Default)]
#[cfg_attr(feature = "clap", derive(clap::Args))]
pub struct Ros2Options {
    /// Publish the bus as ROS 2 topics on Zenoh, in rmw_zenoh's format (ROS 2 nodes with
    /// RMW_IMPLEMENTATION=rmw_zenoh_cpp see them); off the hot path: dropped and counted,
    /// never waited for. Router: tcp/localhost:7447 unless --zenoh-connect.
    #[cfg_attr(feature = "clap", arg(long))]
    pub ros2: bool,
    /// Also write the same ROS 2 messages to this rosbag2 directory (MCAP, CDR; `ros2 bag
    /// play` reads it). Must not exist.
    #[cfg_attr(feature = "clap", arg(long, value_name = "DIR"))]
    pub ros2_bag: Option<PathBuf>,
    /// The robot's ROS 2 namespace (robot1 -> /robot1/foot0/terrain); one per robot of a
    /// fleet.
    #[cfg_attr(feature = "clap", arg(long, value_name = "NS", default_value = ""))]
    pub namespace: String,
    /// ROS_DOMAIN_ID (default: the environment's, else 0).
    #[cfg_attr(feature = "clap", arg(long, value_name = "ID"))]
    pub domain: Option<u32>,
    /// A Zenoh router on the lab's network (tcp/HOST:7447; repeat for several). Without it
    /// nothing leaves this machine: the session reaches tcp/localhost:7447 (rmw_zenohd) and
    /// listens on loopback only.
    #[cfg_attr(feature = "clap", arg(long, value_name = "ENDPOINT"))]
    pub zenoh_connect: Vec<String>,
    /// A Zenoh configuration file (JSON5, as zenohd takes: TLS, access control, the lab's
    /// endpoints).
    #[cfg_attr(feature = "clap", arg(long, value_name = "FILE"))]
    pub zenoh_config: Option<PathBuf>,
}

impl Ros2Options {
    /// True when any ROS 2 output is asked for.
    pub fn any(&self) -> bool {
        self.ros2 || self.ros2_bag.is_some()
    }

    /// The robot's names: its namespace and domain (`ROS_DOMAIN_ID` when not given).
    pub fn names(&self) -> Result<Names, Ros2Error> {
        let domain = self.domain.unwrap_or_else(|| {
            std::env::var("ROS_DOMAIN_ID")
                .ok()
                .and_then(|v| v.trim().parse().ok())
                .unwrap_or(0)
        });
        Ok(Names::new(domain, &self.namespace)?)
    }

    /// The outputs asked for, or `None` when none is. `simulation`: a run with no real time
    /// to keep (the demo) waits up to 5 s for its router before its first message and has
    /// Zenoh block rather than drop; the robot does neither.
    pub fn start(
        &self,
        ids: &IdConfig,
        catalog: &TerrainCatalog,
        simulation: bool,
    ) -> Result<Option<Ros2Output>, Ros2Error> {
        let wait_for_router = simulation.then_some(Duration::from_secs(5));
        if !self.any() {
            return Ok(None);
        }
        let names = self.names()?;
        let bag = match &self.ros2_bag {
            Some(dir) => Some(crate::RosBag::create(dir, names.clone())?),
            None => None,
        };
        let zenoh = if self.ros2 {
            Some(self.zenoh(&names, wait_for_router)?)
        } else {
            None
        };
        Ok(Some(Ros2Output::new(
            crate::Encoder::new(ids.clone(), catalog.clone(), &names),
            zenoh,
            bag,
        )))
    }

    #[cfg(feature = "zenoh")]
    fn zenoh(
        &self,
        names: &Names,
        wait_for_router: Option<Duration>,
    ) -> Result<crate::ZenohPublisher, Ros2Error> {
        let opts = crate::ZenohOptions {
            connect: self.zenoh_connect.clone(),
            config: self.zenoh_config.clone(),
            lossless: wait_for_router.is_some(),
        };
        let mut p = crate::ZenohPublisher::open(names.clone(), &opts)?;
        let router = if opts.connect.is_empty() {
            crate::publisher::DEFAULT_ROUTER.to_string()
        } else {
            opts.connect.join(", ")
        };
        if let Some(t) = wait_for_router
            && !p.wait_for_router(t)
        {
            tracing::warn!(
                "no Zenoh router at {router} after {:.0} s: publishing anyway (messages reach \
                 subscribers once a router is there; start one with `ros2 run rmw_zenoh_cpp \
                 rmw_zenohd` or zenohd)",
                t.as_secs_f64()
            );
        }
        tracing::info!(
            namespace = %names.namespace,
            domain = names.domain,
            "ROS 2 on Zenoh (rmw_zenoh format) via {router}"
        );
        Ok(p)
    }

    #[cfg(not(feature = "zenoh"))]
    fn zenoh(&self, _: &Names, _: Option<Duration>) -> Result<std::convert::Infallible, Ros2Error> {
        Err(Ros2Error::NoZenoh)
    }
}
