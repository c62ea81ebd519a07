#!/usr/bin/env bash
# Regenerates the surface-irradiance references of `prt-bench surface` (issue 11) with the
# independent Mitsuba 3 oracle (surface_oracle.py; not part of this repository: point
# PRT_ORACLE_DIR at its folder): points on visible
# surfaces, the SH of incident radiance there and the exact hemispherical irradiance.
#
# Not part of CI or the tests (it installs a Python venv and libllvm19, and runs minutes).
# Usage, from anywhere:  scripts/surface_refs.sh [cornell|two_rooms|thick_walls|sponza ...]
# (no argument: all). Idempotent: the install step does nothing once done.
#
# Outputs: fixtures/surface/NAME_surface.json, floats rounded to 7 significant digits (far below
# the oracle's own sampling noise, about 1e-3 of SH0 at 65,536 directions) to keep them small.
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
ORACLE="${PRT_ORACLE_DIR:-}"
SCENES="$ROOT/fixtures/scenes"
if [ ! -f "$ORACLE/surface_oracle.py" ]; then
  echo "surface_refs: no surface_oracle.py in $ORACLE; set PRT_ORACLE_DIR to the oracle's folder" >&2
  exit 1
fi
VENV="${PRT_ORACLE_VENV:-/root/.cache/prt-oracle/venv}"
OUT="$ROOT/fixtures/surface"
PY="$VENV/bin/python"

install() {
  # Dr.Jit's LLVM backend needs libLLVM 19 (Debian 12's 14/15 abort); without it the oracle falls
  # back to the scalar variant, about 100x slower.
  if ! ls /usr/lib/x86_64-linux-gnu/libLLVM.so.19* >/dev/null 2>&1; then
    # Another apt may hold the lock: wait for it.
    while fuser /var/lib/dpkg/lock-frontend /var/lib/apt/lists/lock >/dev/null 2>&1; do sleep 5; done
    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libllvm19) \
      || echo "libllvm19 not installed: the oracle falls back to scalar_rgb (~100x slower)"
  fi
  if ! "$PY" -c "import mitsuba, drjit, pygltflib" >/dev/null 2>&1; then
    mkdir -p "$(dirname "$VENV")"
    python3 -m venv "$VENV"
    "$VENV/bin/pip" install -q -r "$ORACLE/requirements.txt"
  fi
}

# oracle NAME SCENE RIG VIEWS SIDEDNESS: the sky argument is the rig's sky colour x intensity
# (surface_oracle.py reads the rig's lights, in the rig format, but not its sky).
oracle() {
  local name=$1 scene=$2 rig=$3 views=$4 sidedness=$5
  local sky
  sky=$("$PY" -c 'import json,sys; s=json.load(open(sys.argv[1])).get("sky") or {"color":[0,0,0]}; print(*[c*s.get("intensity",1.0) for c in s["color"]])' "$rig")
  local raw="$OUT/.${name}_raw.json"
  echo "== $name: sky $sky"
  # shellcheck disable=SC2086
  "$PY" "$ORACLE/surface_oracle.py" --scene "$scene" --lights "$rig" --sky $sky \
    --viewpoints "$views" --points 300 -n 65536 --seed 1234 \
    --sidedness "$sidedness" --spot-falloff gltf -o "$raw"
  "$PY" - "$raw" "$OUT/${name}_surface.json" <<'EOF'
import json, sys
def r(x):
    if isinstance(x, float):
        return float("%.7g" % x)
    if isinstance(x, list):
        return [r(v) for v in x]
    if isinstance(x, dict):
        return {k: r(v) for k, v in x.items()}
    return x
doc = json.load(open(sys.argv[1]))
with open(sys.argv[2], "w") as f:
    json.dump(r(doc), f, separators=(",", ":"))
    f.write("\n")
EOF
  rm -f "$raw"
}

install
mkdir -p "$OUT"
cases=("$@")
[ ${#cases[@]} -eq 0 ] && cases=(cornell two_rooms thick_walls sponza)
for c in "${cases[@]}"; do
  case $c in
    # The same room, rig and viewpoints as the shared reference data's Cornell surface reference
    # (cornell_surface_n65536.json, seed 1234).
    cornell) oracle cornell "$ROOT/fixtures/cornell/cornell.gltf" "$ROOT/fixtures/cornell/rig.json" \
               "$ROOT/fixtures/cornell/cornell_probes.json" gltf ;;
    two_rooms) oracle two_rooms "$ROOT/fixtures/two_rooms.gltf" "$ROOT/fixtures/rigs/two_rooms.json" \
                 "$OUT/two_rooms_views.json" gltf ;;
    thick_walls) oracle thick_walls "$ROOT/fixtures/thick_walls.gltf" \
                   "$ROOT/fixtures/rigs/thick_walls.json" "$OUT/thick_walls_views.json" gltf ;;
    # Sponza's faces point out of the atrium; prt bakes it --double-sided, so every face is
    # two-sided. Then the truth 10 cm off the surface and the pocket flags, as the levels have
    # them (8192 directions; the image reference, sponza_image.json, is refs.py's too: see
    # fixtures/README.md).
    sponza) oracle sponza "$SCENES/sponza_lod4.glb" "$ROOT/fixtures/rigs/sponza_sun_31.json" \
              "$OUT/sponza_views.json" two
            PRT_ORACLE_DIR="$ORACLE" "$PY" "$ROOT/fixtures/levels/refs.py" \
              --scene "$SCENES/sponza_lod4.glb" --rig "$ROOT/fixtures/rigs/sponza_sun_31.json" \
              --sidedness two --extend "$OUT/sponza_surface.json" -n 8192 ;;
    *) echo "unknown case $c (cornell, two_rooms, thick_walls, sponza)" >&2; exit 2 ;;
  esac
done
