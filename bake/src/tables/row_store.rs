//! Every probe's factor rows between the trace and the table encoding, probe after probe, in
//! chunks: the newest in memory, older ones in a temporary file once the rows pass a budget.
//!
//! The rows are the bake's largest working set and the only one that grows with the probe
//! count alone (about as large as the asset).
//! They cannot be encoded as they arrive: a factor names its brick's final number and is placed
//! from its brick's centroid, both known only once every probe is folded
//! ([`crate::merge::fold::BrickFolder::finish_placed`]). So past the budget the oldest chunks are
//! written to a file and read back one at a time when the tables are encoded, which is also in
//! probe order: the memory the rows hold stays within the budget whatever the probe count, and the
//! asset's bytes do not change. Past the budget, two more chunks are held: the one being written
//! and the writer's page-aligned copy of it. Once any chunk is in the file, the rest follow when
//! the trace ends, before the bricks are finished (the bake's peak, with the surfels under merge
//! and the final ones both held).
//!
//! The file is made in [`std::env::temp_dir`] (`TMPDIR`) and, on Unix, unlinked at once, so
//! nothing is left behind however the bake ends. On Linux it is opened for direct I/O where
//! the file system allows it (`O_DIRECT`, else through the page cache; a write refused for
//! its alignment falls back to the page cache too): through the page cache the kernel
//! allocates and tracks a page for every 4 KiB written, which costs system time and is memory
//! too.
//! Direct I/O waits for the disk instead, so a thread of its own writes each chunk while the
//! bake goes on, and another reads the next chunk while the one before is encoded.
//!
//! Why chunks: a probe's rows never span two, so a chunk is freed as soon as its probes are
//! encoded, and chunks of [`CHUNK_BYTES`] are mapped on their own (glibc's mmap threshold
//! rises to at most 32 MiB), so each goes back to the system when freed. Per-probe vectors
//! came from the allocator's shared heaps, which kept the memory: the bake's peak was then
//! reached while the factor table was written beside rows already encoded.

use bytemuck::Pod;

use crate::BakeError;

mod spill;

use spill::{Reader, SpillFile, Writer, PAGE};

/// Bytes of a chunk: above the 32 MiB past which glibc maps every allocation on its own.
pub const CHUNK_BYTES: usize = 64 << 20;

/// Bytes of the smallest chunk, whatever the budget: with a chunk per probe (a budget of
/// nothing), a large bake would write a chunk per probe, each padded to a page.
pub const MIN_CHUNK_BYTES: usize = 64 << 10;

/// Every probe's rows in chunks, the oldest in a file past the budget (module doc).
pub struct RowStore<T> {
    /// Rows a chunk holds (more when one probe has more).
    chunk_rows: usize,
    /// Chunks kept in memory, the one being filled included (at least one).
    held_max: usize,
    chunks: Vec<Chunk<T>>,
    /// The first chunk still in memory: those before it are in the file.
    first_held: usize,
    /// Per probe: its chunk, and where its rows start there and how many there are.
    probes: Vec<(usize, usize, usize)>,
    /// The file, through the thread writing to it while the rows come in, then alone.
    spill: Spill<T>,
    /// Bytes of the file so far, whole pages: where the next chunk goes.
    end: u64,
    /// Bytes of rows written (the file less the pages' padding).
    written: u64,
}

enum Chunk<T> {
    Held(Vec<T>),
    /// `len` rows at byte `at` of the file.
    Spilled {
        at: u64,
        len: usize,
    },
}

enum Spill<T> {
    None,
    Writing(Writer<T>),
    Written(SpillFile),
}

impl<T: Pod + Send> RowStore<T> {
    /// No probes yet; rows kept in memory up to about `budget` bytes: whole chunks of
    /// [`MIN_CHUNK_BYTES`] to [`CHUNK_BYTES`], at least one, a chunk at least one probe; a
    /// chunk being written and the writer's copy of it come on top (module doc).
    pub fn new(budget: usize) -> Self {
        Self::in_chunks_of(budget.clamp(MIN_CHUNK_BYTES, CHUNK_BYTES), budget)
    }

    /// [`RowStore::new`] with chunks of `chunk_bytes`.
    pub fn in_chunks_of(chunk_bytes: usize, budget: usize) -> Self {
        let row = std::mem::size_of::<T>();
        RowStore {
            chunk_rows: (chunk_bytes / row).max(1),
            held_max: (budget / chunk_bytes.max(1)).max(1),
            chunks: Vec::new(),
            first_held: 0,
            probes: Vec::new(),
            spill: Spill::None,
            end: 0,
            written: 0,
        }
    }

    /// Appends the next probe's rows, first handing the oldest chunk to the file's writer if a
    /// new chunk would pass the budget; fails when the file cannot be made or written.
    pub fn push(&mut self, rows: &[T]) -> Result<(), BakeError> {
        let room = match self.chunks.last() {
            Some(Chunk::Held(c)) => c.capacity() - c.len(),
            _ => 0,
        };
        if room < rows.len() {
            if self.chunks.len() - self.first_held >= self.held_max {
                self.spill_oldest()?;
            }
            let capacity = self.chunk_rows.max(rows.len());
            // The buffer of a written chunk if there is one (a fresh 64 MiB mapping costs a
            // page fault per 4 KiB written into it), unless it was larger than this chunk is
            // to be; any others are freed.
            let mut chunk = match &self.spill {
                Spill::Writing(w) => w
                    .done
                    .try_iter()
                    .filter(|b| b.capacity() <= capacity)
                    .last(),
                _ => None,
            }
            .unwrap_or_default();
            chunk.clear();
            chunk.reserve(capacity);
            self.chunks.push(Chunk::Held(chunk));
        }
        let chunk = self.chunks.len().saturating_sub(1);
        let mut start = 0;
        if let Some(Chunk::Held(c)) = self.chunks.last_mut() {
            start = c.len();
            c.extend_from_slice(rows);
        }
        self.probes.push((chunk, start, rows.len()));
        Ok(())
    }

    /// The rows are all in: if some went to the file, the held ones follow them (module doc),
    /// and the writer finishes. A bake within the budget keeps its rows in memory.
    pub fn end(&mut self) -> Result<(), BakeError> {
        if let Spill::Writing(_) = self.spill {
            while self.first_held < self.chunks.len() {
                self.spill_oldest()?;
            }
            if let Spill::Writing(writer) = std::mem::replace(&mut self.spill, Spill::None) {
                self.spill = Spill::Written(writer.finish()?);
            }
        }
        Ok(())
    }

    /// Hands the oldest held chunk to the writer (started with the file on first use, and
    /// again should rows come after [`RowStore::end`]).
    fn spill_oldest(&mut self) -> Result<(), BakeError> {
        let writer = match std::mem::replace(&mut self.spill, Spill::None) {
            Spill::None => Writer::start(SpillFile::create()?)?,
            Spill::Written(file) => Writer::start(file)?,
            Spill::Writing(writer) => writer,
        };
        let (i, at) = (self.first_held, self.end);
        let held = std::mem::replace(&mut self.chunks[i], Chunk::Spilled { at, len: 0 });
        let Chunk::Held(rows) = held else {
            unreachable!("chunks from `first_held` on are in memory");
        };
        let len = rows.len();
        self.chunks[i] = Chunk::Spilled { at, len };
        if writer.send(rows).is_err() {
            // The writer stopped on an error: it says which.
            return match writer.finish() {
                Err(error) => Err(error),
                Ok(_) => unreachable!("the writer stops early only on an error"),
            };
        }
        self.spill = Spill::Writing(writer);
        let bytes = (len * std::mem::size_of::<T>()) as u64;
        self.end += bytes.next_multiple_of(PAGE as u64);
        self.written += bytes;
        self.first_held += 1;
        Ok(())
    }

    /// Probes pushed so far.
    pub fn probe_count(&self) -> usize {
        self.probes.len()
    }

    /// Rows of probe `p`.
    pub fn len(&self, p: usize) -> usize {
        self.probes[p].2
    }

    /// Bytes of rows handed to the file so far.
    pub fn spilled_bytes(&self) -> u64 {
        self.written
    }

    /// Hands every chunk over in probe order, read back from the file (by a thread of its own,
    /// a chunk ahead) if it was written there, and frees it before the next: `f(first probe,
    /// its probes' (start, len) in the chunk, the chunk's rows)`. Probes with no rows before
    /// the first chunk count as the first chunk's; probes but no chunk at all are handed over
    /// once, with no rows. Ends the store first ([`RowStore::end`]); fails when the file
    /// cannot be written or read.
    pub fn drain(
        mut self,
        mut f: impl FnMut(usize, &[(usize, usize)], &[T]),
    ) -> Result<(), BakeError> {
        self.end()?;
        let file = match std::mem::replace(&mut self.spill, Spill::None) {
            Spill::Written(file) => Some(file),
            Spill::None => None,
            Spill::Writing(_) => unreachable!("`end` stops the writer"),
        };
        let spilled: Vec<(u64, usize)> = self
            .chunks
            .iter()
            .filter_map(|c| match *c {
                Chunk::Spilled { at, len } => Some((at, len * std::mem::size_of::<T>())),
                Chunk::Held(_) => None,
            })
            .collect();
        std::thread::scope(|scope| {
            let reader = file
                .as_ref()
                .map(|file| Reader::start(scope, file, spilled));
            let reader = reader.transpose()?;
            let mut first = 0;
            for probes in self.probes.chunk_by(|a, b| a.0 == b.0) {
                let runs: Vec<(usize, usize)> = probes.iter().map(|&(_, s, n)| (s, n)).collect();
                match self.chunks.get_mut(probes[0].0) {
                    Some(Chunk::Held(rows)) => f(first, &runs, &std::mem::take(rows)),
                    Some(&mut Chunk::Spilled { len, .. }) => {
                        let Some((read, reused)) = &reader else {
                            unreachable!("a spilled chunk has a file");
                        };
                        let pages = match read.recv() {
                            Ok(pages) => pages?,
                            Err(_) => unreachable!("the reader sends every chunk"),
                        };
                        let bytes = len * std::mem::size_of::<T>();
                        let page_bytes: &[u8] = bytemuck::cast_slice(&pages);
                        f(first, &runs, bytemuck::cast_slice(&page_bytes[..bytes]));
                        // Gone when the reader has read every chunk.
                        let _ = reused.send(pages);
                    }
                    None => f(first, &runs, &[]),
                }
                first += probes.len();
            }
            Ok(())
        })
    }
}

#[cfg(test)]
mod tests {
    use super::spill::Page;
    use super::*;
    use std::fs::File;
    use std::path::PathBuf;

    /// What `drain` hands over, per probe (checking each row's probe index on the way).
    fn drained(store: RowStore<[u32; 2]>) -> Vec<Vec<[u32; 2]>> {
        let mut out = Vec::new();
        store
            .drain(|first, runs, rows| {
                for (i, &(start, len)) in runs.iter().enumerate() {
                    let probe = &rows[start..start + len];
                    assert!(probe.iter().all(|r| r[0] == (first + i) as u32));
                    out.push(probe.to_vec());
                }
            })
            .unwrap();
        out
    }

    /// Probe `p`'s rows: 0..=7 of them (probe 0 none, probe 17 forty), each its probe and index.
    fn rows_of(p: u32) -> Vec<[u32; 2]> {
        let n = if p == 17 { 40 } else { (p * 5) % 8 };
        (0..n).map(|i| [p, i]).collect()
    }

    fn filled(mut store: RowStore<[u32; 2]>, probes: std::ops::Range<u32>) -> RowStore<[u32; 2]> {
        for p in probes {
            store.push(&rows_of(p)).unwrap();
        }
        store
    }

    /// Chunks of 8 rows (64 bytes, each padded to a page in the file) with a budget of one, two
    /// and all of them: the file holds what does not fit (and everything, after `end`, once it
    /// holds anything), and every probe comes back as it went in, also when more come after
    /// `end`.
    #[test]
    fn spilled_rows_come_back_as_they_went_in() {
        let want: Vec<Vec<[u32; 2]>> = (0..40).map(rows_of).collect();
        let held = filled(RowStore::in_chunks_of(64, usize::MAX), 0..40);
        assert_eq!(held.spilled_bytes(), 0);
        assert_eq!(drained(held), want);
        for budget in [0, 64, 128] {
            let store = filled(RowStore::in_chunks_of(64, budget), 0..40);
            let held = store.chunks.len() - store.first_held;
            assert_eq!(held, (budget / 64).max(1), "budget {budget}");
            assert!(store.spilled_bytes() > 0);
            assert_eq!(drained(store), want, "budget {budget}");
        }
        let mut store = filled(RowStore::in_chunks_of(64, 128), 0..25);
        store.end().unwrap();
        assert_eq!(store.first_held, store.chunks.len(), "all in the file");
        let rows: usize = want[..25].iter().map(Vec::len).sum();
        assert_eq!(store.spilled_bytes(), 8 * rows as u64);
        let store = filled(store, 25..40);
        assert_eq!(drained(store), want);
    }

    /// A budget of nothing still writes chunks of `MIN_CHUNK_BYTES`, one held.
    #[test]
    fn chunks_have_a_floor() {
        let store = RowStore::<[u32; 2]>::new(0);
        assert_eq!(store.chunk_rows, MIN_CHUNK_BYTES / 8);
        assert_eq!(store.held_max, 1);
        let store = RowStore::<[u32; 2]>::new(usize::MAX);
        assert_eq!(store.chunk_rows, CHUNK_BYTES / 8);
    }

    /// No probes, or only probes of no rows: nothing to hand over but them.
    #[test]
    fn empty_stores_drain() {
        assert!(drained(RowStore::new(0)).is_empty());
        let mut store = RowStore::<[u32; 2]>::new(0);
        store.push(&[]).unwrap();
        store.push(&[]).unwrap();
        assert_eq!(store.probe_count(), 2);
        assert_eq!(drained(store), vec![Vec::<[u32; 2]>::new(); 2]);
    }

    /// The spill file leaves nothing in the temporary directory (Unix: unlinked when made).
    #[cfg(unix)]
    #[test]
    fn the_spill_file_is_unlinked() {
        let mut store = filled(RowStore::in_chunks_of(64, 0), 0..40);
        store.end().unwrap();
        let Spill::Written(file) = &store.spill else {
            panic!("nothing written");
        };
        assert!(file.path.starts_with(std::env::temp_dir()));
        assert!(!file.path.exists());
    }

    /// A file whose writes fail (a full disk): the store stops with an error naming it.
    #[cfg(target_os = "linux")]
    #[test]
    fn a_full_disk_is_reported() {
        let path = PathBuf::from("/dev/full");
        let file = File::options().read(true).write(true).open(&path).unwrap();
        let mut store = RowStore::<[u32; 2]>::in_chunks_of(64, 0);
        store.spill = Spill::Written(SpillFile {
            file,
            path,
            end: 0,
            direct: false,
        });
        let pushed: Result<Vec<()>, BakeError> = (0..40).map(|p| store.push(&rows_of(p))).collect();
        let Err(error) = pushed.and_then(|_| store.end()) else {
            panic!("writing to /dev/full succeeded");
        };
        let message = error.to_string();
        assert!(message.contains("/dev/full"), "{message}");
    }

    /// Direct I/O given up (as when a file system refuses its writes): the file goes on through
    /// the page cache, chunks where they belong.
    #[cfg(target_os = "linux")]
    #[test]
    fn direct_io_falls_back() {
        let mut file = SpillFile::create().unwrap();
        let mut staging = Vec::new();
        file.append(&[1; 100], &mut staging).unwrap();
        file.stop_direct().unwrap();
        file.append(&[2; 5000], &mut staging).unwrap();
        assert_eq!(file.end, 3 * PAGE as u64);
        let mut pages = Vec::new();
        file.read(0, 100, &mut pages).unwrap();
        assert!(bytemuck::cast_slice::<Page, u8>(&pages)[..100]
            .iter()
            .all(|&b| b == 1));
        file.read(PAGE as u64, 5000, &mut pages).unwrap();
        assert!(bytemuck::cast_slice::<Page, u8>(&pages)[..5000]
            .iter()
            .all(|&b| b == 2));
    }

    /// A directory the file cannot be made in: an error naming the file.
    #[test]
    fn an_unwritable_directory_is_named() {
        let dir = std::env::temp_dir().join("prt-no-such-dir/below");
        let Err(error) = SpillFile::create_in(&dir) else {
            panic!("made a file in a missing directory");
        };
        let message = error.to_string();
        assert!(
            message.contains("prt-no-such-dir/below/prt-bake-rows-"),
            "{message}"
        );
        assert!(message.contains("TMPDIR"), "{message}");
    }
}
