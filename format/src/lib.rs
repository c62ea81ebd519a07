//! # prt-format: the baked PRT GI asset
//!
//! The types an engine needs to load a prt bake, their binary (de)serialization and their
//! validation. This crate knows no GPU and no BVH builder: the baker (`prt-bake`) produces an
//! [`Asset`], the runtime (`prt-runtime`) consumes one, and both depend only on this crate for it.
//!
//! ## What a bake stores
//! For every probe of a regular grid the baker shot `ray_count` rays along a fixed spherical
//! Fibonacci lattice ([`directions`]). Rays that escaped are sky: they are kept as a per-probe bit
//! mask over the lattice (stored sparse, [`sky_mask`]) plus the SH9 projection of those
//! directions, so that any sky can be applied at runtime. Rays that hit geometry became surfels;
//! surfels were merged into normal-keyed bricks, and each probe keeps a factor table: for every
//! brick its rays hit, the number of those rays, the SH9 projection of their directions
//! (weight 4pi/N each) and their mean hit point relative to the brick's centroid. A brick's radiance is a linear model (mean and gradient, fitted over
//! its surfels); at runtime, with `L_b(x)` that model evaluated at offset `x`:
//!
//! `c_k(probe) = sum over factors f of transfer_k(f) * L_{brick(f)}(offset(f)) + sky term`
//!
//! which is exactly the Monte Carlo projection of docs/conventions.md section 2 when every ray hit its
//! own brick (merging off), and an approximation that shares relighting work between probes
//! otherwise. Factors are stored in f32, f16 or (default) 8-byte slots: most as a lobe toward
//! their mean hit point ([`lobe`]), the others with packed terms of 5-7 bits ([`TransferPrecision`]).
//!
//! ## File layout ([`io`])
//! `magic (8) | format_version u32 | payload length u64 | payload (bincode 2) | xxh3-64 checksum`.
//! Loading checks magic, version, length and checksum before decoding, then validates every count,
//! index range and float ([`validate`]). It returns a typed [`FormatError`] and never panics.

// SH and colour maths index several parallel arrays with one index; range loops read best.
#![allow(clippy::needless_range_loop)]

pub mod asset;
pub mod coarse;
pub mod depth;
pub mod directions;
pub mod error;
pub mod factors;
pub mod io;
pub mod lobe;
pub mod rig;
mod sections;
pub mod sh;
pub mod sky_mask;
mod snorm;
pub mod summary;
pub mod surface;
pub mod surfel;
pub mod surfel_terms;
pub mod tier;
pub mod validate;

pub use asset::*;
pub use error::FormatError;
pub use factors::*;
pub use io::{
    decode, encode, read_asset, read_regular_file, stage_asset, write_asset_atomic, Staged,
    FORMAT_VERSION, MAGIC,
};
pub use rig::{Light, LightKind, LightRig, Sky};
pub use summary::Summary;
pub use surfel::PackedSurfel;
