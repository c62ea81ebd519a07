//! Where [`super::RowStore`]'s chunks go past its budget: a temporary file (direct I/O on
//! Linux where the file system allows it), a writer thread and a reader thread a chunk ahead
//! (the module doc of [`super`] says why).

use std::fs::File;
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::PathBuf;
use std::sync::mpsc::{channel, sync_channel, Receiver, Sender, SyncSender};
use std::thread::JoinHandle;

use bytemuck::Pod;

use crate::BakeError;

/// The thread writing chunks to the file in the order they come, each padded to whole
/// pages, and handing their buffers back. Dropped without [`Writer::finish`] (a bake failing
/// for another reason), it still waits for the chunk being written.
pub(super) struct Writer<T> {
    /// At most one chunk waits while one is written (a rendezvous: `push` waits for the
    /// writer rather than hold more than the budget and two chunks). `None` once finishing.
    chunks: Option<SyncSender<Vec<T>>>,
    /// Buffers of written chunks.
    pub(super) done: Receiver<Vec<T>>,
    thread: Option<JoinHandle<Result<SpillFile, BakeError>>>,
}

impl<T: Pod + Send> Writer<T> {
    /// Starts the thread; fails when the system will not start one.
    pub(super) fn start(mut file: SpillFile) -> Result<Self, BakeError> {
        let (chunks, to_write) = sync_channel::<Vec<T>>(0);
        let (written, done) = channel();
        let path = file.path.clone();
        let thread = std::thread::Builder::new()
            .name("prt-rows-writer".into())
            .spawn(move || {
                let mut staging = Vec::new();
                for rows in to_write {
                    file.append(bytemuck::cast_slice(&rows), &mut staging)?;
                    // Gone when the store has stopped taking buffers back.
                    let _ = written.send(rows);
                }
                Ok(file)
            })
            .map_err(|error| spill_error(&path, error))?;
        Ok(Writer {
            chunks: Some(chunks),
            done,
            thread: Some(thread),
        })
    }

    /// Hands `rows` over; fails when the writer has stopped (on an error: see `finish`).
    pub(super) fn send(&self, rows: Vec<T>) -> Result<(), ()> {
        match &self.chunks {
            Some(chunks) => chunks.send(rows).map_err(|_| ()),
            None => Err(()),
        }
    }

    /// Waits for every chunk to be written; the file, or the writer's error.
    pub(super) fn finish(mut self) -> Result<SpillFile, BakeError> {
        self.chunks = None;
        match self.thread.take().map(JoinHandle::join) {
            Some(Ok(file)) => file,
            Some(Err(panic)) => std::panic::resume_unwind(panic),
            None => unreachable!("a writer is finished once"),
        }
    }
}

impl<T> Drop for Writer<T> {
    fn drop(&mut self) {
        self.chunks = None;
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

/// The thread reading spilled chunks back in order, a chunk ahead of their encoding, into
/// page buffers that come back to it once encoded.
pub(super) struct Reader;

/// Chunks read (or the error), and buffers handed back.
type ReadChannels = (Receiver<Result<Vec<Page>, BakeError>>, Sender<Vec<Page>>);

impl Reader {
    /// Reads the chunks at `spilled` (byte offset, bytes) of `file`; fails when the system
    /// will not start a thread.
    pub(super) fn start<'s>(
        scope: &'s std::thread::Scope<'s, '_>,
        file: &'s SpillFile,
        spilled: Vec<(u64, usize)>,
    ) -> Result<ReadChannels, BakeError> {
        let (send, read) = sync_channel(0);
        let (reused, back) = channel::<Vec<Page>>();
        std::thread::Builder::new()
            .name("prt-rows-reader".into())
            .spawn_scoped(scope, move || {
                for (at, bytes) in spilled {
                    let mut pages = back.try_recv().unwrap_or_default();
                    let chunk = file.read(at, bytes, &mut pages).map(|()| pages);
                    let failed = chunk.is_err();
                    if send.send(chunk).is_err() || failed {
                        return;
                    }
                }
            })
            .map_err(|error| spill_error(&file.path, error))?;
        Ok((read, reused))
    }
}

/// A page, aligned as direct I/O needs its buffers, lengths and file offsets to be.
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C, align(4096))]
pub(super) struct Page([u8; PAGE]);
pub(super) const PAGE: usize = 4096;

/// The file chunks are written to: made on first use, unlinked at once on Unix (removed when
/// dropped elsewhere), opened for direct I/O on Linux where the file system allows it
/// (module doc).
pub(super) struct SpillFile {
    pub(super) file: File,
    pub(super) path: PathBuf,
    /// Bytes written, whole pages: where the next chunk goes.
    pub(super) end: u64,
    /// Whether the file was opened for direct I/O (and has not fallen back since).
    #[cfg(target_os = "linux")]
    pub(super) direct: bool,
}

impl SpillFile {
    pub(super) fn create() -> Result<Self, BakeError> {
        Self::create_in(&std::env::temp_dir())
    }

    pub(super) fn create_in(dir: &std::path::Path) -> Result<Self, BakeError> {
        use std::sync::atomic::{AtomicU64, Ordering};
        static MADE: AtomicU64 = AtomicU64::new(0);
        let name = format!(
            "prt-bake-rows-{}-{}.tmp",
            std::process::id(),
            MADE.fetch_add(1, Ordering::Relaxed)
        );
        let path = dir.join(name);
        let mut options = std::fs::OpenOptions::new();
        options.read(true).write(true);
        let file = options
            .clone()
            .create_new(true)
            .open(&path)
            .map_err(|error| spill_error(&path, error))?;
        // Opened again for direct I/O, not created so: a file system that refuses the flag
        // may do so after making the file.
        #[cfg(target_os = "linux")]
        let (file, direct) = {
            use std::os::unix::fs::OpenOptionsExt;
            match options.custom_flags(libc::O_DIRECT).open(&path) {
                Ok(direct) => (direct, true),
                Err(_) => (file, false),
            }
        };
        #[cfg(unix)]
        std::fs::remove_file(&path).map_err(|error| spill_error(&path, error))?;
        Ok(SpillFile {
            file,
            path,
            end: 0,
            #[cfg(target_os = "linux")]
            direct,
        })
    }

    /// Writes `bytes` at the end through `staging`, padded to whole pages. A file system that
    /// took the direct I/O flag but refuses the write (`EINVAL`: alignment it wants larger,
    /// some network and FUSE file systems) gets it again through the page cache.
    pub(super) fn append(
        &mut self,
        bytes: &[u8],
        staging: &mut Vec<Page>,
    ) -> Result<(), BakeError> {
        let staged = staged(staging, bytes.len());
        staged[..bytes.len()].copy_from_slice(bytes);
        let written = self.write_at(self.end, staged);
        #[cfg(target_os = "linux")]
        let written = match written {
            Err(e) if self.direct && e.raw_os_error() == Some(libc::EINVAL) => self
                .stop_direct()
                .and_then(|()| self.write_at(self.end, staged)),
            written => written,
        };
        written.map_err(|error| spill_error(&self.path, error))?;
        self.end += staged.len() as u64;
        Ok(())
    }

    fn write_at(&self, at: u64, bytes: &[u8]) -> std::io::Result<()> {
        let mut file = &self.file;
        file.seek(SeekFrom::Start(at))?;
        file.write_all(bytes)
    }

    /// Clears the direct I/O flag (`fcntl`).
    #[cfg(target_os = "linux")]
    pub(super) fn stop_direct(&mut self) -> std::io::Result<()> {
        use std::os::fd::AsRawFd;
        let fd = self.file.as_raw_fd();
        // SAFETY: `fd` is this file's open descriptor; F_GETFL and F_SETFL read and set its
        // status flags only.
        let cleared = unsafe {
            let flags = libc::fcntl(fd, libc::F_GETFL);
            flags >= 0 && libc::fcntl(fd, libc::F_SETFL, flags & !libc::O_DIRECT) >= 0
        };
        if !cleared {
            return Err(std::io::Error::last_os_error());
        }
        self.direct = false;
        Ok(())
    }

    /// Reads the `bytes` at byte `at` (and the rest of their last page) into `pages`.
    pub(super) fn read(
        &self,
        at: u64,
        bytes: usize,
        pages: &mut Vec<Page>,
    ) -> Result<(), BakeError> {
        let staged = staged(pages, bytes);
        let mut file = &self.file;
        file.seek(SeekFrom::Start(at))
            .and_then(|_| file.read_exact(staged))
            .map_err(|error| spill_error(&self.path, error))
    }
}

/// The first `bytes` of `pages`, rounded up to whole pages (grown to that if shorter).
fn staged(pages: &mut Vec<Page>, bytes: usize) -> &mut [u8] {
    let count = bytes.div_ceil(PAGE);
    if pages.len() < count {
        pages.resize(count, Page([0; PAGE]));
    }
    &mut bytemuck::cast_slice_mut(pages)[..count * PAGE]
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
