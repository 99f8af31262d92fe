"""Watching imubake's output folder: each new take is imported once, as it appears.

imubake writes a take's sidecar last (renamed into place), so a sidecar appearing means the take is
complete. `Watcher.poll` lists the sidecars under the folder and imports those not seen before
(or changed since: a reconverted take), each into its own action, retargeted onto the chosen
armature when one is set. Sidecars present when watching starts are not imported.

In Blender a `bpy.app.timers` callback calls `poll` with a limit of one take per tick, so the UI
never waits long; timers never fire in a headless `bpy`, so tests call `poll` directly.
"""

import os

import bpy

from . import sidecar as sc
from .take_import import TakeError, import_take
from .retarget import RetargetError, bake_imported

INTERVAL_S = 1.0


def _stat(path):
    try:
        st = os.stat(path)
    except OSError:
        return None
    return (st.st_mtime_ns, st.st_size)


class Watcher:
    """The state of one watched folder: which sidecars (and their versions) were handled."""

    def __init__(self, folder):
        if not os.path.isdir(folder):
            raise TakeError("%s is not a folder" % folder)
        self.folder = os.path.abspath(folder)
        self.seen = {p: _stat(p) for p in sc.find_sidecars(self.folder)}
        self.log = []  # (take name, message), newest last

    def pending(self):
        return [p for p in sc.find_sidecars(self.folder) if self.seen.get(p) != _stat(p)]

    def poll(self, context, target=None, limit=None, **retarget_options):
        """Imports new takes (at most `limit`); returns [(sidecar path, action name or error)]."""
        done = []
        for path in self.pending()[:limit]:
            self.seen[path] = _stat(path)
            try:
                imported = import_take(context, path)
                if target is not None:
                    action = bake_imported(context, imported, target, **retarget_options).action
                else:
                    action = imported.action
                message = "imported %s (%d frames)" % (action.name, imported.frames)
                done.append((path, action.name))
            except (TakeError, RetargetError) as e:
                message = "failed: %s" % e
                done.append((path, e))
            print("imubake watch: %s: %s" % (os.path.basename(path), message))
            self.log.append((os.path.basename(path), message))
            del self.log[:-20]
        return done


_watcher = None


def current():
    return _watcher


def start(folder):
    """Starts watching `folder` (replacing any watch) and registers the timer."""
    global _watcher
    _watcher = Watcher(folder)
    if not bpy.app.timers.is_registered(_tick):
        bpy.app.timers.register(_tick, first_interval=INTERVAL_S, persistent=True)
    return _watcher


def stop():
    global _watcher
    _watcher = None
    if bpy.app.timers.is_registered(_tick):
        bpy.app.timers.unregister(_tick)


def poll(context=None, limit=None):
    """One poll of the current watch, with the scene's chosen target; [] when not watching."""
    if _watcher is None:
        return []
    context = context or bpy.context
    scene = context.scene
    target = scene.imubake_watch_target if hasattr(scene, "imubake_watch_target") else None
    if target is not None and target.type != "ARMATURE":
        target = None
    reference = getattr(scene, "imubake_watch_reference", "AUTO")
    return _watcher.poll(context, target=target, limit=limit, reference=reference)


def _tick():
    if _watcher is None:
        return None
    try:
        done = poll(bpy.context, limit=1)
    except Exception as e:  # a timer that raises is unregistered by Blender: keep watching
        print("imubake watch: %s" % e)
        done = []
    # More waiting: come back soon; otherwise at the normal interval.
    return 0.05 if done and _watcher.pending() else INTERVAL_S
