//! The process's panic hook, which only the binary sets: a library turns a dependency's panic
//! on hostile input into a typed error (`prt_scene`'s glTF reading, the bake's BVH build) but
//! leaves the hook alone. While a command runs such a call ([`quietly`]), a panic's report is
//! kept rather than printed, so that the error the library makes of it is the one line on
//! stderr (docs/conventions.md section 6); a panic that escapes the call instead (a bug) has
//! its kept reports printed before it goes on unwinding. Outside such calls the report is
//! Rust's default one.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

/// Calls of [`quietly`] under way. A count, not a lock held across the call: the call runs
/// rayon jobs, and a worker waiting inside one can steal another's.
static QUIET: AtomicUsize = AtomicUsize::new(0);
/// Reports of the panics while [`QUIET`] was above 0, dropped when the last call ends.
static KEPT: Mutex<Vec<String>> = Mutex::new(Vec::new());

/// Sets the hook (once, first thing in `main`).
pub fn install() {
    let default = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        if QUIET.load(Ordering::SeqCst) == 0 {
            return default(info);
        }
        let thread = std::thread::current();
        let location = info
            .location()
            .map(|l| format!(" at {l}"))
            .unwrap_or_default();
        let message = info.payload_as_str().unwrap_or("Box<dyn Any>");
        let backtrace = std::backtrace::Backtrace::capture();
        let backtrace = match backtrace.status() {
            std::backtrace::BacktraceStatus::Captured => format!("stack backtrace:\n{backtrace}"),
            _ => "note: run with `RUST_BACKTRACE=1` to display a backtrace\n".into(),
        };
        let report = format!(
            "thread '{}' panicked{location}:\n{message}\n{backtrace}",
            thread.name().unwrap_or("<unnamed>")
        );
        KEPT.lock().unwrap_or_else(|e| e.into_inner()).push(report);
    }));
}

/// Runs `f` with panic reports kept back ([`install`]): printed only if a panic escapes `f`.
pub fn quietly<T>(f: impl FnOnce() -> T) -> T {
    QUIET.fetch_add(1, Ordering::SeqCst);
    // Unwind safe: a panic out of `f` is resumed below, nothing `f` touched is seen after it.
    let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(f));
    let kept = if QUIET.fetch_sub(1, Ordering::SeqCst) == 1 {
        std::mem::take(&mut *KEPT.lock().unwrap_or_else(|e| e.into_inner()))
    } else {
        Vec::new()
    };
    match outcome {
        Ok(value) => value,
        Err(payload) => {
            for report in kept {
                eprint!("{report}");
            }
            std::panic::resume_unwind(payload)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::quietly;

    /// A call inside a call, on the same thread, as when a rayon worker waiting inside one
    /// bake's BVH build steals another bake's: it finishes, a panic the inner call's library
    /// catches comes back as its value, and its kept report is dropped once the calls end.
    #[test]
    fn quietly_nests() {
        super::install();
        let (send, receive) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let failing = || -> u32 { panic!("inner failure") };
            let inner = quietly(|| quietly(|| prt_scene::catch_panic(failing)));
            send.send(inner).ok();
        });
        let got = receive
            .recv_timeout(std::time::Duration::from_secs(30))
            .expect("quietly inside quietly did not finish: deadlock");
        assert_eq!(got, Err("inner failure".to_string()));
        assert!(super::KEPT.lock().unwrap().is_empty());
    }
}
