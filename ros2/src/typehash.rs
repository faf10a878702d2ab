//! RIHS01 type hashes (REP 2011): rmw_zenoh puts one in every key expression, so a subscriber
//! with another definition of a type never matches. The hash itself is the `ros2-types`
//! crate's (SHA-256 of the type description as rosidl writes it); this module hands it our
//! [`crate::types`] tables. The test suite checks every hash against `rosbags`' own.

use ros2_types::types::{Field, FieldType, IndividualTypeDescription, TypeDescriptionMsg};

use crate::types::{Base, MsgType, referenced};

/// `RIHS01_` and 64 hex digits.
pub fn rihs01(t: &MsgType) -> String {
    let msg = TypeDescriptionMsg::new(
        individual(t),
        referenced(t).into_iter().map(individual).collect(),
    );
    // It only fails on JSON it cannot write; ours is plain names and numbers.
    ros2_types::calculate_type_hash(&msg).unwrap_or_else(|_| "RIHS01_".into())
}

fn individual(t: &MsgType) -> IndividualTypeDescription {
    let fields = t
        .fields
        .iter()
        .map(|f| {
            let ty = match (f.base, f.sequence) {
                (Base::Nested(n), false) => FieldType::nested(n),
                (Base::Nested(n), true) => FieldType::nested_sequence(n),
                (b, false) => FieldType::primitive(b.type_id()),
                // An unbounded sequence: 144 above the element's id (FieldType.msg).
                (b, true) => FieldType::primitive(b.type_id() + 144),
            };
            Field::new(f.name, ty)
        })
        .collect();
    IndividualTypeDescription::new(t.name, fields)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::types;

    #[test]
    fn standard_types_hash_as_ros_2_publishes_them() {
        // ROS 2 Jazzy's hashes, as `rosbags` computes them (the interop test recomputes every
        // type with it).
        assert_eq!(
            rihs01(&types::TIME),
            "RIHS01_b106235e25a4c5ed35098aa0a61a3ee9c9b18d197f398b0e4206cea9acf9c197"
        );
        assert_eq!(
            rihs01(&types::HEADER_MSG),
            "RIHS01_f49fb3ae2cf070f793645ff749683ac6b06203e41c891e17701b1cb597ce6a01"
        );
        assert_eq!(
            rihs01(&types::IMAGE),
            "RIHS01_d31d41a9a4c4bc8eae9be757b0beed306564f7526c88ea6a4588fb9582527d47"
        );
        assert_eq!(
            rihs01(&types::DIAGNOSTIC_ARRAY),
            "RIHS01_5a8a36efb05fb25070fa0fb3810290c0e6cd4862b54a8fb975a1ee8dc55a333e"
        );
        assert_eq!(
            rihs01(&types::JOINT_STATE),
            "RIHS01_a13ee3a330e346c9d87b5aa18d24e11690752bd33a0350f11c5882bc9179260e"
        );
    }
}
