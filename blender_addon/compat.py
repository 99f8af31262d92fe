"""Animation API differences between Blender 4.2 LTS and 5.0.

Blender 4.4 introduced layered actions (slots, layers, strips, channelbags) and 5.0 removed
`Action.fcurves`: F-curves live in the channelbag of the slot an object uses. Everything the
add-on does with F-curves goes through these functions.
"""

import bpy

LAYERED = "fcurves" not in bpy.types.Action.bl_rna.properties


def _channelbag(action, obj, create):
    adt = obj.animation_data
    slot = adt.action_slot if adt is not None else None
    if slot is None:
        if not create:
            return None
        slot = action.slots.new(id_type="OBJECT", name=obj.name)
        adt.action_slot = slot
    if not action.layers:
        if not create:
            return None
        action.layers.new("Layer")
    layer = action.layers[0]
    if not layer.strips:
        if not create:
            return None
        layer.strips.new(type="KEYFRAME")
    strip = layer.strips[0]
    bag = strip.channelbag(slot)
    if bag is None and create:
        bag = strip.channelbag(slot, ensure=True)
    return bag


def fcurves(obj):
    """The F-curves of the action `obj` plays (empty when it has none)."""
    adt = obj.animation_data
    if adt is None or adt.action is None:
        return []
    action = adt.action
    if not LAYERED:
        return list(action.fcurves)
    bag = _channelbag(action, obj, create=False)
    return list(bag.fcurves) if bag is not None else []


def new_action(obj, name):
    """A new action assigned to `obj` (replacing what it played)."""
    obj.animation_data_create()
    action = bpy.data.actions.new(name)
    obj.animation_data.action = action
    return action


def new_fcurve(obj, data_path, index, group):
    """An F-curve in the action `obj` plays, for `data_path[index]`, in group `group`."""
    action = obj.animation_data.action
    if not LAYERED:
        return action.fcurves.new(data_path, index=index, action_group=group)
    bag = _channelbag(action, obj, create=True)
    fc = bag.fcurves.new(data_path, index=index)
    if group:
        grp = bag.groups.get(group) or bag.groups.new(group)
        fc.group = grp
    return fc


def set_keys(fc, frames, values, interpolation="LINEAR"):
    """Replaces the keys of `fc` with (frames[i], values[i]) in one call (fast for long takes)."""
    n = len(frames)
    points = fc.keyframe_points
    if len(points):
        points.clear()
    points.add(n)
    co = [0.0] * (2 * n)
    co[0::2] = frames
    co[1::2] = values
    points.foreach_set("co", co)
    points.foreach_set("handle_left", co)
    points.foreach_set("handle_right", co)
    ipo = bpy.types.Keyframe.bl_rna.properties["interpolation"].enum_items[interpolation].value
    points.foreach_set("interpolation", [ipo] * n)
    fc.update()


def remove_fcurve(obj, fc):
    """Removes `fc` from the action `obj` plays."""
    action = obj.animation_data.action
    if not LAYERED:
        action.fcurves.remove(fc)
        return
    _channelbag(action, obj, create=False).fcurves.remove(fc)
