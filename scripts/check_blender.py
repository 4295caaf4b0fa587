"""Import species files into Blender (the PyPI `bpy` module) and check what a person sees there.

    python check_blender.py [--summary-tsv FILE] FILE.glb...

Blender's glTF importer does not know MSFT_lod. A chain file must still show exactly one level: the
mesh objects visible in the view layer after the import are the default glTF scene's mesh nodes,
nothing else (the coarser levels live in a second glTF scene, which Blender puts in another
Blender scene or an excluded collection; nodes of no scene would land, visible, in "Orphan Nodes").
A file without MSFT_lod (a flower species' variants) must show exactly its default scene's mesh
nodes too. Materials must not be repeated: Blender copies a material that a file holds twice as `name.001`,
so the imported material count must equal the file's distinct material count and no name may
carry such a suffix. Exits 1 on any failure.
"""

import json
import re
import struct
import sys
import time

import bpy


def gltf_json(path):
    with open(path, "rb") as f:
        data = f.read()
    if data[:4] != b"glTF":
        raise ValueError(f"{path}: not a GLB file")
    (json_len,) = struct.unpack_from("<I", data, 12)
    return json.loads(data[20 : 20 + json_len])


def default_scene_meshes(doc):
    """Mesh nodes under the default scene's roots (what a viewer without MSFT_lod shows)."""
    scene = doc["scenes"][doc.get("scene", 0)]
    stack, count = list(scene["nodes"]), 0
    while stack:
        node = doc["nodes"][stack.pop()]
        count += "mesh" in node
        stack.extend(node.get("children", []))
    return count


def check(path):
    doc = gltf_json(path)
    problems = []
    chain = "MSFT_lod" in doc.get("extensionsUsed", [])
    want_visible = default_scene_meshes(doc)
    lod_levels = sum(len(n.get("extensions", {}).get("MSFT_lod", {}).get("ids", [])) for n in doc["nodes"])
    materials = doc.get("materials", [])
    distinct = len({json.dumps(m, sort_keys=True) for m in materials})
    if distinct != len(materials):
        problems.append(f"the file holds {len(materials)} materials, only {distinct} distinct")

    # both ways the importer can place glTF scenes: as collections (orphan nodes then go into an
    # excluded collection) or as Blender scenes (orphan nodes then stay visible)
    seconds = 0.0
    for as_collection in (True, False):
        bpy.ops.wm.read_factory_settings(use_empty=True)
        t = time.time()
        result = bpy.ops.import_scene.gltf(filepath=path, import_scene_as_collection=as_collection)
        seconds += time.time() - t
        if "FINISHED" not in result:
            problems.append(f"import failed: {result}")
        visible = [o.name for o in bpy.context.view_layer.objects if o.type == "MESH" and o.visible_get()]
        if len(visible) != want_visible:
            problems.append(
                f"{len(visible)} mesh objects visible (import_scene_as_collection={as_collection}), "
                f"the default scene has {want_visible}: {visible[:8]}"
            )
    all_meshes = [o.name for o in bpy.data.objects if o.type == "MESH"]
    names = sorted(m.name for m in bpy.data.materials)
    copies = [n for n in names if re.search(r"\.\d{3}$", n)]
    if copies:
        problems.append(f"repeated materials imported as copies: {copies}")
    if len(names) != distinct:
        problems.append(f"{len(names)} materials in Blender, {distinct} in the file: {names}")
    row = {
        "file": path,
        "visible": len(visible),
        "objects": len(all_meshes),
        "levels": lod_levels if chain else "-",
        "materials": len(names),
        "seconds": seconds,
        "problems": problems,
    }
    return row


def main(argv):
    summary = None
    if argv[:1] == ["--summary-tsv"]:
        summary, argv = argv[1], argv[2:]
    if not argv:
        print(__doc__)
        return 2
    failed = 0
    print(f"Blender {bpy.app.version_string}: importing {len(argv)} species files")
    print(f"{'file':<60} {'visible':>7} {'mesh objects':>12} {'lod levels':>10} {'materials':>9} {'s':>6}  result")
    rows = []
    for path in argv:
        try:
            row = check(path)
        except Exception as e:  # a file the importer cannot read is a failure, not a crash of the check
            row = {"file": path, "visible": "-", "objects": "-", "levels": "-", "materials": "-", "seconds": 0.0, "problems": [f"{type(e).__name__}: {e}"]}
        rows.append(row)
        status = "ok" if not row["problems"] else "FAIL: " + "; ".join(row["problems"])
        failed += bool(row["problems"])
        short = path if len(path) <= 60 else "…" + path[-59:]
        print(f"{short:<60} {row['visible']:>7} {row['objects']:>12} {row['levels']:>10} {row['materials']:>9} {row['seconds']:>6.2f}  {status}")
    if summary:
        with open(summary, "a") as f:
            for row in rows:
                f.write(f"{row['file']}\t{'ok' if not row['problems'] else 'FAIL'}\t{row['visible']}\t{row['objects']}\n")
    print(f"{len(rows) - failed} of {len(rows)} species files show one level and no repeated material in Blender")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
