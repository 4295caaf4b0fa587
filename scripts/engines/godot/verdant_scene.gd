@tool
class_name VerdantScene
extends Node3D
## A verdant scene folder (out/<scene>/) in Godot 4, built at run time or in the editor:
## the terrain (terrain/terrain.glb) and, per placement tile, species, variant and level, one
## MultiMeshInstance3D holding that tile's instances, shown over the level's range of switch
## distances (GeometryInstance3D visibility ranges), the coarsest level up to the species' cull
## distance: the selection verdant's view stage makes for scene.glb, at tile granularity.
##
## What it reads (docs/scene.md, "Replaying the selection in an engine"):
## - manifest.json: view.chains.<species> (pick, variants[v][k].file/mesh/switch_distance_m),
##   view.views[0].species[j].cull, scatter.species[j].table, settings.lod;
## - placements/<species>.csv or .bin: one row per instance (x, y, z, quaternion, scale, yaw,
##   tile, variant);
## - the level files (species/*.glb) through GLTFDocument, each mesh taken by its glTF name.
##
## Use: add a Node3D, attach this script, set scene_dir to the folder, and call build() (or leave
## build_on_ready on). Distances are verdant's for its reference screen ([lod] in the preset) times
## distance_factor; with distance_factor 0 the factor is worked out from the viewport's camera
## (its vertical field of view and the viewport height against the reference screen's).

## The scene folder verdant wrote (holding manifest.json).
@export_dir var scene_dir: String = ""
## Build when the node enters the tree.
@export var build_on_ready: bool = true
## Scales every switch and cull distance; 0: from the current camera against the reference screen.
@export var distance_factor: float = 0.0
## Also load terrain/terrain.glb.
@export var with_terrain: bool = true

var _meshes: Dictionary = {}


func _ready() -> void:
	if build_on_ready and scene_dir != "":
		build()


## Builds the terrain and every species' instances as children of this node (removing what an
## earlier build added). Returns the number of MultiMeshInstance3D nodes made.
func build() -> int:
	for child in get_children():
		if child.has_meta("verdant"):
			child.queue_free()
	_meshes.clear()
	var manifest: Dictionary = _read_json(scene_dir.path_join("manifest.json"))
	if manifest.is_empty():
		return 0
	if with_terrain:
		var terrain: Node3D = _load_scene(scene_dir.path_join("terrain/terrain.glb"))
		if terrain != null:
			terrain.name = "terrain"
			terrain.set_meta("verdant", true)
			add_child(terrain)
	var view: Dictionary = manifest.get("view", {})
	var chains: Dictionary = view.get("chains", {})
	var views: Array = view.get("views", [])
	var first_view: Dictionary = views[0] if views.size() > 0 else {}
	var factor: float = distance_factor if distance_factor > 0.0 else _camera_factor(manifest)
	var made: int = 0
	var species_list: Array = manifest.get("scatter", {}).get("species", [])
	for j in species_list.size():
		var entry: Dictionary = species_list[j]
		var species_name: String = entry.get("name", "")
		if not chains.has(species_name):
			continue
		var cull_m: float = INF
		for s in first_view.get("species", []):
			if s.get("name", "") == species_name and s.get("cull") != null:
				cull_m = float(s["cull"]["distance_m"])
		var rows: Array = _read_table(scene_dir.path_join(entry.get("table", "")))
		made += _build_species(species_name, chains[species_name], rows, cull_m, factor)
	return made


## One node per (tile, variant, level) of a species; returns how many.
func _build_species(
	species: String, chain: Dictionary, rows: Array, cull_m: float, factor: float
) -> int:
	var variants: Array = chain.get("variants", [])
	var pick: Array = chain.get("pick", [])
	var root := Node3D.new()
	root.name = species
	root.set_meta("verdant", true)
	add_child(root)
	# (tile, built variant) -> rows
	var groups: Dictionary = {}
	for row in rows:
		var v: int = int(row["variant"])
		var built: int = int(pick[v]) if v < pick.size() else v
		if built >= variants.size():
			push_warning("%s: a row names variant %d of %d" % [species, v, variants.size()])
			continue
		var key := Vector2i(int(row["tile"]), built)
		if not groups.has(key):
			groups[key] = []
		groups[key].append(row)
	var made: int = 0
	for key in groups:
		var group: Array = groups[key]
		var levels: Array = variants[key.y]
		# instances switch at their own scale times the distances: the tile uses its mean scale
		var scale_sum: float = 0.0
		for row in group:
			scale_sum += float(row["scale"].y)
		var mean_scale: float = scale_sum / group.size()
		for k in levels.size():
			var level: Dictionary = levels[k]
			var mesh: Mesh = _mesh(level["file"], level["mesh"])
			if mesh == null:
				continue
			var begin: float = float(level["switch_distance_m"]) * factor * mean_scale
			var end: float = cull_m * factor * mean_scale if cull_m < INF else 0.0
			if k + 1 < levels.size():
				end = float(levels[k + 1]["switch_distance_m"]) * factor * mean_scale
			if end > 0.0 and end <= begin:
				continue  # a level whose range is empty (its switch equals the next one's)
			var node := MultiMeshInstance3D.new()
			node.name = "%s_t%d_v%d_LOD%d" % [species, key.x, key.y, k]
			node.multimesh = _multimesh(mesh, group)
			node.visibility_range_begin = begin
			node.visibility_range_end = end
			root.add_child(node)
			made += 1
	return made


func _multimesh(mesh: Mesh, rows: Array) -> MultiMesh:
	var mm := MultiMesh.new()
	mm.transform_format = MultiMesh.TRANSFORM_3D
	mm.mesh = mesh
	mm.instance_count = rows.size()
	for i in rows.size():
		var row: Dictionary = rows[i]
		var basis := Basis(row["rotation"]) * Basis.from_scale(row["scale"])
		mm.set_instance_transform(i, Transform3D(basis, row["position"]))
	return mm


## The mesh named `mesh_name` in a level file (each file loaded once).
func _mesh(file: String, mesh_name: String) -> Mesh:
	if not _meshes.has(file):
		var found: Dictionary = {}
		var doc := GLTFDocument.new()
		var state := GLTFState.new()
		if doc.append_from_file(scene_dir.path_join(file), state) == OK:
			for gltf_mesh in state.get_meshes():
				var importer: ImporterMesh = gltf_mesh.mesh
				if importer == null:
					continue
				# the glTF name: GLTFMesh.original_name (Godot 4.3+), else the importer's name,
				# which older versions prefix with the scene's ("<scene>_<mesh>")
				var original: Variant = gltf_mesh.get("original_name")
				var key: String = str(original) if original != null else importer.resource_name
				found[key] = importer.get_mesh()
		else:
			push_warning("verdant: cannot read %s" % file)
		_meshes[file] = found
	var meshes: Dictionary = _meshes[file]
	if meshes.has(mesh_name):
		return meshes[mesh_name]
	for key in meshes:
		if str(key).ends_with("_" + mesh_name):
			return meshes[key]
	push_warning("verdant: no mesh %s in %s" % [mesh_name, file])
	return null


func _load_scene(path: String) -> Node3D:
	var doc := GLTFDocument.new()
	var state := GLTFState.new()
	if doc.append_from_file(path, state) != OK:
		push_warning("verdant: cannot read %s" % path)
		return null
	return doc.generate_scene(state) as Node3D


## verdant's distances are for its reference screen: a camera with another field of view or
## viewport height sees things bigger or smaller by H / tan(fov/2) over the reference's.
func _camera_factor(manifest: Dictionary) -> float:
	var lod: Dictionary = manifest.get("settings", {}).get("lod", {})
	var camera: Camera3D = get_viewport().get_camera_3d() if is_inside_tree() else null
	if camera == null or lod.is_empty():
		return 1.0
	var height: float = get_viewport().get_visible_rect().size.y
	var view: float = height / tan(deg_to_rad(camera.fov) * 0.5)
	var reference_fov: float = deg_to_rad(float(lod["fov_y_deg"]))
	var reference: float = float(lod["screen_height_px"]) / tan(reference_fov * 0.5)
	return view / reference


func _read_json(path: String) -> Dictionary:
	var text := FileAccess.get_file_as_string(path)
	if text == "":
		push_error("verdant: cannot read %s" % path)
		return {}
	var parsed: Variant = JSON.parse_string(text)
	return parsed if parsed is Dictionary else {}


## The rows of a placement table, CSV or binary, as dictionaries.
func _read_table(path: String) -> Array:
	if path.ends_with(".bin"):
		return _read_binary_table(path)
	var rows: Array = []
	var f := FileAccess.open(path, FileAccess.READ)
	if f == null:
		push_error("verdant: cannot read %s" % path)
		return rows
	f.get_csv_line()  # the header
	while not f.eof_reached():
		var c := f.get_csv_line()
		if c.size() < 13:
			continue
		var rotation := Quaternion(float(c[3]), float(c[4]), float(c[5]), float(c[6]))
		(
			rows
			. append(
				{
					"position": Vector3(float(c[0]), float(c[1]), float(c[2])),
					"rotation": rotation,
					"scale": Vector3(float(c[7]), float(c[8]), float(c[9])),
					"tile": int(c[11]),
					"variant": int(c[12]),
				}
			)
		)
	return rows


## A binary table: `VPLT`, version 1, u64 rows, then the arrays (src/export/table_bin.rs).
func _read_binary_table(path: String) -> Array:
	var rows: Array = []
	var f := FileAccess.open(path, FileAccess.READ)
	if f == null or f.get_buffer(4).get_string_from_ascii() != "VPLT" or f.get_32() != 1:
		push_error("verdant: %s is not a version 1 binary placement table" % path)
		return rows
	var n: int = f.get_64()
	rows.resize(n)
	for i in n:
		rows[i] = {"position": Vector3(f.get_double(), f.get_double(), f.get_double())}
	for i in n:
		rows[i]["rotation"] = Quaternion(f.get_float(), f.get_float(), f.get_float(), f.get_float())
	for i in n:
		rows[i]["scale"] = Vector3(f.get_float(), f.get_float(), f.get_float())
	for i in n:
		f.get_float()  # yaw_deg: inside the rotation already
	for i in n:
		rows[i]["tile"] = f.get_32()
	for i in n:
		rows[i]["variant"] = f.get_32()
	return rows
