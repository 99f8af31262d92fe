#!/usr/bin/env bash
# Golden outputs: converts a fixed list of takes and compares the SHA-256 of every BVH, GLB and
# .bin written with scripts/golden.sha256 (recorded by `scripts/golden.sh --record` on the code
# before a change that must not change outputs). Exit 1 on any difference.
#
#   scripts/golden.sh            compare
#   scripts/golden.sh --record   write scripts/golden.sha256 from this code
#
# The takes: the bundled samples with default settings; the walk at 29.97 fps in cm without
# smoothing; the SOU log through paper 002's Listing-2 (legacy) mapping; the SOU log on the sou12
# rig as .gltf at 24 fps; a generated 60-minute, 16-sensor, 100 Hz log with default settings.
set -euo pipefail
cd "$(dirname "$0")/.."
record=false
[ "${1:-}" = "--record" ] && record=true

work=target/golden
mkdir -p "$work"
cargo build --release --quiet --bin imubake --example long_log
bin=target/release/imubake
long="$work/long60.csv"
[ -s "$long" ] || target/release/examples/long_log "$long" 60 >/dev/null

rm -rf "$work/out"
run() { # name, then convert's arguments
  local name="$1"; shift
  "$bin" convert "$@" --out "$work/out/$name" >/dev/null 2>&1 || { echo "golden: $name failed to convert" >&2; exit 1; }
}
run walk_default samples/walk.csv --mapping mappings/paper000_16imu_mixamo.json
run sou_default samples/sou_wave.log --mapping samples/sou_wave.mapping.json
run walk_2997_cm samples/walk.csv --mapping mappings/paper000_16imu_mixamo.json --fps 29.97 --units cm --smooth none
run sou_2997_cm samples/sou_wave.log --mapping samples/sou_wave.mapping.json --fps 29.97 --units cm --smooth none
run sou_legacy samples/sou_wave.log --mapping samples/sou_wave.legacy.json
run sou12_gltf_24 samples/sou_wave.log --rig sou12 --format gltf --fps 24 --heading sensors
# The long log spins every sensor from its first sample: no body gives a heading.
run long60 "$long" --mapping mappings/paper000_16imu_mixamo.json --heading sensors

actual="$work/actual.sha256"
(cd "$work/out" && find . -type f \( -name '*.bvh' -o -name '*.glb' -o -name '*.bin' \) | sort | xargs sha256sum) > "$actual"
if $record; then
  cp "$actual" scripts/golden.sha256
  echo "golden: recorded $(wc -l < scripts/golden.sha256) files in scripts/golden.sha256"
  exit 0
fi
if diff -u scripts/golden.sha256 "$actual"; then
  echo "golden: all $(wc -l < "$actual") files identical"
else
  echo "golden: outputs differ from scripts/golden.sha256 (above)" >&2
  exit 1
fi
