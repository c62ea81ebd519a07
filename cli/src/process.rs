//! The process around a command of `prt` or `prt-bench`: the environment Mesa wants, the
//! allocator's policy, SIGINT/SIGTERM cleanup, and errors as one line on stderr
//! (docs/conventions.md section 6).

use anyhow::Result;
use clap::Parser;

/// The process's peak resident set size in KiB (`VmHWM` of `/proc/self/status`; Linux only).
pub fn peak_rss_kib() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

/// Tells glibc's allocator to keep the memory the process frees for its own later allocations
/// instead of handing it back to the kernel: blocks below 32 MiB (glibc's largest threshold on
/// 64-bit) always come from its heaps, never from mappings of their own (unmapped as soon as
/// they are freed), and the heaps' free tops are not trimmed. A page handed back costs a page
/// fault the next time it is written, and a bake frees and allocates hundreds of megabytes
/// between its stages; the price is a higher peak (the figures: docs/results/bake_notes.md,
/// `keep_freed_memory`). A process-wide setting, so the binary's to make, not the library's: an
/// engine that embeds the bake keeps its own allocator's policy.
fn keep_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu", target_pointer_width = "64"))]
    // SAFETY: `mallopt` sets allocator parameters and touches no memory of ours; called before
    // any other thread exists (the signal thread is started after it). The trim threshold is
    // set only if the mmap threshold was taken: setting it switches off glibc's dynamic mmap
    // threshold, which without ours would stay at 128 KiB.
    unsafe {
        if libc::mallopt(libc::M_MMAP_THRESHOLD, 32 << 20) == 1 {
            libc::mallopt(libc::M_TRIM_THRESHOLD, i32::MAX);
        }
    }
}

/// Parses the command line as `C` and runs it through `run`: returns when it succeeds, exits 1
/// with `error: ...` on stderr when it fails, 2 with clap's message on one line when the command line is wrong
/// (`--help` and `--version` print as clap prints them). Call it as the whole of `main`: the
/// allocator and signal settings are made before any other thread exists.
pub fn main<C: Parser>(run: impl FnOnce(C) -> Result<()>) {
    // Mesa's Vulkan drivers print "error: XDG_RUNTIME_DIR is invalid or not set" on every device
    // they open when the variable is unset (headless machines, CI); point it at the temp dir.
    // Done first thing, before any thread exists.
    if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
        std::env::set_var("XDG_RUNTIME_DIR", std::env::temp_dir());
    }
    keep_freed_memory();
    crate::signals::install();
    crate::panics::install();
    let cli = match C::try_parse() {
        Ok(cli) => cli,
        Err(e) if !e.use_stderr() => e.exit(),
        Err(e) => {
            // One line, as for every other error (docs/conventions.md section 6): clap's message and
            // its list of possible values, without the usage block.
            let text = e.render().to_string();
            let parts: Vec<&str> = text
                .lines()
                .map(str::trim)
                .filter(|l| {
                    !l.is_empty()
                        && !l.starts_with("Usage:")
                        && !l.starts_with("For more information")
                })
                .collect();
            eprintln!("{}", parts.join(" "));
            std::process::exit(2);
        }
    };
    if let Err(e) = run(cli) {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}
