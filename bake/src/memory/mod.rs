//! Memory plumbing shared by the stages: cache-line prefetches, pages written before the work
//! that needs them, tables filled run by run in parallel, and vectors that grow by chunks.

pub(crate) mod chunked;

/// Asks for the cache line holding `item` without waiting for it (`prefetcht0`).
#[cfg(all(target_arch = "x86_64", target_feature = "sse"))]
#[inline(always)]
pub(crate) fn prefetch<T>(item: &T) {
    use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
    let p: *const T = item;
    // SAFETY: SSE is part of the x86-64 baseline, and a prefetch reads nothing and never faults.
    unsafe { _mm_prefetch::<_MM_HINT_T0>(p.cast()) };
}

/// Loads the cache line holding `item` (its first byte, which the compiler may not drop):
/// where there is no prefetch instruction, independent loads still overlap their misses.
#[cfg(not(all(target_arch = "x86_64", target_feature = "sse")))]
#[inline(always)]
pub(crate) fn prefetch<T>(item: &T) {
    let p: *const T = item;
    // SAFETY: `p` comes from a reference, so its first byte is valid to read.
    std::hint::black_box(unsafe { std::ptr::read_volatile(p.cast::<u8>()) });
}

/// Asks for every cache line of `bytes` (at most 128 of them: its first, 64th and last bytes).
pub(crate) fn prefetch_lines(bytes: &[u8]) {
    debug_assert!(bytes.len() <= 128);
    for at in [0, 64, bytes.len().saturating_sub(1)] {
        if let Some(b) = bytes.get(at) {
            prefetch(b);
        }
    }
}

/// `len` copies of `value`, every page written now: memory made ready beside other work, so
/// that the work it is for does not stop at each first touch of a page.
pub(crate) fn written<T: Copy>(len: usize, value: T) -> Vec<T> {
    let mut v = Vec::with_capacity(len);
    v.resize(len, value);
    v
}

/// `items` cut into consecutive runs of `lens` items (summing to at most `items.len()`), each
/// with the index of its first item: a table filled run by run in parallel.
pub(crate) fn split_runs<'a, T>(
    mut items: &'a mut [T],
    lens: &[usize],
) -> Vec<(usize, &'a mut [T])> {
    let mut runs = Vec::with_capacity(lens.len());
    let mut start = 0;
    for &len in lens {
        let (run, rest) = std::mem::take(&mut items).split_at_mut(len);
        runs.push((start, run));
        items = rest;
        start += len;
    }
    runs
}
