//! The controller's config file: gaits, the terrain -> gait table and the switching policy,
//! read from TOML and validated against the terrain catalog.

use std::collections::BTreeMap;

use protocol::config::{ConfigFileError, Invalid};
use protocol::terrain::{CatalogError, TerrainCatalog};
use serde::{Deserialize, Serialize};

use crate::gait::Gait;

/// The controller's config file: gaits, the terrain -> gait table and the switching policy.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ControllerConfig {
    /// The gaits the controller may run (default: the paper's G1-G3).
    pub gaits: Vec<Gait>,
    /// Terrain name (the catalog's) -> gait id. A terrain not listed gets the safe gait.
    pub terrain_gaits: BTreeMap<String, u8>,
    /// A terrains file adding a lab's terrains to the paper's (see `protocol::terrain`), for
    /// `terrain_gaits` keys beyond the paper's twelve.
    pub terrains: Option<std::path::PathBuf>,
    /// The gait at start.
    pub initial_gait: u8,
    /// Gait for unknown terrain and a lost node. By margin (the largest sudden speed loss a gait
    /// survives, `presrs lab gaits`) the simulated hopper's is G3; the default stays G1 until
    /// the model's energy check knows its terrains in the safe gait (docs/decisions/safe-gait.md).
    pub safe_gait: u8,
    /// Consecutive steps of a new terrain before switching.
    pub switch_after_steps: u32,
    /// Minimum confidence of a TerrainClass that counts, percent.
    pub min_confidence_pct: f64,
    /// Node heartbeat timeout, ms.
    pub heartbeat_timeout_ms: u64,
    /// Bumpless start: how long the controller listens before it commands, ms (0: command at
    /// once). A controller (re)started on a bus where the leg already hops takes over at the
    /// next touchdown it hears, from what the bus says (see [`Controller`](crate::Controller));
    /// when no touchdown comes within this time it starts as on a fresh robot. A leg of motors
    /// whose bridge says nobody commands it is taken at once.
    pub takeover_ms: u64,
    /// LegCommand rate, Hz.
    pub command_hz: f64,
    /// GaitStatus rate, Hz (and at every switch).
    pub status_hz: f64,
    /// The foot this controller runs.
    pub foot: u8,
    /// Switch edges closer than this to the last accepted edge are bounce, µs.
    pub lockout_us: u64,
    /// The adaptation experiment in one run: on each terrain it meets, the controller runs
    /// every gait of `gaits` for this many of the terrain's steps (the safe gait first, then
    /// the others in `gaits` order), then the terrain's own gait; `presrs lab adaptation`
    /// makes the table of the run. 0 (the default): off. Give at least 20: the hopper takes
    /// about six steps to follow a switch, and those are left out of the table.
    pub sweep_steps: u32,
    /// CAN identifier map (the same `[ids]` table as the node's and the DBC's).
    pub ids: protocol::ids::IdConfig,
}

impl Default for ControllerConfig {
    fn default() -> Self {
        let terrain_gaits = [
            ("wood", 3),
            ("carpet", 3),
            ("grass", 2),
            ("clay", 1),
            ("aluminum", 2),
            ("sand", 1),
            ("pine_needles", 1),
            ("gravel", 1),
        ]
        .into_iter()
        .map(|(t, g)| (t.to_string(), g))
        .collect();
        Self {
            gaits: Gait::paper_gaits(),
            terrain_gaits,
            terrains: None,
            initial_gait: 2,
            safe_gait: 1,
            switch_after_steps: 2,
            min_confidence_pct: 60.0,
            heartbeat_timeout_ms: 500,
            takeover_ms: 2000,
            command_hz: 500.0,
            status_hz: 10.0,
            foot: 0,
            lockout_us: 20_000,
            sweep_steps: 0,
            ids: protocol::ids::IdConfig::default(),
        }
    }
}

impl ControllerConfig {
    /// The catalog the `terrains` key names (the paper's twelve without it).
    pub fn catalog(&self) -> Result<TerrainCatalog, CatalogError> {
        TerrainCatalog::load(self.terrains.as_deref())
    }

    /// Checks every field; the error names the field and the allowed range. `terrain_gaits`
    /// keys must be names in `catalog`.
    pub fn validate(&self, catalog: &TerrainCatalog) -> Result<(), Invalid> {
        if self.gaits.is_empty() {
            return Err(Invalid::new("gaits", "gaits: at least one gait is needed"));
        }
        for (i, g) in self.gaits.iter().enumerate() {
            g.validate(&format!("gaits[{i}]"))?;
        }
        let has = |id: u8| self.gaits.iter().any(|g| g.id == id);
        let ids: Vec<u8> = self.gaits.iter().map(|g| g.id).collect();
        if let Some(dup) = ids
            .iter()
            .find(|&&id| ids.iter().filter(|&&j| j == id).count() > 1)
        {
            return Err(Invalid::new(
                "gaits",
                format!("gaits: two gaits have id {dup}; each needs its own"),
            ));
        }
        for (name, id) in [
            ("initial_gait", self.initial_gait),
            ("safe_gait", self.safe_gait),
        ] {
            if !has(id) {
                return Err(Invalid::range(name, id, format!("gait ids {ids:?}")));
            }
        }
        for (t, g) in &self.terrain_gaits {
            let key = format!("terrain_gaits.{t}");
            if catalog.by_name(t).is_none_or(|t| t.is_unknown()) {
                return Err(Invalid::new(
                    &key,
                    format!(
                        "{key}: `{t}` is not a terrain in the catalog; add it to a terrains file \
                         ([[terrain]] id = N, name = \"{t}\") and set `terrains = \"FILE\"`"
                    ),
                ));
            }
            if !has(*g) {
                return Err(Invalid::range(&key, g, format!("gait ids {ids:?}")));
            }
        }
        let range = |name: &str, v: f64, lo: f64, hi: f64| {
            if v.is_finite() && (lo..=hi).contains(&v) {
                Ok(())
            } else {
                Err(Invalid::range(name, v, format!("{lo}..={hi}")))
            }
        };
        range(
            "switch_after_steps",
            self.switch_after_steps as f64,
            1.0,
            100.0,
        )?;
        range("min_confidence_pct", self.min_confidence_pct, 0.0, 100.0)?;
        range(
            "heartbeat_timeout_ms",
            self.heartbeat_timeout_ms as f64,
            50.0,
            60_000.0,
        )?;
        range("takeover_ms", self.takeover_ms as f64, 0.0, 10_000.0)?;
        range("command_hz", self.command_hz, 10.0, 5_000.0)?;
        // Longer than a stance, every edge would be taken for bounce.
        range("lockout_us", self.lockout_us as f64, 0.0, 100_000.0)?;
        range("status_hz", self.status_hz, 0.1, 100.0)?;
        range("sweep_steps", self.sweep_steps as f64, 0.0, 10_000.0)?;
        range(
            "foot",
            self.foot as f64,
            0.0,
            (protocol::ids::MAX_FEET - 1) as f64,
        )?;
        self.ids
            .validate()
            .map_err(|e| Invalid::new("ids", format!("ids: {e}")))?;
        Ok(())
    }

    /// Parses TOML or JSON (by the file's extension) and validates it against the catalog its
    /// `terrains` key names.
    pub fn parse(text: &str, path: &str) -> Result<Self, ConfigFileError> {
        let c: Self = protocol::config::parse(text, path)?;
        let catalog = c.catalog().map_err(|source| ConfigFileError::Terrains {
            path: path.to_string(),
            source,
        })?;
        c.validate(&catalog)
            .map_err(|e| ConfigFileError::invalid(path, e))?;
        Ok(c)
    }

    /// Reads and validates a config file (see [`ControllerConfig::parse`]).
    pub fn load(path: &std::path::Path) -> Result<Self, ConfigFileError> {
        let (text, name) = protocol::config::read_text(path)?;
        Self::parse(&text, &name)
    }

    /// The gait this config runs on `terrain`: its `terrain_gaits` entry, else the safe gait
    /// (`false`: not named).
    pub fn gait_for(&self, terrain: &str) -> (u8, bool) {
        match self.terrain_gaits.get(terrain) {
            Some(&g) => (g, true),
            None => (self.safe_gait, false),
        }
    }
}

/// Adds `terrain = gait` under `[terrain_gaits]` in the config file at `path` (the table
/// made at its end if missing), keeping every other line and comment as it was; the file is
/// read back and checked, and left as it was when the result does not load. A terrain the
/// file names already is left alone (`Ok(false)`).
pub fn add_terrain_gait(
    path: &std::path::Path,
    terrain: &str,
    gait: u8,
) -> Result<bool, AddGaitError> {
    let (text, name) = protocol::config::read_text(path)?;
    let cfg = ControllerConfig::parse(&text, &name)?;
    if cfg.terrain_gaits.contains_key(terrain) {
        return Ok(false);
    }
    // A line edit, not a re-serialisation: the lab's comments and order stay (no maintained
    // crate keeps them through serde's round trip).
    let line = format!("{terrain} = {gait}                  # added by `presrs discover --add`");
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    match lines
        .iter()
        .position(|l| l.trim_start().starts_with("[terrain_gaits]"))
    {
        Some(i) => lines.insert(i + 1, line),
        None => {
            // The file ran on the default table: a table of its own must carry it whole.
            lines.push(String::new());
            lines.push("[terrain_gaits]".into());
            lines.extend(cfg.terrain_gaits.iter().map(|(t, g)| format!("{t} = {g}")));
            lines.push(line);
        }
    }
    let new = lines.join("\n") + "\n";
    ControllerConfig::parse(&new, &name)?;
    std::fs::write(path, new).map_err(|e| AddGaitError::Write(name, e))?;
    Ok(true)
}

/// Why [`add_terrain_gait`] left the file as it was.
#[derive(Debug, thiserror::Error)]
pub enum AddGaitError {
    /// The file does not load, before or with the line.
    #[error(transparent)]
    Config(#[from] ConfigFileError),
    /// It could not be written.
    #[error("cannot write {0}: {1}")]
    Write(String, #[source] std::io::Error),
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A controller on a fresh robot: commanding at once, no takeover.
    pub(crate) fn fresh() -> ControllerConfig {
        ControllerConfig {
            takeover_ms: 0,
            ..ControllerConfig::default()
        }
    }

    #[test]
    fn invalid_config_names_the_field() {
        for (text, key) in [
            ("lockout_us = 500000", "lockout_us"),
            ("switch_after_steps = 0", "switch_after_steps"),
            ("command_hz = 0.0", "command_hz"),
        ] {
            let e = ControllerConfig::parse(text, "c.toml")
                .unwrap_err()
                .to_string();
            assert!(e.contains(key) && e.contains("c.toml"), "{text}: {e}");
        }
        let mut two = fresh();
        two.gaits.push(Gait::g1());
        let e = two
            .validate(&TerrainCatalog::paper())
            .unwrap_err()
            .to_string();
        assert!(e.contains("two gaits have id 1"), "{e}");
        let e = ControllerConfig::parse("safe_gait = 9", "c.toml").unwrap_err();
        assert!(e.to_string().contains("c.toml: safe_gait = 9"), "{e}");
        let e = ControllerConfig::parse("min_confidence_pct = 120.0", "c.toml").unwrap_err();
        let ConfigFileError::Invalid { source, .. } = &e else {
            panic!("{e:?}");
        };
        assert_eq!(source.key, "min_confidence_pct");
        assert!(source.message.contains("0..=100"), "{e}");
    }

    #[test]
    fn a_new_terrains_gait_is_added_to_the_file_with_its_comments_kept() {
        let dir = std::env::temp_dir().join(format!("presrs-ctl-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("c.toml");
        std::fs::write(&p, "# the lab's\nsafe_gait = 2\n").unwrap();
        assert!(add_terrain_gait(&p, "sandpaper_60", 2).unwrap());
        let text = std::fs::read_to_string(&p).unwrap();
        assert!(text.starts_with("# the lab's\n"), "{text}");
        let c = ControllerConfig::load(&p).unwrap();
        assert_eq!(c.gait_for("sandpaper_60"), (2, true));
        // The file ran on the default table: it keeps every terrain of it.
        let d = ControllerConfig::default();
        assert_eq!(c.gait_for("wood"), d.gait_for("wood"));
        // Named already: left alone. A terrain no catalog has: refused, the file as it was.
        assert!(!add_terrain_gait(&p, "sandpaper_60", 1).unwrap());
        assert!(add_terrain_gait(&p, "moon_dust", 2).is_err());
        assert_eq!(std::fs::read_to_string(&p).unwrap(), text);
        assert_eq!(d.gait_for("moon_dust"), (d.safe_gait, false));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
