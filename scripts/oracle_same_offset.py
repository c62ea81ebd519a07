#!/usr/bin/env python3
"""Probe SH from the Mitsuba 3 oracle's tracing, with prt's shadow-ray origin offset.

The oracle (`probe_sh_oracle.py`, which this script imports from ORACLE_DIR) starts each shadow
ray at Mitsuba's `spawn_ray_to`, (1 + max|p|) * 8.94e-5 off the surface: about 1 mm at 10 m.
prt starts it max(1e-6 max|p|, 1e-4 spacing) off (`runtime/src/shadow_rays.rs`): 0.11 mm in
Sponza at a 1.08 m spacing. Where geometry within a millimetre of a lit point decides its shadow
(contacts, grazing sun), the two disagree, and prt's answer is the converged one: the decision
stays the same for offsets from 0.1x to 3x prt's and changes at Mitsuba's (docs/results/
sponza_exact.md). This script computes the oracle's estimator (same Fibonacci directions, same
hits, same emitters and BSDFs) with the shadow ray started at k times prt's offset along the hit's
geometric normal turned towards the probe ray, so that the bake can be compared with the
oracle ray for ray (tests/tests/relight.rs, `sponza_matches_mitsuba_with_the_same_shadow_offset`).

Usage (the oracle installed with its install.sh, run with its venv's python):
    ORACLE_DIR=path/to/oracle $ORACLE_DIR/venv/bin/python scripts/oracle_same_offset.py \
        --scene S.glb --rig RIG.json --probes PROBES.json --spacing 1.08 [--k 1] [-n 512] -o OUT.json
PROBES.json: {"probes": [[x, y, z], ...]} (e.g. positions from `prt relight --json`).
"""
import argparse
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.environ["ORACLE_DIR"])
import probe_sh_oracle as O  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", required=True)
    ap.add_argument("--rig", required=True, help="prt rig JSON (lights and sky)")
    ap.add_argument("--probes", required=True)
    ap.add_argument("--spacing", type=float, required=True, help="the asset's grid spacing (prt's offset scale)")
    ap.add_argument("--k", type=float, default=1.0, help="multiple of prt's offset (0 = Mitsuba's own spawn)")
    ap.add_argument("-n", "--n-dirs", type=int, default=512)
    ap.add_argument("-o", "--out", required=True)
    a = ap.parse_args()

    import mitsuba as mi
    mi.set_variant(O.pick_variant("auto"))
    import drjit as dr

    rig = json.load(open(a.rig))
    sky = rig.get("sky", {})
    sky_rgb = [c * sky.get("intensity", 1.0) for c in sky.get("color", [0, 0, 0])]
    meshes, _ = O.load_gltf(a.scene, "two", False, False, warn=lambda *s: None)
    orc = O.Oracle(meshes, O.normalize_lights(rig), sky_rgb, threads=2, log=lambda *s: None)
    scene = orc.scene
    probes = np.array(json.load(open(a.probes))["probes"], dtype=np.float64)
    dirs = O.fibonacci_sphere(a.n_dirs)

    def f32(x):
        return mi.Float(np.ascontiguousarray(x, dtype=np.float32))

    def vec(x, kind):
        return kind(f32(x[:, 0]), f32(x[:, 1]), f32(x[:, 2]))

    def numpy3(v):
        return np.stack([np.array(v[j]) for j in range(3)], 1)

    out = []
    for s in range(0, len(probes), 64):
        chunk = probes[s:s + 64]
        n = len(chunk)
        o = np.repeat(chunk, a.n_dirs, 0)
        d = np.tile(dirs, (n, 1))
        ray = mi.Ray3f(vec(o, mi.Point3f), vec(d, mi.Vector3f))
        si = scene.ray_intersect(ray)
        hit = si.is_valid()
        bsdf = si.bsdf(ray)
        p = numpy3(si.p)
        normal = numpy3(si.n)
        normal = np.where((np.sum(normal * d, 1) > 0)[:, None], -normal, normal)
        radiance = si.emitter(scene).eval(si)
        for em, extra in orc.lights:
            if extra is not None:
                raise SystemExit("spot lights with a non-Mitsuba falloff are not supported here")
            ds, spec = em.sample_direction(si, mi.Point2f(0.5, 0.5), hit)
            active = hit & dr.any(spec != 0.0)
            f = bsdf.eval(orc.ctx, si, si.to_local(ds.d), active)
            if a.k == 0:
                occluded = scene.ray_test(si.spawn_ray_to(ds.p), active)
            else:
                off = a.k * np.maximum(1e-6 * np.abs(p).max(1), 1e-4 * a.spacing)
                dist = np.array(ds.dist)
                shadow = mi.Ray3f(vec(p + normal * off[:, None], mi.Point3f), ds.d)
                shadow.maxt = f32(np.minimum(np.where(np.isfinite(dist), dist - off, np.inf), 3e38))
                occluded = scene.ray_test(shadow, active)
            radiance += dr.select(active & ~occluded, f * spec, 0.0)
        per_probe = np.array(radiance, dtype=np.float64).T.reshape(n, a.n_dirs, 3)
        for i in range(n):
            sh = O.project_sh9(dirs, per_probe[i])
            out.append({"position": chunk[i].tolist(), "sh": [[float("%.7g" % c) for c in k] for k in sh]})
    json.dump({
        "oracle": "scripts/oracle_same_offset.py over probe_sh_oracle.py (Mitsuba %s)" % mi.__version__,
        "scene": os.path.basename(a.scene), "rig": os.path.basename(a.rig), "n_dirs": a.n_dirs,
        "shadow_offset": "k * max(1e-6 max|p|, 1e-4 * %g), k = %g (0: Mitsuba's spawn_ray_to)" % (a.spacing, a.k),
        "probes": out,
    }, open(a.out, "w"), separators=(",", ":"))


if __name__ == "__main__":
    main()
