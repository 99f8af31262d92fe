"""Each body part's world turn in a source BVH and in its retargeted output, by the independent
numpy BVH reader (tests/blender_addon/bvh_reference.py; not imubake's code).

    python turns.py SOURCE.bvh OUTPUT.bvh SOURCE_PARTS.json TARGET_PARTS.json STEP

STEP: source frames per output frame (the output's rate divides the source's). The parts files
are `imubake inspect --json`. Prints JSON {part: largest angle in degrees between the source
part's world rotation (since the rest pose, every channel zero) and the target part's, over the
frames}; a chain (the spine, the neck) is compared at its top (a one-joint chain takes the
source's top).
"""
import json
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "blender_addon"))
from bvh_reference import Bvh, angle_deg  # noqa: E402


def main():
    src, out, sparts, tparts, step = sys.argv[1:6]
    step = int(step)
    source, target = Bvh(src), Bvh(out)
    sp = json.load(open(sparts))["parts"]
    tp = json.load(open(tparts))["parts"]
    pairs = {}
    for part, s in sp.items():
        t = tp.get(part, {"joints": []})["joints"]
        if s["joints"] and t:
            pairs[part] = (s["joints"][-1], t[-1])
    worst = {part: 0.0 for part in pairs}
    frames = min(target.frames, (source.frames + step - 1) // step)
    for m in range(frames):
        sw, tw = source.world(m * step), target.world(m)
        for part, (sj, tj) in pairs.items():
            worst[part] = max(worst[part], angle_deg(sw[sj][0], tw[tj][0]))
    print(json.dumps(worst))


main()
