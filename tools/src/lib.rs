#![forbid(unsafe_code)]
#![warn(missing_docs)]
//! # presrs-tools: the lab's tools for a real robot
//!
//! What a lab runs on its own robot's data, beside the robot and never on it, with no
//! simulator in its dependencies:
//! - [`adaptation`]: the paper's Table 3 for the lab's robot, speed per terrain and gait from a
//!   recorded run (`presrs lab adaptation`);
//! - [`contact_sheet`]: example stance images of a proposed terrain as one PNG (`presrs
//!   discover --out`);
//! - [`discover_report`]: what `presrs discover` prints and writes of the groups it found;
//! - [`eval`]: a model judged on a captured session (`presrs eval`): confusion, accuracy,
//!   unknown shares, time per classification;
//! - [`replay`]: a candump log to an MCAP recording or a ROS 2 bag, with a model's decisions
//!   beside what the robot's node said (`presrs mcap`);
//! - [`view`]: a recording's pressure image, terrain, contact, gait and speed in one PNG
//!   (`presrs view`), the panels of `docs/foxglove-layout.json`;
//! - [`plot`]: the bundled font and the error every figure shares (the paper's figures in
//!   `presrs-lab` draw with it too).

pub mod adaptation;
pub mod contact_sheet;
pub mod discover_report;
pub mod eval;
pub mod plot;
pub mod replay;
pub mod view;
