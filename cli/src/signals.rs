//! SIGINT and SIGTERM: remove the temporary file of a write in progress, then die of the signal
//! (the shell reports 128 + its number). Without this a kill during the last moments
//! of a bake leaves `NAME.prt.tmpPID` beside the output, and stale ones pile up.
//!
//! How: the two signals are blocked before any other thread exists (threads inherit the mask:
//! rayon's workers, wgpu's), and one thread waits for them with `sigwait`, so that the cleanup
//! runs as ordinary code rather than in a signal handler.

/// Blocks SIGINT and SIGTERM in this thread (and every thread created after it) and starts the
/// thread that handles them. Call first thing in `main`.
pub fn install() {
    // SAFETY: plain libc calls on a local, zero-initialised signal set.
    unsafe {
        let mut set: libc::sigset_t = std::mem::zeroed();
        libc::sigemptyset(&mut set);
        libc::sigaddset(&mut set, libc::SIGINT);
        libc::sigaddset(&mut set, libc::SIGTERM);
        if libc::pthread_sigmask(libc::SIG_BLOCK, &set, std::ptr::null_mut()) != 0 {
            return;
        }
        std::thread::spawn(move || {
            let mut sig: libc::c_int = 0;
            if libc::sigwait(&set, &mut sig) == 0 {
                prt_format::io::remove_pending_temp_files();
                // Die of the signal itself (not exit(128 + sig), which runs other libraries'
                // exit handlers while the GPU and worker threads still run, and which a shell
                // loop reads as "the program handled it" and carries on): default action,
                // unblocked in this thread, raised here.
                libc::signal(sig, libc::SIG_DFL);
                let mut one: libc::sigset_t = std::mem::zeroed();
                libc::sigemptyset(&mut one);
                libc::sigaddset(&mut one, sig);
                libc::pthread_sigmask(libc::SIG_UNBLOCK, &one, std::ptr::null_mut());
                libc::raise(sig);
                // Not reached: the default action ends the process.
                libc::_exit(128 + sig);
            }
        });
    }
}
