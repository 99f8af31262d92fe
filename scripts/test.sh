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

# Python venvs, each current when its stamp matches its requirements file:
#   venv              bpy 5.0.1 (real Blender 5.0), numpy, scipy, h5py: most tests
#   venv-blender42    bpy 4.2 LTS: the Blender add-on is also tested in the oldest Blender it supports
install_venv() { # name requirements-file
  local dir="$CACHE/$1" stamp
  stamp="$(sha256sum "$2" | cut -d' ' -f1)"
  if [ "$(cat "$dir.stamp" 2>/dev/null)" != "$stamp" ] || [ ! -x "$dir/bin/python" ]; then
    step "installing $2 into $dir (bpy is about 1 GB the first time)"
    # An existing venv is updated in place, so adding a package does not download bpy again.
    if [ ! -x "$dir/bin/python" ]; then
      python3 -m venv "$dir"
      "$dir/bin/python" -m pip install --quiet --upgrade pip
    fi
    "$dir/bin/python" -m pip install --quiet -r "$2"
    echo "$stamp" > "$dir.stamp"
  fi
}
install_venv venv scripts/test-requirements.txt
install_venv venv-blender42 scripts/test-requirements-blender42.txt
"$CACHE/venv/bin/python" -c 'import bpy, numpy, scipy, h5py, vqf, ahrs, pythonosc; print("venv: Blender", bpy.app.version_string, "numpy", numpy.__version__, "scipy", scipy.__version__)'
"$CACHE/venv-blender42/bin/python" -c 'import bpy; print("venv-blender42: Blender", bpy.app.version_string)'

# Node packages: the Khronos glTF-Validator (run through scripts/gltf_validate.mjs) and
# playwright-core, which drives Chromium for the viewer's tests (tests/browser/view.mjs).
VALIDATOR_VERSION="2.0.0-dev.3.10"
PLAYWRIGHT_VERSION="1.65.1"
if [ ! -f "$CACHE/node/node_modules/gltf-validator/package.json" ] \
   || ! grep -q "\"version\": \"$VALIDATOR_VERSION\"" "$CACHE/node/node_modules/gltf-validator/package.json" \
   || ! grep -q "\"version\": \"$PLAYWRIGHT_VERSION\"" "$CACHE/node/node_modules/playwright-core/package.json" 2>/dev/null; then
  step "installing gltf-validator $VALIDATOR_VERSION and playwright-core $PLAYWRIGHT_VERSION into $CACHE/node"
  mkdir -p "$CACHE/node"
  npm install --silent --no-audit --no-fund --prefix "$CACHE/node" \
    "gltf-validator@$VALIDATOR_VERSION" "playwright-core@$PLAYWRIGHT_VERSION" >/dev/null
fi

# Debian's packages, installed once with apt: Chromium (the viewer's page runs in it, headless,
# WebGL through SwiftShader; playwright's own browser download does not work here), libhdf5
# (the `hdf5` feature: APDM Opal files), Godot 3's headless editor (`--engine godot` takes
# imported by Godot itself), and Slurm with MUNGE (the documented array job run on a one-node
# cluster that the test starts under a temporary folder; no service is started here).
APT_PACKAGES=""
[ -x /usr/bin/chromium ] || APT_PACKAGES="$APT_PACKAGES chromium"
[ -f /usr/include/hdf5/serial/hdf5.h ] || APT_PACKAGES="$APT_PACKAGES libhdf5-dev"
[ -x /usr/bin/godot3-server ] || APT_PACKAGES="$APT_PACKAGES godot3-server"
[ -x /usr/sbin/slurmctld ] || APT_PACKAGES="$APT_PACKAGES slurm-wlm"
[ -x /usr/sbin/munged ] || APT_PACKAGES="$APT_PACKAGES munge"
if [ -n "$APT_PACKAGES" ]; then
  step "installing Debian's$APT_PACKAGES (apt)"
  SUDO=""
  if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
  $SUDO apt-get update -qq
  # shellcheck disable=SC2086
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq $APT_PACKAGES >/dev/null
fi
/usr/bin/chromium --version
echo "Godot $(/usr/bin/godot3-server --version)"
/usr/sbin/slurmctld -V

# mdBook, to build the reference in docs/ (a broken book fails the run).
MDBOOK_VERSION="0.5.4"
if ! "$CACHE/mdbook/bin/mdbook" --version 2>/dev/null | grep -q "v$MDBOOK_VERSION"; then
  step "installing mdbook $MDBOOK_VERSION into $CACHE/mdbook (a few minutes the first time)"
  cargo install --quiet --locked --version "$MDBOOK_VERSION" --root "$CACHE/mdbook" mdbook
fi

export IMUBAKE_PYTHON="$CACHE/venv/bin/python"
export IMUBAKE_PYTHON_BLENDER42="$CACHE/venv-blender42/bin/python"

step "building the Blender extension (dist/imubake-<version>.zip)"
"$IMUBAKE_PYTHON" scripts/build_blender_addon.py dist
export IMUBAKE_NODE_MODULES="$CACHE/node/node_modules"

step "mdbook build docs (the reference, into target/book)"
"$CACHE/mdbook/bin/mdbook" build docs

step "cargo fmt --check"
cargo fmt --all -- --check

step "cargo clippy (warnings are errors), with the hdf5 feature"
cargo clippy --all-targets --locked --features hdf5 -- -D warnings

step "cargo check without features (what a plain cargo install builds)"
cargo check --locked

step "cargo test, with the hdf5 feature"
# Every test binary runs even when one fails, so one run reports every failure; cargo still exits
# non-zero at the end, which fails this script.
cargo test --locked --features hdf5 --no-fail-fast
