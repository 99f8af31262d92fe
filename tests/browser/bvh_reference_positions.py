"""World positions of a BVH file's joints (End Sites left out) at given frames, by the independent
numpy reader tests/blender_addon/bvh_reference.py, scaled to metres; JSON on stdout:
{"names": [...], "frames": {"N": [[x, y, z], ...]}} in the BVH's own Y-up axes.

    python bvh_reference_positions.py FILE.bvh METRES_PER_UNIT FRAME...
"""

import json
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "blender_addon"))
from bvh_reference import Bvh  # noqa: E402

path, scale, frames = sys.argv[1], float(sys.argv[2]), [int(f) for f in sys.argv[3:]]
bvh = Bvh(path)
names = [n for n in bvh.names if n is not None]
out = {"names": names, "frame_time": bvh.frame_time, "count": bvh.frames, "frames": {}}
for f in frames:
    world = bvh.world(f)
    out["frames"][str(f)] = [[float(v) * scale for v in world[n][1]] for n in names]
json.dump(out, sys.stdout)
