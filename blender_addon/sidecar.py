"""The imubake sidecar (`<stem>.imubake.json`): reading, checking, and the scene rate it implies.

Pure Python, no `bpy`: the sidecar is JSON read with `json.load` and checked field by field, so a
malformed or hostile file gives a clear `SidecarError` and nothing in it is ever evaluated.
The field names are the contract in imubake's conventions.md.
"""

import json
import math
import os
from fractions import Fraction

SUFFIX = ".imubake.json"
# Animation outputs the add-on can import, in order of preference.
ANIMATION_FORMATS = ("bvh", "glb", "gltf")


class SidecarError(Exception):
    """A sidecar that cannot be used; the message names the file and the field."""


class Take:
    """What the add-on needs from a sidecar, checked.

    name      the take's stem (`walk` for `walk.imubake.json`)
    folder    the folder holding the sidecar and its outputs
    fps       the exact frame rate as a Fraction (30000/1001 for 29.97)
    frames    frame count; take frame n is at n / fps seconds and is scene frame n + 1
    outputs   {format: absolute path} for the files the sidecar lists
    units     length unit of the BVH ("m" or "cm"); glTF is always metres
    warnings  the conversion's warnings, as strings
    """

    def __init__(self, path, data):
        self.path = os.path.abspath(path)
        self.folder = os.path.dirname(self.path)
        base = os.path.basename(self.path)
        self.name = base[: -len(SUFFIX)] if base.endswith(SUFFIX) else os.path.splitext(base)[0]
        self.data = data
        self.fps = _fps(path, data)
        self.frames = _positive_int(path, data, "frames")
        rig = _field(path, data, "rig", dict, required=False) or {}
        units = rig.get("units", "m")
        if units not in ("m", "cm"):
            raise SidecarError("%s: rig.units is %r; expected \"m\" or \"cm\"" % (path, units))
        self.units = units
        self.rig_name = rig.get("name") if isinstance(rig.get("name"), str) else None
        self.outputs = _outputs(path, data, self.folder)
        self.warnings = [str(w) for w in (_field(path, data, "warnings", list, required=False) or [])]
        self.contacts = _contacts(path, data, self.frames)
        dropped = _field(path, data, "dropped_lines", list, required=False) or []
        if dropped:
            self.warnings.append("%d line(s) of the capture were dropped (see the sidecar)" % len(dropped))

    @property
    def duration_s(self):
        return (self.frames - 1) / self.fps

    def scene_rate(self):
        """Blender's (fps, fps_base) for this take's rate; see `scene_rate`."""
        return scene_rate(self.fps)

    def animation_file(self, preferred=None):
        """The output to import: `preferred` ("bvh", "glb", "gltf") or the first present."""
        order = [preferred] if preferred else list(ANIMATION_FORMATS)
        for fmt in order:
            path = self.outputs.get(fmt)
            if path is not None:
                if not os.path.isfile(path):
                    raise SidecarError(
                        "%s lists %s but that file is missing" % (self.path, os.path.basename(path))
                    )
                return fmt, path
        wanted = preferred or " or ".join(ANIMATION_FORMATS)
        raise SidecarError(
            "%s lists no %s output; convert with --format bvh,glb" % (self.path, wanted)
        )


def scene_rate(fps):
    """Blender's (render.fps, render.fps_base) for an exact rate: fps / fps_base == rate.

    Integer rates are (rate, 1). Others take the next integer and a base above 1, which is how
    Blender's own presets write NTSC rates: 30000/1001 -> (30, 1.001), 24000/1001 -> (24, 1.001).
    """
    fps = Fraction(fps)
    if fps <= 0:
        raise ValueError("frame rate must be positive, got %s" % fps)
    if fps.denominator == 1:
        return int(fps), 1.0
    whole = max(1, math.ceil(fps))
    return whole, float(Fraction(whole) / fps)


def sidecar_for(path):
    """The sidecar of a chosen file: itself, or `<stem>.imubake.json` next to a .bvh/.glb/.gltf."""
    if path.endswith(SUFFIX):
        return path
    stem, ext = os.path.splitext(path)
    if ext.lower() not in (".bvh", ".glb", ".gltf"):
        raise SidecarError(
            "%s: choose an imubake take: a %s sidecar, or the .bvh/.glb/.gltf next to one"
            % (path, SUFFIX)
        )
    return stem + SUFFIX


def load(path):
    """Reads and checks a sidecar, or the sidecar next to a chosen .bvh/.glb/.gltf."""
    chosen = path
    path = sidecar_for(path)
    if not os.path.isfile(path):
        raise SidecarError(
            "%s has no sidecar (%s expected next to it); imubake writes it last, "
            "so the conversion did not finish or the file was moved without it"
            % (os.path.basename(chosen), os.path.basename(path))
        )
    try:
        with open(path, "rb") as f:
            data = json.loads(f.read().decode("utf-8"))
    except UnicodeDecodeError as e:
        raise SidecarError("%s is not UTF-8 text: %s" % (path, e)) from None
    except ValueError as e:
        raise SidecarError("%s is not valid JSON: %s" % (path, e)) from None
    except OSError as e:
        raise SidecarError("%s cannot be read: %s" % (path, e)) from None
    if not isinstance(data, dict):
        raise SidecarError("%s: expected a JSON object, found %s" % (path, type(data).__name__))
    return Take(path, data)


def find_sidecars(folder):
    """Every sidecar under `folder` (recursively), sorted; hidden files and folders skipped."""
    found = []
    for root, dirs, files in os.walk(folder):
        dirs[:] = sorted(d for d in dirs if not d.startswith("."))
        for name in sorted(files):
            if name.endswith(SUFFIX) and not name.startswith("."):
                found.append(os.path.join(root, name))
    return found


def _field(path, data, key, kind, required=True):
    value = data.get(key)
    if value is None:
        if required:
            raise SidecarError("%s: missing field %r" % (path, key))
        return None
    if not isinstance(value, kind) or isinstance(value, bool):
        raise SidecarError(
            "%s: field %r should be %s, found %s"
            % (path, key, kind.__name__, type(value).__name__)
        )
    return value


def _positive_int(path, data, key):
    value = _field(path, data, key, int)
    if value < 1:
        raise SidecarError("%s: field %r should be at least 1, found %d" % (path, key, value))
    return value


def _fps(path, data):
    fps = _field(path, data, "fps", dict)
    num, den = fps.get("num"), fps.get("den")
    for name, v in (("num", num), ("den", den)):
        if not isinstance(v, int) or isinstance(v, bool) or v < 1:
            raise SidecarError("%s: fps.%s should be a positive integer, found %r" % (path, name, v))
    rate = Fraction(num, den)
    if rate > 32767:
        raise SidecarError("%s: fps %s is above Blender's limit of 32767" % (path, rate))
    return rate


def _outputs(path, data, folder):
    outputs = {}
    for i, entry in enumerate(_field(path, data, "outputs", list)):
        if not isinstance(entry, dict):
            raise SidecarError("%s: outputs[%d] should be an object" % (path, i))
        fmt, rel = entry.get("format"), entry.get("path")
        if not isinstance(fmt, str) or not isinstance(rel, str) or not rel:
            raise SidecarError("%s: outputs[%d] needs string fields format and path" % (path, i))
        # Outputs sit next to the sidecar: a path that leaves the folder is refused.
        if os.path.isabs(rel) or os.path.normpath(rel).startswith(".."):
            raise SidecarError(
                "%s: outputs[%d].path %r is not inside the take's folder" % (path, i, rel)
            )
        outputs.setdefault(fmt, os.path.join(folder, os.path.normpath(rel)))
    return outputs


def _contacts(path, data, frames):
    """The feet's contact intervals ({"left": [[start, end], ...], "right": ...}, frames
    inclusive), or None when the take has none (root mode other than feet)."""
    contacts = data.get("contacts")
    if contacts is None:
        return None
    if not isinstance(contacts, dict):
        raise SidecarError("%s: contacts should be an object, found %s" % (path, type(contacts).__name__))
    out = {}
    for side in ("left", "right"):
        intervals = contacts.get(side, [])
        ok = isinstance(intervals, list) and all(
            isinstance(r, list) and len(r) == 2 and all(isinstance(v, int) and not isinstance(v, bool) for v in r)
            and 0 <= r[0] <= r[1] < frames
            for r in intervals
        )
        if not ok:
            raise SidecarError("%s: contacts.%s should be [[start, end], ...] frames within 0..%d"
                               % (path, side, frames - 1))
        out[side] = intervals
    return out
