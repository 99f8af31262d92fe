"""Bone names and body parts: matching a take's bones to the animator's armature.

The same resolution as imubake's own (`src/rig/names.rs`, `src/rig/anatomy.rs`; checked against
`imubake inspect --json` by `tests/outputs/addon_anatomy.rs`), in pure Python (no bpy):

1. `classify(name)`: what a joint's name says, a side and a word, in the schemes people use —
   Mixamo (`mixamorig:LeftArm`), Unity/VRM (`LeftUpperArm`), `UpperLeg_L`, `upper_arm.L`,
   Unreal's `thigh_l`, CMU (`LHipJoint`), Poser/DAZ (`lShldr`, `rButtock`), SlimeVR (`Left-Hip`),
   Xsens MVN (`LeftShoulder` the upper arm, `LeftHip` the thigh, `T8`), mocopi (`l_up_arm`,
   `torso_3`), Rokoko. `Shoulder` and a sided `Hip` are decided by the hierarchy.
2. `resolve(names, parents, rest, end_sites, declared)`: the skeleton's parts — declared, else
   named (limbs down the chain), else by shape when rest positions are given; the pelvis is where
   the thighs meet, the thorax where the clavicles (else upper arms) meet, the spine and the neck
   chains between.
3. `pairs(source, target)`: the joints to pair, chains by their place along them.

On top, the add-on's Rigify support (which imubake itself does not need): a Rigify metarig
(`spine` is the hips there, `spine.003` the thorax, `spine.004` the neck, `spine.006` the head)
and a generated Rigify rig (its FK controls `upper_arm_fk.L`, `torso`, `spine_fk.001`, ...,
never the DEF/ORG/MCH bones, which constraints drive).

Canonical part names (`CANONICAL`) are Mixamo's: Hips, Spine, Spine1, Spine2, Neck, Head,
LeftShoulder (the clavicle), LeftArm, LeftForeArm, LeftHand, LeftUpLeg, LeftLeg, LeftFoot,
LeftToeBase and the Right ones.
"""

import json
import math
import re

CANONICAL = (
    "Hips", "Spine", "Spine1", "Spine2", "Neck", "Head",
    "LeftShoulder", "LeftArm", "LeftForeArm", "LeftHand",
    "LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase",
    "RightShoulder", "RightArm", "RightForeArm", "RightHand",
    "RightUpLeg", "RightLeg", "RightFoot", "RightToeBase",
)

LEFT, RIGHT = "left", "right"
SIDES = (LEFT, RIGHT)

# Words (names.rs's `Word`).
ROOT, PELVIS, SPINE, NECK, HEAD = "root", "pelvis", "spine", "neck", "head"
CLAVICLE, SHOULDER, UPPER_ARM, FOREARM, HAND = "clavicle", "shoulder", "upper_arm", "forearm", "hand"
HIP, THIGH, SHANK, FOOT, TOES = "hip", "thigh", "shank", "foot", "toes"

# A limb's segments from the body out, with their key (`left_<key>`), Mixamo's and Unity's names.
LIMBS = ("clavicle", "upper_arm", "forearm", "hand", "thigh", "shank", "foot", "toe")
_LIMB_NAMES = {
    "clavicle": ("Shoulder", "Shoulder"),
    "upper_arm": ("Arm", "UpperArm"),
    "forearm": ("ForeArm", "LowerArm"),
    "hand": ("Hand", "Hand"),
    "thigh": ("UpLeg", "UpperLeg"),
    "shank": ("Leg", "LowerLeg"),
    "foot": ("Foot", "Foot"),
    "toe": ("ToeBase", "Toes"),
}
# Every part's id as in `imubake inspect --json`, in anatomy.rs's `Part::all` order.
PARTS = ("pelvis", "spine", "neck", "head") + tuple("%s_%s" % (s, l) for s in SIDES for l in LIMBS)
_PREFIX = {LEFT: "Left", RIGHT: "Right"}

# Central words (no side) -> aliases, lower case without separators.
_CENTRAL = (
    (ROOT, ("root",)),
    (PELVIS, ("hips", "hip", "pelvis")),
    (SPINE, ("spine", "lowerback", "upperback", "waist", "chest", "upperchest", "abdomen",
             "abdomenlower", "abdomenupper", "chestlower", "chestupper", "torso")),
    (NECK, ("neck", "necklower", "neckupper")),
    (HEAD, ("head",)),
)
# Sided words -> aliases.
_SIDED = (
    (CLAVICLE, ("clavicle", "collar", "clav")),
    (SHOULDER, ("shoulder",)),
    (UPPER_ARM, ("arm", "upperarm", "uparm", "shldr", "humerus")),
    (FOREARM, ("forearm", "lowerarm", "lowarm", "elbow")),
    (HAND, ("hand", "wrist")),
    (HIP, ("hip", "hipjoint", "buttock")),
    (THIGH, ("upleg", "thigh", "upperleg", "femur")),
    (SHANK, ("leg", "shin", "calf", "lowerleg", "lowleg", "knee", "tibia")),
    (FOOT, ("foot", "ankle")),
    (TOES, ("toebase", "toe", "toes", "ball")),
)
_MECHANISM_PREFIXES = ("DEF-", "ORG-", "MCH-", "VIS-", "WGT-", "DEF_", "ORG_", "MCH_")
_SEPARATORS = "_.- "


def _ascii_lower(s):
    return "".join(c.lower() if c.isascii() else c for c in s)


def _normalise(s):
    return "".join(c.lower() for c in s if c.isascii() and c.isalnum())


def _is_digits(s):
    return s != "" and all("0" <= c <= "9" for c in s)


def _central_word(n):
    for word, aliases in _CENTRAL:
        if n in aliases:
            return word

    def numbered(stem):
        d = n[len(stem):]
        return n.startswith(stem) and 0 < len(d) <= 3 and _is_digits(d)

    if any(numbered(s) for s in ("spine", "torso", "chest", "abdomen")):
        return SPINE
    if numbered("neck"):
        return NECK

    def vertebra(stem, top):
        d = n[len(stem):]
        return n.startswith(stem) and _is_digits(d) and 1 <= int(d) <= top and not n[1:].startswith("0")

    if vertebra("c", 7):
        return NECK
    if vertebra("l", 5) or vertebra("t", 12):
        return SPINE
    return None


def _sided_word(bare):
    n = _normalise(bare)
    # DAZ Genesis splits a limb into its bend joint (the part) and a twist helper.
    if n.endswith("bend") and len(n) > 4:
        n = n[:-4]
    for word, aliases in _SIDED:
        if n in aliases:
            return word
    return None


def _strip_decoration(name):
    """`mixamorig:LeftArm`, `Armature|LeftArm`, `mixamorig_LeftArm`, `LeftArm_chr00` -> `LeftArm`."""
    name = re.split(r"[:|]", name)[-1]
    if len(name) > 10 and name[:10].lower() == "mixamorig_":
        name = name[10:]
    i = name.rfind("_chr")
    if i > 0 and len(name[i + 4:]) == 2 and _is_digits(name[i + 4:]):
        name = name[:i]
    return name


def _side_of(bare):
    """(side, rest) when the name carries a side (see names.rs's `side_of`), else None."""
    lower = _ascii_lower(bare)
    for word, side in (("left", LEFT), ("right", RIGHT)):
        if lower.startswith(word) and len(bare) > len(word):
            rest = bare[len(word):].lstrip(_SEPARATORS)
            if rest:
                return side, rest
    letter = {"l": LEFT, "r": RIGHT}
    if len(bare) > 2 and bare[0].lower() in letter and bare[0].isascii():
        side = letter[bare[0].lower()]
        if bare[1] in _SEPARATORS:  # `l_up_arm`, `L-Thigh`
            return side, bare[2:]
        if "A" <= bare[1] <= "Z" and _sided_word(bare[1:]) is not None:  # `lThigh`, `RHipJoint`
            return side, bare[1:]
    for word, side in (("left", LEFT), ("right", RIGHT), ("l", LEFT), ("r", RIGHT)):
        if len(lower) > len(word) and lower.endswith(word):
            cut = bare[:len(bare) - len(word)]
            rest = cut.rstrip(_SEPARATORS)
            separated = len(rest) < len(cut)
            if (len(word) > 1 or separated) and _sided_word(rest) is not None:
                return side, rest
    return None


def is_mechanism(name):
    """Bones a rig drives through constraints (Rigify's deform and mechanism bones)."""
    return name.startswith(_MECHANISM_PREFIXES)


def classify(name):
    """What `name` says: `(side, word)` (side None for central words), or None when it names no
    main body part (fingers, twist and helper bones, end effectors, eyes)."""
    if is_mechanism(name):
        return None
    bare = _strip_decoration(name)
    sided = _side_of(bare)
    if sided is not None:
        side, rest = sided
        word = _sided_word(rest)
        return (side, word) if word is not None else None
    word = _central_word(_normalise(bare))
    return (None, word) if word is not None else None


# ---------------------------------------------------------------------------------------------
# The resolution (anatomy.rs's `Anatomy::resolve`).


def _sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def _norm(v):
    return math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])


def _max_last(items, key):
    """Rust's `max_by`: the last of equally greatest items; None when empty."""
    best, best_key = None, None
    for it in items:
        k = key(it)
        if best is None or k >= best_key:
            best, best_key = it, k
    return best


def _min_first(items, key):
    """Rust's `min_by`: the first of equally least items; None when empty."""
    best, best_key = None, None
    for it in items:
        k = key(it)
        if best is None or k < best_key:
            best, best_key = it, k
    return best


class _Tree:
    def __init__(self, names, parents, rest, end_sites):
        n = len(names)
        self.names = names
        self.parents = parents
        self.rest = rest
        self.end_sites = end_sites
        self.depth = [0] * n
        self.children = [[] for _ in range(n)]
        for j in range(n):
            p = self.parent(j)
            if p is not None:
                self.depth[j] = self.depth[p] + 1
                self.children[p].append(j)
        self.words = [classify(x) for x in names]
        self._highest = None

    def parent(self, j):
        p = self.parents[j]
        return p if p is not None and p < j else None

    def below(self, j, a):
        k = self.parent(j)
        while k is not None:
            if k == a:
                return True
            k = self.parent(k)
        return False

    def ancestors_or_self(self, j):
        out = [j]
        k = self.parent(j)
        while k is not None:
            out.append(k)
            k = self.parent(k)
        return out

    def common_ancestor(self, a, b):
        up = set(self.ancestors_or_self(a))
        for j in self.ancestors_or_self(b):
            if j in up:
                return j
        return None

    def path(self, top, bottom):
        if not self.below(bottom, top):
            return []
        out = []
        for j in self.ancestors_or_self(bottom):
            if j == top:
                break
            out.append(j)
        out.reverse()
        return out

    def way(self, a, b):
        m = self.common_ancestor(a, b)
        if m is None:
            return []
        out = []
        if m != a:
            for j in self.ancestors_or_self(a)[1:]:
                if j == m:
                    break
                out.append(j)
        down = self.path(m, b)
        out.extend(down[:-1])
        return out

    def named(self, side, word):
        out = [j for j in range(len(self.words)) if self.words[j] == (side, word)]
        out.sort(key=lambda j: (self.depth[j], j))
        return out

    def has_shape(self):
        return bool(self.rest)

    def bone(self, j, nxt):
        c = nxt if nxt is not None else (self.children[j][0] if self.children[j] else None)
        if c is not None:
            return _norm(_sub(self.rest[c], self.rest[j]))
        e = self.end_sites[j]
        return _norm(e) if e is not None else 0.0

    def highest(self, j):
        """The highest rest point (joints and End Sites) of `j`'s subtree."""
        if self._highest is None:
            # One pass up from the leaves (children come after their parents): no recursion.
            h = [max(self.tip(k)[1], self.rest[k][1]) for k in range(len(self.rest))]
            for k in range(len(h) - 1, -1, -1):
                p = self.parent(k)
                if p is not None:
                    h[p] = max(h[p], h[k])
            self._highest = h
        return self._highest[j]

    def tip(self, j):
        r, e = self.rest[j], self.end_sites[j]
        if e is None:
            return r
        return (r[0] + e[0], r[1] + e[1], r[2] + e[2])


class Anatomy:
    """A skeleton's resolved parts: joint indices into `names`."""

    def __init__(self, skeleton, names, parents):
        self.skeleton = skeleton
        self.names = list(names)
        self.parents = list(parents)
        self.pelvis = None
        self.spine = []  # from the pelvis up; the last is the thorax
        self.neck = []  # from the thorax up
        self.head = None
        self.limbs = {s: {l: None for l in LIMBS} for s in SIDES}
        self.found_by = {}  # part id -> "declared" | "named" | "shape"

    def thorax(self):
        return self.spine[-1] if self.spine else None

    def joints(self, part):
        """The part's joint indices: one, none, or a chain (spine and neck, bottom up)."""
        if part == "pelvis":
            return [] if self.pelvis is None else [self.pelvis]
        if part == "spine":
            return list(self.spine)
        if part == "neck":
            return list(self.neck)
        if part == "head":
            return [] if self.head is None else [self.head]
        side, limb = part.split("_", 1)
        j = self.limbs[side][limb]
        return [] if j is None else [j]

    def found(self, part):
        return self.found_by.get(part)

    def part_of(self, joint):
        for p in PARTS:
            if joint in self.joints(p):
                return p
        return None

    def to_json(self):
        """As `imubake inspect --json`: {"skeleton", "parts": {id: {"joints": [names], "found"}}}."""
        return {"skeleton": self.skeleton,
                "parts": {p: {"joints": [self.names[j] for j in self.joints(p)], "found": self.found(p)}
                          for p in PARTS}}

    def _spine_slots(self):
        s = self.spine
        if len(s) <= 2:
            return list(s)
        return [s[0], s[len(s) // 2], s[-1]]

    def _slots(self, which, spine_names):
        out = []
        if self.pelvis is not None:
            out.append(("Hips", self.pelvis))
        out.extend(zip(spine_names, self._spine_slots()))
        if self.neck:
            out.append(("Neck", self.neck[0]))
        if self.head is not None:
            out.append(("Head", self.head))
        for side in SIDES:
            for limb in LIMBS:
                j = self.limbs[side][limb]
                if j is not None:
                    out.append((_PREFIX[side] + _LIMB_NAMES[limb][which], j))
        return out

    def mixamo_slots(self):
        """[(Mixamo's name, joint)] for each found part (`Hips`, `Spine`, `Spine1`, `Spine2`,
        `Neck`, `Head`, `LeftShoulder` the clavicle, `LeftArm`, ...); a chain's slots: one joint is
        the first, two the first two, more the first, the middle (n // 2) and the top."""
        return self._slots(0, ("Spine", "Spine1", "Spine2"))

    def unity_bones(self):
        """[(Unity's humanoid name, joint)]: `Hips`, `Spine`, `Chest`, `UpperChest`, `Neck`,
        `Head`, `LeftShoulder`, `LeftUpperArm`, `LeftLowerArm`, ..., `LeftToes`."""
        return self._slots(1, ("Spine", "Chest", "UpperChest"))


def _index_parents(names, parents):
    """Parents as indices (or None); names are accepted too."""
    if parents is None:
        return [None] * len(names)
    index = {}
    for i, n in enumerate(names):
        index.setdefault(n, i)
    out = []
    for p in parents:
        if p is None or isinstance(p, int):
            out.append(p)
        else:
            out.append(index.get(p))
    return out


def resolve(names, parents=None, rest=None, end_sites=None, declared=None, skeleton=""):
    """The anatomy of a skeleton (anatomy.rs's `Anatomy::resolve`, step for step).

    names      joint names, each parent before its children
    parents    each joint's parent (index or name, None for roots); None: unknown hierarchy
    rest       rest-pose joint positions, rig world (Y up, +X the body's left); None: no shape
    end_sites  each joint's End Site offset or None
    declared   {part key (`pelvis`, `thorax`, `neck`, `head`, `left_upper_arm`, ...): joint}
    """
    names = list(names)
    n = len(names)
    parents = _index_parents(names, parents)
    rest = [tuple(float(c) for c in r) for r in rest] if rest else []
    end_sites = list(end_sites) if end_sites is not None else [None] * n
    end_sites = [None if e is None else tuple(float(c) for c in e) for e in end_sites]
    if len(end_sites) < n:
        end_sites += [None] * (n - len(end_sites))
    decl = {}
    for k, v in (declared or {}).items():
        if isinstance(v, int):
            decl[k] = v
        elif v in names:
            decl[k] = names.index(v)
    t = _Tree(names, parents, rest, end_sites)
    flat = all(p is None for p in parents) and n > 1
    a = Anatomy(skeleton, names, parents)
    found = a.found_by
    limbs = a.limbs

    def under(j, above):
        return True if above is None else (flat or t.below(j, above))

    for side in SIDES:
        def pick(limb, words, above):
            k = "%s_%s" % (side, limb)
            if k in decl:
                return decl[k], "declared"
            for j in words:
                if under(j, above):
                    return j, "named"
            return None

        # Arms: `Shoulder` is the clavicle when an upper arm is below it.
        upper_words = t.named(side, UPPER_ARM)
        shoulders = t.named(side, SHOULDER)

        def is_clavicle(j):
            if flat:
                return bool(upper_words)
            return any(t.below(u, j) for u in upper_words)

        uppers = upper_words + [j for j in shoulders if not is_clavicle(j)]
        upper = pick("upper_arm", uppers, None)
        clavicles = t.named(side, CLAVICLE) + [j for j in shoulders if is_clavicle(j)]
        clavicle = None
        if "%s_clavicle" % side in decl:
            clavicle = decl["%s_clavicle" % side], "declared"
        else:
            for c in clavicles:
                if upper is None or flat or t.below(upper[0], c):
                    clavicle = c, "named"
                    break
        up = upper[0] if upper else None
        forearm = pick("forearm", t.named(side, FOREARM), up)
        hand = pick("hand", t.named(side, HAND), forearm[0] if forearm else up)
        # Legs: a sided `Hip` is a hip joint when a thigh or another hip is below it.
        thigh_words = t.named(side, THIGH)
        hips = t.named(side, HIP)
        thighs = thigh_words + [j for j in hips
                                if flat or not any(t.below(th, j) for th in thigh_words + hips)]
        thigh = pick("thigh", thighs, None)
        shank = pick("shank", t.named(side, SHANK), thigh[0] if thigh else None)
        above_foot = shank or thigh
        foot = pick("foot", t.named(side, FOOT), above_foot[0] if above_foot else None)
        # SlimeVR names the joint below the ankle `Foot`: a foot below the foot is the toes.
        toe_words = t.named(side, TOES) + [j for j in t.named(side, FOOT)
                                            if not flat and foot and t.below(j, foot[0])]
        toes = pick("toe", toe_words, foot[0] if foot else None)
        for limb, got in (("clavicle", clavicle), ("upper_arm", upper), ("forearm", forearm),
                          ("hand", hand), ("thigh", thigh), ("shank", shank), ("foot", foot),
                          ("toe", toes)):
            if got is not None:
                limbs[side][limb] = got[0]
                found["%s_%s" % (side, limb)] = got[1]
        # A part missing between two found ones: the one joint between them.
        if not flat:
            l = limbs[side]
            for x, m, y in (("upper_arm", "forearm", "hand"), ("thigh", "shank", "foot")):
                if l[x] is not None and l[m] is None and l[y] is not None:
                    between = t.path(l[x], l[y])
                    if len(between) == 2:
                        l[m] = between[0]
                        found["%s_%s" % (side, m)] = "shape"

    if t.has_shape() and not flat:
        _shape_limbs(t, limbs, found)

    # The pelvis: where the thighs meet.
    thighs = [limbs[LEFT]["thigh"], limbs[RIGHT]["thigh"]]
    pelvis = None
    if "pelvis" in decl:
        pelvis = decl["pelvis"], "declared"
    if pelvis is None and thighs[0] is not None and thighs[1] is not None and not flat:
        m = t.common_ancestor(thighs[0], thighs[1])
        if m is not None:
            pelvis = m, "shape"
    if pelvis is None and not flat:
        one = next((x for x in thighs if x is not None), None)
        if one is not None:
            p = t.parent(one)
            while p is not None and t.words[p] is not None and t.words[p][0] is not None \
                    and t.words[p][1] == HIP:
                p = t.parent(p)
            if p is not None:
                pelvis = p, "shape"
    if pelvis is None:
        named = t.named(None, PELVIS) or t.named(None, ROOT)
        if named:
            pelvis = named[0], "named"
    if pelvis is None and not flat and n > 0:
        pelvis = 0, "shape"
    if pelvis is not None:
        how = pelvis[1]
        # Found where the thighs meet, and named so too: named.
        w = t.words[pelvis[0]]
        if how == "shape" and w is not None and w[0] is None and w[1] in (PELVIS, ROOT):
            how = "named"
        found["pelvis"] = how
        pelvis = pelvis[0]
    a.pelvis = pelvis

    # The thorax: where the arms meet.
    def shoulder_of(side):
        c = limbs[side]["clavicle"]
        return c if c is not None else limbs[side]["upper_arm"]

    def thorax_of():
        if "thorax" in decl:
            return decl["thorax"]
        if flat:
            return None
        sa, sb = shoulder_of(LEFT), shoulder_of(RIGHT)
        if sa is not None and sb is not None:
            return t.common_ancestor(sa, sb)
        if sa is not None or sb is not None:
            return t.parent(sa if sa is not None else sb)
        # No arms: the last joint named as the spine on the way from the pelvis to the head,
        # else up the pelvis's children.
        if pelvis is None:
            return None
        heads = t.named(None, HEAD)
        if heads:
            for j in reversed(t.way(pelvis, heads[0])):
                if t.words[j] == (None, SPINE):
                    return j
            return None
        top = pelvis
        while True:
            c = next((c for c in t.children[top] if t.words[c] == (None, SPINE)), None)
            if c is None:
                break
            top = c
        return top if top != pelvis else None

    thorax = thorax_of()
    if pelvis is not None and thorax is not None and thorax != pelvis:
        spine = t.way(pelvis, thorax) + [thorax]
    elif flat:
        spine = t.named(None, SPINE)
    else:
        spine = []
    if spine:
        if "thorax" in decl:
            found["spine"] = "declared"
        elif all(t.words[j] == (None, SPINE) for j in spine):
            found["spine"] = "named"
        else:
            found["spine"] = "shape"
    a.spine = spine
    top = spine[-1] if spine else pelvis

    # The head: named, else the end of the chain rising between the arms.
    def on_arm(j):
        for s in SIDES:
            x = shoulder_of(s)
            if x is not None and (x == j or t.below(x, j)):
                return True
        return False

    def is_leg_root(j):
        for s in SIDES:
            th = limbs[s]["thigh"]
            if th is not None and (th == j or t.below(th, j)):
                return True
        return False

    def head_of():
        if "head" in decl:
            return decl["head"], "declared"
        heads = t.named(None, HEAD)
        if heads:
            h = next((h for h in heads if under(h, top)), heads[0])
            return h, "named"
        if flat or not t.has_shape() or top is None:
            return None
        j = _max_last([c for c in t.children[top] if not on_arm(c) and not is_leg_root(c)],
                      key=t.highest)
        if j is None or t.highest(j) <= t.rest[top][1]:
            return None
        # Up the chain to where it ends or branches (eyes, a head-top marker).
        while len(t.children[j]) == 1:
            j = t.children[j][0]
        return j, "shape"

    head = head_of()
    if head is not None:
        found["head"] = head[1]
        head = head[0]
    a.head = head
    dn = decl.get("neck")
    if dn is not None and head is not None and t.below(head, dn):
        neck = [dn] + t.path(dn, head)[:-1]
    elif dn is not None:
        neck = [dn]
    elif top is not None and head is not None and not flat:
        neck = t.way(top, head)
    else:
        neck = t.named(None, NECK)[:1]
    if neck:
        if dn is not None:
            found["neck"] = "declared"
        elif all(t.words[j] == (None, NECK) for j in neck):
            found["neck"] = "named"
        else:
            found["neck"] = "shape"
    a.neck = neck
    return a


def _shape_limbs(t, limbs, found):
    """Limbs the names said nothing of, from the skeleton's shape (anatomy.rs's `shape_limbs`)."""
    n = len(t.names)
    centre = t.rest[0][0]

    def known(j):
        for s in SIDES:
            for p in limbs[s].values():
                if p is not None and (p == j or t.below(j, p)):
                    return True
        return False

    leaves = [j for j in range(n) if not t.children[j]]

    def side_of(j):
        x = t.tip(j)[0] - centre
        if x > 1e-9:
            return LEFT
        if x < -1e-9:
            return RIGHT
        return None

    def empty(side, parts):
        return all(limbs[side][p] is None for p in parts)

    def other(side):
        return RIGHT if side == LEFT else LEFT

    leg = ("thigh", "shank", "foot", "toe")
    arm = ("clavicle", "upper_arm", "forearm", "hand")
    # Legs: the lowest leaf on each side.
    leg_leaves = {s: _min_first([j for j in leaves if side_of(j) == s and not known(j)],
                                key=lambda j: t.tip(j)[1]) for s in SIDES}
    for side in SIDES:
        if not empty(side, leg):
            continue
        leaf = leg_leaves[side]
        if leaf is None:
            continue
        hip = None
        th = limbs[other(side)]["thigh"]
        if th is not None:
            h = t.parent(th)
            if h is not None and t.below(leaf, h):
                hip = h
        if hip is None and leg_leaves[other(side)] is not None:
            hip = t.common_ancestor(leaf, leg_leaves[other(side)])
        if hip is None:
            continue
        _assign_chain(t, t.path(hip, leaf), side, leg, False, limbs, found)
    # Arms: the leaf furthest out on each side, not in a leg.
    arm_leaves = {s: _max_last([j for j in leaves if side_of(j) == s and not known(j)],
                               key=lambda j: abs(t.tip(j)[0] - centre)) for s in SIDES}
    for side in SIDES:
        if not empty(side, arm):
            continue
        leaf = arm_leaves[side]
        if leaf is None:
            continue
        base = None
        o = limbs[other(side)]
        x = o["clavicle"] if o["clavicle"] is not None else o["upper_arm"]
        if x is not None:
            b = t.parent(x)
            if b is not None and t.below(leaf, b):
                base = b
        if base is None and arm_leaves[other(side)] is not None:
            base = t.common_ancestor(leaf, arm_leaves[other(side)])
        if base is None:
            continue
        _assign_chain(t, t.path(base, leaf), side, arm, True, limbs, found)


def _assign_chain(t, chain, side, parts, arm, limbs, found):
    """A limb's parts along `chain`: the upper arm (thigh) starts the two longest consecutive
    bones, or in an arm that branches into fingers the second joint with a bone of its own above
    the hand; the joint before it is the clavicle (arms only); the rest follow."""
    if len(chain) < 2:
        return
    bones = [t.bone(j, chain[i + 1] if i + 1 < len(chain) else None) for i, j in enumerate(chain)]
    longest = _max_last(range(len(chain) - 1), key=lambda a: bones[a] + bones[a + 1])
    if longest is None:
        longest = 0
    start = longest
    # An arm that branches into fingers: the hand is where it branches (or the joint it sits
    # on), the forearm and upper arm the two joints with a bone of their own above it.
    if arm:
        # The last branch: twist helpers branch off the upper arm and forearm before it.
        b = next((i for i in range(len(chain) - 1, -1, -1) if len(t.children[chain[i]]) > 1), None)
        if b is not None:
            r = t.rest[chain[b]]
            eps = 1e-9 * (1.0 + _norm(r))
            sits = b > 0 and _norm(_sub(r, t.rest[chain[b - 1]])) <= eps
            hand = b - 1 if sits else b
            long = [i for i in range(hand - 1, -1, -1) if bones[i] > 1e-9][:2]
            if len(long) == 2:
                start = long[1]

    def put(limb, j):
        limbs[side][limb] = j
        found["%s_%s" % (side, limb)] = "shape"

    rest = parts[1:] if arm else parts
    if arm and start > 0:
        put(parts[0], chain[start - 1])
    for k, limb in enumerate(rest):
        if start + k < len(chain):
            put(limb, chain[start + k])


def pairs(source, target):
    """[(source joint, target joint)] for the parts both anatomies have: one joint per part, and
    along the spine and the neck each target joint with the source joint at the same place along
    the chain (first with first, top with top, between by rounding i·(n−1)/(m−1); a target chain
    of one joint takes the source's top)."""
    out = []
    for part in PARTS:
        s, tt = source.joints(part), target.joints(part)
        if not s or not tt:
            continue
        n, m = len(s), len(tt)
        for i, tj in enumerate(tt):
            if m == 1:
                k = n - 1
            else:
                k = _round_half_away(i * (n - 1) / (m - 1))
            out.append((s[min(k, n - 1)], tj))
    return out


def _round_half_away(x):
    """Rust's `f64::round` (halves away from zero), not Python's banker's rounding."""
    return int(math.floor(x + 0.5)) if x >= 0 else -int(math.floor(-x + 0.5))


# ---------------------------------------------------------------------------------------------
# Skeletons from the add-on's callers, and the Rigify layer.


class Skeleton:
    """An armature as the resolution reads it: bone names, parents (names or indices, None for
    roots), rest heads in the rig world (Y up, +X the body's left) and leaf tails as End Sites."""

    def __init__(self, names, parents=None, rest=None, end_sites=None, declared=None, name=""):
        self.names = list(names)
        self.parents = parents
        self.rest = rest
        self.end_sites = end_sites
        self.declared = declared
        self.name = name


def _skeleton(x):
    return x if isinstance(x, Skeleton) else Skeleton(list(x))


# A Rigify metarig's spine chain (the hips are `spine`): declared parts.
_RIGIFY_META = {"pelvis": "spine", "thorax": "spine.003", "neck": "spine.004", "head": "spine.006"}
# A generated Rigify rig: the torso master carries the hips' rotation and the root motion; the
# FK spine controls the spine, `neck`/`head` controls the rest.
_RIGIFY_GENERATED_SPINE = {"torso": "Hips", "spine_fk.001": "Spine", "spine_fk.002": "Spine1",
                           "spine_fk.003": "Spine2", "neck": "Neck", "head": "Head"}
_RIGIFY_MECHANISM = re.compile(r"^(DEF|ORG|MCH|VIS|WGT)[-_.]")
_NOT_FK = re.compile(r"(^|[._-])(ik|tweak|parent|target|pole|socket|master|pivot|roll|heel|rot)([._-]|$)", re.I)
# A limb word -> its limb key (a `Shoulder` alone is taken as the clavicle, a sided `Hip` as the
# thigh, as a flat skeleton with both arms' words resolves them).
_WORD_LIMB = {CLAVICLE: "clavicle", SHOULDER: "clavicle", UPPER_ARM: "upper_arm", FOREARM: "forearm",
              HAND: "hand", HIP: "thigh", THIGH: "thigh", SHANK: "shank", FOOT: "foot", TOES: "toe"}
_SPINE_SLOT = {"spine1": "Spine1", "spine02": "Spine1", "chest": "Spine1",
               "spine2": "Spine2", "spine03": "Spine2", "upperchest": "Spine2"}


def is_rigify_generated(bone_names):
    return any(n.startswith("upper_arm_fk.") or n.startswith("thigh_fk.") for n in bone_names)


def is_rigify_metarig(bone_names):
    names = set(bone_names)
    return "spine.001" in names and "spine" in names and not is_rigify_generated(bone_names)


def _generated_limb_name(name):
    """A generated Rigify rig's FK control as its limb bone's name (`upper_arm_fk.L` ->
    `upper_arm.L`), or None for any other bone."""
    if _RIGIFY_MECHANISM.match(name):
        return None
    if name.startswith("shoulder."):
        return name  # the shoulder controls have no FK/IK variants
    if "_fk" not in name or _NOT_FK.search(name):
        return None
    return name.replace("_fk", "")


def _rigify_generated_anatomy(names):
    """A generated Rigify rig's parts from its control names (its mechanism bones interleave the
    hierarchy, so names alone decide here)."""
    a = Anatomy("", names, [None] * len(names))
    slots = {}
    for j, name in enumerate(names):
        if name in _RIGIFY_GENERATED_SPINE:
            slots.setdefault(_RIGIFY_GENERATED_SPINE[name], j)
            continue
        limb_name = _generated_limb_name(name)
        w = classify(limb_name) if limb_name else None
        if w is not None and w[0] is not None and w[1] in _WORD_LIMB:
            key = "%s_%s" % (w[0], _WORD_LIMB[w[1]])
            if a.found(key) is None:
                a.limbs[w[0]][_WORD_LIMB[w[1]]] = j
                a.found_by[key] = "named"
    if "Hips" in slots:
        a.pelvis = slots["Hips"]
        a.found_by["pelvis"] = "named"
    a.spine = [slots[s] for s in ("Spine", "Spine1", "Spine2") if s in slots]
    if a.spine:
        a.found_by["spine"] = "named"
    if "Neck" in slots:
        a.neck = [slots["Neck"]]
        a.found_by["neck"] = "named"
    if "Head" in slots:
        a.head = slots["Head"]
        a.found_by["head"] = "named"
    return a


def anatomy(skeleton):
    """The anatomy of a `Skeleton` (or a plain list of bone names), Rigify rigs included."""
    sk = _skeleton(skeleton)
    if is_rigify_generated(sk.names):
        return _rigify_generated_anatomy(sk.names)
    declared = dict(sk.declared or {})
    if is_rigify_metarig(sk.names):
        for key, bone in _RIGIFY_META.items():
            if bone in sk.names:
                declared.setdefault(key, bone)
    return resolve(sk.names, sk.parents, sk.rest, sk.end_sites, declared, skeleton=sk.name)


def canonical(name, rigify_generated=False):
    """The canonical part name of one bone name on its own (no hierarchy: `Shoulder` is the
    clavicle, a sided `Hip` the thigh; `Chest`/`Spine1` the second spine slot, `UpperChest`/
    `Spine2` the third), or None when it is no main humanoid bone."""
    if rigify_generated:
        if name in _RIGIFY_GENERATED_SPINE:
            return _RIGIFY_GENERATED_SPINE[name]
        name = _generated_limb_name(name)
        if name is None:
            return None
    w = classify(name)
    if w is None:
        return None
    side, word = w
    if side is not None:
        return _PREFIX[side] + _LIMB_NAMES[_WORD_LIMB[word]][0]
    if word == PELVIS:
        return "Hips"
    if word == SPINE:
        return _SPINE_SLOT.get(_normalise(_strip_decoration(name)), "Spine")
    if word == NECK:
        return "Neck"
    if word == HEAD:
        return "Head"
    return None  # a root


def match_armature(bones):
    """{canonical part: bone name} for an armature: a `Skeleton` (the hierarchy and rest heads
    resolve as imubake does) or a list of bone names (names alone)."""
    sk = _skeleton(bones)
    a = anatomy(sk)
    return {slot: sk.names[j] for slot, j in a.mixamo_slots()}


def auto_bone_map(source, target):
    """{source bone: target bone} through the parts both have (`pairs`: chains by their place
    along them). `source`/`target`: `Skeleton`s or lists of bone names. A source joint paired
    with several target joints (a longer target chain) keeps the first: the bake turns each
    target bone by its source's armature-space rotation, so the ones above follow the same way."""
    src, tgt = _skeleton(source), _skeleton(target)
    out = {}
    for s, t in pairs(anatomy(src), anatomy(tgt)):
        out.setdefault(src.names[s], tgt.names[t])
    return out


class BoneMapError(Exception):
    pass


def load_bone_map(path, source_names, target):
    """A bone map from JSON: `{"bones": {"<source bone>": "<target bone or canonical part>"}}`
    (a flat object works too). A value naming a canonical part (`LeftArm`) is resolved on the
    target (a `Skeleton` or its bone names) like the automatic map; every source and target bone
    must exist."""
    try:
        with open(path, "rb") as f:
            data = json.loads(f.read().decode("utf-8"))
    except (OSError, ValueError) as e:
        raise BoneMapError("%s: cannot read the bone map: %s" % (path, e)) from None
    if isinstance(data, dict) and isinstance(data.get("bones"), dict):
        data = data["bones"]
    if not isinstance(data, dict) or not all(isinstance(k, str) and isinstance(v, str) for k, v in data.items()):
        raise BoneMapError('%s: expected {"bones": {"source bone": "target bone", ...}}' % path)
    target = _skeleton(target)
    targets = set(target.names)
    parts = match_armature(target)
    sources = set(source_names.names if isinstance(source_names, Skeleton) else source_names)
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
