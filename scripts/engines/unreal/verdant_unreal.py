"""Imports a verdant scene folder (out/<scene>/) into the open level of Unreal Engine 5.

Run it in the editor (Tools > Execute Python Script, or the Output Log's Python console):

    py "scripts/engines/unreal/verdant_unreal.py" "D:/out/demo"  [--dest /Game/Verdant/demo] [--no-terrain]

What it makes (README.md, "Engines"):
- the terrain: terrain/terrain.glb imported through the glTF importer, one StaticMeshActor per
  chunk (the meshes are in world space);
- per species and built variant, one Static Mesh whose LODs are the chain's level files (LOD k
  from `<species>_v<v>_LOD<k>.glb`) with verdant's screen sizes (LODScreenSize[k] =
  manifest.json plants[].lods[k].screen_size: the bounding sphere's diameter over the screen
  height at level k's switch distance, Unreal's own measure), and one Foliage Type for it whose
  cull distance is the species' cull distance of the first view (times the variant's mean
  instance scale: verdant's switch and cull distances scale with each instance);
- every row of placements/<species>.csv (or .bin) as a foliage instance of its variant's type.

glTF is right-handed, +Y up, metres; Unreal left-handed, +Z up, centimetres. Unreal's glTF
importer maps a point (x, y, z) to (x, z, y) * 100 and a rotation quaternion (x, y, z, w) to
(-x, -z, -y, w) (GLTFCore ConvertVec3 / ConvertQuat); an instance's transform M becomes
C M C^-1 with C that mapping, which is what `gltf_to_unreal` returns, so each instance lands on
the mesh the importer made exactly where scene.glb draws it. scripts/check_engine_scripts.py checks
that conversion on every table row of the built scenes and that every Unreal name used here
exists in the UE 5.6 Python API (PyPI unreal-stub).

The reading and converting part is plain Python (no `unreal` import), so it runs and is tested
outside the editor: `python verdant_unreal.py --plan out/demo` prints what would be made.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import struct
import sys
from dataclasses import dataclass, field
from typing import Any, Callable

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]

# centimetres per metre (the glTF importer's default ImportScale)
UNREAL_UNITS_PER_METRE = 100.0


@dataclass
class Row:
    """One placement table row: glTF position (m), rotation (x, y, z, w), scale, tile, variant."""

    position: Vec3
    rotation: Quat
    scale: Vec3
    tile: int
    variant: int


@dataclass
class Level:
    file: str
    mesh: str
    screen_size: float
    triangles: int


@dataclass
class FoliagePlan:
    """One Static Mesh with LODs and its Foliage Type: a species' built variant."""

    species: str
    variant: int
    levels: list[Level]
    # centimetres; 0: never culled
    cull_distance_cm: int
    # Unreal transforms: (location cm, rotation quaternion, scale)
    transforms: list[tuple[Vec3, Quat, Vec3]] = field(default_factory=list)


def read_manifest(scene_dir: str) -> dict[str, Any]:
    with open(os.path.join(scene_dir, "manifest.json"), encoding="utf-8") as f:
        return json.load(f)


def read_table(path: str) -> list[Row]:
    """The rows of a placement table, CSV (x,y,z,qx,qy,qz,qw,sx,sy,sz,yaw_deg,tile,variant) or
    binary (`VPLT`, version 1, u64 rows, then column arrays: f64 positions, f32 rotations and
    scales and yaw, u32 tiles and variants; src/export/table_bin.rs)."""
    if path.endswith(".bin"):
        return _read_binary_table(path)
    rows = []
    with open(path, newline="", encoding="utf-8") as f:
        reader = csv.reader(f)
        next(reader, None)
        for c in reader:
            if len(c) < 13:
                continue
            v = [float(x) for x in c[:10]]
            rows.append(Row((v[0], v[1], v[2]), (v[3], v[4], v[5], v[6]), (v[7], v[8], v[9]), int(c[11]), int(c[12])))
    return rows


def _read_binary_table(path: str) -> list[Row]:
    with open(path, "rb") as f:
        data = f.read()
    if data[:4] != b"VPLT" or struct.unpack_from("<I", data, 4)[0] != 1:
        raise ValueError(f"{path} is not a version 1 binary placement table")
    n = struct.unpack_from("<Q", data, 8)[0]
    at = 16
    pos = struct.unpack_from(f"<{3 * n}d", data, at)
    at += 24 * n
    rot = struct.unpack_from(f"<{4 * n}f", data, at)
    at += 16 * n
    scl = struct.unpack_from(f"<{3 * n}f", data, at)
    at += 12 * n + 4 * n  # and the yaw column, inside the rotation already
    tiles = struct.unpack_from(f"<{n}I", data, at)
    at += 4 * n
    variants = struct.unpack_from(f"<{n}I", data, at)
    return [
        Row(
            (pos[3 * i], pos[3 * i + 1], pos[3 * i + 2]),
            (rot[4 * i], rot[4 * i + 1], rot[4 * i + 2], rot[4 * i + 3]),
            (scl[3 * i], scl[3 * i + 1], scl[3 * i + 2]),
            tiles[i],
            variants[i],
        )
        for i in range(n)
    ]


def gltf_to_unreal(position: Vec3, rotation: Quat, scale: Vec3) -> tuple[Vec3, Quat, Vec3]:
    """An instance's glTF translation, rotation and scale as Unreal's (the importer's mapping C:
    (x, y, z) -> (x, z, y) * 100; the transform becomes C M C^-1)."""
    x, y, z = position
    qx, qy, qz, qw = rotation
    sx, sy, sz = scale
    u = UNREAL_UNITS_PER_METRE
    return (x * u, z * u, y * u), (-qx, -qz, -qy, qw), (sx, sz, sy)


def plan(scene_dir: str, read: Callable[[str], list[Row]] = read_table) -> list[FoliagePlan]:
    """What the import makes for the scene folder: per species and built variant, its levels,
    cull distance and every instance's Unreal transform (`read` reads a table's rows)."""
    manifest = read_manifest(scene_dir)
    view = manifest.get("view", {})
    chains = view.get("chains", {})
    views = view.get("views", [])
    first = views[0] if views else {}
    # screen size per level file, as the plants stage reported it
    screen: dict[str, float] = {}
    for p in manifest.get("plants", []):
        for lod in p.get("lods", []):
            screen[lod["file"]] = float(lod.get("screen_size", 1.0))
    plans = []
    for entry in manifest.get("scatter", {}).get("species", []):
        name = entry["name"]
        chain = chains.get(name)
        if chain is None:
            continue
        cull_m = 0.0
        for s in first.get("species", []):
            if s.get("name") == name and s.get("cull"):
                cull_m = float(s["cull"]["distance_m"])
        variants = chain.get("variants", [])
        pick = chain.get("pick", list(range(len(variants))))
        groups: dict[int, list[Row]] = {}
        for row in read(os.path.join(scene_dir, entry["table"])):
            built = pick[row.variant] if row.variant < len(pick) else row.variant
            if built >= len(variants):
                raise ValueError(f"{entry['table']}: a row names variant {row.variant} of {len(variants)}")
            groups.setdefault(built, []).append(row)
        for built in sorted(groups):
            rows = groups[built]
            levels = [
                Level(lv["file"], lv["mesh"], screen.get(lv["file"], 1.0 if k == 0 else 0.0), int(lv["triangles"]))
                for k, lv in enumerate(variants[built])
            ]
            mean_scale = sum(r.scale[1] for r in rows) / len(rows)
            cull_cm = int(round(cull_m * mean_scale * UNREAL_UNITS_PER_METRE)) if cull_m > 0 else 0
            plans.append(
                FoliagePlan(
                    name,
                    built,
                    levels,
                    min(cull_cm, 2**31 - 1),
                    [gltf_to_unreal(r.position, r.rotation, r.scale) for r in rows],
                )
            )
    return plans


class UnrealScene:
    """The editor side: imports the files and places the instances (needs the `unreal` module)."""

    def __init__(self, scene_dir: str, dest: str) -> None:
        import unreal  # only inside the editor

        self.ue = unreal
        self.scene_dir = scene_dir
        self.dest = dest.rstrip("/")
        self.tools = unreal.AssetToolsHelpers.get_asset_tools()
        self.meshes = unreal.get_editor_subsystem(unreal.StaticMeshEditorSubsystem)
        self.actors = unreal.get_editor_subsystem(unreal.EditorActorSubsystem)
        self.imported: dict[str, list[Any]] = {}

    def import_file(self, rel: str, folder: str) -> list[Any]:
        """The Static Meshes the glTF importer makes of one file (each file imported once)."""
        if rel in self.imported:
            return self.imported[rel]
        ue = self.ue
        task = ue.AssetImportTask()
        task.set_editor_property("filename", os.path.join(self.scene_dir, rel))
        task.set_editor_property("destination_path", f"{self.dest}/{folder}")
        task.set_editor_property("automated", True)
        task.set_editor_property("replace_existing", True)
        task.set_editor_property("save", False)
        self.tools.import_asset_tasks([task])
        found = []
        for path in task.get_editor_property("imported_object_paths"):
            asset = ue.EditorAssetLibrary.load_asset(path)
            if isinstance(asset, ue.StaticMesh):
                found.append(asset)
        if not found:
            ue.log_warning(f"verdant: {rel} gave no Static Mesh")
        self.imported[rel] = found
        return found

    def level_mesh(self, level: Level, folder: str) -> Any:
        meshes = self.import_file(level.file, folder)
        for m in meshes:
            if m.get_name() == level.mesh or m.get_name().endswith("_" + level.mesh):
                return m
        return meshes[0] if meshes else None

    def foliage(self, p: FoliagePlan) -> int:
        """The variant's Static Mesh with its LODs, its Foliage Type and instances; returns the
        instance count placed."""
        ue = self.ue
        folder = f"{p.species}/v{p.variant}"
        base = self.level_mesh(p.levels[0], folder)
        if base is None:
            return 0
        for k, level in enumerate(p.levels[1:], start=1):
            mesh = self.level_mesh(level, folder)
            if mesh is not None:
                self.meshes.set_lod_from_static_mesh(base, k, mesh, 0, True)
        base.set_editor_property("auto_compute_lod_screen_size", False)
        self.meshes.set_lod_screen_sizes(base, [lv.screen_size for lv in p.levels])
        foliage_type = self.tools.create_asset(
            f"FT_{p.species}_v{p.variant}",
            f"{self.dest}/{folder}",
            ue.FoliageType_InstancedStaticMesh,
            ue.FoliageType_InstancedStaticMeshFactory(),
        )
        foliage_type.set_editor_property("mesh", base)
        if p.cull_distance_cm > 0:
            cull = ue.Int32Interval()
            cull.set_editor_property("min", int(p.cull_distance_cm * 0.9))
            cull.set_editor_property("max", p.cull_distance_cm)
            foliage_type.set_editor_property("cull_distance", cull)
        transforms = []
        for (loc, q, s) in p.transforms:
            t = ue.Transform()
            t.translation = ue.Vector(*loc)
            t.rotation = ue.Quat(*q)
            t.scale3d = ue.Vector(*s)
            transforms.append(t)
        world = ue.get_editor_subsystem(ue.UnrealEditorSubsystem).get_editor_world()
        ue.InstancedFoliageActor.add_instances(world, foliage_type, transforms)
        return len(transforms)

    def terrain(self) -> int:
        """terrain/terrain.glb as one StaticMeshActor per chunk at the origin (world-space meshes)."""
        ue = self.ue
        made = 0
        for mesh in self.import_file("terrain/terrain.glb", "terrain"):
            actor = self.actors.spawn_actor_from_class(ue.StaticMeshActor, ue.Vector(0.0, 0.0, 0.0))
            actor.set_actor_label(mesh.get_name())
            actor.static_mesh_component.set_static_mesh(mesh)
            made += 1
        return made


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scene_dir", help="a verdant scene folder (holding manifest.json)")
    ap.add_argument("--dest", default=None, help="content folder (default /Game/Verdant/<scene>)")
    ap.add_argument("--no-terrain", action="store_true", help="leave the terrain out")
    ap.add_argument("--plan", action="store_true", help="print what would be made and stop (no editor needed)")
    a = ap.parse_args(argv)
    plans = plan(a.scene_dir)
    if a.plan:
        for p in plans:
            sizes = ", ".join(f"{lv.screen_size:.4f}" for lv in p.levels)
            print(
                f"{p.species} v{p.variant}: {len(p.levels)} LODs (screen sizes {sizes}), "
                f"cull {p.cull_distance_cm} cm, {len(p.transforms)} instances"
            )
        return 0
    name = os.path.basename(os.path.normpath(a.scene_dir))
    ue_scene = UnrealScene(a.scene_dir, a.dest or f"/Game/Verdant/{name}")
    chunks = 0 if a.no_terrain else ue_scene.terrain()
    placed = sum(ue_scene.foliage(p) for p in plans)
    print(f"verdant: {chunks} terrain chunks, {placed} foliage instances of {len(plans)} foliage types")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
