//! Per-probe sky masks, stored sparse (format 17; issue 32, item 1: bytes per probe).
//!
//! A probe's sky mask says which of its `N` lattice rays ([`crate::directions`]) escaped to the
//! sky; an image sky ([`crate::rig::Sky`]) is applied at runtime by summing its radiance over
//! those rays. Stored as a plain bit per ray it was 256 bytes a probe at 2048 rays, a tenth of
//! a default bake's per-probe transport data, though most of a mask is uniform: a probe in a
//! closed room sees no sky at all, and one in the open sees it over whole regions of the
//! sphere. What is stored now, exactly the same bits:
//!
//! - **Sky order.** Bit `j` of a mask is ray [`sky_order`]`(N)[j]`, not ray `j`. The lattice is
//!   cut into `B = round(sqrt(N / 32))` bands of consecutive rays (a band is a ring of the
//!   sphere: the lattice's `z` falls with the index) and each band is sorted by its rays'
//!   azimuth, so that a 32-bit word is a compact patch of directions (at 2048 rays, a ring 0.25
//!   high and 45 degrees wide) rather than a ring all the way round. Only the patches a sky's
//!   edge crosses are then mixed. Computed from `N` alone, with integer bands and azimuths as
//!   f64 products (IEEE multiplication is exact to specify: every machine gets the same order).
//! - **Sparse words.** A probe's record is two bitmaps of [`header_words`] words each, which
//!   words are *mixed* (stored) and which are *full* (every ray escaped), then its mixed words
//!   in order; a word in neither bitmap is empty.
//! - **Index.** [`Asset::sky_mask`] starts with one word per placed probe and one more: where
//!   each probe's record starts (in words from the array's start) and where the last ends. The
//!   GPU reads the array as it is (`shaders/gather.wgsl`, `sky_word`).
//!
//! The order and the record are the format: changing [`sky_order`] (its band count included)
//! or the record's layout needs a new `FORMAT_VERSION`, or older assets would read their bits
//! as other rays (`sky_order_is_pinned` fails first).
//!
//! Default bakes (`prt bake`, 2048 rays, `prt inspect`), bytes per placed probe with the index,
//! against 256 before: Cornell 52, `fixtures/two_rooms` 20 (no sky), Sponza 88, the 120 m
//! street at 1 m 82 (in the lattice's own order, 81 / 20 / 157 / 185: a word there is a thin
//! ring of every azimuth, which a sky's edge crosses nearly always).
//!
//! [`Asset::sky_mask`]: crate::Asset::sky_mask

use crate::FormatError;

/// Bands the lattice is cut into for [`sky_order`]: as many as a band has words, which
/// measured best of 4, 8, 16 and 32 bands at 2048 rays (docs/results/packing.md, format 17).
fn bands(n: u32) -> u32 {
    ((f64::from(n) / 32.0).sqrt().round() as u32).clamp(1, n.max(1))
}

/// Bit `j` of a stored mask is lattice ray `sky_order(n)[j]`: the lattice in bands of
/// consecutive rays, each sorted by azimuth (module docs).
pub fn sky_order(n: u32) -> Vec<u32> {
    let b = u64::from(bands(n));
    // The lattice's azimuth of ray i is i times the golden angle: its fraction of a turn is
    // frac(i (3 - sqrt 5) / 2), never the same for two rays.
    let golden = (3.0 - 5.0_f64.sqrt()) / 2.0;
    let turn = |i: u32| (f64::from(i) * golden).fract();
    let band = |i: u32| u64::from(i) * b / u64::from(n);
    let mut order: Vec<u32> = (0..n).collect();
    order.sort_by(|&x, &y| band(x).cmp(&band(y)).then(turn(x).total_cmp(&turn(y))));
    order
}

/// Where each lattice ray's bit sits in a mask: the inverse of [`sky_order`].
pub fn sky_positions(n: u32) -> Vec<u32> {
    let mut at = vec![0u32; n as usize];
    for (j, &i) in sky_order(n).iter().enumerate() {
        at[i as usize] = j as u32;
    }
    at
}

/// Words of a mask of `n` rays.
pub fn mask_words(n: u32) -> usize {
    (n as usize).div_ceil(32)
}

/// Words of each of a record's two bitmaps (mixed, full) for `n` rays.
pub fn header_words(n: u32) -> usize {
    mask_words(n).div_ceil(32)
}

/// One probe's record from its mask in sky order ([`mask_words`] words, bits past `n` clear).
pub fn encode(mask: &[u32], n: u32) -> Vec<u32> {
    debug_assert_eq!(mask.len(), mask_words(n));
    let h = header_words(n);
    let mut record = vec![0u32; 2 * h];
    for (w, &word) in mask.iter().enumerate() {
        if word == full_word(w, n) {
            record[h + w / 32] |= 1 << (w % 32);
        } else if word != 0 {
            record[w / 32] |= 1 << (w % 32);
            record.push(word);
        }
    }
    record
}

/// Word `w` of a mask of `n` rays with every ray set (the last word holds only `n % 32` rays).
fn full_word(w: usize, n: u32) -> u32 {
    let rays = (n as usize).saturating_sub(32 * w).min(32);
    match rays {
        32 => u32::MAX,
        r => (1u32 << r) - 1,
    }
}

/// A probe's whole mask in sky order ([`mask_words`] words) from its `record` (`n` rays).
pub fn decode(record: &[u32], n: u32) -> Vec<u32> {
    (0..mask_words(n)).map(|w| word(record, n, w)).collect()
}

/// Word `w` of a probe's mask (bit `j`: the ray at sky-order position `32 w + j` escaped) from
/// its `record` (`n` rays). Twin of `sky_word` in `shaders/gather.wgsl`.
pub fn word(record: &[u32], n: u32, w: usize) -> u32 {
    let h = header_words(n);
    let bit = 1u32 << (w % 32);
    if record[h + w / 32] & bit != 0 {
        return full_word(w, n);
    }
    let mixed = record[w / 32];
    if mixed & bit == 0 {
        return 0;
    }
    let before: u32 = record[..w / 32].iter().map(|m| m.count_ones()).sum::<u32>()
        + (mixed & (bit - 1)).count_ones();
    record[2 * h + before as usize]
}

/// Builds [`crate::Asset::sky_mask`] from each placed probe's record, in slot order.
pub fn with_index<R: AsRef<[u32]>>(records: impl ExactSizeIterator<Item = R>) -> Vec<u32> {
    let count = records.len();
    let mut out = vec![0u32; count + 1];
    let at = |len: usize| u32::try_from(len).expect("a sky mask array under 2^32 words");
    for (slot, record) in records.enumerate() {
        out[slot] = at(out.len());
        out.extend_from_slice(record.as_ref());
    }
    out[count] = at(out.len());
    out
}

/// The record of the probe in `slot` of an indexed array ([`with_index`]; validated).
pub fn record(sky_mask: &[u32], slot: usize) -> &[u32] {
    &sky_mask[sky_mask[slot] as usize..sky_mask[slot + 1] as usize]
}

/// Checks an indexed array for `slots` placed probes of `n` rays: the index rises from just
/// past itself to the array's end, and each record is its two bitmaps (disjoint, no bit past
/// the mask's words) and exactly as many words as it marks mixed, none of them empty or full,
/// no bit past `n`.
pub fn validate(sky_mask: &[u32], slots: usize, n: u32) -> Result<(), FormatError> {
    let bad = |index: usize, what: String| FormatError::invalid("sky_mask", index, what);
    if sky_mask.len() < slots + 1 {
        return Err(FormatError::Count {
            section: "sky_mask",
            found: sky_mask.len(),
            expected: slots + 1,
        });
    }
    let (h, words) = (header_words(n), mask_words(n));
    let ends = |s: usize| sky_mask[s] as usize;
    // The index's first entry is where the first record starts, just past the index: it says
    // how many probes the array holds.
    if ends(0) != slots + 1 {
        return Err(FormatError::Count {
            section: "sky_mask",
            found: ends(0).saturating_sub(1),
            expected: slots,
        });
    }
    if ends(slots) != sky_mask.len() {
        return Err(FormatError::Count {
            section: "sky_mask",
            found: sky_mask.len(),
            expected: ends(slots),
        });
    }
    for slot in 0..slots {
        let (a, b) = (ends(slot), ends(slot + 1));
        if b < a || b > sky_mask.len() {
            return Err(bad(
                slot + 1,
                format!(
                    "index entry {} is {b}: before the previous record's start {a} or past the \
                     array's {} words",
                    slot + 1,
                    sky_mask.len()
                ),
            ));
        }
        if b < a + 2 * h {
            return Err(bad(
                slot,
                format!(
                    "record of {} words, shorter than its {} bitmap words",
                    b - a,
                    2 * h
                ),
            ));
        }
        let r = &sky_mask[a..b];
        let mixed: usize = r[..h].iter().map(|m| m.count_ones() as usize).sum();
        for w in 0..32 * h {
            let (m, f) = (r[w / 32] >> (w % 32) & 1, r[h + w / 32] >> (w % 32) & 1);
            if (m | f) != 0 && (w >= words || m & f != 0) {
                return Err(bad(
                    slot,
                    format!("word {w} marked mixed {m} and full {f} (a mask of {words} words)"),
                ));
            }
        }
        if b - a != 2 * h + mixed {
            return Err(bad(
                slot,
                format!(
                    "record of {} words, its bitmaps mark {mixed} mixed words",
                    b - a
                ),
            ));
        }
        let marked = (0..words).filter(|&w| r[w / 32] >> (w % 32) & 1 != 0);
        for (w, &word) in marked.zip(&r[2 * h..]) {
            if word == 0 || word == full_word(w, n) || word & !full_word(w, n) != 0 {
                return Err(bad(
                    slot,
                    format!("mixed word {w} is {word:#010x} (empty, full or past ray {n})"),
                ));
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The order is a permutation, and a record gives back every bit of the mask it was made
    /// from, for lattices whose last word is partial too.
    #[test]
    fn records_round_trip() {
        for n in [1, 31, 32, 100, 512, 2048, 2049, 4096] {
            let order = sky_order(n);
            let mut seen = vec![false; n as usize];
            order.iter().for_each(|&i| seen[i as usize] = true);
            assert!(seen.iter().all(|&s| s), "{n}: not a permutation");
            let words = mask_words(n);
            // Empty, full, and a cap of the sky over the upper rays (in ray order, then sky order).
            for pattern in 0..3 {
                let mut mask = vec![0u32; words];
                for (j, &i) in order.iter().enumerate() {
                    let up = (i as f64) < f64::from(n) * 0.3 || i % 7 == 0;
                    let set = match pattern {
                        0 => false,
                        1 => true,
                        _ => up,
                    };
                    mask[j / 32] |= u32::from(set) << (j % 32);
                }
                let record = encode(&mask, n);
                let indexed = with_index([record.clone(), record].into_iter());
                validate(&indexed, 2, n).unwrap();
                assert_eq!(decode(super::record(&indexed, 1), n), mask, "{n} {pattern}");
            }
        }
    }

    /// The order is the format's: these values are format 17's (module docs).
    #[test]
    fn sky_order_is_pinned() {
        let sum = |n: u32| -> u64 {
            (sky_order(n).iter().enumerate())
                .map(|(j, &i)| (j as u64 + 1) * u64::from(i))
                .sum()
        };
        assert_eq!(
            &sky_order(64)[..12],
            &[0, 55, 21, 42, 8, 63, 29, 50, 16, 37, 3, 58]
        );
        assert_eq!(
            [sum(64), sum(2048), sum(2049)],
            [65_708, 2_852_111_216, 2_856_311_920]
        );
    }

    /// At 2048 rays the sky of a probe beside a tall wall (the upper hemisphere on one side of
    /// a vertical plane) takes a few mixed words in sky order, where every word above the
    /// horizon is mixed in the lattice's order (each a ring of every azimuth).
    #[test]
    fn sky_order_makes_words_compact() {
        let n = 2048;
        let dirs = crate::directions::fibonacci_directions(n);
        let sky = |i: u32| {
            let d = dirs[i as usize];
            d[2] > 0.0 && d[0] < 0.0
        };
        let mixed = |order: &[u32]| {
            (order.chunks(32))
                .filter(|c| c.iter().any(|&i| sky(i)) && !c.iter().all(|&i| sky(i)))
                .count()
        };
        let lattice: Vec<u32> = (0..n).collect();
        let (ours, theirs) = (mixed(&sky_order(n)), mixed(&lattice));
        assert!(
            ours * 3 < theirs,
            "sky order {ours} mixed words, lattice order {theirs}"
        );
    }
}
