//! Helpers shared by the cross-crate tests in `tests/`: paths to fixtures (the repository's own
//! scenes and the vendored public scenes and reference data: no test reads outside the clone),
//! scratch directories, and small bake shortcuts.

use std::path::{Path, PathBuf};

use prt_bake::{BakeSettings, NoProgress};
use prt_format::sh::ShRgb;
use prt_format::Asset;
use prt_runtime::gpu::wgpu;

/// The headless GPU device the GPU tests run on (lavapipe in CI); no adapter fails the test,
/// never skips it.
pub fn gpu_device() -> (wgpu::Device, wgpu::Queue) {
    let (device, queue, _) =
        prt_runtime::gpu::headless_device().expect("a GPU adapter (lavapipe in CI) is required");
    (device, queue)
}

/// Worst |got - reference| over `asset`'s valid probes and every coefficient, relative to each
/// probe's largest |SH0| channel plus 1e-7 of the largest in `reference` (so nearly black probes,
/// where float rounding dominates, do not fail on noise). Every value of `got` must be finite.
pub fn worst_of_sh0(asset: &Asset, got: &[ShRgb], reference: &[ShRgb]) -> f32 {
    let peak = reference
        .iter()
        .map(|c| c[0].iter().fold(0.0f32, |m, v| m.max(v.abs())))
        .fold(0.0, f32::max);
    let mut w = 0.0f32;
    for (i, (x, y)) in got.iter().zip(reference).enumerate() {
        if !asset.probes[i].is_valid() {
            continue;
        }
        let dc = y[0].iter().fold(0.0f32, |m, v| m.max(v.abs())) + 1e-7 * peak;
        for k in 0..9 {
            for c in 0..3 {
                assert!(x[k][c].is_finite(), "probe {i}: {}", x[k][c]);
                w = w.max((x[k][c] - y[k][c]).abs() / dc);
            }
        }
    }
    w
}

/// `fixtures/<rel>` of this repository.
pub fn fixture(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../fixtures")
        .join(rel)
}

/// The reference Cornell box (`fixtures/cornell/cornell.gltf`, with the independent renderer's
/// probe SH beside it).
pub fn cornell() -> PathBuf {
    fixture("cornell/cornell.gltf")
}

/// Settings with `rays` rays and otherwise the fast preset's ([`BakeSettings::fast`]: every hit
/// in its own brick's factor, no coarse bricks unless a test asks for them; sparse placement,
/// as every preset but the exact one).
pub fn rays(rays: u32) -> BakeSettings {
    BakeSettings {
        rays,
        ..BakeSettings::fast()
    }
}

/// Bakes in memory and panics with the error's message on failure.
pub fn bake_ok(path: &Path, settings: &BakeSettings) -> Asset {
    match prt_bake::bake(path, settings, &NoProgress) {
        Ok((asset, _)) => asset,
        Err(e) => panic!("baking {} failed: {e}", path.display()),
    }
}

/// Bakes in memory and returns the error, panicking if the bake succeeds.
pub fn bake_err(path: &Path, settings: &BakeSettings) -> prt_bake::BakeError {
    match prt_bake::bake(path, settings, &NoProgress) {
        Ok(_) => panic!("baking {} succeeded, expected an error", path.display()),
        Err(e) => e,
    }
}

/// `lighting` with every light's intensity and a constant sky times `k` (an image sky is left
/// as it is).
pub fn brighter(lighting: &prt_runtime::Lighting, k: f32) -> prt_runtime::Lighting {
    let mut l = lighting.clone();
    for light in &mut l.rig.lights {
        light.intensity *= k;
    }
    if let prt_runtime::sky::SkyModel::Constant(c) = &mut l.sky {
        *c = c.map(|x| x * k);
    }
    l
}

/// Bounds that hold exactly one probe, at `p` (a zero-extent grid has one probe per axis,
/// placed at the centre of the bounds).
pub fn point_bounds(p: [f32; 3]) -> Option<[f32; 6]> {
    Some([p[0], p[1], p[2], p[0], p[1], p[2]])
}

/// A scratch directory, unique per process and test name, removed when dropped.
pub struct ScratchDir(PathBuf);

impl ScratchDir {
    pub fn new(test_name: &str) -> ScratchDir {
        let dir =
            std::env::temp_dir().join(format!("prt-tests-{}-{test_name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("create scratch dir");
        ScratchDir(dir)
    }

    pub fn path(&self) -> &Path {
        &self.0
    }

    /// Names of the entries in the directory, sorted.
    pub fn entries(&self) -> Vec<String> {
        let mut names: Vec<String> = std::fs::read_dir(&self.0)
            .expect("list scratch dir")
            .map(|e| {
                e.expect("dir entry")
                    .file_name()
                    .to_string_lossy()
                    .into_owned()
            })
            .collect();
        names.sort();
        names
    }
}

impl Drop for ScratchDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// A surface point and its unit normal.
pub type SurfacePoint = ([f32; 3], [f32; 3]);

/// Front-face surfels of `asset`: where the lookup reads the probes at surfaces.
pub fn surfel_points(asset: &Asset) -> Vec<SurfacePoint> {
    asset
        .surfels
        .iter()
        .filter(|s| s.flags & prt_format::BRICK_BACKFACE == 0)
        .map(|s| (s.position, s.normal))
        .collect()
}

/// Both bakes relit with the rig at `rig` and sampled with the default surface lookup at every
/// `step`-th of `points`: the mean relative difference of `b`'s irradiance from `a`'s, after
/// `check` has seen each pair of samples (a's, b's) and its point.
pub fn surface_difference(
    (a, b): (&Asset, &Asset),
    rig: &Path,
    (points, step): (&[SurfacePoint], usize),
    check: impl Fn(&prt_runtime::Sample, &prt_runtime::Sample, [f32; 3]),
) -> f64 {
    let lighting = prt_runtime::load_rig(rig).unwrap();
    let lookup = prt_runtime::LookupSettings::default();
    let relit = |x: &Asset| {
        let relighter = prt_runtime::CpuRelighter::new(x).unwrap();
        relighter.relight(&lighting, 1).unwrap()
    };
    let (ra, rb) = (relit(a), relit(b));
    let surface = prt_runtime::surface::SurfaceSampler::for_relit;
    let (sa, sb) = (surface(a, &ra, &lookup), surface(b, &rb, &lookup));
    let (mut diff, mut total) = (0.0f64, 0.0f64);
    for &(p, n) in points.iter().step_by(step) {
        let (x, y) = (sa.sample(p, n), sb.sample(p, n));
        check(&x, &y, p);
        for c in 0..3 {
            diff += f64::from((x.irradiance[c] - y.irradiance[c]).abs());
            total += f64::from(x.irradiance[c].abs());
        }
    }
    diff / total
}

/// The validation error of `asset` after `damage`; panics when validation accepts it.
pub fn refused(asset: &Asset, damage: &dyn Fn(&mut Asset)) -> String {
    let mut a = asset.clone();
    damage(&mut a);
    match prt_format::validate::validate(&a) {
        Err(e) => e.to_string(),
        Ok(()) => panic!("accepted"),
    }
}
