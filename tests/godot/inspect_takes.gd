# What Godot 3 made of each imported take, for tests/outputs/godot_import.rs. Run headless as
#   godot3-server --path PROJECT -s inspect_takes.gd
# after the project's files were imported (`--export-pack`). Reads res://request.json,
# {"takes": [{"file": "res://a/walk.glb", "times": [seconds, ...]}]}, and writes
# res://result.json: per take its animations, the first one's length, each track's node path and
# key count and its first keys' times, the skeleton's bone names, and every bone's world position
# (metres, Godot's Y-up axes) at each time, the animation seeked there.
extends SceneTree


func _find(node, cls):
	if node.is_class(cls):
		return node
	for child in node.get_children():
		var found = _find(child, cls)
		if found != null:
			return found
	return null


func _inspect(take):
	var scene = load(take["file"])
	if scene == null:
		return {"file": take["file"], "error": "Godot could not load it"}
	var root = scene.instance()
	get_root().add_child(root)
	var player = _find(root, "AnimationPlayer")
	var skeleton = _find(root, "Skeleton")
	var names = player.get_animation_list()
	var animation = player.get_animation(names[0])
	var tracks = []
	for i in range(animation.get_track_count()):
		var times = []
		for k in range(min(animation.track_get_key_count(i), 4)):
			times.append(animation.track_get_key_time(i, k))
		tracks.append({
			"path": str(animation.track_get_path(i)),
			"keys": animation.track_get_key_count(i),
			"first_times": times,
		})
	var bones = []
	for b in range(skeleton.get_bone_count()):
		bones.append(skeleton.get_bone_name(b))
	player.play(names[0])
	var positions = []
	for t in take["times"]:
		player.seek(t, true)
		var frame = []
		for b in range(skeleton.get_bone_count()):
			var p = skeleton.global_transform.xform(skeleton.get_bone_global_pose(b).origin)
			frame.append([p.x, p.y, p.z])
		positions.append(frame)
	root.queue_free()
	return {
		"file": take["file"],
		"animations": names,
		"length": animation.length,
		"tracks": tracks,
		"bones": bones,
		"positions": positions,
	}


func _init():
	var file = File.new()
	file.open("res://request.json", File.READ)
	var request = parse_json(file.get_as_text())
	file.close()
	var results = []
	for take in request["takes"]:
		results.append(_inspect(take))
	file.open("res://result.json", File.WRITE)
	file.store_string(to_json({"engine": Engine.get_version_info()["string"], "takes": results}))
	file.close()
	quit()
