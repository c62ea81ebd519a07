//! # prt-runtime: relighting baked prt assets
//!
//! An engine loads an asset (`prt-format`), describes its lights and sky ([`rig`], [`sky`]) and
//! relights the probe volume. This crate holds the CPU reference relight ([`relight`]); every
//! GPU stage must reproduce its numbers.

// SH and colour maths index several parallel arrays with one index; range loops read best.
#![allow(clippy::needless_range_loop)]

pub mod contract;
pub mod fill;
pub mod gpu;
pub mod lights;
pub mod output;
pub mod radiance_word;
pub mod relight;
pub mod rig;
pub mod sample;
pub mod settings;
pub mod shadow_rays;
pub mod sky;
pub mod surface;

pub use relight::{CpuRelighter, RelightError, RelightStats, Relit};
pub use rig::{load_rig, load_rig_with_warnings, Lighting, RigLoadError};
pub use sample::{Sample, VolumeSampler};
pub use settings::{Bounces, LookupSettings, MAX_BOUNCES};
pub use sky::SkyModel;
