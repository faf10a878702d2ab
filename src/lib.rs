//! The library side of the `presrs` package: what the binary, its benchmarks and its system
//! tests share. The binary itself only wires the member crates (`src/main.rs`).

#[cfg(feature = "lab")]
pub use lab::simdata;
