"""Runs the add-on's test suite inside real Blender (the `bpy` module of the running Python).

usage: python tests/blender_addon/run.py ZIP TAKES_DIR [unittest names...]

Installs the extension ZIP into a temporary BLENDER_USER_RESOURCES (never the home folder) with
Blender's own `extensions.package_install_files`, enables it, then runs the test_*.py modules of
this folder. TAKES_DIR holds imubake takes made by the Rust driver (tests/outputs/blender_addon.rs):
`walk_24`, `walk_2997`, `walk_60`, `walk_120` (BVH + GLB + sidecar each). Also read from the
environment: IMUBAKE_SHARED_DATA (../shared/data), IMUBAKE_BIN (the imubake binary).
Exit status 0 when every test passes. Also runs as `blender -b -P run.py -- ZIP TAKES_DIR`.
"""

import os
import sys
import tempfile
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))


def main(argv):
    if "--" in argv:
        argv = argv[argv.index("--") + 1:]
    else:
        argv = argv[1:]
    if len(argv) < 2:
        sys.exit(__doc__)
    zip_path, takes = os.path.abspath(argv[0]), os.path.abspath(argv[1])
    resources = tempfile.mkdtemp(prefix="imubake-blender-user-")
    # Must be set before bpy starts: Blender reads it once.
    os.environ["BLENDER_USER_RESOURCES"] = resources
    os.environ["IMUBAKE_ADDON_ZIP"] = zip_path
    os.environ["IMUBAKE_TAKES"] = takes
    sys.path.insert(0, HERE)
    import harness

    harness.install(zip_path)
    loader = unittest.TestLoader()
    if len(argv) > 2:
        suite = loader.loadTestsFromNames(argv[2:])
    else:
        suite = loader.discover(HERE, pattern="test_*.py", top_level_dir=HERE)
    result = unittest.TextTestRunner(verbosity=2, stream=sys.stdout).run(suite)
    sys.stdout.flush()
    return 0 if result.wasSuccessful() else 1


if __name__ == "__main__":
    code = main(sys.argv)
    # bpy as a module can hang on interpreter exit with handlers registered; leave at once.
    os._exit(code)
