"""Baking a take's motion onto the animator's armature.

For each mapped bone pair (source s, target t), with rotations in armature space:

    R_t(f) = D_s(f) · R_t(ref),   D_s(f) = R_s(f) · R_s(rest)⁻¹

so the target bone turns, in the armature's frame, exactly as the source bone has turned since
the take's calibration pose (imubake's rigs rest in T-pose, the pose every take is calibrated to).
`R_t(ref)` is the target's reference pose: its rest pose ("REST"), the pose it has now ("CURRENT",
for a pose the animator set), or its rest with arms and legs turned to point where the take's
T-pose points them ("AUTO": upper arms, forearms, hands, thighs and shins; Rigify's arms rest
about 28° below horizontal, Mixamo's in T-pose already). Bone positions follow the target's own
hierarchy; only the hips move, by the source hips' displacement scaled by the ratio of hip heights.

Local (matrix_basis) values come from the parent's pose: on a rig without constraints this is
exact matrix algebra; on a rig with constraints (a generated Rigify rig, whose FK controls hang
from mechanism bones) Blender evaluates the parents level by level. Keys are written straight into
new F-curves, one per frame.
"""

import bpy
from mathutils import Matrix

from . import compat, names

# Parts aligned by the automatic T-pose reference.
ALIGNED_PARTS = ("LeftArm", "LeftForeArm", "LeftHand", "LeftUpLeg", "LeftLeg",
                 "RightArm", "RightForeArm", "RightHand", "RightUpLeg", "RightLeg")
REFERENCES = ("AUTO", "CURRENT", "REST")


class RetargetError(Exception):
    pass


class Retargeted:
    """What `retarget` did: the new action, the bone map, and the reference pose used
    ({target bone: 4x4 armature-space matrix}) so callers and tests can check it."""

    def __init__(self, action, bone_map, reference, root_bone, hip_scale):
        self.action = action
        self.bone_map = bone_map
        self.reference = reference
        self.root_bone = root_bone
        self.hip_scale = hip_scale


def _order(arm):
    """Bone names, parents first."""
    out = []

    def visit(bone):
        out.append(bone.name)
        for child in bone.children:
            visit(child)

    for bone in arm.data.bones:
        if bone.parent is None:
            visit(bone)
    return out


def _rot(m):
    return m.to_3x3().normalized()


def skeleton(arm):
    """The armature as `names` resolves it (as imubake does a rig): bones parents first, their
    parents, rest heads in imubake's rig world (Blender's Z up becomes Y up, facing −Y becomes
    facing +Z, +X stays the body's left; the object's rotation included) and the tails of leaf
    bones as End Sites."""
    bones = arm.data.bones
    order = _order(arm)
    rot = _rot(arm.matrix_world)

    def rig(v):
        w = rot @ v
        return (w.x, w.z, -w.y)

    return names.Skeleton(
        order,
        parents=[bones[n].parent.name if bones[n].parent else None for n in order],
        rest=[rig(bones[n].head_local) for n in order],
        end_sites=[None if bones[n].children else rig(bones[n].tail_local - bones[n].head_local)
                   for n in order],
        name=arm.name,
    )


def _hip_height(arm, hips):
    bones = arm.data.bones
    lowest = min(min(b.head_local.z, b.tail_local.z) for b in bones)
    height = bones[hips].head_local.z - lowest
    if height <= 1e-6:
        raise RetargetError("%s: the hips bone %s is not above the feet" % (arm.name, hips))
    return height


class _Target:
    """The target armature's hierarchy and how to pose it."""

    def __init__(self, arm):
        self.arm = arm
        self.order = _order(arm)
        bones = arm.data.bones
        self.parent = {n: (bones[n].parent.name if bones[n].parent else None) for n in self.order}
        # Rest transform relative to the parent (or to the armature for roots).
        self.offset = {}
        for n in self.order:
            b = bones[n]
            self.offset[n] = (b.parent.matrix_local.inverted() @ b.matrix_local) if b.parent else b.matrix_local.copy()
        self.ancestors = {}
        for n in self.order:
            p = self.parent[n]
            self.ancestors[n] = (self.ancestors[p] | {p}) if p else frozenset()
        self.evaluated = any(pb.constraints for pb in arm.pose.bones)
        self._level_cache = {}

    def _levels(self, keyed):
        """`keyed` bones ordered by how many keyed ancestors they have: parents come first, and
        in evaluated mode each level needs a single update of the pose."""
        key = frozenset(keyed)
        if key not in self._level_cache:
            index = {n: i for i, n in enumerate(self.order)}
            self._level_cache[key] = sorted(key, key=lambda n: (len(self.ancestors[n] & key), index[n]))
        return self._level_cache[key]

    def solve(self, basis0, desired_rot, desired_head, keyed):
        """Armature-space pose of the `keyed` bones (parents first) and their matrix_basis.

        basis0        {bone: matrix_basis} for bones without a desired rotation
        desired_rot   {bone: 3x3 armature-space rotation}
        desired_head  {bone: armature-space head position} (the root motion)
        """
        pose, basis = {}, {}
        pbs = self.arm.pose.bones
        pending = set()  # bones set since Blender last evaluated the pose (evaluated mode)
        for n in self._levels(keyed):
            p = self.parent[n]
            if self.evaluated:
                # Evaluate only when an ancestor changed: one update per hierarchy level.
                if pending and not pending.isdisjoint(self.ancestors[n]):
                    bpy.context.view_layer.update()
                    pending.clear()
                parent_pose = pbs[p].matrix if p else Matrix.Identity(4)
            else:
                # Keyed sets hold every ancestor of their bones (`_chain_bones`).
                parent_pose = pose[p] if p else Matrix.Identity(4)
            frame = parent_pose @ self.offset[n]
            if n in desired_rot:
                b0 = basis0[n]
                head = desired_head.get(n, (frame @ b0).translation)
                want = Matrix.Translation(head) @ desired_rot[n].to_4x4()
                m = frame.inverted() @ want
            else:
                m = basis0[n]
            basis[n] = m
            pose[n] = frame @ m
            if self.evaluated:
                pbs[n].matrix_basis = m
                pending.add(n)
        if self.evaluated and pending:
            bpy.context.view_layer.update()
        return pose, basis


def _chain_bones(target, mapped):
    """Mapped bones and the bones between them and the root: what the bake keys."""
    keyed = set()
    for n in mapped:
        while n is not None and n not in keyed:
            keyed.add(n)
            n = target.parent[n]
    return keyed


def retarget(context, source, target, *, bone_map=None, reference="AUTO", action_name=None,
             frame_start=None, frame_end=None):
    """Bakes `source`'s animation (an imported take) onto armature `target`; returns Retargeted.

    bone_map   {source bone: target bone}; automatic through `names` (the armatures' parts,
               resolved from names, hierarchy and rest shape) when None
    reference  "AUTO", "CURRENT" or "REST" (see the module's doc)
    """
    if target.type != "ARMATURE":
        raise RetargetError("%s is not an armature" % target.name)
    if reference not in REFERENCES:
        raise RetargetError("reference must be one of %s" % ", ".join(REFERENCES))
    src_skeleton, tgt_skeleton = skeleton(source), skeleton(target)
    if bone_map is None:
        bone_map = names.auto_bone_map(src_skeleton, tgt_skeleton)
    bone_map = {s: t for s, t in bone_map.items() if s in source.pose.bones and t in target.pose.bones}
    if not bone_map:
        raise RetargetError(
            "no bone of %s matches a bone of %s; choose a bone map (JSON)" % (source.name, target.name))
    # Each pair's body part, from either side's anatomy (names, hierarchy, rest shape).
    part_of = {b: p for p, b in names.match_armature(tgt_skeleton).items()}
    part_of_source = {b: p for p, b in names.match_armature(src_skeleton).items()}
    part_of_pair = {s: part_of_source.get(s) or part_of.get(t) for s, t in bone_map.items()}

    scene = context.scene
    start = scene.frame_start if frame_start is None else frame_start
    end = scene.frame_end if frame_end is None else frame_end
    tgt = _Target(target)
    # Without constraints the bake keys the mapped bones and the bones between them (at their
    # reference pose); with constraints only the mapped controls, whose parents Blender drives.
    keyed = set(bone_map.values()) if tgt.evaluated else _chain_bones(tgt, bone_map.values())

    # Source armature space -> target armature space (object rotations; scale is handled by the
    # hip-height ratio).
    to_target = _rot(target.matrix_world).inverted() @ _rot(source.matrix_world)
    to_target_t = to_target.transposed()
    src_rest_inv = {s: _rot(source.data.bones[s].matrix_local).transposed() for s in bone_map}

    # Reference pose of the target.
    pbs = target.pose.bones
    if reference == "CURRENT":
        basis0 = {n: pbs[n].matrix_basis.copy() for n in tgt.order}
    else:
        basis0 = {n: Matrix.Identity(4) for n in tgt.order}
    saved_basis = {n: pbs[n].matrix_basis.copy() for n in tgt.order}
    # The target's own action would override the pose while Blender evaluates frames.
    if target.animation_data is not None:
        target.animation_data.action = None
    # Rigify limbs follow their FK controls only with the IK/FK switch at FK (1.0).
    ik_fk = _fk_switches(target)
    for n in ik_fk:
        pbs[n]["IK_FK"] = 1.0
    try:
        if tgt.evaluated:
            for n in tgt.order:
                pbs[n].matrix_basis = basis0[n]
        ref_pose, _ = tgt.solve(basis0, {}, {}, set(tgt.order))
        if reference == "AUTO":
            ref_pose = _align_limbs(tgt, basis0, source, bone_map, part_of_pair, to_target)
        if tgt.evaluated:
            # What Blender makes of the reference pose, constraints included (DEF bones too).
            bpy.context.view_layer.update()
            ref_pose = {n: pbs[n].matrix.copy() for n in tgt.order}
        reference_rot = {t: _rot(ref_pose[t]) for t in bone_map.values()}

        # Root motion: the hips' displacement since the source's rest, scaled by hip height.
        src_hips = next((s for s, p in part_of_pair.items() if p == "Hips"), None)
        root = bone_map.get(src_hips) if src_hips else None
        scale = None
        if root is not None:
            scale = _hip_height(target, root) / _hip_height(source, src_hips)
            src_hips_rest = source.data.bones[src_hips].head_local.copy()
            root_rest = ref_pose[root].translation.copy()

        values = {n: [] for n in keyed}
        for f in range(start, end + 1):
            scene.frame_set(f)
            desired = {}
            for s, t in bone_map.items():
                delta = _rot(source.pose.bones[s].matrix) @ src_rest_inv[s]
                desired[t] = to_target @ delta @ to_target_t @ reference_rot[t]
            heads = {}
            if root is not None:
                d = source.pose.bones[src_hips].head - src_hips_rest
                heads[root] = root_rest + (to_target @ d) * scale
            _, basis = tgt.solve(basis0, desired, heads, keyed)
            for n in keyed:
                values[n].append(basis[n])
    finally:
        for n, m in saved_basis.items():
            pbs[n].matrix_basis = m

    name = action_name or source.name
    src_action = source.animation_data.action if source.animation_data else None
    if src_action is not None and src_action.name == name:
        # The imported take's action is temporary: the baked one gets the take's name.
        src_action.name = name + " (imported)"
    action = _write_action(target, name, values, root, start, ik_fk)
    return Retargeted(action, bone_map, ref_pose, root, scale)


def _align_limbs(tgt, basis0, source, bone_map, part_of_pair, to_target):
    """The rest (or current) pose with limb bones turned to the source's T-pose directions."""
    aligned = {}
    for s, t in bone_map.items():
        if part_of_pair.get(s) in ALIGNED_PARTS:
            b = source.data.bones[s]
            want = to_target @ (b.tail_local - b.head_local)
            if want.length > 1e-9:
                aligned[t] = want.normalized()
    return align_to(tgt, basis0, aligned)


def align_to(tgt, basis0, aligned):
    """The reference pose (from `basis0`) with the bones of `aligned` ({target bone: direction in
    the target's armature space}) turned to point that way; `basis0` becomes that pose."""
    pose, desired_rot, basis = {}, {}, {}
    # Parents first: each bone's direction is measured after its parents have turned.
    for n in tgt.order:
        p = tgt.parent[n]
        frame = (pose[p] if p else Matrix.Identity(4)) @ tgt.offset[n]
        m = frame @ basis0[n]
        if n in aligned:
            y = m.to_3x3().col[1].normalized()
            turn = y.rotation_difference(aligned[n]).to_matrix()
            desired_rot[n] = turn @ _rot(m)
            m = Matrix.Translation(m.translation) @ desired_rot[n].to_4x4()
        pose[n] = m
        basis[n] = frame.inverted() @ m
    if tgt.evaluated:
        # Constraints move parents: let Blender place each level before turning the next.
        pose, basis = tgt.solve(basis0, desired_rot, {}, set(tgt.order))
    # The aligned pose is the base the bake starts from.
    basis0.update(basis)
    return pose


def _fk_switches(target):
    """Rigify's IK/FK switch properties ("IK_FK" on the limb parents): 1.0 is FK."""
    found = []
    for pb in target.pose.bones:
        if "IK_FK" in pb.keys():
            found.append(pb.name)
    return found


def _write_action(target, name, values, root, start, ik_fk):
    action = compat.new_action(target, name)
    pbs = target.pose.bones
    for n, mats in values.items():
        pb = pbs[n]
        frames = [float(start + i) for i in range(len(mats))]
        mode = pb.rotation_mode
        if mode == "AXIS_ANGLE":
            pb.rotation_mode = mode = "QUATERNION"
        if mode == "QUATERNION":
            comps = ([], [], [], [])
            prev = None
            for m in mats:
                q = m.to_quaternion()
                if prev is not None and q.dot(prev) < 0:
                    q = -q  # the same rotation, no flip through 180° between keys
                prev = q
                for i in range(4):
                    comps[i].append(q[i])
            path = "rotation_quaternion"
        else:
            comps = ([], [], [])
            prev = None
            for m in mats:
                e = m.to_euler(mode, prev) if prev is not None else m.to_euler(mode)
                prev = e
                for i in range(3):
                    comps[i].append(e[i])
            path = "rotation_euler"
        data_path = 'pose.bones["%s"].%s' % (n, path)
        for i, c in enumerate(comps):
            compat.set_keys(compat.new_fcurve(target, data_path, i, n), frames, c)
        if n == root:
            data_path = 'pose.bones["%s"].location' % n
            for i in range(3):
                compat.set_keys(compat.new_fcurve(target, data_path, i, n), frames,
                                [m.to_translation()[i] for m in mats])
    for n in ik_fk:
        pbs[n]["IK_FK"] = 1.0
        fc = compat.new_fcurve(target, 'pose.bones["%s"]["IK_FK"]' % n, 0, n)
        compat.set_keys(fc, [float(start)], [1.0], interpolation="CONSTANT")
    return action


def bake_imported(context, imported, target, *, bone_map_path=None, reference="AUTO"):
    """Bakes an imported take (`take_import.ImportedTake`) onto `target` as an action named after
    the take, then removes the imported armature whatever happened. `bone_map_path`: a bone-map
    JSON (see `names.load_bone_map`), else names are matched automatically. Raises RetargetError
    or names.BoneMapError."""
    try:
        bone_map = None
        if bone_map_path:
            bone_map = names.load_bone_map(
                bone_map_path,
                [b.name for b in imported.armature.data.bones],
                skeleton(target),
            )
        result = retarget(context, imported.armature, target, bone_map=bone_map, reference=reference,
                          action_name=imported.name)
        # The feet's contacts go with the motion onto the character.
        from .take_import import key_contacts

        key_contacts(target, imported.take)
        return result
    finally:
        remove_armature(imported.armature)


def remove_armature(obj):
    """Removes an imported armature, its children, its armature data and its action."""
    doomed = [obj] + list(obj.children_recursive)
    action = obj.animation_data.action if obj.animation_data else None
    datas = [(o.type, o.data) for o in doomed if o.data is not None]
    for o in doomed:
        bpy.data.objects.remove(o, do_unlink=True)
    for kind, data in datas:
        coll = {"ARMATURE": bpy.data.armatures, "MESH": bpy.data.meshes}.get(kind)
        if coll is not None and data.users == 0:
            coll.remove(data)
    if action is not None and action.users == 0:
        bpy.data.actions.remove(action)
