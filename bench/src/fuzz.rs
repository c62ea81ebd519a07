//! `prt-bench fuzz` (issue 8): a stable-toolchain mutation fuzzer for the two file formats prt
//! reads from strangers, glTF scenes and `.prt` assets, run for a fixed time by
//! `scripts/stress.sh` (briefly in CI, for minutes on demand).
//!
//! - **gltf**: every JSON glTF under `fixtures/` (good, bad and hostile) is parsed, and one to
//!   three random edits are applied to random places in its JSON tree: a value replaced by one
//!   from a list of troublemakers (0, -1, 2^31, 2^32, 2^53, 1e39, component-type codes, "VEC2",
//!   "MAT4", "../x", "/dev/zero", an empty object), a key removed, an array element duplicated.
//!   The result is baked (32 rays, at most 4,096 probes, one thread).
//! - **asset**: small bakes of the Cornell room and the two-room fixture are encoded, bytes are
//!   flipped, overwritten, cut or repeated, and (four times in five) the length and checksum are
//!   fixed up so that the mutation reaches the decoder and validation; an asset that decodes is
//!   relit on the CPU.
//!
//! Errors are the expected outcome. A panic anywhere (caught here) is a failure, as is an input
//! that takes longer than `--slow` seconds; both are saved to `--out`. Allocation bombs abort the
//! process: `scripts/stress.sh` runs this under a memory limit so that they show as a failure.
//! Deterministic for a given `--seed` (xorshift64*).

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use prt_bake::{BakeSettings, NoProgress};
use serde_json::Value;

#[derive(clap::Args)]
pub struct FuzzArgs {
    /// What to fuzz: gltf or asset.
    #[arg(long)]
    target: String,
    /// Wall-clock budget in seconds.
    #[arg(long, default_value_t = 10.0)]
    seconds: f64,
    /// Random seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// An input slower than this many seconds counts as a failure (a hang).
    #[arg(long, default_value_t = 10.0)]
    slow: f64,
    /// Directory the bundled fixtures are relative to (the repository root).
    #[arg(long, default_value = ".")]
    root: PathBuf,
    /// Directory to save failing inputs into [default: none saved].
    #[arg(long)]
    out: Option<PathBuf>,
}

/// xorshift64* (Vigna 2016): small, fast and deterministic.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

/// Counts of one run.
#[derive(Default)]
struct Tally {
    inputs: u64,
    accepted: u64,
    refused: u64,
    panics: u64,
    slow: u64,
    slowest: Duration,
}

/// `prt-bench fuzz`: fuzzes `--target` for `--seconds`; fails when an input panicked or was slow.
pub fn run(args: FuzzArgs) -> Result<()> {
    let mut rng = Rng(args.seed.max(1).wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1);
    if let Some(out) = &args.out {
        std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    }
    let scratch = std::env::temp_dir().join(format!("prt-fuzz-{}", std::process::id()));
    std::fs::create_dir_all(&scratch)?;
    let result = match args.target.as_str() {
        "gltf" => fuzz_gltf(&args, &mut rng, &scratch),
        "asset" => fuzz_asset(&args, &mut rng),
        other => bail!("--target {other}: expected gltf or asset"),
    };
    let _ = std::fs::remove_dir_all(&scratch);
    let t = result?;
    println!(
        "fuzz {}: {} inputs in {:.0} s (seed {}): {} accepted, {} refused with an error, {} panics, {} slower than {} s (slowest {:.2} s)",
        args.target,
        t.inputs,
        args.seconds,
        args.seed,
        t.accepted,
        t.refused,
        t.panics,
        t.slow,
        args.slow,
        t.slowest.as_secs_f64()
    );
    if t.panics + t.slow > 0 {
        bail!("{} failing inputs", t.panics + t.slow);
    }
    Ok(())
}

/// Runs `f` on one input, counting its outcome and saving the input when it fails.
fn attempt(
    args: &FuzzArgs,
    t: &mut Tally,
    input: &[u8],
    ext: &str,
    f: impl FnOnce() -> Result<(), String> + std::panic::UnwindSafe,
) {
    t.inputs += 1;
    // The input being tried stays on disk until it ends: an abort (allocation bomb) or a hang
    // that the process does not survive leaves it behind.
    let current = args
        .out
        .as_ref()
        .map(|o| o.join(format!("{}-current.{ext}", args.target)));
    if let Some(c) = &current {
        let _ = std::fs::write(c, input);
    }
    let start = Instant::now();
    // A panic the libraries turn into an error stays quiet; one that escapes is reported.
    let outcome = std::panic::catch_unwind(|| prt_cli::panics::quietly(f));
    let took = start.elapsed();
    if let Some(c) = &current {
        let _ = std::fs::remove_file(c);
    }
    t.slowest = t.slowest.max(took);
    let failed = match outcome {
        Ok(Ok(())) => {
            t.accepted += 1;
            false
        }
        Ok(Err(_)) => {
            t.refused += 1;
            false
        }
        Err(_) => {
            t.panics += 1;
            true
        }
    };
    let slow = took.as_secs_f64() > args.slow;
    t.slow += u64::from(slow);
    if failed || slow {
        if let Some(out) = &args.out {
            let name = format!("{}-{}.{ext}", args.target, t.inputs);
            let _ = std::fs::write(out.join(name), input);
        }
    }
}

fn gltf_corpus(root: &Path) -> Result<Vec<Value>> {
    let mut docs = Vec::new();
    for dir in ["fixtures", "fixtures/bad", "fixtures/hostile"] {
        let Ok(entries) = std::fs::read_dir(root.join(dir)) else {
            continue;
        };
        let mut paths: Vec<PathBuf> = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|x| x == "gltf"))
            .collect();
        paths.sort();
        for p in paths {
            if let Ok(v) = serde_json::from_slice::<Value>(&std::fs::read(&p)?) {
                docs.push(v);
            }
        }
    }
    if docs.is_empty() {
        bail!("no .gltf files under {}/fixtures", root.display());
    }
    Ok(docs)
}

/// Every place in `v`, as a path of keys and indices.
fn places(v: &Value, at: &mut Vec<Place>, out: &mut Vec<Vec<Place>>) {
    out.push(at.clone());
    match v {
        Value::Object(m) => {
            for (k, c) in m {
                at.push(Place::Key(k.clone()));
                places(c, at, out);
                at.pop();
            }
        }
        Value::Array(a) => {
            for (i, c) in a.iter().enumerate() {
                at.push(Place::Index(i));
                places(c, at, out);
                at.pop();
            }
        }
        _ => {}
    }
}

#[derive(Clone)]
enum Place {
    Key(String),
    Index(usize),
}

fn at_mut<'a>(v: &'a mut Value, path: &[Place]) -> Option<&'a mut Value> {
    path.iter().try_fold(v, |v, p| match p {
        Place::Key(k) => v.get_mut(k.as_str()),
        Place::Index(i) => v.get_mut(*i),
    })
}

fn troublemaker(rng: &mut Rng) -> Value {
    let pick = [
        serde_json::json!(0),
        serde_json::json!(-1),
        serde_json::json!(1),
        serde_json::json!(3),
        serde_json::json!(2147483648u64),
        serde_json::json!(4294967296u64),
        serde_json::json!(9007199254740993u64),
        serde_json::json!(1e39),
        serde_json::json!(-1e39),
        serde_json::json!(1e-45),
        serde_json::json!(5120),
        serde_json::json!(5126),
        serde_json::json!("VEC2"),
        serde_json::json!("MAT4"),
        serde_json::json!("SCALAR"),
        serde_json::json!("../x.bin"),
        serde_json::json!("/dev/zero"),
        serde_json::json!("data:,"),
        serde_json::json!(""),
        serde_json::json!({}),
        serde_json::json!([]),
        serde_json::json!([0, 0]),
        serde_json::json!(null),
        serde_json::json!(true),
    ];
    pick[rng.below(pick.len())].clone()
}

fn mutate_json(doc: &mut Value, rng: &mut Rng) {
    for _ in 0..1 + rng.below(3) {
        let mut all = Vec::new();
        places(doc, &mut Vec::new(), &mut all);
        let path = all[rng.below(all.len())].clone();
        match rng.below(4) {
            0 | 1 => {
                if let Some(v) = at_mut(doc, &path) {
                    *v = troublemaker(rng);
                }
            }
            2 => {
                if let Some((Place::Key(k), parent)) = path.split_last() {
                    if let Some(Value::Object(m)) = at_mut(doc, parent) {
                        m.remove(k);
                    }
                }
            }
            _ => {
                if let Some(Value::Array(a)) = at_mut(doc, &path) {
                    if let Some(first) = a.first().cloned() {
                        a.push(first);
                    }
                }
            }
        }
    }
}

fn fuzz_gltf(args: &FuzzArgs, rng: &mut Rng, scratch: &Path) -> Result<Tally> {
    let corpus = gltf_corpus(&args.root)?;
    let settings = BakeSettings {
        rays: 32,
        max_probes: 4096,
        threads: Some(1),
        ..BakeSettings::default()
    };
    let deadline = Instant::now() + Duration::from_secs_f64(args.seconds);
    let mut t = Tally::default();
    // Mutated files sit beside copies of the corpus' external files, so relative URIs resolve.
    for name in ["bomb.png", "bomb.exr"] {
        let _ = std::fs::copy(
            args.root.join("fixtures/hostile").join(name),
            scratch.join(name),
        );
    }
    while Instant::now() < deadline {
        let mut doc = corpus[rng.below(corpus.len())].clone();
        mutate_json(&mut doc, rng);
        let bytes = serde_json::to_vec(&doc)?;
        let path = scratch.join("input.gltf");
        std::fs::write(&path, &bytes)?;
        attempt(args, &mut t, &bytes, "gltf", || {
            prt_bake::bake(&path, &settings, &NoProgress)
                .map(|_| ())
                .map_err(|e| e.to_string())
        });
    }
    Ok(t)
}

fn fuzz_asset(args: &FuzzArgs, rng: &mut Rng) -> Result<Tally> {
    let small = |scene: &str, spacing: f32| -> Result<Vec<u8>> {
        let settings = BakeSettings {
            rays: 64,
            spacing: Some(spacing),
            ..BakeSettings::default()
        };
        let (asset, _) = prt_bake::bake(&args.root.join(scene), &settings, &NoProgress)?;
        Ok(prt_format::encode(&asset)?)
    };
    let corpus = [
        small("fixtures/cornell/cornell.gltf", 0.5)?,
        small("fixtures/two_rooms.gltf", 1.0)?,
    ];
    let lighting = prt_runtime::load_rig(&args.root.join("fixtures/rigs/point_spot_sun_sky.json"))?;
    let deadline = Instant::now() + Duration::from_secs_f64(args.seconds);
    let mut t = Tally::default();
    while Instant::now() < deadline {
        let mut bytes = corpus[rng.below(corpus.len())].clone();
        for _ in 0..1 + rng.below(4) {
            let n = bytes.len();
            let i = rng.below(n);
            match rng.below(5) {
                0 => bytes[i] ^= 1 << rng.below(8),
                1 => bytes[i] = [0, 0xFF, 0x7F, 0x80][rng.below(4)],
                2 => {
                    let end = (i + 1 + rng.below(8)).min(n);
                    bytes[i..end].fill(0xFF);
                }
                3 => bytes.truncate(i.max(1)),
                _ => {
                    let end = (i + 1 + rng.below(64)).min(n);
                    let chunk = bytes[i..end].to_vec();
                    bytes.splice(i..i, chunk);
                }
            }
        }
        if rng.below(5) != 0 && bytes.len() >= 28 {
            // Fix up length and checksum (io.rs layout: 20-byte prefix, 8-byte checksum).
            let body = bytes.len() - 8;
            let payload = (body - 20) as u64;
            bytes[12..20].copy_from_slice(&payload.to_le_bytes());
            let sum = xxhash_rust::xxh3::xxh3_64(&bytes[..body]);
            bytes[body..].copy_from_slice(&sum.to_le_bytes());
        }
        attempt(args, &mut t, &bytes, "prt", || {
            let asset = prt_format::decode(&bytes).map_err(|e| e.to_string())?;
            prt_runtime::CpuRelighter::new(&asset)
                .map_err(|e| e.to_string())?
                .relight(&lighting, 1)
                .map(|_| ())
                .map_err(|e| e.to_string())
        });
    }
    Ok(t)
}
