"""Import a verdant scene folder into Blender fast: the terrain, and every species as Geometry Nodes
instances of one object per mesh, instead of one object per instance.

    blender --background --python scripts/blender_import.py -- SCENE_DIR [--save FILE.blend] [--check] [--render FILE.png]
    python scripts/blender_import.py SCENE_DIR [--save FILE.blend] [--check] [--render FILE.png]   (the PyPI bpy module)

Blender's glTF importer (4.x) expands EXT_mesh_gpu_instancing into an object per instance: the
demo's scene.glb took 19 minutes and made 122 507 objects. This script reads scene.glb itself, hands
Blender a copy without the instanced nodes but with one prototype node per instanced mesh (so the
importer brings the terrain, the meshes and their materials, as usual), then makes per mesh one
point cloud with the instances' positions, rotations and scales as attributes and an "Instance on
Points" modifier over its prototype (hidden). Coordinates follow the importer: glTF +Y up becomes
Blender +Z up ((x, y, z) → (x, −z, y)).

--check: afterwards, count the instances Blender's evaluated scene holds and compare them with
what manifest.json says the first view draws and, for a sample, with the placement tables' rows
(exit 1 on a mismatch). Prints the seconds and the object and instance counts either way.

--render FILE.png: renders the first [[view]] (Cycles on the CPU, 480 px across, 16 samples, a sun
and a sky-coloured world, the Standard view transform) and checks what a person sees in it: the
scene, its snow when the preset has [snow], green ground cover when it has grass (exit 1 if not).
"""

import base64
import csv
import json
import os
import struct
import sys
import tempfile
import time

import numpy as np

import bpy

EXT = "EXT_mesh_gpu_instancing"
PROTO_PREFIX = "verdant_proto_"



def table_rows(path):
    """A placement table's rows as dicts of the CSV's columns: a .csv read as text, a .bin
    (`[scatter] table = "binary"`: `VPLT`, version 1, u64 rows, then the arrays; see
    src/export/table_bin.rs) read by its layout."""
    if not path.endswith(".bin"):
        with open(path) as f:
            yield from csv.DictReader(f)
        return
    with open(path, "rb") as f:
        data = f.read()
    if data[:4] != b"VPLT" or int.from_bytes(data[4:8], "little") != 1:
        raise ValueError(f"{path}: not a version 1 binary placement table")
    n = int.from_bytes(data[8:16], "little")
    o = 16
    arrays = []
    for dtype, k in (("<f8", 3), ("<f4", 4), ("<f4", 3), ("<f4", 1), ("<u4", 1), ("<u4", 1)):
        a = np.frombuffer(data, dtype=dtype, count=n * k, offset=o).reshape(n, k)
        o += a.nbytes
        arrays.append(a)
    pos, rot, scale = arrays[0], arrays[1], arrays[2]
    for i in range(n):
        yield {"x": pos[i, 0], "y": pos[i, 1], "z": pos[i, 2], "qx": rot[i, 0], "qy": rot[i, 1], "qz": rot[i, 2],
               "qw": rot[i, 3], "sx": scale[i, 0], "sy": scale[i, 1], "sz": scale[i, 2]}

def read_glb(path):
    data = open(path, "rb").read()
    if data[:4] != b"glTF":
        raise SystemExit(f"{path}: not a GLB file")
    (json_len,) = struct.unpack_from("<I", data, 12)
    doc = json.loads(data[20 : 20 + json_len])
    chunk = b""
    at = 20 + json_len
    if at + 8 <= len(data):
        (bin_len,) = struct.unpack_from("<I", data, at)
        chunk = data[at + 8 : at + 8 + bin_len]
    buffers = []
    for i, b in enumerate(doc.get("buffers", [])):
        uri = b.get("uri")
        if uri is None:
            buffers.append(chunk)
        elif uri.startswith("data:"):
            buffers.append(base64.b64decode(uri.split(",", 1)[1]))
        else:
            buffers.append(open(os.path.join(os.path.dirname(path), uri), "rb").read())
    return doc, chunk, buffers


def accessor(doc, buffers, index):
    """A float accessor as an (count, components) array."""
    a = doc["accessors"][index]
    if a["componentType"] != 5126:
        raise SystemExit(f"accessor {index}: expected floats")
    n = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[a["type"]]
    v = doc["bufferViews"][a["bufferView"]]
    base = v.get("byteOffset", 0) + a.get("byteOffset", 0)
    stride = v.get("byteStride", 4 * n)
    raw = np.frombuffer(buffers[v["buffer"]], dtype=np.uint8, count=stride * (a["count"] - 1) + 4 * n, offset=base)
    rows = np.lib.stride_tricks.as_strided(raw, shape=(a["count"], 4 * n), strides=(stride, 1))
    return np.ascontiguousarray(rows).view("<f4").reshape(a["count"], n).astype(np.float64)


def quat_mul(a, b):
    """Hamilton products of (x, y, z, w) quaternions, row by row."""
    ax, ay, az, aw = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bx, by, bz, bw = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return np.stack([aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz], axis=-1)


def rotate(q, v):
    """Vectors v rotated by unit quaternions q (x, y, z, w)."""
    u, w = q[..., :3], q[..., 3:4]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def world_transforms(doc):
    """Per node: (translation, rotation xyzw, scale) of its world transform, for the nodes of the
    default scene (composed as T·R·S down the tree; exact for the uniform scales verdant writes)."""
    out = {}
    scene = doc["scenes"][doc.get("scene", 0)]
    stack = [(r, np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]), np.ones(3)) for r in scene["nodes"]]
    while stack:
        i, pt, pq, ps = stack.pop()
        node = doc["nodes"][i]
        t = np.array(node.get("translation", [0.0, 0.0, 0.0]))
        q = np.array(node.get("rotation", [0.0, 0.0, 0.0, 1.0]))
        s = np.array(node.get("scale", [1.0, 1.0, 1.0]))
        wt = pt + rotate(pq, ps * t)
        wq = quat_mul(pq, q)
        ws = ps * s
        out[i] = (wt, wq, ws)
        stack.extend((c, wt, wq, ws) for c in node.get("children", []))
    return out


def instances_by_mesh(doc, buffers):
    """{mesh index: (translations, rotations xyzw, scales)} in glTF world space."""
    world = world_transforms(doc)
    groups = {}
    for i, node in enumerate(doc["nodes"]):
        ext = node.get("extensions", {}).get(EXT)
        if ext is None or "mesh" not in node or i not in world:
            continue
        attrs = ext["attributes"]
        n = doc["accessors"][next(iter(attrs.values()))]["count"]
        t = accessor(doc, buffers, attrs["TRANSLATION"]) if "TRANSLATION" in attrs else np.zeros((n, 3))
        q = accessor(doc, buffers, attrs["ROTATION"]) if "ROTATION" in attrs else np.tile([0.0, 0.0, 0.0, 1.0], (n, 1))
        s = accessor(doc, buffers, attrs["SCALE"]) if "SCALE" in attrs else np.ones((n, 3))
        wt, wq, ws = world[i]
        t = wt + rotate(np.broadcast_to(wq, q.shape), ws * t)
        q = quat_mul(np.broadcast_to(wq, q.shape), q)
        s = ws * s
        groups.setdefault(node["mesh"], []).append((t, q, s))
    return {m: tuple(np.concatenate(parts, axis=0) for parts in zip(*chunks)) for m, chunks in groups.items()}


def without_instances(doc):
    """The document without its instanced nodes, plus one prototype node per instanced mesh."""
    doc = json.loads(json.dumps(doc))
    instanced = {i for i, n in enumerate(doc["nodes"]) if EXT in n.get("extensions", {})}
    keep = [i for i in range(len(doc["nodes"])) if i not in instanced]
    new_index = {old: new for new, old in enumerate(keep)}
    meshes = sorted({doc["nodes"][i]["mesh"] for i in instanced if "mesh" in doc["nodes"][i]})
    nodes = []
    for old in keep:
        node = doc["nodes"][old]
        if "children" in node:
            node["children"] = [new_index[c] for c in node["children"] if c in new_index]
            if not node["children"]:
                del node["children"]
        nodes.append(node)
    protos = []
    for m in meshes:
        protos.append(len(nodes))
        nodes.append({"name": PROTO_PREFIX + (doc["meshes"][m].get("name") or f"mesh{m}"), "mesh": m})
    doc["nodes"] = nodes
    for s in doc.get("scenes", []):
        s["nodes"] = [new_index[r] for r in s["nodes"] if r in new_index]
    doc["scenes"][doc.get("scene", 0)]["nodes"] += protos
    for key in ("extensionsUsed", "extensionsRequired"):
        if key in doc:
            doc[key] = [e for e in doc[key] if e != EXT]
            if not doc[key]:
                del doc[key]
    return doc, {m: doc["nodes"][p]["name"] for m, p in zip(meshes, protos)}


def write_glb(path, doc, chunk):
    js = json.dumps(doc, separators=(",", ":")).encode()
    js += b" " * (-len(js) % 4)
    chunk = chunk + b"\0" * (-len(chunk) % 4)
    total = 12 + 8 + len(js) + (8 + len(chunk) if chunk else 0)
    with open(path, "wb") as f:
        f.write(b"glTF" + struct.pack("<II", 2, total) + struct.pack("<I", len(js)) + b"JSON" + js)
        if chunk:
            f.write(struct.pack("<I", len(chunk)) + b"BIN\0" + chunk)


def instancer_group():
    """Geometry Nodes: each point becomes an instance of the object in the modifier's input,
    rotated and scaled by the point's `verdant_rotation` and `verdant_scale`."""
    group = bpy.data.node_groups.new("verdant instances", "GeometryNodeTree")
    group.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    group.interface.new_socket("Object", in_out="INPUT", socket_type="NodeSocketObject")
    group.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    n = group.nodes
    gin, gout = n.new("NodeGroupInput"), n.new("NodeGroupOutput")
    info = n.new("GeometryNodeObjectInfo")
    info.transform_space = "RELATIVE"
    info.inputs["As Instance"].default_value = True
    rot = n.new("GeometryNodeInputNamedAttribute")
    rot.data_type = "QUATERNION"
    rot.inputs["Name"].default_value = "verdant_rotation"
    scale = n.new("GeometryNodeInputNamedAttribute")
    scale.data_type = "FLOAT_VECTOR"
    scale.inputs["Name"].default_value = "verdant_scale"
    inst = n.new("GeometryNodeInstanceOnPoints")
    link = group.links.new
    link(gin.outputs[1], info.inputs["Object"])
    link(gin.outputs[0], inst.inputs["Points"])
    link(info.outputs["Geometry"], inst.inputs["Instance"])
    link(rot.outputs["Attribute"], inst.inputs["Rotation"])
    link(scale.outputs["Attribute"], inst.inputs["Scale"])
    link(inst.outputs["Instances"], gout.inputs[0])
    return group


def to_blender(v):
    """glTF (x, y, z), +Y up → Blender (x, −z, y), +Z up."""
    return np.stack([v[:, 0], -v[:, 2], v[:, 1]], axis=1)


def build(scene_dir):
    started = time.time()
    glb = os.path.join(scene_dir, "scene.glb")
    doc, chunk, buffers = read_glb(glb)
    groups = instances_by_mesh(doc, buffers)
    stripped, proto_names = without_instances(doc)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "scene_without_instances.glb")
        write_glb(path, stripped, chunk)
        bpy.ops.import_scene.gltf(filepath=path)
    group = instancer_group()
    collection = bpy.data.collections.new("verdant instances")
    bpy.context.scene.collection.children.link(collection)
    per_mesh = {}
    for m, (t, q, s) in sorted(groups.items()):
        proto = bpy.data.objects[proto_names[m]]
        proto.hide_viewport = True
        proto.hide_render = True
        name = doc["meshes"][m].get("name") or f"mesh{m}"
        me = bpy.data.meshes.new(f"{name}_points")
        me.vertices.add(len(t))
        me.vertices.foreach_set("co", to_blender(t).astype(np.float32).ravel())
        # Blender quaternions are (w, x, y, z); the axis change turns the vector part like a position
        wxyz = np.stack([q[:, 3], q[:, 0], -q[:, 2], q[:, 1]], axis=1)
        me.attributes.new("verdant_rotation", "QUATERNION", "POINT").data.foreach_set("value", wxyz.astype(np.float32).ravel())
        sb = np.stack([s[:, 0], s[:, 2], s[:, 1]], axis=1)
        me.attributes.new("verdant_scale", "FLOAT_VECTOR", "POINT").data.foreach_set("vector", sb.astype(np.float32).ravel())
        obj = bpy.data.objects.new(f"{name}_instances", me)
        collection.objects.link(obj)
        mod = obj.modifiers.new("instances", "NODES")
        mod.node_group = group
        key = group.interface.items_tree["Object"].identifier
        mod[key] = proto
        per_mesh[name] = len(t)
    return time.time() - started, per_mesh


def check(scene_dir, per_mesh):
    """Evaluated instances against what manifest.json says the first view draws, and a sample of them
    against the placement tables' rows at their positions (position and frame); problems."""
    problems = []
    manifest = json.load(open(os.path.join(scene_dir, "manifest.json")))
    species = manifest.get("scatter", {}).get("species", [])
    view = (manifest.get("view") or {}).get("views", [{}])[0]
    want = sum(s.get("drawn", 0) for s in view.get("species", []))
    depsgraph = bpy.context.evaluated_depsgraph_get()
    positions, frames = [], []
    for inst in depsgraph.object_instances:
        if inst.is_instance and inst.object.name.startswith(PROTO_PREFIX):
            m = inst.matrix_world
            positions.append(tuple(m.translation))
            frames.append([[m[r][c] for c in range(3)] for r in range(3)])
    if len(positions) != want or sum(per_mesh.values()) != want:
        problems.append(f"{len(positions)} instances evaluated, {sum(per_mesh.values())} points, the first view draws {want}")
    # every table row, in Blender axes, with its frame
    rows_p, rows_f = [], []
    c = np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])
    for s in species:
        for r in table_rows(os.path.join(scene_dir, s["table"])):
            rows_p.append((float(r["x"]), -float(r["z"]), float(r["y"])))
            x, y, z, w = (float(r[k]) for k in ("qx", "qy", "qz", "qw"))
            sc = np.array([float(r[k]) for k in ("sx", "sy", "sz")])
            rot = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
            # a model vertex v (glTF) must land at C·(R(q)·S·v + t), C the axis change
            rows_f.append(c @ rot @ np.diag(sc) @ c.T)
    table = np.array(rows_p) if rows_p else np.zeros((0, 3))
    # a sample of Blender's instances: each stands where a table row is, turned and scaled like it
    for k in range(0, len(positions), max(1, len(positions) // 200)):
        p = np.array(positions[k])
        if len(table) == 0:
            problems.append("instances but no placement rows")
            break
        j = int(np.argmin(np.abs(table - p).max(axis=1)))
        if np.abs(table[j] - p).max() > 1e-2:
            problems.append(f"an instance at {tuple(p)} (Blender axes) is at no table row's position")
            break
        if np.abs(np.array(frames[k]) - rows_f[j]).max() > 1e-3:
            problems.append(f"the instance at {tuple(p)} is turned or scaled unlike its table row")
            break
    return problems


def render_view(scene_dir, out_png, width=480, engine="CYCLES", samples=16):
    """Renders the first [[view]] of manifest.json (its eye, direction and vertical field of view, at
    `width` pixels across with the view's aspect) under a sun and a sky-coloured world, to
    `out_png`; returns the seconds it took."""
    from mathutils import Vector

    started = time.time()
    manifest = json.load(open(os.path.join(scene_dir, "manifest.json")))
    cam = manifest["view"]["views"][0]["camera"]
    scene = bpy.context.scene
    data = bpy.data.cameras.new("verdant_view")
    data.sensor_fit = "VERTICAL"
    data.angle_y = np.radians(cam["fov_y_deg"])
    data.clip_start = 0.1
    data.clip_end = 1e6
    obj = bpy.data.objects.new("verdant_view", data)
    scene.collection.objects.link(obj)
    obj.location = Vector(to_blender(np.array([cam["eye"]], dtype=float))[0])
    forward = Vector(to_blender(np.array([cam["forward"]], dtype=float))[0])
    obj.rotation_mode = "QUATERNION"
    obj.rotation_quaternion = forward.to_track_quat("-Z", "Y")
    scene.camera = obj
    sun = bpy.data.objects.new("verdant_sun", bpy.data.lights.new("verdant_sun", "SUN"))
    sun.data.energy = 3.0
    sun.rotation_euler = (np.radians(40.0), 0.0, np.radians(30.0))
    scene.collection.objects.link(sun)
    world = bpy.data.worlds.new("verdant_sky")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.55, 0.7, 0.9, 1.0)
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 1.0
    scene.world = world
    w, h = cam["size_px"]
    scene.render.resolution_x = width
    scene.render.resolution_y = max(1, round(width * h / w))
    scene.render.resolution_percentage = 100
    scene.render.engine = engine
    if engine == "CYCLES":
        scene.cycles.device = "CPU"
        scene.cycles.samples = samples
        scene.cycles.use_denoising = False
    scene.view_settings.view_transform = "Standard"
    scene.render.image_settings.file_format = "PNG"
    scene.render.filepath = os.path.abspath(out_png)
    bpy.ops.render.render(write_still=True)
    return time.time() - started


def frame_stats(png):
    """What a rendered frame shows where it is not the sky (the top-left pixel's colour), as
    scripts/engines/frame_stats.js measures it for three.js and Babylon: the share covered, and of
    the covered pixels the dark (luminance < 0.08), green-leading and snow-white shares."""
    img = bpy.data.images.load(os.path.abspath(png))
    w, h = img.size
    px = (np.array(img.pixels[:], dtype=np.float32).reshape(h, w, 4)[:, :, :3] * 255.0).round()
    bpy.data.images.remove(img)
    sky = px[h - 1, 0]  # rows run bottom-up: the last is the top
    covered = np.abs(px - sky).sum(axis=2) >= 12
    n = max(int(covered.sum()), 1)
    c = px[covered]
    lum = 0.2126 * c[:, 0] + 0.7152 * c[:, 1] + 0.0722 * c[:, 2]
    green = (c[:, 1] > c[:, 0]) & (c[:, 1] > c[:, 2])
    white = (c.min(axis=1) > 0.7 * 255) & (c.max(axis=1) - c.min(axis=1) < 0.12 * 255)
    return {
        "covered": covered.sum() / (w * h),
        "dark": (lum < 0.08 * 255).sum() / n,
        "green": green.sum() / n,
        "white": white.sum() / n,
    }


def frame_summary(png):
    s = frame_stats(png)
    return ", ".join(f"{k} {100 * v:.0f} %" for k, v in s.items())


def rendered_problems(scene_dir, png):
    """What a person must see in the first view: the scene (not an empty or black frame), its snow
    when the preset has [snow], green ground cover when it has grass and no snow."""
    manifest = json.load(open(os.path.join(scene_dir, "manifest.json")))
    s = frame_stats(png)
    problems = []
    if s["covered"] < 0.2:
        problems.append(f"only {100 * s['covered']:.0f} % of the frame shows the scene")
    if s["dark"] > 0.2:
        problems.append(f"{100 * s['dark']:.0f} % of what is shown is dark")
    if manifest.get("snow") and s["white"] < 0.1:
        problems.append(f"a [snow] scene with {100 * s['white']:.0f} % of it snow-white")
    kinds = {p.get("look") for p in manifest.get("plants", [])}
    if not manifest.get("snow") and "grass" in kinds and s["green"] < 0.25:
        problems.append(f"a scene with grass, green leading on only {100 * s['green']:.0f} % of it")
    return problems


def main(argv):
    if not argv or argv[0].startswith("-"):
        print(__doc__)
        return 2
    scene_dir = argv[0]
    seconds, per_mesh = build(scene_dir)
    objects = len(bpy.data.objects)
    print(f"blender_import {os.path.basename(os.path.normpath(scene_dir))}: {seconds:.1f} s, {objects} objects, "
          f"{sum(per_mesh.values())} instances of {len(per_mesh)} meshes (" + ", ".join(f"{k} {v}" for k, v in per_mesh.items()) + ")")
    status = 0
    if "--check" in argv:
        problems = check(scene_dir, per_mesh)
        for p in problems:
            print(f"FAIL {p}")
        status = 1 if problems else 0
        if not problems:
            print("ok   every instance the view draws is an instance in Blender's evaluated scene, where its table row says")
    if "--render" in argv:
        out = argv[argv.index("--render") + 1]
        seconds = render_view(scene_dir, out)
        problems = rendered_problems(scene_dir, out)
        for p in problems:
            print(f"FAIL render: {p}")
        status = 1 if problems else status
        print(f"{'FAIL' if problems else 'ok  '} rendered the first view to {out} in {seconds:.1f} s: {frame_summary(out)}")
    if "--save" in argv:
        out = argv[argv.index("--save") + 1]
        bpy.ops.wm.save_as_mainfile(filepath=os.path.abspath(out))
        print(f"wrote {out}")
    return status


if __name__ == "__main__":
    args = sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else sys.argv[1:]
    sys.exit(main(args))
