#!/usr/bin/env bash
# Regenerates the bundled sample captures in samples/ (deterministic).
#   samples/sou_wave.log  paper-002 SOU log, 12 nodes (scripts/make_samples.py, standard library)
#   samples/walk.csv      16-sensor imubake CSV (paper 000's layout) simulated by `imubake simulate`
#                         from ../shared/data/bvh/pymo_walk.bvh (omimo/PyMO, MIT), 0.5° of noise,
#                         heading 35°, for the mixamo rig with mappings/paper000_16imu_mixamo.json
set -euo pipefail
cd "$(dirname "$0")/.."
python3 scripts/make_samples.py
cargo run --quiet --release -- simulate ../shared/data/bvh/pymo_walk.bvh \
  --mapping mappings/paper000_16imu_mixamo.json --bone-map Spine2=Spine \
  --noise-deg 0.5 --heading-deg 35 --seed 2026 --output samples/walk.csv
