//! # Filling the coarse levels' grid points: the CPU twin of `shaders/fill.wgsl`
//!
//! A sparse bake leaves the grid points away from surfaces untraced and flags them as filled
//! from a coarse level (`prt_format::tier` says which, and why this is seam-free). After every
//! gather each filled point gets the trilinear interpolation of the SH of its level's points
//! around it, each weighted by its trilinear weight times its validity and renormalised, so
//! that a coarse point inside geometry drops out as it does from any lookup, and so does a
//! corner the bake found hidden from the point (`prt_format::FILL_HIDDEN_SHIFT`). Validation
//! guarantees every filled point has a valid coarse point with a positive weight and reads no
//! filled one, so the order of the fills does not matter.

use prt_format::sh::{ShRgb, SH_COUNT};
use prt_format::{tier, Asset, Grid, Probe};

/// Sets the SH of every filled grid point of `asset` in `sh` (one per probe, grid order) from
/// the coarse points around it.
pub fn fill(asset: &Asset, sh: &mut [ShRgb]) {
    fill_points(&asset.header.grid, &asset.probes, sh);
}

/// [`fill`] of the grid points `probes` on `grid`.
pub fn fill_points(grid: &Grid, probes: &[Probe], sh: &mut [ShRgb]) {
    for (index, probe) in probes.iter().enumerate() {
        if !probe.is_filled() || index >= sh.len() {
            continue;
        }
        let mut acc = [[0.0f32; 3]; SH_COUNT];
        let mut total = 0.0f32;
        for (c, w) in tier::filled_from(grid, probes, index) {
            if c >= sh.len() {
                continue;
            }
            total += w;
            for k in 0..SH_COUNT {
                for ch in 0..3 {
                    acc[k][ch] += w * sh[c][k][ch];
                }
            }
        }
        if total > 0.0 {
            sh[index] = acc.map(|v| v.map(|x| x / total));
        }
    }
}
