//! RIHS01 type hashes, as ROS 2 computes them (REP 2011, `rosidl_generator_type_description`):
//! SHA-256 of the type description as JSON (the type's fields, then every type it references,
//! sorted by name; default values left out), with Python's `json.dumps` separators. rmw_zenoh
//! puts the hash in every key expression, so a subscriber with another definition of the type
//! never matches. Written here because no maintained Rust crate computes it; the test suite
//! checks it against `rosbags`' own computation for every type.

use sha2::{Digest, Sha256};
use std::fmt::Write;

use crate::types::{Base, MsgType, referenced};

/// `RIHS01_` and 64 hex digits.
pub fn rihs01(t: &MsgType) -> String {
    let json = description_json(t);
    let digest = Sha256::digest(json.as_bytes());
    let mut s = String::with_capacity(7 + 64);
    s.push_str("RIHS01_");
    for b in digest {
        let _ = write!(s, "{b:02x}");
    }
    s
}

/// The JSON that is hashed.
pub fn description_json(t: &MsgType) -> String {
    let mut s = String::from("{\"type_description\": ");
    one(&mut s, t);
    s.push_str(", \"referenced_type_descriptions\": [");
    for (i, r) in referenced(t).into_iter().enumerate() {
        if i > 0 {
            s.push_str(", ");
        }
        one(&mut s, r);
    }
    s.push_str("]}");
    s
}

fn one(s: &mut String, t: &MsgType) {
    let _ = write!(s, "{{\"type_name\": \"{}\", \"fields\": [", t.name);
    for (i, f) in t.fields.iter().enumerate() {
        if i > 0 {
            s.push_str(", ");
        }
        let id = f.base.type_id() + if f.sequence { 144 } else { 0 };
        let nested = match f.base {
            Base::Nested(n) => n,
            _ => "",
        };
        let _ = write!(
            s,
            "{{\"name\": \"{}\", \"type\": {{\"type_id\": {id}, \"capacity\": 0, \
             \"string_capacity\": 0, \"nested_type_name\": \"{nested}\"}}}}",
            f.name
        );
    }
    s.push_str("]}");
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::types;

    #[test]
    fn standard_types_hash_as_ros_2_publishes_them() {
        // Values from ROS 2 Jazzy's generated type descriptions (`ros2 interface` / the
        // packages' `*.json`), also what `rosbags` computes; the interop test recomputes
        // every type with rosbags.
        assert_eq!(
            rihs01(&types::TIME),
            "RIHS01_b106235e25a4c5ed35098aa0a61a3ee9c9b18d197f398b0e4206cea9acf9c197"
        );
        assert_eq!(
            rihs01(&types::HEADER_MSG),
            "RIHS01_f49fb3ae2cf070f793645ff749683ac6b06203e41c891e17701b1cb597ce6a01"
        );
    }

    #[test]
    fn the_json_has_python_separators_and_sorted_references() {
        let j = description_json(&types::HEADER_MSG);
        assert!(j.starts_with(
            "{\"type_description\": {\"type_name\": \"std_msgs/msg/Header\", \"fields\": \
             [{\"name\": \"stamp\", \"type\": {\"type_id\": 1, \"capacity\": 0, "
        ));
        assert!(j.ends_with("\"nested_type_name\": \"\"}}]}]}"));
    }
}
