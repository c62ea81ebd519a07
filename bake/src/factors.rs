//! Per-probe factor tables: for every brick a probe's rays hit, the number of those rays and the
//! SH9 projection of their directions, `4pi/N sum_{rays i into the brick} Y_k(w_i)`.
//!
//! The weights come from the probe's own rays, never from a heuristic such as the prior art's
//! rescaled cosine between a brick's normal and the probe direction; every (probe, brick) pair is
//! kept however many there are. With `L_b` the brick's radiance, the probe's SH is
//! `sum_f transfer_k(f) L_{b(f)}` plus the sky term: the Monte Carlo projection of
//! conventions.md section 2 with each hit's radiance replaced by its brick's.

use prt_format::sh::{self, SH_COUNT};

use crate::trace::Hit;

/// (brick, rays, transfer k = 1..9) rows of one probe, sorted by brick.
pub fn probe_factors(
    hits: &[Hit],
    hit_brick: &[u32],
    directions: &[glam::Vec3],
    weight: f32,
) -> Vec<(u32, u32, [f32; SH_COUNT - 1])> {
    let mut order: Vec<(u32, u32)> = hits
        .iter()
        .zip(hit_brick)
        .map(|(h, &b)| (b, h.ray))
        .collect();
    order.sort_unstable();
    let mut rows: Vec<(u32, u32, [f32; SH_COUNT - 1])> = Vec::new();
    for (brick, ray) in order {
        let y = sh::basis(directions[ray as usize].to_array());
        if rows.last().is_none_or(|r| r.0 != brick) {
            rows.push((brick, 0, [0.0; SH_COUNT - 1]));
        }
        let row = rows.last_mut().expect("a row was just pushed");
        row.1 += 1;
        for k in 1..SH_COUNT {
            row.2[k - 1] += weight * y[k];
        }
    }
    rows
}
