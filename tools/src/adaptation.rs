//! The paper's Table 3 for the lab's own robot: forward speed per terrain and gait, from any
//! recorded run that holds FootContact, LegState, GaitStatus and TerrainClass, with no
//! simulator truth. Each hop is measured as the controller measures it
//! ([`controller::stride`], run here by a listening [`controller::Controller`] per foot, so
//! the debounce and the clocks are the robot's own); its terrain is the node's decision of its
//! stance, its gait the one in force at its touchdown.
//!
//! A hop just after a gait or terrain change runs at the old gait's speed: the hopper takes
//! about [`SETTLE_STRIDES`] steps to follow (`controller::machine`'s switch rate), so those
//! strides are listed but not in the table.

use std::collections::BTreeMap;

use controller::{Controller, ControllerConfig};
use node::order_stats::{median, upper_quantile};
use protocol::messages::{Message, TERRAIN_UNKNOWN, decode};
use protocol::{IdConfig, Stamped, TerrainCatalog};

/// Strides after a change of gait or terrain left out of the table.
pub const SETTLE_STRIDES: usize = 6;

/// One hop of the run.
#[derive(Clone, Debug, PartialEq)]
pub struct Stride {
    /// The foot.
    pub foot: u8,
    /// Its touchdown on the log's clock, µs.
    pub touchdown_us: u64,
    /// The node's terrain for its stance (`TERRAIN_UNKNOWN` when none was heard or unknown).
    pub terrain: u8,
    /// The gait in force at its touchdown (0: no GaitStatus heard yet).
    pub gait: u8,
    /// The measured hop.
    pub hop: controller::stride::StrideEstimate,
    /// At least [`SETTLE_STRIDES`] strides since the gait or the terrain last changed.
    pub settled: bool,
}

/// One cell of the table: a terrain and gait's settled strides.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cell {
    /// Strides.
    pub strides: usize,
    /// Median forward speed, m/s.
    pub median_m_s: f64,
    /// The interquartile range, m/s.
    pub quartiles_m_s: (f64, f64),
}

/// Per foot: the listening controller, the hops it closed, what the node and the controller
/// said meanwhile.
struct Foot {
    controller: Controller,
    last_touchdown: Option<u64>,
    /// TerrainClass receive times and terrains since the last stride closed.
    terrains: Vec<(u64, u8)>,
    since_change: usize,
    last_key: Option<(u8, u8)>,
}

/// Every stride of a recorded run, in time order.
pub fn strides(
    records: impl IntoIterator<Item = Stamped>,
    ids: &IdConfig,
    catalog: &TerrainCatalog,
) -> Vec<Stride> {
    let mut feet: BTreeMap<u8, Foot> = BTreeMap::new();
    // The gait in force, with the log time it came.
    let mut gaits: Vec<(u64, u8)> = Vec::new();
    let mut out = Vec::new();
    let mut quiet = Vec::new();
    for st in records {
        let Ok(Some((foot, msg))) = decode(&st.frame, ids) else {
            continue;
        };
        let t = st.t_us;
        match msg {
            Message::GaitStatus(g) => {
                if gaits.last().is_none_or(|&(_, id)| id != g.gait) {
                    gaits.push((t, g.gait));
                }
                continue;
            }
            Message::TerrainClass(tc) => {
                if let Some(f) = feet.get_mut(&foot) {
                    f.terrains.push((t, tc.terrain));
                }
                continue;
            }
            Message::FootContact(_) | Message::LegState(_) => {}
            _ => continue,
        }
        let f = feet.entry(foot).or_insert_with(|| Foot {
            controller: Controller::new(
                ControllerConfig {
                    foot,
                    ..ControllerConfig::default()
                },
                catalog,
            ),
            last_touchdown: None,
            terrains: Vec::new(),
            since_change: 0,
            last_key: None,
        });
        quiet.clear();
        f.controller.on_message(foot, &msg, t, &mut quiet);
        let Some(hop) = f.controller.last_stride() else {
            continue;
        };
        if f.last_touchdown == Some(hop.touchdown_us) {
            continue;
        }
        f.last_touchdown = Some(hop.touchdown_us);
        // The stride began a stance and a flight before this touchdown, on the log's clock.
        let start = t.saturating_sub(((hop.stance_s + hop.flight_s) * 1e6) as u64);
        let terrain = f
            .terrains
            .iter()
            .find(|&&(at, _)| at >= start)
            .map_or(TERRAIN_UNKNOWN, |&(_, id)| id);
        f.terrains.retain(|&(at, _)| at >= t);
        let gait = gaits
            .iter()
            .rev()
            .find(|&&(at, _)| at <= start)
            .map_or(0, |&(_, g)| g);
        let key = (terrain, gait);
        f.since_change = if f.last_key == Some(key) {
            f.since_change + 1
        } else {
            0
        };
        f.last_key = Some(key);
        out.push(Stride {
            foot,
            touchdown_us: start,
            terrain,
            gait,
            hop,
            settled: f.since_change >= SETTLE_STRIDES,
        });
    }
    out
}

/// The table: per (terrain, gait) of the settled strides on known ground with a gait.
pub fn table(strides: &[Stride]) -> BTreeMap<(u8, u8), Cell> {
    let mut speeds: BTreeMap<(u8, u8), Vec<f64>> = BTreeMap::new();
    for s in strides {
        if s.settled && s.terrain != TERRAIN_UNKNOWN && s.gait != 0 {
            speeds
                .entry((s.terrain, s.gait))
                .or_default()
                .push(s.hop.speed_m_s);
        }
    }
    speeds
        .into_iter()
        .map(|(k, mut v)| {
            (
                k,
                Cell {
                    strides: v.len(),
                    median_m_s: median(&mut v),
                    quartiles_m_s: (upper_quantile(&mut v, 0.25), upper_quantile(&mut v, 0.75)),
                },
            )
        })
        .collect()
}

/// The table as Markdown: a row per terrain, a column per gait (median speed, strides).
pub fn markdown(cells: &BTreeMap<(u8, u8), Cell>, catalog: &TerrainCatalog) -> String {
    let mut gaits: Vec<u8> = cells.keys().map(|&(_, g)| g).collect();
    gaits.sort_unstable();
    gaits.dedup();
    let mut terrains: Vec<u8> = cells.keys().map(|&(t, _)| t).collect();
    terrains.dedup();
    let mut md = String::from("| terrain |");
    for g in &gaits {
        md.push_str(&format!(" G{g} (m/s) |"));
    }
    md.push_str("\n|---|");
    md.push_str(&"---|".repeat(gaits.len()));
    md.push('\n');
    for t in terrains {
        let name = catalog
            .by_id(t)
            .map_or_else(|| format!("terrain {t}"), |x| x.name().to_string());
        md.push_str(&format!("| {name} |"));
        for g in &gaits {
            match cells.get(&(t, *g)) {
                Some(c) => md.push_str(&format!(
                    " {:.3} ({:.3}-{:.3}, {} strides) |",
                    c.median_m_s, c.quartiles_m_s.0, c.quartiles_m_s.1, c.strides
                )),
                None => md.push_str(" - |"),
            }
        }
        md.push('\n');
    }
    md
}

/// The report of a run from `source` (a log's name): what was measured, then the table. None
/// when no stride settled on known ground with a gait.
pub fn report(source: &str, strides: &[Stride], catalog: &TerrainCatalog) -> Option<String> {
    let cells = table(strides);
    if cells.is_empty() {
        return None;
    }
    let settled = strides.iter().filter(|s| s.settled).count();
    Some(format!(
        "Forward speed per terrain and gait, {source}: median (interquartile range, strides). {} \
         strides measured, {settled} settled ({SETTLE_STRIDES} after each change of gait or \
         terrain left out: the hopper takes that long to follow).\n\n{}",
        strides.len(),
        markdown(&cells, catalog)
    ))
}

/// Every stride as CSV, with [`STRIDES_CSV_HEADER`].
pub fn csv(strides: &[Stride], catalog: &TerrainCatalog) -> String {
    let mut s = format!("{STRIDES_CSV_HEADER}\n");
    for r in strides {
        let name = catalog.by_id(r.terrain).map_or_else(
            || format!("terrain {}", r.terrain),
            |x| x.name().to_string(),
        );
        s.push_str(&format!(
            "{},{},{},{},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{}\n",
            protocol::candump::format_seconds(r.touchdown_us),
            r.foot,
            name,
            r.gait,
            r.hop.speed_m_s,
            r.hop.stance_s,
            r.hop.flight_s,
            r.hop.touchdown_angle_rad,
            r.hop.liftoff_angle_rad,
            r.hop.energy_ratio,
            r.settled
        ));
    }
    s
}

/// The columns of [`csv`].
pub const STRIDES_CSV_HEADER: &str = "t_s,foot,terrain,gait,speed_m_s,stance_s,flight_s,touchdown_angle_rad,liftoff_angle_rad,energy_ratio,settled";
