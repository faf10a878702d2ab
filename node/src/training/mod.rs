//! The robot's training path beyond the paper's fit ([`crate::classifier::train`]): how a
//! model's unknown-ground checks are chosen on the lab's own runs ([`choice`]).

pub mod choice;
