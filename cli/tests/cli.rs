//! The `prt` binary's command-line contract (conventions.md section 6): exit codes, one-line
//! errors, no partial output, and `inspect --json`.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn fixture(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../fixtures")
        .join(rel)
}

fn cornell() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/reference/cornell/cornell.gltf")
}

/// A scratch directory unique to this process and test, removed when dropped.
struct Scratch(PathBuf);

impl Scratch {
    fn new(name: &str) -> Scratch {
        let dir = std::env::temp_dir().join(format!("prt-cli-tests-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        Scratch(dir)
    }

    fn entries(&self) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(&self.0)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn prt(args: &[&std::ffi::OsStr], cwd: Option<&Path>) -> Output {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_prt"));
    cmd.args(args);
    if let Some(dir) = cwd {
        cmd.current_dir(dir);
    }
    cmd.output().expect("run prt")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// `prt bake` of a broken glTF exits non-zero with exactly one stderr line, starting with
/// "error:" and naming the file, and writes nothing.
#[test]
fn bake_of_broken_gltf_fails_cleanly() {
    let dir = Scratch::new("broken");
    let out = dir.0.join("out.prt");
    let input = fixture("bad/broken_json.gltf");
    let o = prt(
        &[
            "bake".as_ref(),
            input.as_os_str(),
            "-o".as_ref(),
            out.as_os_str(),
        ],
        None,
    );
    let stderr = text(&o.stderr);
    assert!(!o.status.success(), "exit status {:?}", o.status);
    let lines: Vec<&str> = stderr.lines().collect();
    assert_eq!(lines.len(), 1, "stderr is not one line: {stderr:?}");
    assert!(lines[0].starts_with("error:"), "{stderr:?}");
    assert!(lines[0].contains("broken_json.gltf"), "{stderr:?}");
    assert!(!out.exists());
    assert!(dir.entries().is_empty(), "left {:?}", dir.entries());
}

/// `prt bake` then `prt inspect --json` gives the summary object other tools depend on, and it
/// agrees with the file.
#[test]
fn bake_then_inspect_json() {
    let dir = Scratch::new("inspect");
    let out = dir.0.join("cornell.prt");
    let input = cornell();
    let o = prt(
        &[
            "bake".as_ref(),
            input.as_os_str(),
            "-o".as_ref(),
            out.as_os_str(),
            "--rays".as_ref(),
            "64".as_ref(),
        ],
        None,
    );
    assert!(o.status.success(), "bake failed: {}", text(&o.stderr));
    assert_eq!(dir.entries(), ["cornell.prt"]);

    let o = prt(
        &["inspect".as_ref(), out.as_os_str(), "--json".as_ref()],
        None,
    );
    assert!(o.status.success(), "inspect failed: {}", text(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout)
        .unwrap_or_else(|e| panic!("inspect --json is not JSON ({e}): {}", text(&o.stdout)));
    for key in [
        "format_version",
        "probe_count",
        "valid_probe_count",
        "surfel_count",
        "brick_count",
        "factor_count",
        "file_bytes",
    ] {
        assert!(v[key].is_u64(), "{key} missing or not a count: {v}");
    }
    let grid = &v["grid"];
    assert!(
        grid["origin"].as_array().is_some_and(|a| a.len() == 3),
        "{grid}"
    );
    assert!(grid["spacing"].as_f64().is_some_and(|s| s > 0.0), "{grid}");
    let counts: Vec<u64> = grid["counts"]
        .as_array()
        .expect("grid.counts")
        .iter()
        .map(|c| c.as_u64().expect("count"))
        .collect();
    assert_eq!(counts.len(), 3);
    assert_eq!(v["probe_count"].as_u64(), Some(counts.iter().product()));
    assert_eq!(
        v["file_bytes"].as_u64(),
        Some(std::fs::metadata(&out).unwrap().len())
    );
    assert_eq!(
        v["format_version"].as_u64(),
        Some(u64::from(prt_format::FORMAT_VERSION))
    );
    assert!(v["valid_probe_count"].as_u64() <= v["probe_count"].as_u64());
}

/// A scene with an external buffer bakes when given relative to another working directory.
#[test]
fn bake_resolves_external_buffers_from_another_directory() {
    let dir = Scratch::new("two_files");
    let out = dir.0.join("quad.prt");
    let o = prt(
        &[
            "bake".as_ref(),
            "two_files/scene.gltf".as_ref(),
            "-o".as_ref(),
            out.as_os_str(),
            "--rays".as_ref(),
            "64".as_ref(),
        ],
        Some(&fixture("")),
    );
    assert!(o.status.success(), "bake failed: {}", text(&o.stderr));
    assert!(out.is_file());
}

/// `prt relight --backend gpu` writes the same JSON as `--backend cpu` (conventions.md section
/// 6): same probes, positions and validity, SH within 1e-4 of each probe's SH0 (plus 1e-7 of the
/// brightest probe's, for near-black probes).
#[test]
fn relight_json_is_the_same_on_cpu_and_gpu() {
    let dir = Scratch::new("relight_json");
    let asset = dir.0.join("cornell.prt");
    let rig = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/cornell/rig_spot_range.json");
    let out = prt(
        &[
            "bake".as_ref(),
            cornell().as_os_str(),
            "-o".as_ref(),
            asset.as_os_str(),
            "--rays".as_ref(),
            "128".as_ref(),
        ],
        None,
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    let mut docs = Vec::new();
    for backend in ["cpu", "gpu"] {
        let json = dir.0.join(format!("{backend}.json"));
        let out = prt(
            &[
                "relight".as_ref(),
                asset.as_os_str(),
                "--lights".as_ref(),
                rig.as_os_str(),
                "--backend".as_ref(),
                backend.as_ref(),
                "--json".as_ref(),
                json.as_os_str(),
            ],
            None,
        );
        assert!(out.status.success(), "{backend}: {}", text(&out.stderr));
        let doc: serde_json::Value =
            serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
        docs.push(doc);
    }
    let probes = |d: &serde_json::Value| d["probes"].as_array().unwrap().clone();
    let (cpu, gpu) = (probes(&docs[0]), probes(&docs[1]));
    assert_eq!(cpu.len(), gpu.len());
    let dc = |p: &serde_json::Value| {
        p["sh"][0]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap().abs())
            .fold(0.0, f64::max)
    };
    let peak = cpu.iter().map(dc).fold(0.0, f64::max);
    for (c, g) in cpu.iter().zip(&gpu) {
        assert_eq!(c["index"], g["index"]);
        assert_eq!(c["position"], g["position"]);
        assert_eq!(c["valid"], g["valid"]);
        let tol = 1e-4 * dc(c) + 1e-7 * peak;
        for k in 0..9 {
            for ch in 0..3 {
                let (a, b) = (
                    c["sh"][k][ch].as_f64().unwrap(),
                    g["sh"][k][ch].as_f64().unwrap(),
                );
                assert!(
                    (a - b).abs() <= tol,
                    "probe {} k {k}: cpu {a} gpu {b}",
                    c["index"]
                );
            }
        }
    }
}
