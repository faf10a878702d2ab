//! Config files: the one loader of the node's, the controller's, the simulator's and the DBC
//! tool's files (TOML, or JSON by the file's extension), and the errors every config check
//! returns: each names the file, the key and what is allowed.
//!
//! ```
//! use presrs_protocol::{config, IdConfig};
//! #[derive(serde::Deserialize)]
//! struct File { ids: IdConfig }
//! let f: File = config::parse("[ids]\nextended = true\n", "robot.toml")?;
//! assert!(f.ids.extended);
//! match config::parse::<File>("[ids]\nextended = 3\n", "robot.toml") {
//!     Err(e) => assert!(e.to_string().starts_with("robot.toml: ")),
//!     Ok(_) => unreachable!("3 is not a bool"),
//! }
//! # Ok::<(), config::ConfigFileError>(())
//! ```

use std::fmt::Display;
use std::path::Path;

use serde::Deserialize as _;
use serde::de::DeserializeOwned;
use thiserror::Error;

use crate::ids::IdConfig;
use crate::terrain::CatalogError;

/// A config value outside what works, or a file that does not fit together.
#[derive(Debug, Error, Clone, PartialEq, Eq)]
#[error("{message}")]
pub struct Invalid {
    /// The key, as written in the file (`feet`, `gaits[0].omega`, `segments[2].length_m`).
    pub key: String,
    /// The whole message: the key, its value and what is allowed.
    pub message: String,
}

impl Invalid {
    /// A problem with `key`, described by `message` (which names the key).
    pub fn new(key: impl Into<String>, message: impl Into<String>) -> Self {
        Self {
            key: key.into(),
            message: message.into(),
        }
    }

    /// `key = value: allowed ALLOWED`.
    pub fn range(key: &str, value: impl Display, allowed: impl Display) -> Self {
        Self::new(key, format!("{key} = {value}: allowed {allowed}"))
    }
}

/// A config file that cannot be used.
#[derive(Debug, Error, Clone, PartialEq, Eq)]
pub enum ConfigFileError {
    /// The file cannot be read.
    #[error("cannot read {path}: {reason}")]
    Read {
        /// The file.
        path: String,
        /// What the OS said.
        reason: String,
    },
    /// Not TOML (or JSON) of the expected shape: a typo in a key, a value of the wrong type.
    #[error("{path}: {reason}")]
    Parse {
        /// The file.
        path: String,
        /// What the parser said (with the line and the key).
        reason: String,
    },
    /// Parsed, but a value is outside what works.
    #[error("{path}: {source}")]
    Invalid {
        /// The file.
        path: String,
        /// Which key and why.
        source: Invalid,
    },
    /// The terrains file the config names cannot be used.
    #[error("{path}: terrains: {source}")]
    Terrains {
        /// The config file.
        path: String,
        /// What is wrong with the terrains file.
        source: CatalogError,
    },
}

impl ConfigFileError {
    /// The error for `path` whose content failed `check`.
    pub fn invalid(path: &str, source: Invalid) -> Self {
        Self::Invalid {
            path: path.to_string(),
            source,
        }
    }
}

/// Parses a config's text: JSON when `path` ends in `.json`, TOML otherwise. `path` names the
/// file in errors.
pub fn parse<T: DeserializeOwned>(text: &str, path: &str) -> Result<T, ConfigFileError> {
    let parsed = if path.ends_with(".json") {
        serde_json::from_str(text).map_err(|e| e.to_string())
    } else {
        toml::from_str(text).map_err(|e| e.to_string())
    };
    parsed.map_err(|reason| ConfigFileError::Parse {
        path: path.to_string(),
        reason: reason.trim_end().to_string(),
    })
}

/// A config file's text and its name for errors; a file that cannot be read is
/// [`ConfigFileError::Read`].
pub fn read_text(path: &Path) -> Result<(String, String), ConfigFileError> {
    let name = path.display().to_string();
    match std::fs::read_to_string(path) {
        Ok(text) => Ok((text, name)),
        Err(e) => Err(ConfigFileError::Read {
            path: name,
            reason: e.to_string(),
        }),
    }
}

/// Reads and parses a config file (see [`parse`]).
pub fn read<T: DeserializeOwned>(path: &Path) -> Result<T, ConfigFileError> {
    let (text, name) = read_text(path)?;
    parse(&text, &name)
}

/// The `[ids]` table of a config file (the node's, the controller's, or one of its own),
/// checked; the defaults when the file has no `[ids]` table.
pub fn ids_from_file(path: &Path) -> Result<IdConfig, ConfigFileError> {
    // Only the [ids] table is read: the rest of the file is another tool's business.
    #[derive(serde::Deserialize)]
    struct Toml {
        ids: Option<toml::Value>,
    }
    #[derive(serde::Deserialize)]
    struct Json {
        ids: Option<serde_json::Value>,
    }
    let (text, name) = read_text(path)?;
    let parse_error = |reason: String| ConfigFileError::Parse {
        path: name.clone(),
        reason: format!("[ids]: {reason}"),
    };
    let ids = if name.ends_with(".json") {
        match parse::<Json>(&text, &name)?.ids {
            Some(v) => IdConfig::deserialize(v).map_err(|e| parse_error(e.to_string()))?,
            None => IdConfig::default(),
        }
    } else {
        match parse::<Toml>(&text, &name)?.ids {
            Some(v) => IdConfig::deserialize(v).map_err(|e| parse_error(e.to_string()))?,
            None => IdConfig::default(),
        }
    };
    ids.validate()
        .map_err(|e| ConfigFileError::invalid(&name, Invalid::new("ids", format!("ids: {e}"))))?;
    Ok(ids)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(serde::Deserialize, Debug)]
    #[serde(deny_unknown_fields)]
    struct C {
        feet: u8,
    }

    #[test]
    fn toml_or_json_by_extension_and_errors_name_the_file() {
        assert_eq!(parse::<C>("feet = 2", "a.toml").unwrap().feet, 2);
        assert_eq!(parse::<C>("{\"feet\": 3}", "a.json").unwrap().feet, 3);
        let e = parse::<C>("fet = 2", "node.toml").unwrap_err().to_string();
        assert!(e.starts_with("node.toml: ") && e.contains("fet"), "{e}");
        let e = read::<C>(Path::new("/nonexistent/node.toml")).unwrap_err();
        assert!(matches!(e, ConfigFileError::Read { .. }), "{e}");
        assert_eq!(
            Invalid::range("feet", 0, "1..=8").to_string(),
            "feet = 0: allowed 1..=8"
        );
    }
}
