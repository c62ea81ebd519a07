//! The `prt` binary's command-line contract (docs/conventions.md section 6): exit codes, one-line
//! errors, no partial output, and `inspect --json`.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn fixture(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../fixtures")
        .join(rel)
}

fn cornell() -> PathBuf {
    fixture("cornell/cornell.gltf")
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

/// `prt bake` of a scene whose buffer lies in a sibling folder (`../textures/quad.bin`) exits
/// non-zero with one stderr line naming the buffer, its URI and `--allow-path`, and bakes with
/// `--allow-path` naming that folder.
#[test]
fn bake_needs_allow_path_for_files_outside_the_scene_folder() {
    let dir = Scratch::new("allow_path");
    let (scenes, textures) = (dir.0.join("scenes"), dir.0.join("textures"));
    std::fs::create_dir_all(&scenes).unwrap();
    std::fs::create_dir_all(&textures).unwrap();
    std::fs::copy(fixture("two_files/scene.bin"), textures.join("quad.bin")).unwrap();
    let gltf = std::fs::read_to_string(fixture("two_files/scene.gltf")).unwrap();
    let input = scenes.join("quad.gltf");
    std::fs::write(
        &input,
        gltf.replace("\"scene.bin\"", "\"../textures/quad.bin\""),
    )
    .unwrap();
    let out = dir.0.join("quad.prt");
    let mut args: Vec<&std::ffi::OsStr> = vec![
        "bake".as_ref(),
        input.as_os_str(),
        "-o".as_ref(),
        out.as_os_str(),
        "--rays".as_ref(),
        "32".as_ref(),
    ];
    let o = prt(&args, None);
    let stderr = text(&o.stderr);
    assert!(!o.status.success(), "exit status {:?}", o.status);
    assert_eq!(stderr.lines().count(), 1, "{stderr:?}");
    for fragment in ["error:", "buffer 0 (../textures/quad.bin)", "--allow-path"] {
        assert!(stderr.contains(fragment), "{fragment:?} not in {stderr:?}");
    }
    assert!(!out.exists());
    args.extend(["--allow-path".as_ref(), textures.as_os_str()]);
    let o = prt(&args, None);
    assert!(o.status.success(), "bake failed: {}", text(&o.stderr));
    assert!(out.exists());
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
    // Every factor reads a brick or a coarse brick of some level; the default bake has coarse
    // ones (far ratio 5) at 64 rays too.
    let levels: Vec<u64> = v["factors_by_level"]
        .as_array()
        .expect("factors_by_level")
        .iter()
        .map(|n| n.as_u64().expect("count"))
        .collect();
    assert!(levels.len() >= 2, "{levels:?}");
    assert_eq!(
        levels.iter().sum::<u64>(),
        v["factor_count"].as_u64().unwrap()
    );
    assert!(v["single_ray_factors"].as_u64() <= v["factor_count"].as_u64());
    let text_out = prt(&["inspect".as_ref(), out.as_os_str()], None);
    assert!(
        text(&text_out.stdout).contains("factor levels    per probe: "),
        "{}",
        text(&text_out.stdout)
    );
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

/// `prt relight --backend gpu` writes the same JSON as `--backend cpu` (docs/conventions.md section
/// 6): same probes, positions and validity, SH within 1e-4 of each probe's SH0 (plus 1e-7 of the
/// brightest probe's, for near-black probes); and its stats list the GPU allocations.
#[test]
fn relight_json_is_the_same_on_cpu_and_gpu() {
    let dir = Scratch::new("relight_json");
    let asset = bake_cornell(&dir);
    let rig = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/cornell/rig_spot_range.json");
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
    // The GPU run lists what it allocated, every buffer once, adding up to its total.
    let memory = docs[1]["stats"]["gpu_memory"].as_array().unwrap();
    let sum: u64 = memory.iter().map(|a| a["bytes"].as_u64().unwrap()).sum();
    assert_eq!(Some(sum), docs[1]["stats"]["gpu_memory_bytes"].as_u64());
    assert!(memory.iter().any(|a| a["name"] == "factors (all chunks)"));
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

/// `prt relight --json` flags every dilated probe (docs/conventions.md section 6): the default
/// Cornell bake has probes inside its walls that copy a neighbour's data; they are `"valid":
/// true, "dilated": true`, measured probes `"dilated": false`, and the counts match `prt inspect`.
#[test]
fn relight_json_flags_dilated_probes() {
    let dir = Scratch::new("relight_dilated");
    let asset = dir.0.join("cornell.prt");
    let json = dir.0.join("relit.json");
    let rig = cornell_rig();
    let run = |args: &[&std::ffi::OsStr]| {
        let o = prt(args, None);
        assert!(o.status.success(), "{}", text(&o.stderr));
        o
    };
    // Without the virtual offset the probes inside Cornell's boxes stay there, dilated.
    run(&[
        "bake".as_ref(),
        cornell().as_os_str(),
        "-o".as_ref(),
        asset.as_os_str(),
        "--no-virtual-offset".as_ref(),
    ]);
    let inspect = run(&["inspect".as_ref(), asset.as_os_str(), "--json".as_ref()]);
    let summary: serde_json::Value = serde_json::from_slice(&inspect.stdout).unwrap();
    run(&[
        "relight".as_ref(),
        asset.as_os_str(),
        "--lights".as_ref(),
        rig.as_os_str(),
        "--json".as_ref(),
        json.as_os_str(),
    ]);
    let doc: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    let probes = doc["probes"].as_array().unwrap();
    let flag = |p: &serde_json::Value, key: &str| p[key].as_bool().expect(key);
    let dilated = probes.iter().filter(|p| flag(p, "dilated")).count();
    let measured = probes
        .iter()
        .filter(|p| flag(p, "valid") && !flag(p, "dilated"))
        .count();
    assert!(dilated > 0, "the Cornell bake has dilated probes");
    assert!(
        probes
            .iter()
            .all(|p| !flag(p, "dilated") || flag(p, "valid")),
        "a dilated probe is valid"
    );
    assert_eq!(
        dilated as u64,
        summary["dilated_probe_count"].as_u64().unwrap()
    );
    assert_eq!(
        measured as u64,
        summary["valid_probe_count"].as_u64().unwrap()
    );
}

/// Bakes the Cornell reference room with the default settings into `dir`. (At 128 rays on the
/// default grid, 64 of 4,913 probes relit with the point light and sun differ between the GPU
/// and the CPU by up to 3.4e-3 of SH0: surfels' light decisions, not yet explained; with the sky
/// alone, or at 512 rays, none does.)
fn bake_cornell(dir: &Scratch) -> PathBuf {
    let (out, asset) = bake_cornell_with(dir, "cornell.prt", &[]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    asset
}

/// `prt bake` of the Cornell reference room into `dir`'s `name` with the options `extra`: what
/// it printed, and the asset's path.
fn bake_cornell_with(dir: &Scratch, name: &str, extra: &[&str]) -> (Output, PathBuf) {
    let (scene, asset) = (cornell(), dir.0.join(name));
    let mut args: Vec<&std::ffi::OsStr> = vec![
        "bake".as_ref(),
        scene.as_os_str(),
        "-o".as_ref(),
        asset.as_os_str(),
    ];
    args.extend(extra.iter().map(std::ffi::OsStr::new));
    (prt(&args, None), asset)
}

fn cornell_rig() -> PathBuf {
    fixture("cornell/rig.json")
}

/// `prt sample ASSET --lights RIG --points POINTS --json OUT [more args]`.
fn sample(asset: &Path, points: &Path, out: &Path, more: &[&str]) -> Output {
    let rig = cornell_rig();
    let mut args: Vec<&std::ffi::OsStr> = vec![
        "sample".as_ref(),
        asset.as_os_str(),
        "--lights".as_ref(),
        rig.as_os_str(),
        "--points".as_ref(),
        points.as_os_str(),
        "--json".as_ref(),
        out.as_os_str(),
    ];
    args.extend(more.iter().map(|s| std::ffi::OsStr::new(*s)));
    prt(&args, None)
}

/// `prt sample` on both backends returns the same samples, in input order, with normalised
/// normals: irradiance within 1% of the point's mean irradiance plus 0.1% of the brightest
/// point's (the GPU relight differs from the CPU's by ~1e-4, the half-float volume by 2^-11 per
/// texel; measured worst 0.35% on the Cornell reference points).
#[test]
fn sample_is_the_same_on_cpu_and_gpu() {
    let dir = Scratch::new("sample_backends");
    let asset = bake_cornell(&dir);
    // Inside the room, on the floor and walls and outside the grid, with assorted normals.
    let points: Vec<serde_json::Value> = (0..64)
        .map(|i| {
            let t = i as f64 / 64.0;
            let p = [
                -0.98 + 1.96 * (t * 7.3).fract(),
                0.01 + 1.98 * (t * 3.1).fract(),
                -0.98 + 1.96 * (t * 5.7).fract(),
            ];
            let a = i as f64 * 2.399_963;
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / 64.0;
            let r = (1.0 - z * z).sqrt();
            let n = [3.0 * r * a.cos(), 3.0 * z, 3.0 * r * a.sin()];
            serde_json::json!({"position": p, "normal": n})
        })
        .collect();
    let input = dir.0.join("points.json");
    std::fs::write(&input, serde_json::json!({ "points": points }).to_string()).unwrap();
    let mut docs = Vec::new();
    for backend in ["cpu", "gpu"] {
        let json = dir.0.join(format!("{backend}.json"));
        let out = sample(&asset, &input, &json, &["--backend", backend]);
        assert!(out.status.success(), "{backend}: {}", text(&out.stderr));
        let doc: serde_json::Value =
            serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
        docs.push(doc["samples"].as_array().unwrap().clone());
    }
    let (cpu, gpu) = (&docs[0], &docs[1]);
    assert_eq!(cpu.len(), points.len());
    assert_eq!(gpu.len(), points.len());
    let v = |s: &serde_json::Value, k: &str, c: usize| s[k][c].as_f64().unwrap();
    let mean_e = |s: &serde_json::Value| (0..3).map(|c| v(s, "irradiance", c)).sum::<f64>() / 3.0;
    let peak = cpu.iter().map(mean_e).fold(0.0, f64::max);
    assert!(peak > 0.0);
    for (i, ((c, g), p)) in cpu.iter().zip(gpu).zip(&points).enumerate() {
        for a in 0..3 {
            assert!((v(c, "position", a) - p["position"][a].as_f64().unwrap()).abs() < 1e-6);
            assert!((v(c, "normal", a) - p["normal"][a].as_f64().unwrap() / 3.0).abs() < 1e-6);
        }
        assert_eq!(c["position"], g["position"]);
        assert!((c["validity"].as_f64().unwrap() - g["validity"].as_f64().unwrap()).abs() < 1e-3);
        let tol = 1e-2 * mean_e(c) + 1e-3 * peak;
        for ch in 0..3 {
            let (a, b) = (v(c, "irradiance", ch), v(g, "irradiance", ch));
            assert!(
                (a - b).abs() <= tol,
                "point {i} ch {ch}: cpu {a} gpu {b} (tol {tol})"
            );
        }
    }
}

/// `prt sample --explain` adds to each sample how the lookup read it, and prints a line per
/// point: a point on the floor has a surfel (with its normal, near field and sky term) and the
/// probes it weighed; one in the air has none. With `--backend gpu` it is refused (the explanation is the CPU twin's) and
/// nothing is written.
#[test]
fn sample_explains_each_point() {
    let dir = Scratch::new("sample_explain");
    let asset = bake_cornell(&dir);
    let input = dir.0.join("points.json");
    let points = r#"{"points": [{"position": [0.1, 0.0, 0.2], "normal": [0, 1, 0]},
        {"position": [0.0, 1.0, 0.0], "normal": [0, 1, 0]}]}"#;
    std::fs::write(&input, points).unwrap();
    let json = dir.0.join("explained.json");
    let out = sample(&asset, &input, &json, &["--explain"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let said = text(&out.stdout);
    assert!(
        said.contains("point 0: E ") && said.contains("normal agreement"),
        "{said}"
    );
    assert!(
        said.contains("point 1: E ") && said.contains("no surfel"),
        "{said}"
    );
    let doc: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    let samples = doc["samples"].as_array().unwrap();
    let (floor, air) = (&samples[0]["explain"], &samples[1]["explain"]);
    for key in [
        "normal",
        "agreement",
        "near_hits",
        "escaping",
        "near",
        "ringing_floor",
        "before_floor",
        "sky_term",
    ] {
        assert!(!floor["surfel"][key].is_null(), "{key}: {floor}");
    }
    assert!(air["surfel"].is_null(), "{air}");
    for e in [floor, air] {
        let probes = e["probes"].as_array().unwrap();
        assert!(!probes.is_empty() && probes.len() <= 8, "{e}");
        assert_eq!(e["probes_irradiance"].as_array().unwrap().len(), 3);
    }
    let plain = dir.0.join("plain.json");
    assert!(sample(&asset, &input, &plain, &[]).status.success());
    let doc: serde_json::Value = serde_json::from_slice(&std::fs::read(&plain).unwrap()).unwrap();
    assert!(doc["samples"][0].get("explain").is_none(), "{doc}");
    let refused = dir.0.join("refused.json");
    let out = sample(&asset, &input, &refused, &["--explain", "--backend", "gpu"]);
    assert!(!out.status.success());
    assert!(
        text(&out.stderr).contains("--backend cpu"),
        "{}",
        text(&out.stderr)
    );
    assert!(!refused.exists());
}

/// Bad `prt sample` input exits non-zero with one stderr line naming the file, the point and the
/// value, and writes nothing.
#[test]
fn sample_bad_input_fails_cleanly() {
    let dir = Scratch::new("sample_bad");
    let asset = bake_cornell(&dir);
    let ok = r#"{"position": [0, 1, 0], "normal": [0, 1, 0]}"#;
    // (file name, contents, extra args, what the error must mention)
    let cases: Vec<(&str, String, Vec<&str>, Vec<&str>)> = vec![
        ("missing.json", String::new(), vec![], vec!["missing.json"]),
        (
            "malformed.json",
            "{\"points\": [".into(),
            vec![],
            vec!["malformed.json", "JSON"],
        ),
        (
            "no_list.json",
            "{\"pts\": []}".into(),
            vec![],
            vec!["no_list.json", "points"],
        ),
        (
            "no_normal.json",
            format!(r#"{{"points": [{ok}, {{"position": [0, 1, 0]}}]}}"#),
            vec![],
            vec!["no_normal.json", "point 1", "normal", "missing"],
        ),
        (
            "huge.json",
            format!(
                r#"{{"points": [{ok}, {ok}, {{"position": [1e300, 1, 0], "normal": [0, 1, 0]}}]}}"#
            ),
            vec![],
            vec!["huge.json", "point 2", "position", "1e+300"],
        ),
        (
            "text.json",
            r#"{"points": [{"position": [0, "up", 0], "normal": [0, 1, 0]}]}"#.into(),
            vec![],
            vec!["text.json", "point 0", "\"up\""],
        ),
        (
            "zero.json",
            format!(r#"{{"points": [{ok}, {{"position": [0, 1, 0], "normal": [0, 0, 0]}}]}}"#),
            vec![],
            vec![
                "zero.json",
                "point 1",
                "normal",
                "[0.0, 0.0, 0.0]",
                "zero length",
            ],
        ),
        (
            "neg.json",
            format!(r#"{{"points": [{ok}]}}"#),
            vec!["--normal-bias", "-0.1"],
            vec!["--normal-bias", "-0.1"],
        ),
        (
            "nan.json",
            format!(r#"{{"points": [{ok}]}}"#),
            vec!["--normal-bias", "NaN"],
            vec!["--normal-bias", "NaN"],
        ),
    ];
    for (name, contents, args, mentions) in cases {
        let input = dir.0.join(name);
        if name != "missing.json" {
            std::fs::write(&input, contents).unwrap();
        }
        let out = dir.0.join("out.json");
        let o = sample(&asset, &input, &out, &args);
        let stderr = text(&o.stderr);
        assert!(!o.status.success(), "{name}: exit status {:?}", o.status);
        let lines: Vec<&str> = stderr.lines().collect();
        assert_eq!(lines.len(), 1, "{name}: stderr is not one line: {stderr:?}");
        assert!(lines[0].starts_with("error:"), "{name}: {stderr:?}");
        for m in mentions {
            assert!(
                lines[0].contains(m),
                "{name}: {stderr:?} does not mention {m:?}"
            );
        }
        assert!(!out.exists(), "{name}: wrote {}", out.display());
        let _ = std::fs::remove_file(&input);
        let left: Vec<String> = dir
            .entries()
            .into_iter()
            .filter(|e| e != "cornell.prt")
            .collect();
        assert!(left.is_empty(), "{name}: left {left:?}");
    }
}

/// `prt render SCENE ASSET --lights RIG -o OUT [more args]`, 160x90 unless `more` sets a size.
fn render(scene: &Path, asset: &Path, rig: &Path, out: &Path, more: &[&str]) -> Output {
    let mut args: Vec<&std::ffi::OsStr> = vec![
        "render".as_ref(),
        scene.as_os_str(),
        asset.as_os_str(),
        "--lights".as_ref(),
        rig.as_os_str(),
        "-o".as_ref(),
        out.as_os_str(),
    ];
    if !more.contains(&"--size") {
        args.extend(["--size", "160x90"].map(std::ffi::OsStr::new));
    }
    args.extend(more.iter().map(|s| std::ffi::OsStr::new(*s)));
    prt(&args, None)
}

/// `prt render` writes a PNG (and the EXR on request) for every view, and nothing else.
#[test]
fn render_writes_every_view() {
    let dir = Scratch::new("render-ok");
    let asset = bake_cornell(&dir);
    for view in ["lit", "direct", "indirect", "albedo", "heatmap"] {
        let png = dir.0.join(format!("{view}.png"));
        let exr = dir.0.join(format!("{view}.exr"));
        let o = render(
            &cornell(),
            &asset,
            &cornell_rig(),
            &png,
            &["--view", view, "--exr", exr.to_str().unwrap()],
        );
        assert!(o.status.success(), "{view}: {}", text(&o.stderr));
        let bytes = std::fs::read(&png).unwrap();
        assert_eq!(&bytes[1..4], b"PNG", "{view}");
        assert!(std::fs::metadata(&exr).unwrap().len() > 0);
    }
    let mut want: Vec<String> = ["lit", "direct", "indirect", "albedo", "heatmap"]
        .iter()
        .flat_map(|v| [format!("{v}.exr"), format!("{v}.png")])
        .collect();
    want.push("cornell.prt".into());
    want.sort();
    assert_eq!(dir.entries(), want);
}

/// Every bad render input gives one `error:` line naming the flag or file and the value, a
/// non-zero exit, and no output file.
#[test]
fn render_bad_input_fails_cleanly() {
    let dir = Scratch::new("render-bad");
    let asset = bake_cornell(&dir);
    let out = dir.0.join("out.png");
    let many = fixture("rigs/cornell_256.json");
    // 4,097 lights: one more than the GI runtime (and the Forward+ stage) can be built for.
    let too_many = dir.0.join("rig_4097.json");
    let mut doc: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&many).unwrap()).unwrap();
    let first = doc["lights"][0].clone();
    doc["lights"] = serde_json::Value::Array(vec![first; 4097]);
    std::fs::write(&too_many, serde_json::to_vec(&doc).unwrap()).unwrap();
    let other = fixture("lights.gltf");
    let empty = fixture("empty.gltf");
    let (scene, rig) = (cornell(), cornell_rig());
    let cases: Vec<(&Path, &Path, Vec<&str>, Vec<&str>)> = vec![
        (
            &scene,
            &rig,
            vec!["--view", "shiny"],
            vec!["--view", "shiny"],
        ),
        (&scene, &rig, vec!["--size", "0x90"], vec!["--size", "0x90"]),
        (&scene, &rig, vec!["--size", "9000000x90"], vec!["9000000"]),
        (&scene, &rig, vec!["--fov", "0"], vec!["--fov", "0"]),
        (&scene, &rig, vec!["--fov", "180"], vec!["--fov", "180"]),
        (
            &scene,
            &rig,
            vec!["--eye", "1,1,1", "--target", "1,1,1"],
            vec!["--eye", "--target"],
        ),
        (&scene, &rig, vec!["--tile", "8"], vec!["--tile", "8"]),
        (&other, &rig, vec![], vec!["lights.gltf", "--force"]),
        (&empty, &rig, vec!["--force"], vec!["no triangles"]),
        (
            &scene,
            &too_many,
            vec!["--view", "lit"],
            vec!["4097", "4096"],
        ),
    ];
    for (s, r, args, needles) in cases {
        let o = render(s, &asset, r, &out, &args);
        let stderr = text(&o.stderr);
        assert!(!o.status.success(), "{args:?} succeeded");
        let lines: Vec<&str> = stderr.lines().collect();
        assert_eq!(
            lines.len(),
            1,
            "{args:?}: stderr is not one line: {stderr:?}"
        );
        assert!(lines[0].starts_with("error:"), "{args:?}: {stderr:?}");
        for n in needles {
            assert!(lines[0].contains(n), "{args:?}: {n:?} not in {stderr:?}");
        }
        assert!(!out.exists(), "{args:?} left {}", out.display());
        assert_eq!(dir.entries(), ["cornell.prt", "rig_4097.json"], "{args:?}");
    }
    // The lit view takes the 257 lights, GI included.
    let o = render(&scene, &asset, &many, &out, &["--view", "lit"]);
    assert!(o.status.success(), "{}", text(&o.stderr));
}

/// Outputs that would destroy something are refused before any work: a device such as
/// `/dev/null` (the atomic rename would replace it with a regular file), the command's own
/// input scene, asset or rig. The inputs stay as they were.
#[test]
fn outputs_never_replace_inputs_or_devices() {
    let dir = Scratch::new("outputs");
    let scene = dir.0.join("scene.gltf");
    std::fs::copy(cornell(), &scene).unwrap();
    let before = std::fs::read(&scene).unwrap();
    for out in [scene.as_path(), Path::new("/dev/null")] {
        let o = prt(
            &[
                "bake".as_ref(),
                scene.as_os_str(),
                "-o".as_ref(),
                out.as_os_str(),
                "--rays".as_ref(),
                "64".as_ref(),
            ],
            None,
        );
        let stderr = text(&o.stderr);
        assert!(!o.status.success(), "bake -o {} succeeded", out.display());
        assert_eq!(stderr.lines().count(), 1, "{stderr:?}");
        assert!(stderr.contains(&out.display().to_string()), "{stderr:?}");
    }
    assert_eq!(
        std::fs::read(&scene).unwrap(),
        before,
        "the scene was changed"
    );
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        let dev = std::fs::metadata("/dev/null").unwrap();
        assert!(
            dev.file_type().is_char_device(),
            "/dev/null is no longer a device"
        );
    }
    let asset = bake_cornell(&dir);
    let asset_bytes = std::fs::read(&asset).unwrap();
    let rig = dir.0.join("rig.json");
    std::fs::copy(cornell_rig(), &rig).unwrap();
    for out in [&asset, &rig] {
        let o = prt(
            &[
                "relight".as_ref(),
                asset.as_os_str(),
                "--lights".as_ref(),
                rig.as_os_str(),
                "--json".as_ref(),
                out.as_os_str(),
            ],
            None,
        );
        assert!(
            !o.status.success(),
            "relight --json {} succeeded",
            out.display()
        );
        assert!(
            text(&o.stderr).contains("refusing to overwrite"),
            "{}",
            text(&o.stderr)
        );
    }
    assert_eq!(
        std::fs::read(&asset).unwrap(),
        asset_bytes,
        "the asset was changed"
    );
}

/// The output's directory is checked before the bake, not after it: a missing one fails at once
/// with a message naming it, and nothing is written anywhere.
#[test]
fn missing_output_directory_fails_before_baking() {
    let dir = Scratch::new("missing-dir");
    let out = dir.0.join("no_such_dir").join("x.prt");
    let start = std::time::Instant::now();
    let o = prt(
        &[
            "bake".as_ref(),
            fixture("scenes/sponza_lod4.glb").as_os_str(),
            "--double-sided".as_ref(),
            "-o".as_ref(),
            out.as_os_str(),
        ],
        None,
    );
    assert!(!o.status.success());
    let err = text(&o.stderr);
    assert!(
        err.contains("no_such_dir") && err.contains("directory"),
        "{err}"
    );
    assert!(
        start.elapsed().as_secs_f64() < 10.0,
        "failed only after {:?}",
        start.elapsed()
    );
    assert!(dir.entries().is_empty(), "{:?}", dir.entries());
}

/// SIGTERM while the asset is being written removes the temporary file and the process dies of
/// the signal (the shell reports 143); the output is not created. The signal is sent when the temporary file appears
/// (Sponza at 1.2 m writes about 100 MB); if a run finishes before that is seen, it is retried.
#[test]
fn sigterm_during_the_write_leaves_no_temporary_file() {
    let dir = Scratch::new("sigterm");
    let out = dir.0.join("sponza.prt");
    for _attempt in 0..3 {
        let mut child = Command::new(env!("CARGO_BIN_EXE_prt"))
            .args([
                "bake".as_ref(),
                fixture("scenes/sponza_lod4.glb").as_os_str(),
                "--double-sided".as_ref(),
                "--spacing".as_ref(),
                "1.2".as_ref(),
                "-o".as_ref(),
                out.as_os_str(),
            ])
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let signalled = loop {
            if child.try_wait().unwrap().is_some() {
                break false;
            }
            if dir.entries().iter().any(|e| e.contains(".tmp")) {
                // SAFETY: kill(2) on our own child's pid.
                unsafe { libc::kill(child.id() as i32, libc::SIGTERM) };
                break true;
            }
            std::thread::sleep(std::time::Duration::from_micros(200));
        };
        let status = child.wait().unwrap();
        if !signalled || status.success() {
            // Finished before the signal arrived: try again.
            let _ = std::fs::remove_file(&out);
            continue;
        }
        use std::os::unix::process::ExitStatusExt;
        assert_eq!(status.signal(), Some(libc::SIGTERM), "{status:?}");
        assert!(dir.entries().is_empty(), "left behind: {:?}", dir.entries());
        return;
    }
    panic!("three bakes finished before their temporary file was seen");
}

/// `--quality fast` is the 512-direction lattice without coarse bricks exactly (the same
/// bytes), and the default is not: 2048 rays.
#[test]
fn quality_fast_is_512_rays_without_coarse_bricks() {
    let dir = Scratch::new("quality-fast");
    let bake = |name: &str, extra: &[&str]| {
        let args = [&["--spacing", "0.5"], extra].concat();
        let (out, asset) = bake_cornell_with(&dir, name, &args);
        assert!(out.status.success(), "{}", text(&out.stderr));
        std::fs::read(asset).unwrap()
    };
    let fast = bake("fast.prt", &["--quality", "fast"]);
    assert_eq!(
        bake("explicit.prt", &["--rays", "512", "--far-ratio", "0"]),
        fast
    );
    assert_ne!(bake("default.prt", &[]), fast);
}

/// Factor rows past `--row-memory` go to a file in `$TMPDIR`: the bake reports them, and when
/// that directory cannot take them it fails with one line naming the file and the remedy, and
/// writes nothing.
#[test]
fn row_memory_spills_to_tmpdir_or_says_why_not() {
    let dir = Scratch::new("spill");
    let out = dir.0.join("cornell.prt");
    let input = cornell();
    let bake = |tmpdir: &Path| {
        Command::new(env!("CARGO_BIN_EXE_prt"))
            .args([
                "bake".as_ref(),
                input.as_os_str(),
                "-o".as_ref(),
                out.as_os_str(),
            ])
            .args(["--row-memory", "0"])
            .env("TMPDIR", tmpdir)
            .output()
            .expect("run prt")
    };
    let o = bake(&dir.0);
    assert!(o.status.success(), "bake failed: {}", text(&o.stderr));
    let stdout = text(&o.stdout);
    assert!(
        stdout.contains("of factor rows past --row-memory waited in a temporary file"),
        "{stdout}"
    );
    assert_eq!(dir.entries(), ["cornell.prt"], "the row file is gone");
    std::fs::remove_file(&out).unwrap();

    let missing = dir.0.join("no_such_dir");
    let o = bake(&missing);
    let stderr = text(&o.stderr);
    assert!(!o.status.success(), "exit status {:?}", o.status);
    assert_eq!(stderr.lines().count(), 1, "{stderr:?}");
    assert!(stderr.starts_with("error:"), "{stderr:?}");
    assert!(stderr.contains("no_such_dir/prt-bake-rows-"), "{stderr:?}");
    assert!(stderr.contains("TMPDIR"), "{stderr:?}");
    assert!(dir.entries().is_empty(), "left {:?}", dir.entries());
}

/// `--probe-budget` caps the probes with data and the bake says what it dropped (and warns when
/// it cannot);
/// `--prune-error` is refused with `--uniform` before any work, and `--quality high` drops
/// nothing.
#[test]
fn probe_budget_and_prune_error() {
    let dir = Scratch::new("refine");
    let bake = |name: &str, extra: &[&str]| {
        let args = [&["--spacing", "0.25", "--rays", "64"], extra].concat();
        bake_cornell_with(&dir, name, &args)
    };
    let (out, asset) = bake("budget.prt", &["--probe-budget", "500"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let stdout = text(&out.stdout);
    let line = stdout
        .lines()
        .find(|l| l.starts_with("refine"))
        .unwrap_or_else(|| {
            panic!("no refine line: {stdout}");
        });
    assert!(
        line.contains("500 of") && line.contains("(budget 500)"),
        "{line}"
    );
    let asset = prt_format::read_asset(&asset).unwrap();
    assert_eq!(asset.probes.iter().filter(|p| p.has_data()).count(), 500);
    // Below what every other grid point alone needs: as far as it goes, with a warning.
    let (out, _) = bake("small.prt", &["--probe-budget", "200"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let stderr = text(&out.stderr);
    assert!(
        stderr.contains("warning: probe budget 200 not met"),
        "{stderr}"
    );

    let (out, asset) = bake("uniform.prt", &["--uniform", "--prune-error", "0.1"]);
    assert!(!out.status.success());
    let stderr = text(&out.stderr);
    assert!(
        stderr.contains("--prune-error") && stderr.contains("--uniform"),
        "{stderr}"
    );
    assert!(!asset.exists());

    let (out, _) = bake("high.prt", &["--quality", "high"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let stdout = text(&out.stdout);
    assert!(!stdout.lines().any(|l| l.starts_with("refine")), "{stdout}");
}

/// `--cells-per-spacing` is the frontier's `--cells`: the asset records a cell of the spacing
/// over it, the same bytes as `--cell-size` of that many metres, and `--quality high` keeps its
/// 24th without it; a value outside 1..=256 is refused naming it and writes nothing, and it
/// cannot be combined with `--cell-size` or `--no-merge`.
#[test]
fn cells_per_spacing_sets_the_cell_size() {
    let dir = Scratch::new("cells");
    let bake = |name: &str, extra: &[&str]| {
        let args = [&["--spacing", "0.5", "--rays", "64"], extra].concat();
        bake_cornell_with(&dir, name, &args)
    };
    let (out, sixth) = bake("sixth.prt", &["--cells-per-spacing", "6"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let asset = prt_format::read_asset(&sixth).unwrap();
    let cell = asset.header.settings.cell_size;
    assert!((cell - 0.5 / 6.0).abs() < 1e-6, "cell {cell}");
    let (out, metres) = bake("metres.prt", &["--cell-size", &(0.5f32 / 6.0).to_string()]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert_eq!(
        std::fs::read(&sixth).unwrap(),
        std::fs::read(&metres).unwrap()
    );

    let (out, high) = bake("high.prt", &["--quality", "high"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let cell = prt_format::read_asset(&high)
        .unwrap()
        .header
        .settings
        .cell_size;
    assert!(
        (cell - 0.5 / 24.0).abs() < 1e-6,
        "high keeps a 24th: {cell}"
    );

    for bad in ["0", "0.5", "300", "NaN"] {
        let (out, asset) = bake("bad.prt", &["--cells-per-spacing", bad]);
        assert!(!out.status.success(), "{bad}");
        let stderr = text(&out.stderr);
        assert!(
            stderr.contains(&format!("cells_per_spacing = {bad}"))
                && stderr.contains("between 1 and 256"),
            "{bad}: {stderr}"
        );
        assert!(!asset.exists(), "{bad}");
    }
    let (out, _) = bake("no_merge.prt", &["--cells-per-spacing", "6", "--no-merge"]);
    assert!(!out.status.success());
    assert!(
        text(&out.stderr).contains("--no-merge"),
        "{}",
        text(&out.stderr)
    );
    let (out, _) = bake(
        "both.prt",
        &["--cells-per-spacing", "6", "--cell-size", "0.1"],
    );
    assert!(!out.status.success());
    assert!(
        text(&out.stderr).contains("--cell-size"),
        "{}",
        text(&out.stderr)
    );
}
