"""Builds and validates the Blender extension zip from blender_addon/.

Usage: python scripts/build_blender_addon.py [OUT_DIR]      (default: dist/)

Run with a Python that has the `bpy` module (the test venv): it uses Blender's own extension
tool (`blender -c extension build` is the same script), so the manifest is checked exactly as
Blender checks it. Prints the zip's path.
"""

import glob
import importlib.util
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def blender_ext_tool():
    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.submodule_search_locations:
        sys.exit("error: this Python has no bpy module; use the test venv (scripts/test.sh)")
    base = spec.submodule_search_locations[0]
    found = glob.glob(os.path.join(base, "*", "scripts", "addons_core", "bl_pkg", "cli", "blender_ext.py"))
    if not found:
        sys.exit("error: Blender's extension tool (blender_ext.py) is not under %s" % base)
    return found[0]


def main():
    out_dir = os.path.abspath(sys.argv[1] if len(sys.argv) > 1 else os.path.join(ROOT, "dist"))
    os.makedirs(out_dir, exist_ok=True)
    tool = blender_ext_tool()
    source = os.path.join(ROOT, "blender_addon")
    manifest = open(os.path.join(source, "blender_manifest.toml"), encoding="utf-8").read()
    version = next(line.split('"')[1] for line in manifest.splitlines() if line.startswith("version"))
    zip_path = os.path.join(out_dir, "imubake-%s.zip" % version)
    for args in (
        ["build", "--source-dir", source, "--output-filepath", zip_path],
        ["validate", zip_path],
    ):
        run = subprocess.run([sys.executable, tool, *args], capture_output=True, text=True)
        if run.returncode != 0 or "FATAL_ERROR" in run.stdout or "Error" in run.stdout:
            sys.exit("error: blender_ext %s failed:\n%s%s" % (args[0], run.stdout, run.stderr))
    print(zip_path)


if __name__ == "__main__":
    main()
