//! The fold's map from brick key to provisional brick: open addressing with linear probing,
//! the key stored beside its brick in one 16-byte slot, so that a lookup is one cache line.
//!
//! The fold looks a brick up for nearly every run of a probe's hits in one brick (runs are
//! short) in a table far larger than the caches. A lookup in foldhash's `HashMap` reads a line
//! of control bytes, then the line of the entry: two dependent cache misses. Here the fold
//! hashes every run of a probe first and asks for their slots' lines together
//! ([`BrickIndex::home`], [`crate::memory::prefetch`]), then looks them up in order
//! ([`BrickIndex::find`]). The key is hashed by one folded multiply ([`BrickIndex::hash`]):
//! through foldhash's `Hasher` (the cell as a slice, length first, then the flags) hashing
//! cost more than the lookups.
//!
//! The hash is foldhash's folded multiply with a seed drawn per process from foldhash: the keys
//! come from where the file's geometry is, so a fixed fast hash could be made to collide. The
//! table is only looked up (and walked only to rehash it as it grows), so the seed never
//! changes the result.

use std::hash::BuildHasher;

use crate::merge::key::Key;

/// Bricks the index can number: the brick shares its slot's last word with the key's flags
/// (4 bits).
pub const MAX_BRICKS: u32 = 1 << 28;

/// A key (cell, then flags in the top 4 bits of `tag`) and its brick (the low 28 bits), or
/// nothing (`tag == EMPTY`). Four to a cache line, none across two.
#[derive(Clone, Copy)]
#[repr(C, align(16))]
struct Slot {
    cell: [i32; 3],
    tag: u32,
}
const _: () = assert!(std::mem::size_of::<Slot>() == 16);

/// An empty slot's tag: flags are at most 13 (axis 0..6, back face 8), so no key has it.
const EMPTY: u32 = u32::MAX;

const FREE: Slot = Slot {
    cell: [0; 3],
    tag: EMPTY,
};

/// Brick key to provisional brick ([module docs](self)).
pub struct BrickIndex {
    /// A power of two of them, at most three quarters full.
    slots: Vec<Slot>,
    len: usize,
    /// Per process, from foldhash's random seed.
    seed: [u64; 2],
}

impl Default for BrickIndex {
    fn default() -> Self {
        BrickIndex {
            slots: vec![FREE; 1024],
            len: 0,
            seed: {
                let random = foldhash::fast::RandomState::default();
                [random.hash_one(1u64), random.hash_one(2u64)]
            },
        }
    }
}

impl BrickIndex {
    /// Makes room for `more` keys, so that [`BrickIndex::home`]s taken before they are added
    /// stay valid while they are.
    pub fn reserve(&mut self, more: usize) {
        let needed = (self.len + more).saturating_mul(4) / 3 + 1;
        if needed <= self.slots.len() {
            return;
        }
        let old = std::mem::replace(&mut self.slots, vec![FREE; needed.next_power_of_two()]);
        for slot in old.into_iter().filter(|s| s.tag != EMPTY) {
            let mask = self.slots.len() - 1;
            let mut i = self.hash(slot.cell, slot.tag >> 28) & mask;
            while self.slots[i].tag != EMPTY {
                i = (i + 1) & mask;
            }
            self.slots[i] = slot;
        }
    }

    /// Where the search for `key` starts; its line is asked for now (a prefetch).
    #[inline]
    pub fn home(&self, key: &Key) -> usize {
        let i = self.hash([key.0, key.1, key.2], key.3) & (self.slots.len() - 1);
        crate::memory::prefetch(&self.slots[i]);
        i
    }

    /// The brick of `key`, searching from its `home`; or the free slot where it goes
    /// ([`BrickIndex::insert`]).
    #[inline]
    pub fn find(&self, key: &Key, home: usize) -> Result<u32, usize> {
        let mask = self.slots.len() - 1;
        let cell = [key.0, key.1, key.2];
        let mut i = home;
        loop {
            let s = &self.slots[i];
            if s.tag == EMPTY {
                return Err(i);
            }
            if s.cell == cell && s.tag >> 28 == key.3 {
                return Ok(s.tag & (MAX_BRICKS - 1));
            }
            i = (i + 1) & mask;
        }
    }

    /// Puts `key` and its `brick` (below [`MAX_BRICKS`]) in the free slot `at` that
    /// [`BrickIndex::find`] gave; room for it was [`BrickIndex::reserve`]d.
    pub fn insert(&mut self, at: usize, key: &Key, brick: u32) {
        debug_assert!(key.3 < 15 && brick < MAX_BRICKS && self.slots[at].tag == EMPTY);
        self.slots[at] = Slot {
            cell: [key.0, key.1, key.2],
            tag: key.3 << 28 | brick,
        };
        self.len += 1;
    }

    /// foldhash's folded multiply of the key's two halves, each mixed with a word of the seed.
    #[inline]
    fn hash(&self, cell: [i32; 3], flags: u32) -> usize {
        let a = u64::from(cell[0] as u32) | u64::from(cell[1] as u32) << 32;
        let b = u64::from(cell[2] as u32) | u64::from(flags) << 32;
        let full = u128::from(a ^ self.seed[0]) * u128::from(b ^ self.seed[1]);
        (full as u64 ^ (full >> 64) as u64) as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Keys found after growth, as the fold uses the index (room reserved, every home taken,
    /// then finds and inserts in order): cells shared by keys of different flags (back faces
    /// among them: the flags' top bit is the slot's top bit), bricks up to the last one the
    /// index numbers; keys absent, or present with other flags, are not found.
    #[test]
    fn finds_what_was_inserted_across_growth() {
        let mut index = BrickIndex::default();
        let cells = (0..700).map(|i| (i % 17 - 8, i / 17 % 13, -(i / 221)));
        let keys: Vec<Key> = cells
            .flat_map(|(x, y, z)| [0, 5, 8, 13].map(|f| (x, y, z, f)))
            .collect();
        let brick = |i: usize| MAX_BRICKS - 1 - i as u32 * 7;
        for (p, probe) in keys.chunks(300).enumerate() {
            index.reserve(probe.len());
            let homes: Vec<usize> = probe.iter().map(|k| index.home(k)).collect();
            for (j, (key, home)) in probe.iter().zip(homes).enumerate() {
                let i = 300 * p + j;
                let at = index.find(key, home).expect_err("not yet inserted");
                index.insert(at, key, brick(i));
                assert_eq!(index.find(key, home), Ok(brick(i)));
            }
        }
        assert!(index.slots.len().is_power_of_two() && 4 * index.len <= 3 * index.slots.len());
        for (i, key) in keys.iter().enumerate() {
            assert_eq!(index.find(key, index.home(key)), Ok(brick(i)), "{key:?}");
        }
        for absent in [(1000, 0, 0, 0), (0, 0, 0, 1), (-8, 0, 0, 9)] {
            assert!(
                index.find(&absent, index.home(&absent)).is_err(),
                "{absent:?}"
            );
        }
    }
}
