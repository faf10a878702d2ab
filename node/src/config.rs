//! The node's configuration file (`node.toml`).

use protocol::IdConfig;
use protocol::config::{ConfigFileError, Invalid};
use protocol::terrain::{CatalogError, TerrainCatalog};
use serde::{Deserialize, Serialize};

/// How dead sensor lines are repaired before classification.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RepairMode {
    /// No repair.
    None,
    /// The paper's filter on every image: fills every all-zero line, also legitimately empty ones.
    PerImage,
    /// Only lines learned dead from the stance history (zero while their neighbours carry load
    /// for `dead_after_stances` stances in a row).
    History,
}

/// Whether and how the model is refitted to a foot's dead lines (history repair only).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RefitMode {
    /// Classify damaged images with the model as trained (after the repair).
    Off,
    /// Refit on the classification thread when the dead lines change: that step's decision
    /// waits for it (about 0.1 s). Reproducible; the replay and the lock-step demo use it.
    Inline,
    /// Refit on a background thread; until it is done, the model as trained decides.
    Background,
}

impl RefitMode {
    /// The mode whose decisions do not depend on the wall clock: background becomes inline.
    pub fn reproducible(self) -> Self {
        match self {
            RefitMode::Background => RefitMode::Inline,
            m => m,
        }
    }
}

/// The paper's sampled frame, ms after touchdown (section 7.1): the node's when neither its
/// config nor its model names one.
pub const DEFAULT_SAMPLE_MS: u32 = 70;

/// The node's config file (`/etc/presrs/node.toml`); every key has a default.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct NodeConfig {
    /// Feet served: 0..feet.
    pub feet: u8,
    /// Micro-switch debounce, µs.
    pub debounce_us: u32,
    /// Stance time of the sampled frame, ms: set, it pins the frame (the lab's word wins over
    /// the model's); unset, the model's (`train` measured it on the lab's stances), else
    /// [`DEFAULT_SAMPLE_MS`]. A capture made with it set keeps its stances at that time, and
    /// `train` then pins the model to it.
    pub sample_ms: Option<u32>,
    /// How dead sensor lines are filled.
    pub repair: RepairMode,
    /// Stances in a row a line must stay dead before the history repair fills it.
    pub dead_after_stances: u32,
    /// Refit the model to each foot's learned dead lines (needs a model file that holds its
    /// training images, as `presrs train` writes them).
    pub refit: RefitMode,
    /// Classify every frame in `window_ms` and sum log-posteriors.
    pub multi_frame: bool,
    /// The multi-frame window after touchdown, ms.
    pub window_ms: [u32; 2],
    /// Below this confidence the TerrainClass carries LOW_CONFIDENCE.
    pub low_confidence: f64,
    /// NodeStatus rate, Hz.
    pub status_hz: f64,
    /// Incomplete tactile images are dropped after this long after their first segment, µs.
    /// The spec's 100 ms: a classic-CAN image (391 frames at 111-135 µs, up to 53 ms at full
    /// bus load) must fit, and at 50 ms the worst case did not.
    pub reassembly_timeout_us: u64,
    /// A terrains file adding a lab's terrains to the paper's (`protocol::terrain`): the model's
    /// classes are checked against this catalog at load.
    pub terrains: Option<std::path::PathBuf>,
    /// The CAN identifiers.
    pub ids: IdConfig,
}

impl Default for NodeConfig {
    fn default() -> Self {
        Self {
            feet: 1,
            debounce_us: 5_000,
            sample_ms: None,
            repair: RepairMode::History,
            dead_after_stances: 5,
            refit: RefitMode::Background,
            multi_frame: false,
            window_ms: [40, 100],
            low_confidence: 0.6,
            status_hz: 10.0,
            reassembly_timeout_us: 100_000,
            terrains: None,
            ids: IdConfig::default(),
        }
    }
}

impl NodeConfig {
    /// Parses and checks a TOML config (JSON with a `.json` name); the error names the file,
    /// the key and the range.
    pub fn from_toml(text: &str, path: &str) -> Result<Self, ConfigFileError> {
        let c: Self = protocol::config::parse(text, path)?;
        c.validate()
            .map_err(|e| ConfigFileError::invalid(path, e))?;
        c.catalog().map_err(|source| ConfigFileError::Terrains {
            path: path.to_string(),
            source,
        })?;
        Ok(c)
    }

    /// Reads and checks a config file.
    pub fn load(path: &std::path::Path) -> Result<Self, ConfigFileError> {
        let (text, name) = protocol::config::read_text(path)?;
        Self::from_toml(&text, &name)
    }

    /// A process's node config: the file at `path` (the defaults without one), its `terrains`
    /// key overridden by `terrains` (the process's `--terrains`) when given.
    pub fn load_or_default(
        path: Option<&std::path::Path>,
        terrains: &protocol::TerrainsArg,
    ) -> Result<Self, ConfigFileError> {
        let mut cfg = match path {
            Some(p) => Self::load(p)?,
            None => Self::default(),
        };
        if terrains.terrains.is_some() {
            cfg.terrains.clone_from(&terrains.terrains);
        }
        Ok(cfg)
    }

    /// The catalog the `terrains` key names (the paper's twelve without it).
    pub fn catalog(&self) -> Result<TerrainCatalog, CatalogError> {
        TerrainCatalog::load(self.terrains.as_deref())
    }

    /// Checks every key against its allowed range.
    pub fn validate(&self) -> Result<(), Invalid> {
        if self.feet == 0 || self.feet > protocol::ids::MAX_FEET {
            return Err(Invalid::range(
                "feet",
                self.feet,
                format!("1..={}", protocol::ids::MAX_FEET),
            ));
        }
        if self.debounce_us > 50_000 {
            return Err(Invalid::range("debounce_us", self.debounce_us, "0..=50000"));
        }
        if !(1..=1000).contains(&self.dead_after_stances) {
            return Err(Invalid::range(
                "dead_after_stances",
                self.dead_after_stances,
                "1..=1000",
            ));
        }
        if self.window_ms[1] > 1000 {
            return Err(Invalid::new(
                "window_ms",
                format!(
                    "window_ms = {:?}: the end must be at most 1000",
                    self.window_ms
                ),
            ));
        }
        if let Some(ms) = self.sample_ms
            && !(10..=500).contains(&ms)
        {
            return Err(Invalid::range("sample_ms", ms, "10..=500"));
        }
        if self.window_ms[0] >= self.window_ms[1] {
            return Err(Invalid::new(
                "window_ms",
                format!(
                    "window_ms = {:?}: the start must be before the end",
                    self.window_ms
                ),
            ));
        }
        if !(0.0..=1.0).contains(&self.low_confidence) {
            return Err(Invalid::range(
                "low_confidence",
                self.low_confidence,
                "0..=1",
            ));
        }
        // At least one frame period (an image needs time to arrive), at most a second (the
        // reassembler's two slots per foot hold stale halves no longer than that).
        if !(10_000..=1_000_000).contains(&self.reassembly_timeout_us) {
            return Err(Invalid::range(
                "reassembly_timeout_us",
                self.reassembly_timeout_us,
                "10000..=1000000",
            ));
        }
        if !(0.1..=100.0).contains(&self.status_hz) {
            return Err(Invalid::range("status_hz", self.status_hz, "0.1..=100"));
        }
        self.ids
            .validate()
            .map_err(|e| Invalid::new("ids", format!("ids: {e}")))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_agrees_with_the_spec_and_a_zero_timeout_is_refused() {
        assert_eq!(NodeConfig::default().reassembly_timeout_us, 100_000);
        assert!(NodeConfig::default().validate().is_ok());
        for bad in [0, 9_999, 1_000_001] {
            let cfg = NodeConfig {
                reassembly_timeout_us: bad,
                ..NodeConfig::default()
            };
            let e = cfg.validate().unwrap_err().to_string();
            assert!(
                e.contains("reassembly_timeout_us") && e.contains("10000..=1000000"),
                "{e}"
            );
        }
    }
}
