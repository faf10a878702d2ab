//! The track: a circle of terrain segments, read from TOML and checked against the catalog.

use super::{
    CannotSimulate, ConfigFileError, Deserialize, Invalid, Physics, Terrain, TerrainCatalog,
};

/// One stretch of the track: a catalog terrain the simulator has a model for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Segment {
    pub(super) terrain: Terrain,
    pub(super) physics: Physics,
    /// Length along the track, m.
    pub length_m: f64,
}

impl Segment {
    /// A stretch of `terrain`; an error when the simulator cannot simulate it.
    pub fn new(terrain: Terrain, length_m: f64) -> Result<Self, CannotSimulate> {
        Ok(Self {
            terrain,
            physics: Physics::of(terrain)?,
            length_m,
        })
    }

    pub(super) fn of(physics: Physics, length_m: f64) -> Self {
        Self {
            terrain: physics.terrain(),
            physics,
            length_m,
        }
    }

    /// The terrain of this stretch.
    pub fn terrain(&self) -> Terrain {
        self.terrain
    }
}

/// The paper's circular track (2.8 m diameter) made of terrain segments.
#[derive(Clone, Debug, PartialEq)]
pub struct Track {
    /// Diameter of the circle, m (the paper's: 2.8).
    pub diameter_m: f64,
    /// The terrains in order along the track.
    pub segments: Vec<Segment>,
}

/// A track file: `diameter_m` and `[[segments]]` with `terrain` (a catalog name) and `length_m`.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct TrackFile {
    #[serde(default = "default_diameter")]
    diameter_m: f64,
    segments: Vec<SegmentFile>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct SegmentFile {
    terrain: String,
    length_m: f64,
}

pub(super) fn default_diameter() -> f64 {
    2.8
}

impl Default for Track {
    /// Wood, grass, clay and carpet, a quarter of the circle each.
    fn default() -> Self {
        let q = std::f64::consts::PI * 2.8 / 4.0;
        Self {
            diameter_m: 2.8,
            segments: [
                Physics::Wood,
                Physics::Grass,
                Physics::Clay,
                Physics::Carpet,
            ]
            .into_iter()
            .map(|p| Segment::of(p, q))
            .collect(),
        }
    }
}

impl Track {
    /// Reads and checks a track file (see [`Track::from_toml`]).
    pub fn load(path: &std::path::Path, catalog: &TerrainCatalog) -> Result<Self, ConfigFileError> {
        let (text, name) = protocol::config::read_text(path)?;
        Self::from_toml(&text, &name, catalog)
    }

    /// The track of the file at `path` (a process's `--track`), or the default track (wood,
    /// grass, clay, carpet quarters) without one.
    pub fn load_or_default(
        path: Option<&std::path::Path>,
        catalog: &TerrainCatalog,
    ) -> Result<Self, ConfigFileError> {
        path.map_or_else(|| Ok(Self::default()), |p| Self::load(p, catalog))
    }

    /// Parses a TOML track file (`path` names it in errors) and checks it: every terrain a name
    /// in `catalog` that the simulator can simulate, every length positive.
    pub fn from_toml(
        text: &str,
        path: &str,
        catalog: &TerrainCatalog,
    ) -> Result<Self, ConfigFileError> {
        let t: TrackFile = protocol::config::parse(text, path)?;
        let invalid = |key: String, message: String| {
            ConfigFileError::invalid(path, Invalid::new(key, message))
        };
        if t.segments.is_empty() {
            return Err(invalid(
                "segments".into(),
                "segments: at least one segment is needed".into(),
            ));
        }
        let mut segments = Vec::with_capacity(t.segments.len());
        for (i, s) in t.segments.iter().enumerate() {
            if s.length_m.is_nan() || s.length_m <= 0.0 {
                let key = format!("segments[{i}].length_m");
                let message = format!("{key} = {}: must be > 0", s.length_m);
                return Err(invalid(key, message));
            }
            let key = format!("segments[{i}].terrain");
            let terrain = catalog
                .by_name(&s.terrain)
                .filter(|t| !t.is_unknown())
                .ok_or_else(|| {
                    let message = format!(
                        "{key} = \"{}\": not a terrain in the catalog (a terrains file adds one: \
                         --terrains FILE)",
                        s.terrain
                    );
                    invalid(key.clone(), message)
                })?;
            let segment = Segment::new(terrain, s.length_m)
                .map_err(|e| invalid(key.clone(), format!("{key}: {e}")))?;
            segments.push(segment);
        }
        Ok(Self {
            diameter_m: t.diameter_m,
            segments,
        })
    }

    /// Length of the track's centre line, m.
    pub fn length(&self) -> f64 {
        self.segments.iter().map(|s| s.length_m).sum()
    }

    /// The stretch at distance `x` m along the track (wrapping).
    pub fn segment_at(&self, x: f64) -> Segment {
        let mut x = x.rem_euclid(self.length().max(1e-9));
        for s in &self.segments {
            if x < s.length_m {
                return *s;
            }
            x -= s.length_m;
        }
        self.segments
            .last()
            .copied()
            .unwrap_or(Segment::of(Physics::Wood, 1.0))
    }

    /// The terrain at distance `x` m along the track (wrapping).
    pub fn terrain_at(&self, x: f64) -> Terrain {
        self.segment_at(x).terrain
    }
}
