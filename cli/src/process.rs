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
/// they are freed), and the heaps' free tops are not trimmed (a worker thread's heap that
/// becomes wholly free may still be unmapped). A page handed back costs a page fault the next
/// time it is written, 2.1-2.5 us here (a virtual machine that also reports freed pages to its
/// host), and a bake frees and allocates hundreds of megabytes between its stages. Sponza,
/// `--double-sided`, 2 threads, `prt bake`, alternating the build with this and inlined
/// validation (a74d7ea) with the one before (97c1a71): page faults 43.7-44.3k against
/// 55.9-56.4k at 1.9 m, 147.7-149.5k against 155.4-157.1k at 1.0 m, 587k against 600k at
/// 104,949 probes; the price is peak memory, 176-179 MiB against 153-156 MiB at 1.9 m and
/// 506-511 MiB against 477-483 MiB at 1.0 m (1,274-1,290 MiB against 1,283-1,284 MiB at
/// 104,949 probes). End to end the two builds do not differ within this machine's noise
/// (0.49-0.61 s against 0.52-0.64 s at 1.9 m, six bakes each; 2.91-3.10 s against 3.02-3.13 s
/// at 1.0 m, five each); the CPU time of the six bakes at 1.9 m, user and system, summed to
/// 5.67 s against 6.08 s. Serving every block from the heaps (`M_MMAP_MAX` 0) saved more faults
/// at 1.0 m (143k) but, at 104,949 probes, peaked at 1,744 MiB against 1,282 MiB for 97c1a71
/// and took 6.1-6.3 s to number the bricks against 2.5 s. A process-wide setting, so the
/// binary's to make, not the library's: an engine that embeds the bake keeps its own
/// allocator's policy.
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
