//! Every probe's factor rows between the trace and the table encoding, probe after probe, in
//! chunks: the newest in memory, older ones in a temporary file once the rows pass a budget.
//!
//! The rows are the bake's largest working set and the only one that grows with the probe
//! count alone (Sponza at 105k probes: 35.9 million rows, 959 MiB, against a 1,060 MiB asset).
//! They cannot be encoded as they arrive: a factor names its brick's final number and is placed
//! from its brick's centroid, both known only once every probe is folded
//! ([`crate::bricks::BrickFolder::finish`]). So past the budget the oldest chunks are written
//! to a file and read back one at a time when the tables are encoded, which is also in probe
//! order: the memory the rows hold stays within the budget whatever the probe count, and the
//! asset's bytes do not change. The file is made in [`std::env::temp_dir`] (`TMPDIR`) and, on
//! Unix, unlinked at once, so nothing is left behind however the bake ends.
//!
//! Why chunks: a probe's rows never span two, so a chunk is freed as soon as its probes are
//! encoded, and chunks of [`CHUNK_BYTES`] are mapped on their own (glibc's mmap threshold
//! rises to at most 32 MiB), so each goes back to the system when freed. Per-probe vectors
//! came from the allocator's shared heaps, which kept the memory: the bake's peak was reached
//! while the factor table was written beside rows already encoded (Sponza at 105k probes:
//! 2,355-2,369 MiB then, 2,057 MiB with chunks; at 1.0 m 512 then, 475 MiB).

use std::fs::File;
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::PathBuf;

use bytemuck::Pod;

use crate::BakeError;

/// Bytes of a chunk: above the 32 MiB past which glibc maps every allocation on its own.
pub const CHUNK_BYTES: usize = 64 << 20;

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
    spill: Option<SpillFile>,
    /// The buffer of the chunk last written to the file, for the next chunk: a fresh 64 MiB
    /// mapping costs a page fault per 4 KiB written into it.
    spare: Vec<T>,
}

enum Chunk<T> {
    Held(Vec<T>),
    /// `len` rows at byte `at` of the spill file.
    Spilled {
        at: u64,
        len: usize,
    },
}

impl<T: Pod> RowStore<T> {
    /// No probes yet; rows kept in memory up to about `budget` bytes (whole chunks of at most
    /// [`CHUNK_BYTES`], at least one chunk, a chunk at least one probe).
    pub fn new(budget: usize) -> Self {
        Self::in_chunks_of(budget.min(CHUNK_BYTES), budget)
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
            spill: None,
            spare: Vec::new(),
        }
    }

    /// Appends the next probe's rows, first writing the oldest chunk to the file if a new
    /// chunk would pass the budget; fails when the file cannot be made or written.
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
            let mut chunk = std::mem::take(&mut self.spare);
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

    /// The rows are all in: if some went to the file, the held ones follow them, since the
    /// bricks are finished next ([`crate::bricks::BrickFolder::finish`], the bake's peak, with
    /// the surfels under merge and the final ones both held) and then the rows are read back
    /// in probe order anyway. A bake within the budget keeps its rows in memory.
    pub fn end(&mut self) -> Result<(), BakeError> {
        if self.spill.is_some() {
            while self.first_held < self.chunks.len() {
                self.spill_oldest()?;
            }
        }
        self.spare = Vec::new();
        Ok(())
    }

    fn spill_oldest(&mut self) -> Result<(), BakeError> {
        let i = self.first_held;
        let spill = match &mut self.spill {
            Some(spill) => spill,
            None => self.spill.insert(SpillFile::create()?),
        };
        let len = match &self.chunks[i] {
            Chunk::Held(rows) => rows.len(),
            Chunk::Spilled { len, .. } => *len,
        };
        let spilled = Chunk::Spilled { at: 0, len };
        if let Chunk::Held(rows) = std::mem::replace(&mut self.chunks[i], spilled) {
            let at = spill.append(bytemuck::cast_slice(&rows))?;
            self.chunks[i] = Chunk::Spilled { at, len };
            self.spare = rows;
        }
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

    /// Bytes written to the file so far.
    pub fn spilled_bytes(&self) -> u64 {
        self.spill.as_ref().map_or(0, |s| s.written)
    }

    /// Hands every chunk over in probe order, read back from the file if it was written
    /// there, and frees it before the next: `f(first probe, its probes' (start, len) in the
    /// chunk, the chunk's rows)`. Probes with no rows before the first chunk count as the first
    /// chunk's; probes but no chunk at all are handed over once, with no rows. Fails when the
    /// file cannot be read.
    pub fn drain(
        mut self,
        mut f: impl FnMut(usize, &[(usize, usize)], &[T]),
    ) -> Result<(), BakeError> {
        let mut first = 0;
        // Chunks from the file are read into one buffer, for the reason of `spare`.
        let mut buffer: Vec<T> = Vec::new();
        for probes in self.probes.chunk_by(|a, b| a.0 == b.0) {
            let held;
            let rows: &[T] = match self.chunks.get_mut(probes[0].0) {
                Some(Chunk::Held(rows)) => {
                    held = std::mem::take(rows);
                    &held
                }
                Some(&mut Chunk::Spilled { at, len }) => match &mut self.spill {
                    Some(spill) => {
                        if buffer.len() < len {
                            buffer.resize(len, T::zeroed());
                        }
                        spill.read(at, &mut buffer[..len])?;
                        &buffer[..len]
                    }
                    None => unreachable!("a spilled chunk has a file"),
                },
                None => &[],
            };
            let runs: Vec<(usize, usize)> = probes.iter().map(|&(_, s, n)| (s, n)).collect();
            f(first, &runs, rows);
            first += probes.len();
        }
        Ok(())
    }
}

/// The file chunks are written to: made on first use, unlinked at once on Unix (removed when
/// dropped elsewhere).
struct SpillFile {
    file: File,
    path: PathBuf,
    /// Bytes written so far (where the next chunk goes).
    written: u64,
}

impl SpillFile {
    fn create() -> Result<Self, BakeError> {
        Self::create_in(&std::env::temp_dir())
    }

    fn create_in(dir: &std::path::Path) -> Result<Self, BakeError> {
        use std::sync::atomic::{AtomicU64, Ordering};
        static MADE: AtomicU64 = AtomicU64::new(0);
        let name = format!(
            "prt-bake-rows-{}-{}.tmp",
            std::process::id(),
            MADE.fetch_add(1, Ordering::Relaxed)
        );
        let path = dir.join(name);
        let file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create_new(true)
            .open(&path)
            .map_err(|error| spill_error(&path, error))?;
        #[cfg(unix)]
        std::fs::remove_file(&path).map_err(|error| spill_error(&path, error))?;
        Ok(SpillFile {
            file,
            path,
            written: 0,
        })
    }

    /// Writes `bytes` at the end; returns where they start.
    fn append(&mut self, bytes: &[u8]) -> Result<u64, BakeError> {
        let at = self.written;
        self.file
            .write_all(bytes)
            .map_err(|error| spill_error(&self.path, error))?;
        self.written += bytes.len() as u64;
        Ok(at)
    }

    /// Reads the rows at byte `at` into `rows`.
    fn read<T: Pod>(&mut self, at: u64, rows: &mut [T]) -> Result<(), BakeError> {
        self.file
            .seek(SeekFrom::Start(at))
            .and_then(|_| self.file.read_exact(bytemuck::cast_slice_mut(rows)))
            .map_err(|error| spill_error(&self.path, error))
    }
}

#[cfg(not(unix))]
impl Drop for SpillFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

fn spill_error(path: &std::path::Path, error: std::io::Error) -> BakeError {
    BakeError::Spill {
        path: path.to_owned(),
        error,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Probes of 0..=7 rows (a probe of no rows first, one larger than a chunk), each row its
    /// probe and index: what `drain` hands over, per probe.
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

    fn filled(mut store: RowStore<[u32; 2]>) -> RowStore<[u32; 2]> {
        for p in 0..40u32 {
            let n = if p == 17 { 40 } else { (p * 5) % 8 };
            let rows: Vec<[u32; 2]> = (0..n).map(|i| [p, i]).collect();
            store.push(&rows).unwrap();
        }
        store
    }

    /// Chunks of 8 rows (64 bytes) with a budget of one, two and all of them: the file
    /// holds what does not fit (and everything, after `end`, once it holds anything), and
    /// every probe comes back as it went in.
    #[test]
    fn spilled_rows_come_back_as_they_went_in() {
        let all = drained(filled(RowStore::in_chunks_of(64, usize::MAX)));
        assert_eq!(all.len(), 40);
        assert_eq!(all[17].len(), 40);
        for budget in [0, 64, 128] {
            let store = filled(RowStore::in_chunks_of(64, budget));
            let held = store.chunks.len() - store.first_held;
            assert_eq!(held, (budget / 64).max(1), "budget {budget}");
            assert!(store.spilled_bytes() > 0);
            assert_eq!(drained(store), all, "budget {budget}");
        }
        let mut store = filled(RowStore::in_chunks_of(64, 128));
        store.end().unwrap();
        assert_eq!(store.first_held, store.chunks.len(), "all in the file");
        let rows: usize = all.iter().map(Vec::len).sum();
        assert_eq!(store.spilled_bytes(), 8 * rows as u64);
        assert_eq!(drained(store), all);
        let mut held = filled(RowStore::in_chunks_of(64, usize::MAX));
        held.end().unwrap();
        assert_eq!(held.spilled_bytes(), 0);
        assert_eq!(drained(held), all);
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
        let store = filled(RowStore::in_chunks_of(64, 0));
        let spill = store.spill.as_ref().unwrap();
        assert!(spill.written > 0);
        assert!(spill.path.starts_with(std::env::temp_dir()));
        assert!(!spill.path.exists());
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
