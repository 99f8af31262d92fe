"""The live view's posing: a VMC frame (`vmc.Frame`) onto the animator's character.

The frame's local rotations (Unity's humanoid bones, left-handed axes) are composed down Unity's
humanoid hierarchy into world rotations in imubake's rig world (right-handed, Y up, facing +Z:
X mirrored back, `(x, y, z, w)` → `(w, x, −y, −z)`; a bone not sent keeps the identity), turned
into Blender's world (Z up, facing −Y: +90° about X), and applied with the bake's maths
(`retarget`): each matched bone turns, in the armature's frame, as the sent bone has turned since
the rest pose — `R_t = D · R_t(ref)` — its reference pose the character's rest ("REST"), the
pose it has now ("CURRENT"), or its rest with arms and legs turned to point where the performer's
T-pose points them ("AUTO", as the bake's). The hips move by the sent hips' displacement since the first frame,
scaled by the ratio of the hips' heights. Keys, when recording, go on the scene's current frame.
"""

import math

import bpy
from mathutils import Matrix, Quaternion, Vector

from . import names, retarget

# Unity's humanoid hierarchy (the bones VMC names), parents first.
PARENT = {
    "Hips": None, "Spine": "Hips", "Chest": "Spine", "UpperChest": "Chest", "Neck": "UpperChest",
    "Head": "Neck",
    "LeftShoulder": "UpperChest", "LeftUpperArm": "LeftShoulder", "LeftLowerArm": "LeftUpperArm",
    "LeftHand": "LeftLowerArm",
    "RightShoulder": "UpperChest", "RightUpperArm": "RightShoulder", "RightLowerArm": "RightUpperArm",
    "RightHand": "RightLowerArm",
    "LeftUpperLeg": "Hips", "LeftLowerLeg": "LeftUpperLeg", "LeftFoot": "LeftLowerLeg",
    "LeftToes": "LeftFoot",
    "RightUpperLeg": "Hips", "RightLowerLeg": "RightUpperLeg", "RightFoot": "RightLowerLeg",
    "RightToes": "RightFoot",
}
# imubake's rig world → Blender's: Y up becomes Z up, facing +Z becomes facing −Y.
TO_BLENDER = Matrix.Rotation(math.radians(90.0), 3, "X")


def unity_to_rig(x, y, z, w):
    """A VMC rotation (Unity axes, x y z w) as a rotation in imubake's rig world."""
    return Quaternion((w, x, -y, -z))


def world_rotations(frame):
    """{Unity bone: 3x3 world rotation in Blender's axes} for the bones the frame sent."""
    world = {}
    for name, parent in PARENT.items():
        local = Matrix.Identity(3)
        if name in frame.bones:
            local = unity_to_rig(*frame.bones[name][1]).to_matrix()
        world[name] = (world[parent] if parent else Matrix.Identity(3)) @ local
    t = TO_BLENDER
    return {n: t @ world[n] @ t.transposed() for n in PARENT if n in frame.bones}


class LiveView:
    """Poses `target` (an armature) from VMC frames; `key(frame)` records the pose shown."""

    def __init__(self, target, reference="REST"):
        if target.type != "ARMATURE":
            raise retarget.RetargetError("%s is not an armature" % target.name)
        self.target = target
        self.tgt = retarget._Target(target)
        parts = names.match_armature(retarget.skeleton(target))
        self.bone_of = {}
        for unity in PARENT:
            part = names.canonical(unity)
            if part in parts:
                self.bone_of[unity] = parts[part]
        if not self.bone_of:
            raise retarget.RetargetError("no bone of %s has a humanoid name" % target.name)
        pbs = target.pose.bones
        # Rigify limbs follow their FK controls only with the IK/FK switch at FK (1.0).
        for n in retarget._fk_switches(target):
            pbs[n]["IK_FK"] = 1.0
        if reference == "CURRENT":
            self.basis0 = {n: pbs[n].matrix_basis.copy() for n in self.tgt.order}
        else:
            self.basis0 = {n: Matrix.Identity(4) for n in self.tgt.order}
        self.to_target = retarget._rot(target.matrix_world).inverted()
        ref_pose, _ = self.tgt.solve(self.basis0, {}, {}, set(self.tgt.order))
        if reference == "AUTO":
            # The performer's rig rests in T-pose: arms along its left–right axis, legs down
            # (Blender's ±X and −Z); the character's limbs are turned to point the same way.
            aligned = {}
            for unity, bone in self.bone_of.items():
                part = names.canonical(unity)
                if part in retarget.ALIGNED_PARTS:
                    if part.endswith(("Arm", "ForeArm", "Hand")):
                        d = Vector((1.0 if part.startswith("Left") else -1.0, 0.0, 0.0))
                    else:
                        d = Vector((0.0, 0.0, -1.0))
                    aligned[bone] = (self.to_target @ d).normalized()
            ref_pose = retarget.align_to(self.tgt, self.basis0, aligned)
        if self.tgt.evaluated:
            bpy.context.view_layer.update()
            ref_pose = {n: pbs[n].matrix.copy() for n in self.tgt.order}
        self.reference = {t: retarget._rot(ref_pose[t]) for t in self.bone_of.values()}
        mapped = set(self.bone_of.values())
        self.keyed = mapped if self.tgt.evaluated else retarget._chain_bones(self.tgt, mapped)
        self.root = self.bone_of.get("Hips")
        self.root_rest = ref_pose[self.root].translation.copy() if self.root else None
        self.hips_height = retarget._hip_height(target, self.root) if self.root else None
        self.first_hips = None
        self.matched = sorted(self.bone_of)
        self.unmatched = []

    def apply(self, frame):
        """Poses the character as the frame says; the bones' matrix_basis set."""
        world = world_rotations(frame)
        self.unmatched = sorted(n for n in frame.bones if n not in self.bone_of)
        desired = {}
        t, t_inv = self.to_target, self.to_target.transposed()
        for unity, d in world.items():
            bone = self.bone_of.get(unity)
            if bone is not None:
                desired[bone] = t @ d @ t_inv @ self.reference[bone]
        heads = {}
        hips = frame.bones.get("Hips")
        if self.root is not None and hips is not None:
            x, y, z = hips[0]
            p = TO_BLENDER @ Vector((-x, y, z))
            if self.first_hips is None:
                self.first_hips = p.copy()
            scale = self.hips_height / max(self.first_hips.z, 1e-6)
            heads[self.root] = self.root_rest + (t @ (p - self.first_hips)) * scale
        _, basis = self.tgt.solve(self.basis0, desired, heads, self.keyed)
        pbs = self.target.pose.bones
        for n in self.keyed:
            pbs[n].matrix_basis = basis[n]
        return basis

    def key(self, frame_number):
        """Keys the pose shown on `frame_number` (rotations of the keyed bones, the hips' place)."""
        pbs = self.target.pose.bones
        for n in self.keyed:
            pb = pbs[n]
            if pb.rotation_mode == "AXIS_ANGLE":
                pb.rotation_mode = "QUATERNION"
            path = "rotation_quaternion" if pb.rotation_mode == "QUATERNION" else "rotation_euler"
            pb.keyframe_insert(path, frame=frame_number, group=n)
            if n == self.root:
                pb.keyframe_insert("location", frame=frame_number, group=n)



class Session:
    """A live view: the receiver, the posing, and the recording under way (if any)."""

    def __init__(self, target, port=39539, reference="REST", performer=("127.0.0.1", 39540)):
        from . import vmc

        self.view = LiveView(target, reference)
        self.receiver = vmc.Receiver(port)
        self.performer = performer
        self.shown = 0
        self.last_t = None
        self.recording = None  # (action, first frame time, scene frame of it)
        self.keys = 0
        self.error = None
        self._rate = []  # (monotonic time, packets) samples for packets per second

    def close(self):
        self.receiver.close()

    def tick(self, context=None):
        """Drains the socket and shows the newest frame (keying it when recording); never raises
        into Blender: an error is kept in `error` for the panel."""
        import time

        context = context or bpy.context
        try:
            frame = self.receiver.drain()
            now = time.monotonic()
            self._rate.append((now, self.receiver.packets))
            self._rate = [(t, p) for t, p in self._rate if now - t <= 1.0]
            if frame is None:
                return None
            self.view.apply(frame)
            self.shown += 1
            self.last_t = frame.t
            if self.recording is not None:
                self._key(context, frame)
            self.error = None
            return frame
        except Exception as e:  # noqa: BLE001 — the panel shows it; the timer keeps running
            self.error = str(e)
            return None

    def packets_per_second(self):
        if len(self._rate) < 2:
            return 0.0
        (t0, p0), (t1, p1) = self._rate[0], self._rate[-1]
        return (p1 - p0) / (t1 - t0) if t1 > t0 else 0.0

    def start_recording(self, context=None):
        """A new action on the character, named after the time, keyed from the scene's start."""
        import time

        from . import compat

        context = context or bpy.context
        name = time.strftime("imubake live %Y-%m-%d %H:%M:%S")
        action = compat.new_action(self.view.target, name)
        self.recording = [action, None, context.scene.frame_start]
        self.keys = 0
        return action

    def stop_recording(self):
        """The action stays on the character, ready to edit."""
        action = self.recording[0] if self.recording else None
        self.recording = None
        return action

    def _key(self, context, frame):
        # The scene frame of this frame's time since the first recorded one, at the scene's exact
        # rate (fps / fps_base): a 60 fps stream recorded into a 24 fps scene keys every 2.5
        # frames' time, the newest frame of each scene frame winning.
        scene = context.scene
        rate = scene.render.fps / scene.render.fps_base
        if self.recording[1] is None:
            self.recording[1] = frame.t if frame.t is not None else 0.0
        t = (frame.t if frame.t is not None else 0.0) - self.recording[1]
        f = self.recording[2] + int(round(t * rate))
        self.view.key(f)
        self.keys += 1

    def recalibrate(self):
        """Asks the performer (`imubake live --listen`) to calibrate again."""
        import socket

        from . import vmc

        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.sendto(vmc.calibration_request(), self.performer)


_session = None
INTERVAL_S = 1.0 / 60.0


def current():
    return _session


def start(target, port=39539, reference="REST", performer=("127.0.0.1", 39540)):
    """Starts the live view (replacing any) and its timer."""
    global _session
    stop()
    _session = Session(target, port, reference, performer)
    if not bpy.app.timers.is_registered(_tick):
        bpy.app.timers.register(_tick, first_interval=INTERVAL_S, persistent=True)
    return _session


def stop():
    global _session
    if _session is not None:
        _session.close()
    _session = None
    if bpy.app.timers.is_registered(_tick):
        bpy.app.timers.unregister(_tick)


def _tick():
    if _session is None:
        return None
    _session.tick()
    return INTERVAL_S
