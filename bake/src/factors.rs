//! Per-probe factor tables: for every brick a probe's rays hit, the number of those rays and the
//! SH9 projection of their directions, `4pi/N sum_{rays i into the brick} Y_k(w_i)`.
//!
//! The weights come from the probe's own rays, never from a heuristic such as the prior art's
//! rescaled cosine between a brick's normal and the probe direction; every (probe, brick) pair is
//! kept however many there are. With `L_b` the brick's radiance, the probe's SH is
//! `sum_f transfer_k(f) L_{b(f)}` plus the sky term: the Monte Carlo projection of
//! conventions.md section 2 with each hit's radiance replaced by its brick's.

use glam::Vec3;
use prt_format::sh::SH_COUNT;
use prt_format::{Brick, FactorRow};

use crate::trace::Hit;

/// Factor rows of one probe while bricks are provisional ([`crate::bricks::BrickFolder`]):
/// keyed by provisional brick, sorted by it, the last field holding the sum of the rays' hit
/// points until [`finish`] turns it into the offset.
pub fn probe_rows(
    hits: &[Hit],
    hit_brick: &[u32],
    basis: &[[f32; SH_COUNT]],
    weight: f32,
) -> Vec<FactorRow> {
    let mut order: Vec<(u32, u32, usize)> = hits
        .iter()
        .zip(hit_brick)
        .enumerate()
        .map(|(i, (h, &b))| (b, h.ray, i))
        .collect();
    order.sort_unstable();
    let mut rows: Vec<FactorRow> = Vec::new();
    for (brick, ray, i) in order {
        let y = &basis[ray as usize];
        if rows.last().is_none_or(|r| r.0 != brick) {
            rows.push((brick, 0, [0.0; SH_COUNT - 1], [0.0; 3]));
        }
        let row = rows.last_mut().expect("a row was just pushed");
        row.1 += 1;
        row.3 = (Vec3::from(row.3) + hits[i].position).to_array();
        for k in 1..SH_COUNT {
            row.2[k - 1] += weight * y[k];
        }
    }
    rows
}

/// The final rows of one probe, sorted by brick: provisional bricks renumbered by `remap`, hit
/// sums turned into offsets, the mean of the rays' hit points minus the brick's centroid (see
/// `prt_format::FactorF32`).
pub fn finish(rows: &mut [FactorRow], remap: &[u32], bricks: &[Brick]) {
    for row in rows.iter_mut() {
        row.0 = remap[row.0 as usize];
        let centroid = Vec3::from(bricks[row.0 as usize].centroid);
        row.3 = (Vec3::from(row.3) / row.1 as f32 - centroid).to_array();
    }
    rows.sort_unstable_by_key(|r| r.0);
}
