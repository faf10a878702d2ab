//! The library side of the `presrs` package: what the binary, its benchmarks and its system
//! tests share. The binary itself only wires the member crates (`src/main.rs`).

pub use lab::simdata;
