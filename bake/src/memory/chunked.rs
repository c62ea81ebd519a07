//! A vector that grows by whole chunks and never moves what it holds.
//!
//! The brick fold appends surfels and bricks one at a time, up to hundreds of megabytes, while
//! it runs alone beside the tracing threads. A `Vec` doubling its buffer copies everything into
//! fresh pages each time: for the 64-byte-aligned surfel clusters the allocator cannot extend
//! in place, so every growth is a copy, and the fold's thread is the one the tracing waits
//! for. Chunks are allocated once and filled in place.
//!
//! Chunks should be of 32 MiB or more: glibc maps allocations that large on their own (its
//! mmap threshold rises to at most 32 MiB on 64-bit targets), so a chunk costs only the pages
//! written and goes back to the system when freed. Smaller chunks come from the heaps the
//! bake's other allocations share, and fragment them (a higher peak than growing vectors).

use std::ops::{Index, IndexMut};

/// Items in chunks of `2^BITS` (of 32 MiB or more, see the module doc), indexed like one
/// vector.
pub struct Chunked<T, const BITS: u32> {
    chunks: Vec<Vec<T>>,
    len: usize,
}

impl<T, const BITS: u32> Default for Chunked<T, BITS> {
    fn default() -> Self {
        Chunked {
            chunks: Vec::new(),
            len: 0,
        }
    }
}

impl<T, const BITS: u32> Chunked<T, BITS> {
    const MASK: usize = (1 << BITS) - 1;

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn push(&mut self, item: T) {
        if self.len & Self::MASK == 0 {
            self.chunks.push(Vec::with_capacity(1 << BITS));
        }
        if let Some(chunk) = self.chunks.last_mut() {
            chunk.push(item);
        }
        self.len += 1;
    }

    pub fn get(&self, i: usize) -> Option<&T> {
        self.chunks.get(i >> BITS)?.get(i & Self::MASK)
    }
}

impl<T, const BITS: u32> Index<usize> for Chunked<T, BITS> {
    type Output = T;

    #[inline]
    fn index(&self, i: usize) -> &T {
        &self.chunks[i >> BITS][i & Self::MASK]
    }
}

impl<T, const BITS: u32> IndexMut<usize> for Chunked<T, BITS> {
    #[inline]
    fn index_mut(&mut self, i: usize) -> &mut T {
        &mut self.chunks[i >> BITS][i & Self::MASK]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn indexes_across_chunks_like_a_vector() {
        let mut c = Chunked::<u32, 2>::default();
        assert_eq!(c.get(0), None);
        for i in 0..11 {
            c.push(i * 10);
        }
        assert_eq!(c.len(), 11);
        assert_eq!(c.chunks.len(), 3);
        c[5] += 1;
        let items: Vec<u32> = (0..c.len()).map(|i| c[i]).collect();
        assert_eq!(items, [0, 10, 20, 30, 40, 51, 60, 70, 80, 90, 100]);
        assert_eq!(c.get(10), Some(&100));
        assert_eq!(c.get(11), None);
        assert_eq!(c.get(12), None);
    }
}
