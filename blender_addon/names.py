"""Bone names: matching a take's bones to the animator's armature.

Every common humanoid naming scheme is reduced to one canonical part name per bone (the names of
imubake's own Mixamo rig: Hips, Spine, Spine1, Spine2, Neck, Head, LeftShoulder, LeftArm,
LeftForeArm, LeftHand, LeftUpLeg, LeftLeg, LeftFoot, LeftToeBase and the Right ones):

- Mixamo (`mixamorig:LeftArm`, any `namespace:` prefix), Unity/VRM humanoid (`LeftUpperArm`),
  `.L/.R`, `_l/_r`, `_L/_R` suffixes (`upper_arm.L`, `upperarm_l` as in Unreal's mannequin);
- a Rigify metarig (`spine` is the hips there, `spine.001`.. the spine, `spine.004` the neck,
  `spine.006` the head);
- a generated Rigify rig: its FK controls (`upper_arm_fk.L`, `torso`, `spine_fk.001`, ...), never
  the DEF/ORG/MCH bones, which constraints drive.

Pure Python (no bpy), so the rules are easy to read and test.
"""

import json
import re

CANONICAL = (
    "Hips", "Spine", "Spine1", "Spine2", "Neck", "Head",
    "LeftShoulder", "LeftArm", "LeftForeArm", "LeftHand",
    "LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase",
    "RightShoulder", "RightArm", "RightForeArm", "RightHand",
    "RightUpLeg", "RightLeg", "RightFoot", "RightToeBase",
)

# Side-free part -> normalised aliases (lower case, no separators).
_ALIASES = {
    "Hips": ("hips", "pelvis", "hip"),
    "Spine": ("spine", "spine01"),
    "Spine1": ("spine1", "spine02", "chest"),
    "Spine2": ("spine2", "spine03", "upperchest"),
    "Neck": ("neck", "neck01", "neck1"),
    "Head": ("head",),
    "Shoulder": ("shoulder", "clavicle"),
    "Arm": ("arm", "upperarm"),
    "ForeArm": ("forearm", "lowerarm"),
    "Hand": ("hand",),
    "UpLeg": ("upleg", "thigh", "upperleg"),
    "Leg": ("leg", "shin", "calf", "lowerleg"),
    "Foot": ("foot",),
    "ToeBase": ("toebase", "toe", "toes", "ball"),
}
_ALIAS_TO_PART = {a: part for part, aliases in _ALIASES.items() for a in aliases}

# A Rigify metarig's spine chain (the hips are `spine`).
_RIGIFY_SPINE = {"spine": "Hips", "spine.001": "Spine", "spine.002": "Spine1", "spine.003": "Spine2",
                 "spine.004": "Neck", "spine.006": "Head"}
# A generated Rigify rig: the torso master carries the hips' rotation and the root motion; the
# FK spine controls the spine, `neck`/`head` controls the rest.
_RIGIFY_GENERATED_SPINE = {"torso": "Hips", "spine_fk.001": "Spine", "spine_fk.002": "Spine1",
                           "spine_fk.003": "Spine2", "neck": "Neck", "head": "Head"}

_MECHANISM = re.compile(r"^(DEF|ORG|MCH|VIS|WGT)[-_.]")
_NOT_FK = re.compile(r"(^|[._-])(ik|tweak|parent|target|pole|socket|master|pivot|roll|heel|rot)([._-]|$)", re.I)
_SIDE_SUFFIX = re.compile(r"^(.*?)[._\-\s]?(l|r|left|right)$", re.I)
_SIDE_PREFIX = re.compile(r"^(left|right|l(?=[_.\-\s])|r(?=[_.\-\s]))[_.\-\s]?(.*)$", re.I)


def _strip_namespace(name):
    # `mixamorig:LeftArm`, `mixamorig1:LeftArm`, `Armature|LeftArm`
    for sep in (":", "|"):
        if sep in name:
            name = name.rsplit(sep, 1)[1]
    if name.lower().startswith("mixamorig_"):
        name = name[len("mixamorig_"):]
    return name


def canonical(name, rigify_generated=False):
    """The canonical part name of a bone name, or None when it is not a main humanoid bone."""
    if _MECHANISM.match(name):
        return None
    if rigify_generated:
        if name in _RIGIFY_GENERATED_SPINE:
            return _RIGIFY_GENERATED_SPINE[name]
        if name.startswith("shoulder."):
            pass  # the shoulder controls have no FK/IK variants
        elif "_fk" not in name or _NOT_FK.search(name):
            return None
        name = name.replace("_fk", "")
    bare = _strip_namespace(name)
    side = ""
    m = _SIDE_PREFIX.match(bare)
    if m and m.group(2):
        side, bare = m.group(1)[0].upper(), m.group(2)
    else:
        m = _SIDE_SUFFIX.match(bare)
        if m and m.group(1) and _norm(m.group(1)) in _ALIAS_TO_PART:
            side, bare = m.group(2)[0].upper(), m.group(1)
    part = _ALIAS_TO_PART.get(_norm(bare))
    if part is None:
        return None
    sided = part not in ("Hips", "Spine", "Spine1", "Spine2", "Neck", "Head")
    if sided != bool(side):
        return None
    if not sided:
        return part
    return ("Left" if side == "L" else "Right") + part


def _norm(s):
    return re.sub(r"[^a-z0-9]", "", s.lower())


def is_rigify_generated(bone_names):
    return any(n.startswith("upper_arm_fk.") or n.startswith("thigh_fk.") for n in bone_names)


def is_rigify_metarig(bone_names):
    names = set(bone_names)
    return "spine.001" in names and "spine" in names and not is_rigify_generated(bone_names)


def match_armature(bone_names):
    """{canonical part: bone name} for an armature's bones (first match wins, in bone order)."""
    generated = is_rigify_generated(bone_names)
    metarig = is_rigify_metarig(bone_names)
    parts = {}
    for name in bone_names:
        if metarig and name in _RIGIFY_SPINE:
            part = _RIGIFY_SPINE[name]
        else:
            part = canonical(name, rigify_generated=generated)
        if part is not None and part not in parts:
            parts[part] = name
    return parts


def auto_bone_map(source_names, target_names):
    """{source bone: target bone} through canonical part names."""
    src = match_armature(source_names)
    tgt = match_armature(target_names)
    return {src[p]: tgt[p] for p in CANONICAL if p in src and p in tgt}


class BoneMapError(Exception):
    pass


def load_bone_map(path, source_names, target_names):
    """A bone map from JSON: `{"bones": {"<source bone>": "<target bone or canonical part>"}}`
    (a flat object works too). A value naming a canonical part (`LeftArm`) is resolved on the
    target like the automatic map; every source and target bone must exist."""
    try:
        with open(path, "rb") as f:
            data = json.loads(f.read().decode("utf-8"))
    except (OSError, ValueError) as e:
        raise BoneMapError("%s: cannot read the bone map: %s" % (path, e)) from None
    if isinstance(data, dict) and isinstance(data.get("bones"), dict):
        data = data["bones"]
    if not isinstance(data, dict) or not all(isinstance(k, str) and isinstance(v, str) for k, v in data.items()):
        raise BoneMapError('%s: expected {"bones": {"source bone": "target bone", ...}}' % path)
    targets = set(target_names)
    parts = match_armature(target_names)
    sources = set(source_names)
    out = {}
    for s, t in data.items():
        if s not in sources:
            raise BoneMapError("%s: source bone %r is not in the take (it has: %s)"
                               % (path, s, ", ".join(sorted(sources))))
        if t not in targets:
            if t in parts:
                t = parts[t]
            else:
                raise BoneMapError("%s: target bone %r is not in the armature" % (path, t))
        out[s] = t
    return out
