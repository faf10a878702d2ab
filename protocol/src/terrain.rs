//! Terrains: the one terrain type of every crate, and the catalog that names the ids on a bus.
//!
//! A [`Terrain`] is an id (`0..=254` on the bus; 255 is [`Terrain::UNKNOWN`]) and a name
//! (`[a-z0-9_]+`). The [`TerrainCatalog`] holds the paper's twelve ([`TerrainCatalog::paper`])
//! plus whatever a lab adds in a terrains file, exactly this shape:
//!
//! ```toml
//! [[terrain]]
//! id = 20
//! name = "asphalt"
//! ```
//!
//! Ids and names are unique across the defaults and the file; a clash is an error naming both
//! entries. Every tool that names terrains (training, the node, the controller's gait table,
//! the DBC's value table, the simulator) takes the same catalog, so an id means the same
//! terrain everywhere and none is ever invented.
//!
//! ```
//! use presrs_protocol::terrain::{Terrain, TerrainCatalog};
//! let cat = TerrainCatalog::from_toml("[[terrain]]\nid = 20\nname = \"asphalt\"\n", "lab.toml")?;
//! assert_eq!(cat.by_name("asphalt").map(Terrain::id), Some(20));
//! assert_eq!(cat.by_id(8), Some(Terrain::WOOD));
//! assert!(TerrainCatalog::from_toml("[[terrain]]\nid = 8\nname = \"tarmac\"\n", "x").is_err());
//! # Ok::<(), presrs_protocol::terrain::CatalogError>(())
//! ```

use std::collections::HashSet;
use std::fmt;
use std::path::Path;
use std::sync::{Mutex, OnceLock};

use serde::Deserialize;
use thiserror::Error;

/// A terrain: its id on the bus and its name. Cheap to copy and compare; names of terrains
/// from a file are interned once per process.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Terrain {
    id: u8,
    name: &'static str,
}

/// The id that means "not classified" (no sample, or below the unknown threshold).
pub const UNKNOWN_ID: u8 = 0xFF;

impl Terrain {
    /// Not classified: no sample, or the image was unlike every trained terrain.
    pub const UNKNOWN: Terrain = Terrain::paper(UNKNOWN_ID, "unknown");
    /// Section 4 (static set) and section 5 (the sandpapers' reference).
    pub const ALUMINUM: Terrain = Terrain::paper(0, "aluminum");
    /// Section 4.
    pub const SAND: Terrain = Terrain::paper(1, "sand");
    /// Section 4.
    pub const PINE_NEEDLES: Terrain = Terrain::paper(2, "pine_needles");
    /// Section 4.
    pub const GRAVEL: Terrain = Terrain::paper(3, "gravel");
    /// Section 5 (grit 220).
    pub const SANDPAPER_220: Terrain = Terrain::paper(4, "sandpaper_220");
    /// Section 5 (grit 150).
    pub const SANDPAPER_150: Terrain = Terrain::paper(5, "sandpaper_150");
    /// Section 5 (grit 100).
    pub const SANDPAPER_100: Terrain = Terrain::paper(6, "sandpaper_100");
    /// Section 5 (grit 60).
    pub const SANDPAPER_60: Terrain = Terrain::paper(7, "sandpaper_60");
    /// Section 7 (the hopper's track).
    pub const WOOD: Terrain = Terrain::paper(8, "wood");
    /// Section 7.
    pub const CARPET: Terrain = Terrain::paper(9, "carpet");
    /// Section 7.
    pub const CLAY: Terrain = Terrain::paper(10, "clay");
    /// Section 7.
    pub const GRASS: Terrain = Terrain::paper(11, "grass");

    /// The paper's twelve terrains, in id order.
    pub const PAPER: [Terrain; 12] = [
        Terrain::ALUMINUM,
        Terrain::SAND,
        Terrain::PINE_NEEDLES,
        Terrain::GRAVEL,
        Terrain::SANDPAPER_220,
        Terrain::SANDPAPER_150,
        Terrain::SANDPAPER_100,
        Terrain::SANDPAPER_60,
        Terrain::WOOD,
        Terrain::CARPET,
        Terrain::CLAY,
        Terrain::GRASS,
    ];

    const fn paper(id: u8, name: &'static str) -> Terrain {
        Terrain { id, name }
    }

    /// The id on the bus (TerrainClass, the DBC's value table).
    pub fn id(self) -> u8 {
        self.id
    }

    /// The name (a terrains file's `name`, a dataset's class folder, the controller's keys).
    pub fn name(self) -> &'static str {
        self.name
    }

    /// True for [`Terrain::UNKNOWN`].
    pub fn is_unknown(self) -> bool {
        self.id == UNKNOWN_ID
    }
}

impl fmt::Display for Terrain {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name)
    }
}

/// A terrains file or entry that cannot be used.
#[derive(Debug, Error, Clone, PartialEq, Eq)]
pub enum CatalogError {
    /// The file cannot be read.
    #[error("cannot read the terrains file {path}: {reason}")]
    Read {
        /// The file.
        path: String,
        /// What the OS said.
        reason: String,
    },
    /// The file is not TOML of the documented shape.
    #[error(
        "{origin}: not a terrains file ({reason}); expected entries like\n[[terrain]]\nid = 20\nname = \"asphalt\""
    )]
    Parse {
        /// The file.
        origin: String,
        /// What the parser said.
        reason: String,
    },
    /// An id outside 0-254.
    #[error("{origin}: terrain `{name}` has id {id}; ids are 0 to 254 (255 means unknown)")]
    IdRange {
        /// The file.
        origin: String,
        /// The entry's name.
        name: String,
        /// The entry's id.
        id: i64,
    },
    /// A name that is not `[a-z0-9_]+`.
    #[error(
        "{origin}: terrain name `{name}` (id {id}) must be lowercase letters, digits and `_`, e.g. `wet_grass`"
    )]
    BadName {
        /// The file.
        origin: String,
        /// The entry's name.
        name: String,
        /// The entry's id.
        id: u8,
    },
    /// Two entries share an id or a name.
    #[error("{origin}: terrain `{new}` clashes with {existing}: ids and names must be unique")]
    Clash {
        /// The file.
        origin: String,
        /// The new entry, as `name` (id N).
        new: String,
        /// The entry it clashes with, and where that one is from.
        existing: String,
    },
}

/// The terrains a bus knows: the paper's twelve and a lab's own. See the module docs.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TerrainCatalog {
    /// Sorted by id.
    terrains: Vec<Terrain>,
    /// How many of them came from a file (the rest are the paper's).
    added: usize,
}

impl Default for TerrainCatalog {
    fn default() -> Self {
        Self::paper()
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct File {
    #[serde(default)]
    terrain: Vec<Entry>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Entry {
    id: i64,
    name: String,
}

/// `--terrains FILE`: a lab's own terrains beside the paper's twelve, as a process's option
/// (with the `clap` feature: `#[command(flatten)]`).
#[derive(Clone, Debug, Default)]
#[cfg_attr(feature = "clap", derive(clap::Args))]
pub struct TerrainsArg {
    /// A terrains file adding your own terrains to the paper's twelve: entries
    /// `[[terrain]]` with `id = 20` and `name = "asphalt"` (ids 0-254, names [a-z0-9_]+).
    #[cfg_attr(feature = "clap", arg(long, value_name = "FILE"))]
    pub terrains: Option<std::path::PathBuf>,
}

impl TerrainsArg {
    /// The catalog: the paper's terrains plus the file's.
    pub fn catalog(&self) -> Result<TerrainCatalog, CatalogError> {
        TerrainCatalog::load(self.terrains.as_deref())
    }
}

/// A terrain name a catalog does not have ([`TerrainCatalog::known`]): the message lists the
/// catalog and names the fix.
#[derive(Debug, thiserror::Error, Clone, PartialEq, Eq)]
#[error(
    "`{name}` is not a terrain of the catalog (known: {}); add it with a terrains file \
     (--terrains)",
    known.join(", ")
)]
pub struct NotInCatalog {
    /// The name given.
    pub name: String,
    /// The catalog's names.
    pub known: Vec<String>,
}

impl TerrainCatalog {
    /// The paper's twelve terrains (ids 0-11).
    pub fn paper() -> Self {
        Self {
            terrains: Terrain::PAPER.to_vec(),
            added: 0,
        }
    }

    /// The paper's terrains plus those of a terrains file (`path`), or the paper's alone.
    pub fn load(path: Option<&Path>) -> Result<Self, CatalogError> {
        let Some(path) = path else {
            return Ok(Self::paper());
        };
        let text = std::fs::read_to_string(path).map_err(|e| CatalogError::Read {
            path: path.display().to_string(),
            reason: e.to_string(),
        })?;
        Self::from_toml(&text, &path.display().to_string())
    }

    /// The paper's terrains plus those of a terrains file's text; `origin` names it in errors.
    pub fn from_toml(text: &str, origin: &str) -> Result<Self, CatalogError> {
        let file: File = toml::from_str(text).map_err(|e| CatalogError::Parse {
            origin: origin.to_string(),
            reason: e.message().to_string(),
        })?;
        let mut cat = Self::paper();
        for e in file.terrain {
            cat.add(e.id, &e.name, origin)?;
        }
        Ok(cat)
    }

    /// Adds one terrain (as a file entry would), checking its id, name and uniqueness.
    pub fn add(&mut self, id: i64, name: &str, origin: &str) -> Result<Terrain, CatalogError> {
        let id = u8::try_from(id)
            .ok()
            .filter(|&i| i != UNKNOWN_ID)
            .ok_or_else(|| CatalogError::IdRange {
                origin: origin.to_string(),
                name: name.to_string(),
                id,
            })?;
        if name.is_empty()
            || !name
                .bytes()
                .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'_')
            || name == Terrain::UNKNOWN.name
        {
            return Err(CatalogError::BadName {
                origin: origin.to_string(),
                name: name.to_string(),
                id,
            });
        }
        if let Some(t) = self.terrains.iter().find(|t| t.id == id || t.name == name) {
            let from = if Terrain::PAPER.contains(t) {
                "a default terrain"
            } else {
                "an earlier entry"
            };
            return Err(CatalogError::Clash {
                origin: origin.to_string(),
                new: format!("`{name}` (id {id})"),
                existing: format!("`{}` (id {}), {from}", t.name, t.id),
            });
        }
        let t = Terrain {
            id,
            name: intern(name),
        };
        let at = self.terrains.partition_point(|x| x.id < id);
        self.terrains.insert(at, t);
        self.added += 1;
        Ok(t)
    }

    /// The terrain with this bus id ([`Terrain::UNKNOWN`] for 255), if the catalog has it.
    pub fn by_id(&self, id: u8) -> Option<Terrain> {
        if id == UNKNOWN_ID {
            return Some(Terrain::UNKNOWN);
        }
        self.terrains.iter().find(|t| t.id == id).copied()
    }

    /// The terrain with this name (`"unknown"` is [`Terrain::UNKNOWN`]), if the catalog has it.
    pub fn by_name(&self, name: &str) -> Option<Terrain> {
        if name == Terrain::UNKNOWN.name {
            return Some(Terrain::UNKNOWN);
        }
        self.terrains.iter().find(|t| t.name == name).copied()
    }

    /// The known terrain (never [`Terrain::UNKNOWN`]) with this name, or why not: the error
    /// lists the catalog and names the fix, for a label a user typed.
    pub fn known(&self, name: &str) -> Result<Terrain, NotInCatalog> {
        self.by_name(name)
            .filter(|t| !t.is_unknown())
            .ok_or_else(|| NotInCatalog {
                name: name.to_string(),
                known: self.iter().map(|t| t.name.to_string()).collect(),
            })
    }

    /// For printing an id heard on a bus: its name, or `id N` for one the catalog lacks.
    pub fn describe(&self, id: u8) -> String {
        match self.by_id(id) {
            Some(t) => t.name.to_string(),
            None => format!("id {id}"),
        }
    }

    /// Every terrain, in id order ([`Terrain::UNKNOWN`] not included).
    pub fn iter(&self) -> impl Iterator<Item = Terrain> + '_ {
        self.terrains.iter().copied()
    }

    /// How many terrains came from a terrains file.
    pub fn added(&self) -> usize {
        self.added
    }

    /// The lowest id from [`FIRST_LAB_ID`] up that no terrain has: the id a terrain a lab
    /// adds gets (`presrs discover --add`); None when all are taken.
    pub fn free_id(&self) -> Option<u8> {
        (FIRST_LAB_ID..UNKNOWN_ID).find(|&id| self.by_id(id).is_none())
    }
}

/// The first id a lab's own terrains get by default: the paper's end at 11, and a gap leaves
/// room for terrains a later paper adds.
pub const FIRST_LAB_ID: u8 = 20;

/// Adds the entry `id`, `name` to the terrains file at `path` (made if missing; its entries
/// kept as they are) and reads the file back: the catalog it now gives. Nothing is written
/// when the entry clashes with the file or the defaults.
pub fn append_entry(path: &Path, id: u8, name: &str) -> Result<TerrainCatalog, CatalogError> {
    let origin = path.display().to_string();
    let old = match std::fs::read_to_string(path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => String::new(),
        Err(e) => {
            return Err(CatalogError::Read {
                path: origin,
                reason: e.to_string(),
            });
        }
    };
    let mut cat = TerrainCatalog::from_toml(&old, &origin)?;
    cat.add(id as i64, name, &origin)?;
    let mut text = old;
    if !text.is_empty() && !text.ends_with('\n') {
        text.push('\n');
    }
    if !text.is_empty() {
        text.push('\n');
    }
    text.push_str(&format!("[[terrain]]\nid = {id}\nname = \"{name}\"\n"));
    std::fs::write(path, &text).map_err(|e| CatalogError::Read {
        path: origin.clone(),
        reason: format!("cannot write it: {e}"),
    })?;
    TerrainCatalog::load(Some(path))
}

/// A `'static` copy of a terrain name, made once per distinct name in a process (catalogs are
/// loaded at start-up and on reload; a few bytes per name).
fn intern(name: &str) -> &'static str {
    static NAMES: OnceLock<Mutex<HashSet<&'static str>>> = OnceLock::new();
    let mut names = NAMES
        .get_or_init(Default::default)
        .lock()
        .unwrap_or_else(|e| e.into_inner());
    if let Some(n) = names.get(name) {
        return n;
    }
    let n: &'static str = Box::leak(name.to_string().into_boxed_str());
    names.insert(n);
    n
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_entry_appended_keeps_the_file_and_a_clash_writes_nothing() {
        let dir = std::env::temp_dir().join(format!("presrs-terrains-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("terrains.toml");
        // A file not made yet: made, and read back.
        let cat = append_entry(&path, 20, "mud").unwrap();
        assert_eq!(cat.by_name("mud").map(Terrain::id), Some(20));
        assert_eq!(cat.free_id(), Some(21));
        let cat = append_entry(&path, 21, "gravel_wet").unwrap();
        assert_eq!(cat.added(), 2);
        let before = std::fs::read_to_string(&path).unwrap();
        assert!(
            before.starts_with("[[terrain]]\nid = 20\nname = \"mud\"\n"),
            "{before}"
        );
        // The same name again, a default's name, a default's id: refused, the file as it was.
        for (id, name) in [(22, "mud"), (22, "grass"), (8, "tarmac")] {
            assert!(append_entry(&path, id, name).is_err(), "{id} {name}");
            assert_eq!(std::fs::read_to_string(&path).unwrap(), before);
        }
        assert_eq!(TerrainCatalog::paper().free_id(), Some(FIRST_LAB_ID));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn the_paper_catalog_has_twelve_terrains_in_id_order() {
        let c = TerrainCatalog::paper();
        let ids: Vec<u8> = c.iter().map(Terrain::id).collect();
        assert_eq!(ids, (0..12).collect::<Vec<u8>>());
        assert_eq!(c.by_name("grass"), Some(Terrain::GRASS));
        assert_eq!(c.by_id(255), Some(Terrain::UNKNOWN));
        assert_eq!(c.by_id(12), None);
        assert_eq!(c.describe(200), "id 200");
    }

    #[test]
    fn a_file_adds_terrains_and_refuses_clashes_naming_both() {
        let c = TerrainCatalog::from_toml(
            "[[terrain]]\nid = 20\nname = \"asphalt\"\n[[terrain]]\nid = 12\nname = \"wet_grass\"\n",
            "lab.toml",
        )
        .unwrap();
        assert_eq!(c.added(), 2);
        let ids: Vec<u8> = c.iter().map(Terrain::id).collect();
        assert_eq!(&ids[10..], &[10, 11, 12, 20]);
        let asphalt = c.by_name("asphalt").unwrap();
        assert_eq!(
            (asphalt.id(), asphalt.to_string().as_str()),
            (20, "asphalt")
        );
        // Loading the same names again gives equal terrains.
        let again = TerrainCatalog::from_toml("[[terrain]]\nid = 20\nname = \"asphalt\"\n", "b")
            .unwrap()
            .by_id(20);
        assert_eq!(again, Some(asphalt));

        let clash = |text: &str| TerrainCatalog::from_toml(text, "lab.toml").unwrap_err();
        let e = clash("[[terrain]]\nid = 8\nname = \"tarmac\"\n").to_string();
        assert!(
            e.contains("`tarmac` (id 8)") && e.contains("`wood` (id 8), a default"),
            "{e}"
        );
        let e = clash("[[terrain]]\nid = 30\nname = \"grass\"\n").to_string();
        assert!(e.contains("`grass` (id 11)"), "{e}");
        let e = clash("[[terrain]]\nid = 30\nname = \"a\"\n[[terrain]]\nid = 30\nname = \"b\"\n")
            .to_string();
        assert!(
            e.contains("`b` (id 30)") && e.contains("`a` (id 30), an earlier entry"),
            "{e}"
        );
        assert!(matches!(
            clash("[[terrain]]\nid = 255\nname = \"x\"\n"),
            CatalogError::IdRange { id: 255, .. }
        ));
        assert!(matches!(
            clash("[[terrain]]\nid = -1\nname = \"x\"\n"),
            CatalogError::IdRange { .. }
        ));
        assert!(matches!(
            clash("[[terrain]]\nid = 40\nname = \"Wet Grass\"\n"),
            CatalogError::BadName { .. }
        ));
        assert!(matches!(
            clash("[[terrain]]\nid = 40\nname = \"unknown\"\n"),
            CatalogError::BadName { .. }
        ));
        assert!(matches!(
            clash("[[terrain]]\nid = 40\nname = \"x\"\ncolour = 3\n"),
            CatalogError::Parse { .. }
        ));
        let example = include_str!("../../examples/terrains.toml");
        assert_eq!(
            TerrainCatalog::from_toml(example, "example")
                .unwrap()
                .added(),
            2
        );
        let e = TerrainCatalog::load(Some(Path::new("/nonexistent/terrains.toml"))).unwrap_err();
        assert!(e.to_string().contains("/nonexistent/terrains.toml"), "{e}");
    }
}
