#!/usr/bin/env python3
"""Every node's world position in a GLB at given times, computed independently of imubake (and
of any engine) with numpy and scipy: a minimal GLB reader (the JSON and BIN chunks, float
accessors), each node's animated translation, rotation and scale sampled as the glTF 2.0 spec
says (LINEAR: lerp, slerp for rotations; STEP; held before the first and after the last key),
world transforms composed down the scene's hierarchy.

usage:
  glb_positions.py positions FILE.glb|FILE.gltf TIMES.json   (TIMES.json: a JSON list of seconds)
      prints JSON {"nodes": {name: [[x, y, z] per time]}, "duration_s": last key time}
  glb_positions.py rename FILE.glb OUT.glb NAMES.json   (NAMES.json: {old name: new name})
      writes a copy whose nodes are renamed (the JSON chunk rewritten, padded to 4 bytes)
"""
import json
import os
import struct
import sys

import numpy as np
from scipy.spatial.transform import Rotation, Slerp


def read_glb(path):
    if path.endswith(".gltf"):  # JSON, one buffer in a file beside it
        doc = json.load(open(path, encoding="utf-8"))
        uri = doc["buffers"][0]["uri"]
        return doc, open(os.path.join(os.path.dirname(path), uri), "rb").read()
    data = open(path, "rb").read()
    magic, version, length = struct.unpack_from("<III", data, 0)
    assert magic == 0x46546C67 and version == 2 and length == len(data), "not a GLB 2.0"
    offset, doc, binary = 12, None, b""
    while offset < length:
        chunk_length, chunk_type = struct.unpack_from("<II", data, offset)
        chunk = data[offset + 8:offset + 8 + chunk_length]
        if chunk_type == 0x4E4F534A:
            doc = json.loads(chunk.decode("utf-8"))
        elif chunk_type == 0x004E4942:
            binary = chunk
        offset += 8 + chunk_length
    return doc, binary


def write_glb(path, doc, binary):
    text = json.dumps(doc).encode("utf-8")
    text += b" " * (-len(text) % 4)
    binary = binary + b"\0" * (-len(binary) % 4)
    chunks = struct.pack("<II", len(text), 0x4E4F534A) + text
    if binary:
        chunks += struct.pack("<II", len(binary), 0x004E4942) + binary
    with open(path, "wb") as f:
        f.write(struct.pack("<III", 0x46546C67, 2, 12 + len(chunks)) + chunks)


COMPONENTS = {"SCALAR": 1, "VEC3": 3, "VEC4": 4, "MAT4": 16}


def accessor(doc, binary, index):
    a = doc["accessors"][index]
    assert a["componentType"] == 5126, "float accessors only"
    view = doc["bufferViews"][a["bufferView"]]
    n = COMPONENTS[a["type"]]
    start = view.get("byteOffset", 0) + a.get("byteOffset", 0)
    stride = view.get("byteStride", 4 * n)
    rows = [np.frombuffer(binary, "<f4", n, start + i * stride) for i in range(a["count"])]
    return np.array(rows, dtype=np.float64).reshape(a["count"], n)


def sample(times, values, interpolation, path, t):
    if t <= times[0]:
        return values[0]
    if t >= times[-1]:
        return values[-1]
    k = int(np.searchsorted(times, t, side="right")) - 1
    if interpolation == "STEP":
        return values[k]
    assert interpolation == "LINEAR", interpolation
    u = (t - times[k]) / (times[k + 1] - times[k])
    if path == "rotation":
        pair = Rotation.from_quat(values[k:k + 2])  # glTF stores x, y, z, w: scipy's order
        return Slerp([0.0, 1.0], pair)([u]).as_quat()[0]
    return (1 - u) * values[k] + u * values[k + 1]


def positions(path, times):
    doc, binary = read_glb(path)
    nodes = doc["nodes"]
    channels = {}  # (node, path) -> (times, values, interpolation)
    duration = 0.0
    for anim in doc.get("animations", [])[:1]:
        for ch in anim["channels"]:
            s = anim["samplers"][ch["sampler"]]
            key_times = accessor(doc, binary, s["input"])[:, 0]
            duration = max(duration, float(key_times[-1]))
            channels[(ch["target"]["node"], ch["target"]["path"])] = (
                key_times,
                accessor(doc, binary, s["output"]),
                s.get("interpolation", "LINEAR"),
            )
    parent = {}
    for i, n in enumerate(nodes):
        for c in n.get("children", []):
            parent[c] = i
    out = {n.get("name", str(i)): [] for i, n in enumerate(nodes)}
    for t in times:
        world = {}

        def local(i):
            n = nodes[i]
            trs = {
                "translation": np.array(n.get("translation", [0, 0, 0]), float),
                "rotation": np.array(n.get("rotation", [0, 0, 0, 1]), float),
                "scale": np.array(n.get("scale", [1, 1, 1]), float),
            }
            for p in trs:
                if (i, p) in channels:
                    trs[p] = sample(*channels[(i, p)], p, t)
            m = np.eye(4)
            m[:3, :3] = Rotation.from_quat(trs["rotation"]).as_matrix() * trs["scale"]
            m[:3, 3] = trs["translation"]
            return m

        def world_of(i):
            if i not in world:
                m = local(i)
                world[i] = world_of(parent[i]) @ m if i in parent else m
            return world[i]

        for i, n in enumerate(nodes):
            out[n.get("name", str(i))].append(world_of(i)[:3, 3].tolist())
    return {"nodes": out, "duration_s": duration}


def main(argv):
    if len(argv) == 4 and argv[1] == "positions":
        print(json.dumps(positions(argv[2], json.load(open(argv[3])))))
    elif len(argv) == 5 and argv[1] == "rename":
        doc, binary = read_glb(argv[2])
        names = json.load(open(argv[4]))
        for n in doc["nodes"]:
            if n.get("name") in names:
                n["name"] = names[n["name"]]
        write_glb(argv[3], doc, binary)
    else:
        sys.exit(__doc__)


if __name__ == "__main__":
    main(sys.argv)
