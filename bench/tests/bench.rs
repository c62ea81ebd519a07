//! The `prt-bench` binary's contract: `bake --runs N` times `prt bake` processes and cleans up
//! after them, a missing `prt` is named with the command that builds it, and `--out DIR` writes
//! the report to `DIR/<benchmark>.md`.

use std::path::{Path, PathBuf};
use std::process::Command;

fn fixture(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../fixtures")
        .join(rel)
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// A scratch directory unique to this process and test, removed when dropped.
struct Scratch(PathBuf);

impl Scratch {
    fn new(name: &str) -> Scratch {
        let dir =
            std::env::temp_dir().join(format!("prt-bench-tests-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        Scratch(dir)
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn entries(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// Builds the `prt` binary beside `prt-bench` (same target directory and profile) and returns
/// its path. Cargo builds only the binaries of the packages under test, so `cargo test -p
/// prt-bench` alone would not have it; when it is up to date the build does nothing.
fn built_prt() -> PathBuf {
    let bench = Path::new(env!("CARGO_BIN_EXE_prt-bench"));
    let profile_dir = bench.parent().expect("prt-bench's directory");
    let target_dir = profile_dir.parent().expect("the target directory");
    let mut cargo = Command::new(env!("CARGO"));
    cargo
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(["build", "--quiet", "-p", "prt", "--target-dir"])
        .arg(target_dir);
    match profile_dir.file_name().and_then(|n| n.to_str()) {
        Some("debug") => {}
        Some(profile) => {
            cargo.args(["--profile", profile]);
        }
        None => panic!("{}: no profile directory", bench.display()),
    }
    let out = cargo.output().expect("run cargo build -p prt");
    assert!(
        out.status.success(),
        "cargo build -p prt: {}",
        text(&out.stderr)
    );
    let prt = profile_dir.join(format!("prt{}", std::env::consts::EXE_SUFFIX));
    assert!(prt.is_file(), "{}: not built", prt.display());
    prt
}

/// `prt-bench bake --runs N` times N bakes, the later ones `prt bake` processes of their own
/// (the `prt` beside `prt-bench`) timed to their "wrote" line and to their exit, leaves no
/// asset behind, and with `--out` writes its report to `bake.md`.
#[test]
fn bake_times_bake_processes_and_cleans_up() {
    built_prt();
    let dir = Scratch::new("bake");
    let results = Scratch::new("bake-results");
    let out = Command::new(env!("CARGO_BIN_EXE_prt-bench"))
        .args(["bake", "--runs", "3"])
        .arg(fixture("scenes/room.glb"))
        .arg("--out")
        .arg(&results.0)
        .env("TMPDIR", &dir.0)
        .output()
        .expect("run prt-bench");
    assert!(out.status.success(), "{}", text(&out.stderr));
    let report = text(&out.stdout);
    let row = report
        .lines()
        .find(|l| l.contains("3 runs in turn"))
        .unwrap_or_else(|| panic!("no row of repeated runs in:\n{report}"));
    assert!(!row.contains("failed"), "{row}");
    // Three ratios, then the medians to the file written and [to exit].
    let ratios = row.split(" | ").nth(1).unwrap_or_default();
    assert_eq!(ratios.split("%, ").count(), 3, "{row}");
    assert!(
        row.contains("(median ") && row.contains("%]); bakes "),
        "{row}"
    );
    assert_eq!(
        entries(&dir.0),
        Vec::<String>::new(),
        "left behind in TMPDIR"
    );
    assert_eq!(entries(&results.0), ["bake.md"]);
    let written = std::fs::read_to_string(results.0.join("bake.md")).unwrap();
    assert!(
        written.contains(row),
        "bake.md lacks the runs row:\n{written}"
    );
    assert!(
        report.starts_with(&written),
        "bake.md is not the printed report"
    );
}

/// Without a `prt` to run, `--runs` above 1 fails before baking, naming the path it looked at
/// and how to build one, on one line.
#[test]
fn bake_runs_without_prt_name_the_path_and_the_build() {
    let dir = Scratch::new("no-prt");
    let missing = dir.0.join("prt");
    let out = Command::new(env!("CARGO_BIN_EXE_prt-bench"))
        .args(["bake", "--runs", "2", "--prt"])
        .arg(&missing)
        .arg(fixture("scenes/room.glb"))
        .output()
        .expect("run prt-bench");
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert_eq!(stderr.lines().count(), 1, "{stderr:?}");
    assert!(stderr.starts_with("error:"), "{stderr}");
    assert!(stderr.contains(&missing.display().to_string()), "{stderr}");
    assert!(stderr.contains("cargo build --release -p prt"), "{stderr}");
    assert!(text(&out.stdout).is_empty(), "baked before failing");
}

/// The seven benchmarks are subcommands of `prt-bench`.
#[test]
fn benchmarks_are_prt_bench_subcommands() {
    let out = Command::new(env!("CARGO_BIN_EXE_prt-bench"))
        .arg("--help")
        .output()
        .expect("run prt-bench");
    assert!(out.status.success());
    let help = text(&out.stdout);
    for kind in [
        "bake", "accuracy", "gpu", "lights", "render", "surface", "fuzz",
    ] {
        assert!(
            help.lines().any(|l| l.trim_start().starts_with(kind)),
            "no {kind} in:\n{help}"
        );
    }
}
