#!/usr/bin/env bash
# The whole test suite, set-up included: installs what the tests need into a cache outside the
# clone (reused when present), then runs formatting, lints and every test.
#
#   IMUBAKE_TEST_CACHE  cache folder (default ~/.cache/imubake-test)
#   CI=true             a test whose tool or ../shared/data is missing fails instead of skipping
set -euo pipefail
cd "$(dirname "$0")/.."

CACHE="${IMUBAKE_TEST_CACHE:-$HOME/.cache/imubake-test}"
mkdir -p "$CACHE"
step() { printf '\n== %s\n' "$*"; }

# Python venv: bpy (real Blender 5.0), numpy, scipy, h5py. A stamp of the requirements file
# decides whether the venv is current.
req_stamp="$(sha256sum scripts/test-requirements.txt | cut -d' ' -f1)"
if [ "$(cat "$CACHE/venv.stamp" 2>/dev/null)" != "$req_stamp" ] || [ ! -x "$CACHE/venv/bin/python" ]; then
  step "installing the test venv into $CACHE/venv (bpy is about 1 GB the first time)"
  rm -rf "$CACHE/venv"
  python3 -m venv "$CACHE/venv"
  "$CACHE/venv/bin/python" -m pip install --quiet --upgrade pip
  "$CACHE/venv/bin/python" -m pip install --quiet -r scripts/test-requirements.txt
  echo "$req_stamp" > "$CACHE/venv.stamp"
fi
"$CACHE/venv/bin/python" -c 'import bpy, numpy, scipy, h5py; print("venv: Blender", bpy.app.version_string, "numpy", numpy.__version__, "scipy", scipy.__version__)'

# Khronos glTF-Validator (npm package; run through scripts/gltf_validate.mjs).
VALIDATOR_VERSION="2.0.0-dev.3.10"
if [ ! -f "$CACHE/node/node_modules/gltf-validator/package.json" ] \
   || ! grep -q "\"version\": \"$VALIDATOR_VERSION\"" "$CACHE/node/node_modules/gltf-validator/package.json"; then
  step "installing gltf-validator $VALIDATOR_VERSION into $CACHE/node"
  mkdir -p "$CACHE/node"
  npm install --silent --no-audit --no-fund --prefix "$CACHE/node" "gltf-validator@$VALIDATOR_VERSION" >/dev/null
fi

export IMUBAKE_PYTHON="$CACHE/venv/bin/python"
export IMUBAKE_NODE_MODULES="$CACHE/node/node_modules"

step "cargo fmt --check"
cargo fmt --all -- --check

step "cargo clippy (warnings are errors)"
cargo clippy --all-targets --locked -- -D warnings

step "cargo test"
cargo test --locked
