#!/usr/bin/env python3
"""Re-import a verdant output (glb / gltf / obj) with independent loaders and cross-check it against the
JSON report the CLI wrote beside it; optionally check it is a closed solid and render a thumbnail.

  check_outputs.py FILE --report REPORT.json [--watertight] [--thumb THUMB.png] [--summary-tsv T.tsv]
  check_outputs.py --scene DIR [--thumb THUMB.png] [--summary-tsv T.tsv]
  check_outputs.py --placements DIR   only the scatter check of a built scene (below)
  check_outputs.py --tiles DIR        only the scene tiles' check of a built scene (below)
  check_outputs.py --self-test     check the checker on samples it makes itself (good and broken ones)

--scene checks a folder written by `verdant build` (out/<scene>/) against its manifest.json instead:
every file's size and sha256 (and that the manifest lists every file but manifest/report), each main
terrain file's triangle count (= terrain.output_triangles) and bounds, each LoD file (triangles >= the
level's surface triangles, bounds inside the terrain's, errors within the request, switch distances
increasing), a rendered thumbnail of the primary terrain file, and that preview.png is not blank.
When the manifest has a scatter section it also runs the placements check (--placements alone runs
only that): scene.glb's EXT_mesh_gpu_instancing nodes (FLOAT TRANSLATION/ROTATION/SCALE of equal
count, unit quaternions, the extension in extensionsUsed and extensionsRequired, one `<species>_tile_<t>`
child per tile under a root node named after the species) expanded with pygltflib and compared with
placements/<species>.csv (translations = the CSV's f64 rounded to f32, rotations and scales equal, in
tile order) and placements/<species>.json (count, per-tile counts and AABBs, min pair distance);
up to 20,000 instances per species ray-cast straight down onto scene.glb's terrain with trimesh
(|y - hit| <= 1e-3 m for the f32 glb, 1e-4 m for the f64 CSV); Poisson species at least min_spacing
apart over all instances, and every exclusion radius kept (scipy cKDTree, x/z).
With scene tiles (`[scene] tile`: scene_tiles.json and tiles/, --tiles alone runs only that): every
tile listed once with its bytes and square, nothing unlisted in tiles/, each terrain chunk in exactly
one tile, each chain's instances inside its tile's box and square, the index's counts, and every
species' instances over all tiles exactly its table's positions (as f32), read from the GLBs' own
JSON and binary chunks.

Loaders: trimesh (force='scene', process=False) for every format; for glTF also pygltflib with our own
accessor decoding, because trimesh 5.x ignores EXT_mesh_gpu_instancing / MSFT_lod and does not decode
normalized accessors. The two must agree unless the file uses one of those features, in which case the
pygltflib reading is the one checked. Exit 0 when every check passes, 1 with a message when one fails,
2 on bad usage.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

import numpy as np  # noqa: E402

# pyrender 0.1.45 still uses np.infty, which numpy 2 removed.
if not hasattr(np, "infty"):
    np.infty = np.inf  # type: ignore[attr-defined]

import trimesh  # noqa: E402

BOUNDS_REL_TOL = 1e-4
THUMB_SIZE = (512, 384)
BACKGROUND = (0.93, 0.95, 0.98)
REQUIRED_REPORT_KEYS = [
    "input", "width", "height", "encoding", "mode", "max_error_requested", "max_error", "rms_error",
    "vertices", "triangles", "seconds", "output",
]
REQUIRED_OUTPUT_KEYS = ["files", "meshes", "vertices", "triangles", "bounds"]


class CheckFailed(Exception):
    """One check did not hold; the message says which and with what numbers."""


@dataclass
class Geometry:
    """World-space triangles of everything drawn by a file's default scene."""
    positions: list[np.ndarray] = field(default_factory=list)  # (n, 3) float64 per drawn primitive
    faces: list[np.ndarray] = field(default_factory=list)      # (m, 3) int64 per drawn primitive
    notes: list[str] = field(default_factory=list)

    @property
    def vertex_count(self) -> int:
        return int(sum(len(p) for p in self.positions))

    @property
    def face_count(self) -> int:
        return int(sum(len(f) for f in self.faces))

    def bounds(self) -> np.ndarray:
        if not self.positions:
            raise CheckFailed("the file draws no triangles")
        stacked = np.concatenate(self.positions)
        return np.array([stacked.min(axis=0), stacked.max(axis=0)])

    def merged(self) -> trimesh.Trimesh:
        offsets = np.cumsum([0] + [len(p) for p in self.positions[:-1]])
        faces = np.concatenate([f + o for f, o in zip(self.faces, offsets)])
        return trimesh.Trimesh(np.concatenate(self.positions), faces, process=False)


# ----------------------------------------------------------------------------------------------- trimesh
def run_and_report(name, check, summary_tsv, n_fields):
    """Runs `check` (returning a summary line and `n_fields` table fields), prints OK/FAIL, appends
    'name<TAB>status<TAB>fields…' to `summary_tsv` when given, and returns the exit code."""
    fields = ["-"] * n_fields
    try:
        summary, *fields = check()
        status, code = "ok", 0
        print(f"OK    {summary}")
    except CheckFailed as e:
        status, code = "FAIL", 1
        print(f"FAIL  {name}: {e}", file=sys.stderr)
    except (OSError, ValueError, KeyError, TypeError) as e:
        status, code = "FAIL", 1
        print(f"FAIL  {name}: could not read/check ({type(e).__name__}: {e})", file=sys.stderr)
    if summary_tsv:
        with open(summary_tsv, "a") as f:
            f.write("\t".join([name, status, *map(str, fields)]) + "\n")
    return code


def load_with_trimesh(path: Path) -> Geometry:
    scene = trimesh.load(str(path), force="scene", process=False)
    geom = Geometry()
    for node in scene.graph.nodes_geometry:
        transform, geometry_name = scene.graph[node]
        mesh = scene.geometry[geometry_name]
        if not isinstance(mesh, trimesh.Trimesh):
            geom.notes.append(f"trimesh: skipped non-triangle geometry {geometry_name!r}")
            continue
        positions = trimesh.transform_points(np.asarray(mesh.vertices, dtype=np.float64), transform)
        geom.positions.append(positions)
        geom.faces.append(np.asarray(mesh.faces, dtype=np.int64))
    return geom


# --------------------------------------------------------------------------------------------- pygltflib
COMPONENT_DTYPES = {5120: "<i1", 5121: "<u1", 5122: "<i2", 5123: "<u2", 5125: "<u4", 5126: "<f4"}
TYPE_WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
UNDECODED_BY_TRIMESH = {"EXT_mesh_gpu_instancing", "MSFT_lod", "KHR_mesh_quantization"}


def gltf_buffers(gltf, path: Path) -> list[bytes]:
    import base64

    out = []
    for i, buf in enumerate(gltf.buffers):
        if buf.uri is None:
            blob = gltf.binary_blob()
            if blob is None:
                raise CheckFailed(f"buffer {i} has no uri and the file has no GLB binary chunk")
            out.append(bytes(blob))
        elif buf.uri.startswith("data:"):
            out.append(base64.b64decode(buf.uri.split(",", 1)[1]))
        else:
            from urllib.parse import unquote

            sibling = path.parent / unquote(buf.uri)
            if not sibling.is_file():
                raise CheckFailed(f"buffer {i} refers to {buf.uri!r}, but {sibling} does not exist")
            out.append(sibling.read_bytes())
        if len(out[-1]) < buf.byteLength:
            raise CheckFailed(f"buffer {i} is {len(out[-1])} bytes, shorter than its byteLength {buf.byteLength}")
    return out


def read_accessor(gltf, buffers: list[bytes], index: int) -> np.ndarray:
    """Decode accessor `index` to float64 (or int64 for integer data), applying stride, sparse and
    normalization; returns shape (count, width)."""
    acc = gltf.accessors[index]
    dtype = np.dtype(COMPONENT_DTYPES[acc.componentType])
    width = TYPE_WIDTHS[acc.type]
    if acc.bufferView is None:
        data = np.zeros((acc.count, width), dtype=dtype)
    else:
        view = gltf.bufferViews[acc.bufferView]
        start = (view.byteOffset or 0) + (acc.byteOffset or 0)
        stride = view.byteStride or dtype.itemsize * width
        needed = start + stride * (acc.count - 1) + dtype.itemsize * width if acc.count else start
        if needed > len(buffers[view.buffer]):
            raise CheckFailed(f"accessor {index} reads past the end of buffer {view.buffer}")
        data = np.ndarray((acc.count, width), dtype=dtype, buffer=buffers[view.buffer], offset=start,
                          strides=(stride, dtype.itemsize)).copy()
    if acc.sparse is not None and acc.sparse.count:
        sparse = acc.sparse
        idx_view = gltf.bufferViews[sparse.indices.bufferView]
        idx = np.frombuffer(buffers[idx_view.buffer], dtype=COMPONENT_DTYPES[sparse.indices.componentType],
                            count=sparse.count,
                            offset=(idx_view.byteOffset or 0) + (sparse.indices.byteOffset or 0))
        val_view = gltf.bufferViews[sparse.values.bufferView]
        vals = np.frombuffer(buffers[val_view.buffer], dtype=dtype, count=sparse.count * width,
                             offset=(val_view.byteOffset or 0) + (sparse.values.byteOffset or 0))
        data[idx.astype(np.int64)] = vals.reshape(-1, width)
    if dtype.kind == "f":
        return data.astype(np.float64)
    if acc.normalized:
        info = np.iinfo(dtype)
        return np.maximum(data.astype(np.float64) / info.max, -1.0)
    return data.astype(np.int64) if acc.type == "SCALAR" else data.astype(np.float64)


def quat_to_matrix(q) -> np.ndarray:
    x, y, z, w = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def trs_matrix(t=None, r=None, s=None) -> np.ndarray:
    m = np.eye(4)
    rot = quat_to_matrix(r) if r is not None else np.eye(3)
    scale = np.asarray(s, dtype=np.float64) if s is not None else np.ones(3)
    m[:3, :3] = rot * scale[None, :]
    if t is not None:
        m[:3, 3] = t
    return m


def node_matrix(node) -> np.ndarray:
    if node.matrix is not None and list(node.matrix) != [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]:
        return np.asarray(node.matrix, dtype=np.float64).reshape(4, 4).T  # glTF stores column-major
    return trs_matrix(node.translation, node.rotation, node.scale)


def triangles_of(mode: int, indices: np.ndarray) -> np.ndarray | None:
    if mode == 4:
        if len(indices) % 3:
            raise CheckFailed(f"a TRIANGLES primitive has {len(indices)} indices, not a multiple of 3")
        return indices.reshape(-1, 3)
    if mode == 5:  # strip: alternate winding
        tris = [(indices[i], indices[i + 1], indices[i + 2]) if i % 2 == 0 else
                (indices[i + 1], indices[i], indices[i + 2]) for i in range(len(indices) - 2)]
        return np.array(tris, dtype=np.int64).reshape(-1, 3)
    if mode == 6:  # fan
        tris = [(indices[0], indices[i], indices[i + 1]) for i in range(1, len(indices) - 1)]
        return np.array(tris, dtype=np.int64).reshape(-1, 3)
    return None  # points / lines: not triangles


def load_with_pygltflib(path: Path) -> tuple[Geometry, set[str], object]:
    import pygltflib

    gltf = pygltflib.GLTF2().load(str(path))
    buffers = gltf_buffers(gltf, path)
    used = set(gltf.extensionsUsed or [])
    geom = Geometry()
    if not gltf.scenes:
        raise CheckFailed("the glTF has no scenes, so nothing is drawn")
    scene = gltf.scenes[gltf.scene if gltf.scene is not None else 0]

    def instance_matrices(node) -> list[np.ndarray]:
        ext = (node.extensions or {}).get("EXT_mesh_gpu_instancing")
        if not ext:
            return [np.eye(4)]
        attrs = ext.get("attributes", {})
        arrays = {k: read_accessor(gltf, buffers, v) for k, v in attrs.items()}
        count = len(next(iter(arrays.values()))) if arrays else 0
        return [trs_matrix(arrays["TRANSLATION"][i] if "TRANSLATION" in arrays else None,
                           arrays["ROTATION"][i] if "ROTATION" in arrays else None,
                           arrays["SCALE"][i] if "SCALE" in arrays else None) for i in range(count)]

    def visit(node_index: int, parent: np.ndarray, depth: int) -> None:
        if depth > 256:
            raise CheckFailed("node hierarchy deeper than 256 (a cycle?)")
        node = gltf.nodes[node_index]
        world = parent @ node_matrix(node)
        if node.mesh is not None:
            for prim_index, prim in enumerate(gltf.meshes[node.mesh].primitives):
                if prim.attributes.POSITION is None:
                    raise CheckFailed(f"mesh {node.mesh} primitive {prim_index} has no POSITION")
                local = read_accessor(gltf, buffers, prim.attributes.POSITION)
                count = len(local)
                indices = (read_accessor(gltf, buffers, prim.indices).reshape(-1).astype(np.int64)
                           if prim.indices is not None else np.arange(count, dtype=np.int64))
                if len(indices) and (indices.min() < 0 or indices.max() >= count):
                    raise CheckFailed(f"mesh {node.mesh} primitive {prim_index}: index out of range "
                                      f"(max {indices.max()}, {count} vertices)")
                faces = triangles_of(prim.mode if prim.mode is not None else 4, indices)
                if faces is None:
                    geom.notes.append(f"mesh {node.mesh} primitive {prim_index}: mode {prim.mode} skipped")
                    continue
                homogeneous = np.hstack([local, np.ones((count, 1))])
                for inst in instance_matrices(node):
                    geom.positions.append((homogeneous @ (world @ inst).T)[:, :3])
                    geom.faces.append(faces)
        for child in node.children or []:
            visit(child, world, depth + 1)

    for root in scene.nodes or []:
        visit(root, np.eye(4), 0)
    return geom, used, gltf


# ------------------------------------------------------------------------------------------------- checks
def check_close(name: str, got, want, scale: float) -> None:
    got = np.asarray(got, dtype=np.float64)
    want = np.asarray(want, dtype=np.float64)
    tol = BOUNDS_REL_TOL * max(scale, 1e-9)
    if got.shape != want.shape or not np.all(np.abs(got - want) <= tol):
        raise CheckFailed(f"{name}: file has {np.round(got, 6).tolist()}, report says "
                          f"{np.round(want, 6).tolist()} (tolerance {tol:.3g})")


def obj_vertex_count(path: Path) -> int:
    with open(path, "rb") as f:
        return sum(1 for line in f if line.startswith(b"v ") or line.startswith(b"v\t"))


def check_report(report: dict, file_path: Path) -> list[str]:
    missing = [k for k in REQUIRED_REPORT_KEYS if k not in report]
    if missing:
        raise CheckFailed(f"report lacks keys {missing}")
    out = report["output"]
    missing = [k for k in REQUIRED_OUTPUT_KEYS if k not in out]
    if missing:
        raise CheckFailed(f"report 'output' lacks keys {missing}")
    facts = []
    if not (report["width"] > 0 and report["height"] > 0):
        raise CheckFailed(f"report size {report['width']}x{report['height']} is not positive")
    if not report["triangles"] > 0 or not report["vertices"] > 0:
        raise CheckFailed(f"report has {report['triangles']} triangles, {report['vertices']} vertices")
    if out["triangles"] < report["triangles"]:
        raise CheckFailed(f"output has {out['triangles']} triangles, fewer than the surface's {report['triangles']}")
    for key in ("decode", "mesh", "export", "total"):
        value = report["seconds"].get(key)
        if not isinstance(value, (int, float)) or value < 0 or not math.isfinite(value):
            raise CheckFailed(f"report seconds.{key} = {value!r} is not a non-negative number")
    max_err, rms = report["max_error"], report["rms_error"]
    if max_err is None or rms is None or not (0 <= rms <= max_err + 1e-9) or not math.isfinite(max_err):
        raise CheckFailed(f"report errors look wrong: rms_error {rms}, max_error {max_err}")
    requested = report["max_error_requested"]
    if report["mode"] == "tin" and not report.get("hit_triangle_limit", False):
        if requested is None:
            raise CheckFailed("tin mode report has no max_error_requested")
        if max_err > requested * (1 + 1e-9) + 1e-12:
            raise CheckFailed(f"max_error {max_err} exceeds the requested {requested}")
        facts.append(f"max_error {max_err:.4g} <= {requested:g}")
    else:
        facts.append(f"max_error {max_err:.4g} ({report['mode']}"
                     f"{', hit triangle limit' if report.get('hit_triangle_limit') else ''})")
    # the checked file must be one of the files the report lists, and all of those must exist
    listed = [Path(p) for p in out["files"]]
    if not any(p.name == file_path.name for p in listed):
        raise CheckFailed(f"report output.files {out['files']} does not list {file_path.name}")
    for p in listed:
        if not (p.exists() or (file_path.parent / p.name).exists()):
            raise CheckFailed(f"report lists {p}, which does not exist")
    return facts


def render_thumbnail(mesh: trimesh.Trimesh, bounds: np.ndarray, thumb: Path) -> float:
    """Render `mesh` from above at an angle; return the fraction of pixels that are not background."""
    import pyrender
    from PIL import Image

    lo, hi = bounds
    center = (lo + hi) / 2
    radius = max(float(np.linalg.norm(hi - lo)) / 2, 1e-6)
    # colour by height: green lowlands to pale rock, so relief reads in the thumbnail
    t = (mesh.vertices[:, 1] - lo[1]) / max(hi[1] - lo[1], 1e-9)
    low, high = np.array([70, 120, 60]), np.array([215, 205, 190])
    colors = (low[None, :] * (1 - t[:, None]) + high[None, :] * t[:, None]).astype(np.uint8)
    mesh = mesh.copy()
    mesh.visual = trimesh.visual.ColorVisuals(mesh, vertex_colors=colors)
    scene = pyrender.Scene(bg_color=[*BACKGROUND, 1.0], ambient_light=[0.2, 0.2, 0.2])
    scene.add(pyrender.Mesh.from_trimesh(mesh, smooth=False))

    def look_from(direction, distance):
        z = np.asarray(direction, dtype=np.float64)
        z /= np.linalg.norm(z)
        x = np.cross([0.0, 1.0, 0.0], z)
        x /= np.linalg.norm(x)
        y = np.cross(z, x)
        pose = np.eye(4)
        pose[:3, 0], pose[:3, 1], pose[:3, 2], pose[:3, 3] = x, y, z, center + z * distance
        return pose

    yfov = math.radians(45)
    distance = radius / math.sin(yfov / 2) * 0.9  # terrains are flat: the bounding sphere is loose
    camera = pyrender.PerspectiveCamera(yfov=yfov, aspectRatio=THUMB_SIZE[0] / THUMB_SIZE[1],
                                        znear=max(distance - radius * 1.5, distance * 1e-3),
                                        zfar=distance + radius * 1.5)
    scene.add(camera, pose=look_from([0.55, 1.0, 0.85], distance))
    scene.add(pyrender.DirectionalLight(color=np.ones(3), intensity=2.2), pose=look_from([-0.5, 1.0, 0.35], 1))
    renderer = pyrender.OffscreenRenderer(*THUMB_SIZE)
    try:
        color, _ = renderer.render(scene)
    finally:
        renderer.delete()
    thumb.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(color).save(thumb)
    pixels = color.reshape(-1, 3).astype(np.int16)
    if np.all(pixels == pixels[0]):
        raise CheckFailed(f"thumbnail {thumb} is a single colour {pixels[0].tolist()}")
    background = np.round(np.array(BACKGROUND) * 255).astype(np.int16)
    coverage = float(np.mean(np.abs(pixels - background).max(axis=1) > 3))
    if coverage < 0.01:
        raise CheckFailed(f"thumbnail {thumb} shows almost nothing ({coverage:.2%} of pixels not background)")
    return coverage


def check_file(args) -> tuple[str, int, int]:
    path = Path(args.file)
    if not path.is_file():
        raise CheckFailed(f"{path} does not exist")
    report = json.loads(Path(args.report).read_text())
    facts = check_report(report, path)
    out = report["output"]
    suffix = path.suffix.lower()

    tm_geom = load_with_trimesh(path)
    if suffix in (".glb", ".gltf"):
        geom, used, gltf = load_with_pygltflib(path)
        special = used & UNDECODED_BY_TRIMESH
        if special:
            facts.append(f"uses {sorted(special)}: pygltflib reading checked, trimesh's not")
        elif (tm_geom.face_count, tm_geom.vertex_count) != (geom.face_count, geom.vertex_count):
            raise CheckFailed(f"loaders disagree: trimesh {tm_geom.face_count} faces / {tm_geom.vertex_count} "
                              f"vertices, pygltflib {geom.face_count} / {geom.vertex_count}")
        elif tm_geom.positions:
            check_close("trimesh vs pygltflib bounds", tm_geom.bounds(), geom.bounds(),
                        float(np.abs(geom.bounds()).max()))
        vertex_count = geom.vertex_count
        mesh_counts = {len(gltf.meshes)}
    elif suffix == ".obj":
        geom = tm_geom
        vertex_count = obj_vertex_count(path)  # trimesh splits vertices by uv/normal on OBJ load
        mesh_counts = None
    else:
        raise CheckFailed(f"unsupported file type {suffix!r} (expected .glb, .gltf or .obj)")

    if geom.face_count != out["triangles"]:
        raise CheckFailed(f"file has {geom.face_count} triangles, report output.triangles says {out['triangles']}")
    if vertex_count != out["vertices"]:
        raise CheckFailed(f"file has {vertex_count} vertices, report output.vertices says {out['vertices']}")
    if mesh_counts is not None and out["meshes"] not in mesh_counts and out["meshes"] != len(geom.positions):
        raise CheckFailed(f"file has {sorted(mesh_counts)[0]} meshes ({len(geom.positions)} drawn primitives), "
                          f"report output.meshes says {out['meshes']}")
    for positions in geom.positions:
        if not np.all(np.isfinite(positions)):
            raise CheckFailed("some vertex positions are NaN or infinite")
    bounds = geom.bounds()
    want = np.array([out["bounds"]["min"], out["bounds"]["max"]], dtype=np.float64)
    scale = max(float(np.abs(want).max()), float(np.max(want[1] - want[0])))
    check_close("bounds", bounds, want, scale)

    merged = geom.merged()
    if args.watertight:
        extent = max(float(np.max(bounds[1] - bounds[0])), 1e-9)
        digits = max(0, math.ceil(-math.log10(extent * 1e-7)))
        merged.merge_vertices(digits_vertex=digits)
        if not merged.is_watertight:
            edges = trimesh.grouping.group_rows(merged.edges_sorted, require_count=1)
            raise CheckFailed(f"not watertight after merging by position: {len(edges)} open edges")
        if not merged.is_winding_consistent:
            raise CheckFailed("watertight but winding is inconsistent")
        volume = float(merged.volume)
        if not volume > 0:
            raise CheckFailed(f"watertight but volume {volume:.6g} is not positive (faces point inward?)")
        facts.append(f"watertight, volume {volume:.6g}")
    if args.thumb:
        coverage = render_thumbnail(merged, bounds, Path(args.thumb))
        facts.append(f"thumb {args.thumb} ({coverage:.0%} covered)")
    facts.extend(geom.notes)
    summary = (f"{geom.face_count} tris, {vertex_count} verts, {out['meshes']} meshes, bounds "
               f"{np.round(bounds[0], 3).tolist()}..{np.round(bounds[1], 3).tolist()}; " + "; ".join(facts))
    return summary, geom.face_count, vertex_count


# --------------------------------------------------------------------------------------------- self-test
def self_test() -> int:
    """Make small terrains in every format (plus a box, and an instanced, quantized glb that trimesh
    cannot read right), write reports for them, and check that good files pass and broken ones fail."""
    import tempfile
    import pygltflib

    def grid(n=17, cell=2.0, x0=0, z0=0) -> trimesh.Trimesh:
        i, j = np.meshgrid(np.arange(n) + x0, np.arange(n) + z0, indexing="xy")
        y = 10 * np.sin(i * cell / 9) * np.cos(j * cell / 7)
        v = np.stack([(i * cell).ravel(), y.ravel(), (j * cell).ravel()], 1)
        a = (np.arange(n - 1)[None, :] + n * np.arange(n - 1)[:, None]).ravel()
        f = np.concatenate([np.stack([a, a + n, a + 1], 1), np.stack([a + 1, a + n, a + n + 1], 1)])
        return trimesh.Trimesh(v, f, process=False)  # counter-clockwise seen from +Y

    def write_report(path: Path, files, meshes, verts, tris, bounds, mode="tin", **extra) -> Path:
        report = dict(input="self-test", width=17, height=17, encoding="gray16", mode=mode,
                      max_error_requested=1.0, max_error=0.5, rms_error=0.1, vertices=17 * 17, triangles=12,
                      seconds=dict(decode=0.0, mesh=0.0, export=0.0, total=0.0),
                      output=dict(files=[str(f) for f in files], meshes=meshes, vertices=verts, triangles=tris,
                                  bounds=dict(min=list(map(float, bounds[0])), max=list(map(float, bounds[1])))))
        report.update(extra)
        path.write_text(json.dumps(report))
        return path

    cases = []  # (name, file, report, watertight, thumb, expect_ok)
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        t = grid()
        t.export(d / "t.glb")
        good = write_report(d / "t.json", [d / "t.glb"], 1, len(t.vertices), len(t.faces), t.bounds)
        cases.append(("glb", d / "t.glb", good, False, d / "t.png", True))
        shifted = t.bounds.copy()
        shifted[1][1] += 0.5
        cases.append(("glb, wrong bounds", d / "t.glb", write_report(
            d / "t_bad.json", [d / "t.glb"], 1, len(t.vertices), len(t.faces), shifted), False, None, False))
        cases.append(("glb, wrong count", d / "t.glb", write_report(
            d / "t_cnt.json", [d / "t.glb"], 1, len(t.vertices), len(t.faces) + 1, t.bounds), False, None, False))
        cases.append(("glb, error over request", d / "t.glb", write_report(
            d / "t_err.json", [d / "t.glb"], 1, len(t.vertices), len(t.faces), t.bounds, max_error=1.5),
            False, None, False))
        cases.append(("open surface as solid", d / "t.glb", good, True, None, False))
        # chunks as .gltf + external .bin
        scene = trimesh.Scene()
        for k, (x0, z0) in enumerate([(0, 0), (8, 0), (0, 8), (8, 8)]):
            scene.add_geometry(grid(9, 2.0, x0, z0), geom_name=f"chunk{k}")
        for name, data in scene.export(file_type="gltf").items():
            (d / ("c.gltf" if name.endswith(".gltf") else name)).write_bytes(data)
        nv = sum(len(g.vertices) for g in scene.geometry.values())
        nf = sum(len(g.faces) for g in scene.geometry.values())
        cases.append(("gltf + bin", d / "c.gltf", write_report(
            d / "c.json", [d / "c.gltf"], 4, nv, nf, scene.bounds), False, None, True))
        # closed box
        box = trimesh.creation.box(extents=[32, 10, 32])
        box.export(d / "b.glb")
        cases.append(("watertight box", d / "b.glb", write_report(
            d / "b.json", [d / "b.glb"], 1, len(box.vertices), len(box.faces), box.bounds), True, None, True))
        box.invert()
        box.export(d / "inv.glb")
        cases.append(("inside-out box", d / "inv.glb", write_report(
            d / "inv.json", [d / "inv.glb"], 1, len(box.vertices), len(box.faces), box.bounds), True, None, False))
        # obj
        t.export(d / "g.obj")
        cases.append(("obj", d / "g.obj", write_report(
            d / "g.json", [d / "g.obj"], 1, len(t.vertices), len(t.faces), t.bounds, mode="grid",
            max_error=2.0), False, d / "g.png", True))
        # quad as normalized int16 positions (KHR_mesh_quantization), drawn 3 times by EXT_mesh_gpu_instancing
        q = np.array([[-1, 0, -1, 0], [1, 0, -1, 0], [1, 0, 1, 0], [-1, 0, 1, 0]]) * 32767
        idx = np.array([0, 3, 1, 1, 3, 2], dtype=np.uint16)
        tr = np.array([[0, 0, 0], [3, 1, 0], [0, 0, 3]], dtype=np.float32)
        blob = q.astype(np.int16).tobytes() + idx.tobytes() + b"\0" * 4 + tr.tobytes()
        gl = pygltflib.GLTF2(
            asset=pygltflib.Asset(version="2.0"), scene=0, scenes=[pygltflib.Scene(nodes=[0])],
            extensionsUsed=["EXT_mesh_gpu_instancing", "KHR_mesh_quantization"],
            extensionsRequired=["KHR_mesh_quantization"],
            nodes=[pygltflib.Node(mesh=0, scale=[10, 10, 10], extensions={
                "EXT_mesh_gpu_instancing": {"attributes": {"TRANSLATION": 2}}})],
            meshes=[pygltflib.Mesh(primitives=[pygltflib.Primitive(
                attributes=pygltflib.Attributes(POSITION=0), indices=1)])],
            buffers=[pygltflib.Buffer(byteLength=len(blob))],
            bufferViews=[pygltflib.BufferView(buffer=0, byteOffset=0, byteLength=32, byteStride=8, target=34962),
                         pygltflib.BufferView(buffer=0, byteOffset=32, byteLength=12, target=34963),
                         pygltflib.BufferView(buffer=0, byteOffset=48, byteLength=36)],
            accessors=[pygltflib.Accessor(bufferView=0, componentType=5122, normalized=True, count=4, type="VEC3",
                                          min=[-32767, 0, -32767], max=[32767, 0, 32767]),
                       pygltflib.Accessor(bufferView=1, componentType=5123, count=6, type="SCALAR", min=[0], max=[3]),
                       pygltflib.Accessor(bufferView=2, componentType=5126, count=3, type="VEC3",
                                          min=[0, 0, 0], max=[3, 1, 3])])
        gl.set_binary_blob(blob)
        gl.save_binary(str(d / "i.glb"))
        # node scale 10 applies after the instance translation: instances at 0, (30,10,0), (0,0,30)
        cases.append(("instanced + quantized", d / "i.glb", write_report(
            d / "i.json", [d / "i.glb"], 1, 12, 6, [[-10, 0, -10], [40, 10, 40]], mode="grid", triangles=2), False, None, True))

        wrong = 0
        for name, file, report, watertight, thumb, expect_ok in cases:
            args = argparse.Namespace(file=str(file), report=str(report), watertight=watertight,
                                      thumb=str(thumb) if thumb else None)
            try:
                check_file(args)
                ok, detail = True, "passed"
            except CheckFailed as e:
                ok, detail = False, f"failed: {e}"
            right = ok == expect_ok
            wrong += not right
            print(f"{'ok  ' if right else 'BAD '} self-test {name}: {detail}")
        for name, right, detail in (snow_self_test() + placement_self_test(d / "placements")
                                    + chunk_self_test(d / "chunks")):
            cases.append((name,))
            wrong += not right
            print(f"{'ok  ' if right else 'BAD '} self-test {name}: {detail}")
    print(f"self-test: {len(cases) - wrong} passed, {wrong} failed")
    return 1 if wrong else 0


# ------------------------------------------------------------------------------------------ scene mode
MESH_SUFFIXES = (".glb", ".gltf", ".obj")
SCENE_OWN_FILES = {"manifest.json", "report.json", "report.md"}


def load_geometry(path: Path) -> Geometry:
    """pygltflib for glTF (it decodes everything verdant may write), trimesh for OBJ."""
    if path.suffix.lower() in (".glb", ".gltf"):
        return load_with_pygltflib(path)[0]
    return load_with_trimesh(path)


def check_preview(png: Path, want_size) -> str:
    from PIL import Image

    with Image.open(png) as im:
        size = im.size
        pixels = np.asarray(im.convert("RGB")).reshape(-1, 3)
    if want_size is not None and tuple(size) != tuple(want_size):
        raise CheckFailed(f"{png.name} is {size[0]}x{size[1]} px, report says {want_size[0]}x{want_size[1]}")
    colours, counts = np.unique(pixels, axis=0, return_counts=True)
    if len(colours) < 16:
        raise CheckFailed(f"{png.name} has only {len(colours)} distinct colours: blank?")
    if counts.max() > 0.9 * len(pixels):
        raise CheckFailed(f"{png.name}: one colour {colours[counts.argmax()].tolist()} covers "
                          f"{counts.max() / len(pixels):.0%} of the pixels")
    return f"preview {size[0]}x{size[1]}, {len(colours)} colours"


def check_scene(scene_dir: Path, thumb: Path | None) -> tuple[str, int, int, str]:
    import hashlib

    manifest_path = scene_dir / "manifest.json"
    if not manifest_path.is_file():
        raise CheckFailed(f"{manifest_path} does not exist")
    manifest = json.loads(manifest_path.read_text())
    report_path = scene_dir / "report.json"
    report = json.loads(report_path.read_text()) if report_path.is_file() else None
    if report is None:
        raise CheckFailed(f"{report_path} does not exist")
    facts = []

    # every file: listed once, size and sha256 as on disk; nothing on disk unlisted
    listed = {}
    for entry in manifest.get("files", []):
        rel = entry["path"]
        if rel in listed:
            raise CheckFailed(f"manifest lists {rel} twice")
        listed[rel] = entry
        f = scene_dir / rel
        if not f.is_file():
            raise CheckFailed(f"manifest lists {rel}, which does not exist")
        data = f.read_bytes()
        if len(data) != entry["bytes"]:
            raise CheckFailed(f"{rel} is {len(data)} bytes, manifest says {entry['bytes']}")
        digest = hashlib.sha256(data).hexdigest()
        if digest != entry["sha256"]:
            raise CheckFailed(f"{rel} has sha256 {digest[:16]}…, manifest says {entry['sha256'][:16]}…")
    on_disk = {p.relative_to(scene_dir).as_posix() for p in scene_dir.rglob("*") if p.is_file()}
    unlisted = sorted(on_disk - set(listed) - SCENE_OWN_FILES)
    if unlisted:
        raise CheckFailed(f"files on disk the manifest does not list: {unlisted}")
    missing_own = sorted(SCENE_OWN_FILES - on_disk)
    if missing_own:
        raise CheckFailed(f"the scene folder lacks {missing_own}")
    facts.append(f"{len(listed)} files match their sha256")

    terrain = manifest.get("terrain")
    tris = verts = 0
    if terrain:
        want = np.array([terrain["bounds"]["min"], terrain["bounds"]["max"]], dtype=np.float64)
        scale = max(float(np.abs(want).max()), float(np.max(want[1] - want[0])))
        mains = [scene_dir / f for f in terrain["files"] if f.lower().endswith(MESH_SUFFIXES)]
        if not mains:
            raise CheckFailed(f"terrain.files {terrain['files']} has no mesh file")
        primary_geom = None
        for path in mains:
            geom = load_geometry(path)
            if geom.face_count != terrain["output_triangles"]:
                raise CheckFailed(f"{path.name} has {geom.face_count} triangles, manifest terrain.output_triangles "
                                  f"says {terrain['output_triangles']}")
            for positions in geom.positions:
                if not np.all(np.isfinite(positions)):
                    raise CheckFailed(f"{path.name}: some vertex positions are NaN or infinite")
            check_close(f"{path.name} bounds", geom.bounds(), want, scale)
            if primary_geom is None:
                primary_geom = geom
                tris, verts = geom.face_count, geom.vertex_count
        facts.append(f"{len(mains)} main file(s) with {terrain['output_triangles']} triangles")
        if terrain["width"] and terrain["cell_size_m"]:
            extent = (terrain["width"] - 1) * terrain["cell_size_m"]
            if abs((want[1][0] - want[0][0]) - extent) > 1e-4 * max(extent, 1):
                raise CheckFailed(f"terrain spans {want[1][0] - want[0][0]} m in x, expected {extent} m")
        t_settings = manifest.get("settings", {}).get("terrain") or {}
        skirt_asked = t_settings.get("skirt_m") or 0.0
        # with a chain and chunks, a level's skirts hang its bound plus the coarsest level's (the
        # largest step to a neighbour at any level), at least the preset's
        coarsest = max([t_settings.get("max_error_m") or 0.0] + list(t_settings.get("lods") or []))
        last_distance = -math.inf
        for lod in terrain.get("lods", []):
            n = lod["level"]
            skirt = skirt_asked
            if skirt_asked and t_settings.get("chunk"):
                skirt = max(skirt_asked, lod["max_error_requested_m"] + coarsest)
            if abs((lod.get("skirt_m") or 0.0) - skirt) > 1e-9:
                raise CheckFailed(f"LOD{n}: the manifest's skirt_m {lod.get('skirt_m')} is not {skirt} "
                                  f"(the preset's skirt {skirt_asked}, or the level's bound plus the coarsest)")
            if not lod["max_error_m"] <= lod["max_error_requested_m"] + 1e-9:
                raise CheckFailed(f"LOD{n}: measured max error {lod['max_error_m']} > requested "
                                  f"{lod['max_error_requested_m']}")
            if not lod["switch_distance_m"] > last_distance:
                raise CheckFailed(f"LOD{n}: switch distance {lod['switch_distance_m']} does not increase")
            last_distance = lod["switch_distance_m"]
            lod_meshes = [f for f in lod["files"] if f.lower().endswith(MESH_SUFFIXES)]
            if not lod_meshes:
                raise CheckFailed(f"LOD{n} lists no mesh file: {lod['files']}")
            for rel in lod_meshes:
                if Path(rel).stem != f"terrain_LOD{n}":
                    raise CheckFailed(f"LOD{n} file {rel} is not named terrain_LOD{n}.*")
                geom = load_geometry(scene_dir / rel)
                # the level's count is of the surface; skirts come on top
                if geom.face_count < lod["triangles"]:
                    raise CheckFailed(f"{rel} has {geom.face_count} triangles, fewer than the level's "
                                      f"{lod['triangles']} surface triangles")
                # x/z: the same extent; y: a coarser level's vertices and skirts may lie up to its error
                # (plus the skirt depth below) outside the finest mesh's range
                b = geom.bounds()
                tol = BOUNDS_REL_TOL * scale
                check_close(f"{rel} x/z bounds", b[:, [0, 2]], want[:, [0, 2]], scale)
                slack = lod["max_error_requested_m"] + tol
                if b[0][1] < want[0][1] - skirt - slack or b[1][1] > want[1][1] + slack:
                    raise CheckFailed(f"{rel} heights {b[0][1]:.3f}..{b[1][1]:.3f} reach further than LOD{n}'s error "
                                      f"{lod['max_error_requested_m']} (skirt {skirt}) from the terrain's "
                                      f"{want[0][1]:.3f}..{want[1][1]:.3f}")
        if terrain.get("lods"):
            facts.append(f"{len(terrain['lods'])} LoDs ok")
        # chunked: every file's chunks fill their squares (what a view mixing levels relies on)
        if (manifest.get("settings", {}).get("terrain") or {}).get("chunk") and terrain["cell_size_m"]:
            files = list(terrain["files"]) + [f for lod in terrain.get("lods", []) for f in lod["files"]]
            counts = [check_chunk_squares(scene_dir / f, terrain["cell_size_m"]) for f in files if f.endswith(".glb")]
            counts = [n for n in counts if n is not None]
            if counts:
                facts.append(f"{sum(counts)} chunks in {len(counts)} files fill their squares")
        if thumb is not None and primary_geom is not None:
            coverage = render_thumbnail(primary_geom.merged(), primary_geom.bounds(), thumb)
            facts.append(f"thumb {thumb} ({coverage:.0%} covered)")

    placements = "-"
    if manifest.get("scatter"):
        facts.extend(check_placements(scene_dir, manifest, report))
        sp = manifest["scatter"]["species"]
        placements = f"{len(sp)} species, {sum(s['count'] for s in sp)} instances"

    if (scene_dir / "scene_tiles.json").is_file():
        facts.extend(check_tiles(scene_dir, manifest))
    elif (scene_dir / "tiles").exists():
        raise CheckFailed("tiles/ exists but there is no scene_tiles.json")

    if manifest.get("snow"):
        facts.extend(check_snow(scene_dir, manifest, report))
    elif (scene_dir / "snow").exists():
        raise CheckFailed("snow/ exists but the manifest has no snow section")

    preview = manifest.get("preview")
    if preview:
        stage = report.get("stages", {}).get("preview", {})
        size = (stage["width_px"], stage["height_px"]) if "width_px" in stage else None
        facts.append(check_preview(scene_dir / preview, size))
        if stage.get("map"):
            facts.append("map: " + check_preview(scene_dir / stage["map"], None))
    return f"{manifest.get('scene')}: " + "; ".join(facts), tris, verts, placements


def read_glb_chunks(path: Path) -> tuple[dict, bytes]:
    """A GLB's JSON (parsed) and BIN chunk, read directly: pygltflib's typed parse of a scene tile's
    JSON (tens of thousands of objects) took seconds a file."""
    import struct

    data = path.read_bytes()
    magic, _, length = struct.unpack_from("<III", data, 0)
    if magic != 0x46546C67 or length != len(data):
        raise CheckFailed(f"{path.name} is no GLB of {len(data)} bytes")
    json_len, json_type = struct.unpack_from("<II", data, 12)
    if json_type != 0x4E4F534A:
        raise CheckFailed(f"{path.name}: the first chunk is not JSON")
    doc = json.loads(data[20:20 + json_len])
    at = 20 + json_len
    binary = b""
    if at + 8 <= len(data):
        bin_len, bin_type = struct.unpack_from("<II", data, at)
        if bin_type == 0x004E4942:
            binary = data[at + 8:at + 8 + bin_len]
    return doc, binary


def glb_float_vec3(doc: dict, binary: bytes, index: int, what: str) -> np.ndarray | None:
    """FLOAT VEC3 accessor `index` of a GLB's BIN chunk as (count, 3) float64; None when its view is
    meshopt-compressed (EXT_meshopt_compression: no decoder here)."""
    acc = doc["accessors"][index]
    view = doc["bufferViews"][acc["bufferView"]]
    if "EXT_meshopt_compression" in view.get("extensions", {}):
        return None
    if acc["componentType"] != 5126 or acc["type"] != "VEC3" or view["buffer"] != 0 or "uri" in doc["buffers"][0]:
        raise CheckFailed(f"{what}: accessor {index} is not FLOAT VEC3 in the GLB's binary chunk")
    start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    stride = view.get("byteStride", 12)
    n = acc["count"]
    if n and start + stride * (n - 1) + 12 > len(binary):
        raise CheckFailed(f"{what}: accessor {index} reads past the binary chunk")
    return np.ndarray((n, 3), dtype="<f4", buffer=binary, offset=start, strides=(stride, 4)).astype(np.float64)


def glb_indices(doc: dict, binary: bytes, index: int, what: str) -> np.ndarray | None:
    """Index accessor `index` of a GLB's BIN chunk as (n, 3) int64 triangles; None when its view is
    meshopt-compressed."""
    acc = doc["accessors"][index]
    view = doc["bufferViews"][acc["bufferView"]]
    if "EXT_meshopt_compression" in view.get("extensions", {}):
        return None
    dtype = {5121: "<u1", 5123: "<u2", 5125: "<u4"}.get(acc["componentType"])
    if dtype is None or acc["type"] != "SCALAR" or acc["count"] % 3:
        raise CheckFailed(f"{what}: accessor {index} is not an index list of triangles")
    start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    n = acc["count"]
    if start + n * np.dtype(dtype).itemsize > len(binary):
        raise CheckFailed(f"{what}: accessor {index} reads past the binary chunk")
    return np.frombuffer(binary, dtype=dtype, count=n, offset=start).astype(np.int64).reshape(-1, 3)


def check_chunk_squares(path: Path, cell_m: float) -> int | None:
    """Each terrain chunk of a GLB (a node whose extras give its `sample_min`/`sample_max`) lies in
    its square and its faces seen from above fill it exactly: chunks of different levels side by
    side then leave no hole. Returns the chunks checked; None for a file whose positions are
    quantized or compressed (not read here)."""
    doc, binary = read_glb_chunks(path)
    checked = 0
    for node in doc.get("nodes", []):
        extras = node.get("extras") or {}
        if "sample_min" not in extras or node.get("mesh") is None:
            continue
        lo = np.array(extras["sample_min"], dtype=np.float64) * cell_m
        hi = np.array(extras["sample_max"], dtype=np.float64) * cell_m
        tol = 1e-6 * max(1.0, float(np.abs(hi).max()))
        area = 0.0
        for prim in doc["meshes"][node["mesh"]]["primitives"]:
            attrs = prim["attributes"]
            if doc["accessors"][attrs["POSITION"]]["componentType"] != 5126:
                return None
            pos = glb_float_vec3(doc, binary, attrs["POSITION"], f"{path.name} {node['name']}")
            tris = glb_indices(doc, binary, prim["indices"], f"{path.name} {node['name']}")
            if pos is None or tris is None:
                return None
            xz = pos[:, [0, 2]]
            if len(xz) and (np.any(xz < lo - tol) or np.any(xz > hi + tol)):
                k = int(np.argmax(np.maximum(lo - xz, xz - hi).max(axis=1)))
                raise CheckFailed(f"{path.name}: chunk {node['name']} has a vertex at x, z = {xz[k].tolist()}, "
                                  f"outside its square {lo.tolist()}..{hi.tolist()}")
            a, b, c = xz[tris[:, 0]], xz[tris[:, 1]], xz[tris[:, 2]]
            # glTF faces are counter-clockwise seen from outside: seen from above (+Y, looking down
            # -Y onto x, z) a top face turns clockwise in (x, z), so its cross product is negative
            cross = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
            area += float(-cross[cross < 0].sum()) / 2.0
        square = float(np.prod(hi - lo))
        if abs(area - square) > 1e-5 * square:
            raise CheckFailed(f"{path.name}: chunk {node['name']}'s faces cover {area:.3f} m² of its "
                              f"{square:.3f} m² square seen from above (a hole or an overlap)")
        checked += 1
    return checked


def check_tiles(scene_dir: Path, manifest: dict) -> list[str]:
    """scene_tiles.json and tiles/ ([scene] tile): every tile listed with its bytes, each chunk of the
    terrain in exactly one tile, each tile's instances (its chains' LoD0 nodes, EXT_mesh_gpu_instancing)
    inside the tile's box and square, and every species' instances over all tiles exactly the rows of
    its placement table (positions as f32). Returns facts."""
    index = json.loads((scene_dir / "scene_tiles.json").read_text())
    if index.get("format") != "verdant-scene-tiles" or index.get("version") != 1:
        raise CheckFailed(f"scene_tiles.json: format {index.get('format')!r} version {index.get('version')!r}")
    tile_m, (nx, nz) = index["tile_m"], index["grid"]
    chunks_seen: dict[str, str] = {}
    chains_seen: dict[str, str] = {}
    compressed = False
    positions: dict[str, list[np.ndarray]] = {}
    listed = set()
    for t in index["tiles"]:
        rel = t["file"]
        if rel in listed:
            raise CheckFailed(f"scene_tiles.json lists {rel} twice")
        listed.add(rel)
        path = scene_dir / rel
        if path.stat().st_size != t["bytes"]:
            raise CheckFailed(f"{rel} is {path.stat().st_size} bytes, the index says {t['bytes']}")
        i, j = t["index"]
        if t["rect_m"] != [i * tile_m, j * tile_m, (i + 1) * tile_m, (j + 1) * tile_m] or not (i < nx and j < nz):
            raise CheckFailed(f"{rel}: square {t['rect_m']} is not tile ({i}, {j}) of {tile_m} m in a {nx} x {nz} grid")
        doc, binary = read_glb_chunks(path)
        nodes = doc["nodes"]
        lo, hi = np.array(t["bounds_min"]), np.array(t["bounds_max"])
        x0, z0, x1, z1 = t["rect_m"]
        counts: dict[str, int] = {}
        chunks = 0
        for root in doc["scenes"][doc.get("scene", 0)]["nodes"]:
            top = nodes[root]
            for c in top.get("children", []):
                node = nodes[c]
                if top.get("name") == "terrain":
                    chunks += 1
                    if node["name"] in chunks_seen:
                        raise CheckFailed(f"chunk {node['name']} is in {chunks_seen[node['name']]} and {rel}")
                    chunks_seen[node["name"]] = rel
                    continue
                ext = node.get("extensions", {}).get("EXT_mesh_gpu_instancing")
                if not ext:
                    raise CheckFailed(f"{rel}: node {node.get('name')} of {top.get('name')} instances nothing")
                # a chain (placement tile x variant) whole in one tile, as in scene_lod.glb
                if node["name"] in chains_seen:
                    raise CheckFailed(f"chain {node['name']} is in {chains_seen[node['name']]} and {rel}")
                chains_seen[node["name"]] = rel
                acc = ext["attributes"]["TRANSLATION"]
                # (a quantized mesh's instances carry its grid's offset: not the table's positions)
                quantized = "KHR_mesh_quantization" in doc.get("extensionsUsed", [])
                xyz = None if quantized else glb_float_vec3(doc, binary, acc, f"{rel} {node.get('name')}")
                if xyz is None:
                    compressed = True
                    counts[top["name"]] = counts.get(top["name"], 0) + doc["accessors"][acc]["count"]
                    continue
                if np.any(xyz < lo - 1e-6) or np.any(xyz > hi + 1e-6):
                    raise CheckFailed(f"{rel}: an instance of {node['name']} lies outside the tile's box")
                x, z = xyz[:, 0], xyz[:, 2]
                e = 1e-3  # (an instance goes with its placement tile; f32 rounding on the border)
                off = ((x < x0 - e) & (i > 0)) | ((x >= x1 + e) & (i < nx - 1)) | ((z < z0 - e) & (j > 0)) | \
                      ((z >= z1 + e) & (j < nz - 1))
                if np.any(off):
                    raise CheckFailed(f"{rel}: {int(off.sum())} instances of {node['name']} lie outside its square")
                counts[top["name"]] = counts.get(top["name"], 0) + len(xyz)
                positions.setdefault(top["name"], []).append(xyz)
        if chunks != t["terrain_chunks"] or counts != t["instances"]:
            raise CheckFailed(f"{rel}: {chunks} chunks and instances {counts}, the index says "
                              f"{t['terrain_chunks']} and {t['instances']}")
    on_disk = {p.relative_to(scene_dir).as_posix() for p in (scene_dir / "tiles").glob("*")}
    if on_disk != listed:
        raise CheckFailed(f"tiles/ holds {sorted(on_disk - listed)} unlisted, lacks {sorted(listed - on_disk)}")
    terrain_files = [f for f in manifest["terrain"]["files"] if f.endswith(".glb")]
    if terrain_files:
        total = len(read_glb_chunks(scene_dir / terrain_files[0])[0]["meshes"])
        if len(chunks_seen) != total:
            raise CheckFailed(f"the tiles hold {len(chunks_seen)} chunks of the terrain's {total}")
    totals: dict[str, int] = {}
    for t in index["tiles"]:
        for name, n in t["instances"].items():
            totals[name] = totals.get(name, 0) + n
    for sp in manifest.get("scatter", {}).get("species", []):
        meshed = sp["name"] in (manifest.get("view") or {}).get("chains", {})
        if meshed and totals.get(sp["name"], 0) != sp["count"]:
            raise CheckFailed(f"the tiles instance {totals.get(sp['name'], 0)} {sp['name']}, its table {sp['count']}")
    for sp in [] if compressed else manifest.get("scatter", {}).get("species", []):
        name = sp["name"]
        got = np.concatenate(positions.get(name, [np.zeros((0, 3))]))
        if len(got) == 0 and sp["count"] > 0 and name not in (manifest.get("view") or {}).get("chains", {}):
            continue  # a species without meshes: placement tables only
        rows, _, _ = read_placements_csv(scene_dir / sp.get("table", f"placements/{name}.csv"))
        want = rows[:, :3].astype(np.float32).astype(np.float64)
        if len(got) != len(want):
            raise CheckFailed(f"the tiles instance {len(got)} {name}, its table has {len(want)} rows")
        key = lambda a: a[np.lexsort((a[:, 2], a[:, 1], a[:, 0]))]
        if not np.array_equal(key(got), key(want)):
            raise CheckFailed(f"the tiles' {name} instances are not its table's positions")
    n = sum(sum(t["instances"].values()) for t in index["tiles"])
    if compressed:
        return [f"{len(index['tiles'])} tiles of {tile_m:g} m hold the {len(chunks_seen)} chunks once and the "
                f"tables' {n} rows (compact files: counted, positions not compared)"]
    return [f"{len(index['tiles'])} tiles of {tile_m:g} m hold the {len(chunks_seen)} chunks once and the "
            f"tables' {n} rows"]


# ------------------------------------------------------------------------------------------- snow mode
SNOW_FILES = ["snow/flakes.png", "snow/emitter.json", "snow/particles.csv", "snow/snowfall.glb",
              "snow/cover_mask.png", "snow/terrain_snow.glb"]
GRAVITY_M_S2 = 9.80665
VOLUME_REL_TOL = 1e-5


def read_particles_csv(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(is_far bool[n], xyz float64[n, 3], cell int64[n]) of snow/particles.csv."""
    lines = path.read_text().splitlines()
    want = "field,x,y,z,size_m,cell,angle_rad,spin_rad_s"
    if not lines or lines[0] != want:
        raise CheckFailed(f"{path.name}: header {lines[:1]} is not {want!r}")
    rows = [ln.split(",") for ln in lines[1:] if ln]
    if any(len(r) != 8 or r[0] not in ("near", "far") for r in rows):
        raise CheckFailed(f"{path.name}: a row is not `near|far` + 7 numbers")
    far = np.array([r[0] == "far" for r in rows], dtype=bool)
    xyz = np.array([[float(v) for v in r[1:4]] for r in rows], dtype=np.float64).reshape(-1, 3)
    cell = np.array([int(r[5]) for r in rows], dtype=np.int64)
    return far, xyz, cell


def particles_outside_volume(emitter: dict, far: np.ndarray, xyz: np.ndarray) -> list[str]:
    """Problems with particles outside the emitter's declared volume: the near cylinder (radius r1,
    0 <= y <= fall height) or the far sector (r1..r2 within +-view/2 of -Z)."""
    problems = []
    r1, h = emitter["near_radius_m"], emitter["fall_height_m"]
    tol = VOLUME_REL_TOL * max(r1, h, 1.0)
    radius = np.hypot(xyz[:, 0], xyz[:, 2])
    y = xyz[:, 1]
    if len(y) and (y.min() < -tol or y.max() > h + tol):
        problems.append(f"heights {y.min():.4f}..{y.max():.4f} outside 0..{h}")
    near = ~far
    if near.any() and radius[near].max() > r1 + tol:
        problems.append(f"a near flake at radius {radius[near].max():.5f} > near_radius_m {r1}")
    if far.any():
        f = emitter.get("far")
        if not f:
            problems.append("far flakes but no far field")
        else:
            r2 = f["outer_radius_m"]
            tol2 = VOLUME_REL_TOL * max(r2, 1.0)
            if radius[far].min() < r1 - tol2 or radius[far].max() > r2 + tol2:
                problems.append(f"far flakes at radius {radius[far].min():.4f}..{radius[far].max():.4f} outside {r1}..{r2}")
            # angle from the view direction -Z, positive towards +X
            angle = np.degrees(np.arctan2(xyz[far, 0], -xyz[far, 2]))
            half = f["view_angle_deg"] / 2
            if np.abs(angle).max() > half + 1e-3:
                problems.append(f"a far flake {np.abs(angle).max():.3f} deg off the view axis, more than {half}")
    return problems


def check_snow(scene_dir: Path, manifest: dict, report: dict) -> list[str]:
    """The snow/ folder against manifest.snow, emitter.json and itself: every file there; the particle
    table's counts per field = emitter.json's, every flake inside the declared volume, its atlas cell
    valid; snowfall.glb's instances (EXT_mesh_gpu_instancing, one node per cell) = the table's rows
    (f32 positions, per cell in table order); v = m.g/k; the mask PNG's size, greyness and coverage
    as reported; terrain_snow.glb's _SNOW weights in 0..1 with depth = weight x depth; the layer's
    triangle count; trees and meshes never thinned by snow."""
    import pygltflib
    from PIL import Image

    snow = manifest["snow"]
    settings = (manifest.get("settings") or {}).get("snow") or {}
    files = set(snow["files"])
    want = set(SNOW_FILES) | ({"snow/snow_layer.glb"} if settings.get("layer") else set())
    if files != want:
        raise CheckFailed(f"snow files {sorted(files)}, expected {sorted(want)}")
    facts = []

    emitter = json.loads((scene_dir / "snow/emitter.json").read_text())
    v = emitter["flake_mass_kg"] * GRAVITY_M_S2 / emitter["drag_kg_s"]
    if abs(emitter["terminal_velocity_m_s"] - v) > 1e-4 * v:
        raise CheckFailed(f"emitter.json terminal velocity {emitter['terminal_velocity_m_s']} != m*g/k = {v}")
    if abs(snow["analysis"]["terminal_velocity_m_s"] - v) > 1e-4 * v:
        raise CheckFailed(f"manifest snow terminal velocity {snow['analysis']['terminal_velocity_m_s']} != m*g/k = {v}")
    atlas = emitter["atlas"]
    cells = atlas["columns"] * atlas["rows"]
    if len(atlas["cells"]) != cells:
        raise CheckFailed(f"emitter.json lists {len(atlas['cells'])} atlas cells for {atlas['columns']}x{atlas['rows']}")
    with Image.open(scene_dir / "snow/flakes.png") as im:
        if im.size != (atlas["columns"] * atlas["cell_px"], atlas["rows"] * atlas["cell_px"]):
            raise CheckFailed(f"flakes.png is {im.size}, emitter.json says {atlas['columns']}x{atlas['rows']} cells of {atlas['cell_px']} px")
        alpha = np.asarray(im.convert("RGBA"))[:, :, 3]
    n = atlas["cell_px"]
    empty = [k for k in range(cells) if alpha[(k // atlas["columns"]) * n:(k // atlas["columns"] + 1) * n,
                                               (k % atlas["columns"]) * n:(k % atlas["columns"] + 1) * n].max() < 128]
    if empty:
        raise CheckFailed(f"flakes.png cells {empty} have no opaque texel")

    far, xyz, cell = read_particles_csv(scene_dir / "snow/particles.csv")
    want_near = emitter["near_count"]
    want_far = emitter["far"]["count"] if emitter.get("far") else 0
    if (int((~far).sum()), int(far.sum())) != (want_near, want_far):
        raise CheckFailed(f"particles.csv has {(~far).sum()} near + {far.sum()} far flakes, emitter.json says {want_near} + {want_far}")
    if len(cell) and (cell.min() < 0 or cell.max() >= cells):
        raise CheckFailed(f"particles.csv uses atlas cells {cell.min()}..{cell.max()}, the atlas has {cells}")
    problems = particles_outside_volume(emitter, far, xyz)
    if problems:
        raise CheckFailed("particles.csv: " + "; ".join(problems))

    gltf = pygltflib.GLTF2().load(str(scene_dir / "snow/snowfall.glb"))
    buffers = gltf_buffers(gltf, scene_dir / "snow/snowfall.glb")
    if INSTANCING not in (gltf.extensionsUsed or []):
        raise CheckFailed(f"snowfall.glb does not declare {INSTANCING}")
    total = 0
    for node in gltf.nodes:
        ext = (node.extensions or {}).get(INSTANCING)
        if not ext:
            continue
        k = (node.extras or {}).get("cell")
        t = read_accessor(gltf, buffers, ext["attributes"]["TRANSLATION"])
        mine = xyz[cell == k].astype(np.float32).astype(np.float64)
        if t.shape != mine.shape or not np.array_equal(t, mine):
            raise CheckFailed(f"snowfall.glb node {node.name}: {len(t)} instances do not equal the {len(mine)} CSV rows of cell {k}")
        total += len(t)
    if total != len(xyz):
        raise CheckFailed(f"snowfall.glb has {total} flake instances, particles.csv {len(xyz)} rows")
    facts.append(f"snow: {len(xyz)} flakes ({want_near} near + {want_far} far) inside the emitter volume = snowfall.glb instances, v = {v:.3f} m/s")

    mask = snow["mask"]
    with Image.open(scene_dir / mask["file"]) as im:
        if im.size != (mask["width"], mask["height"]):
            raise CheckFailed(f"{mask['file']} is {im.size}, manifest says {mask['width']}x{mask['height']}")
        rgba = np.asarray(im.convert("RGBA")).astype(np.int64)
    if max(im.size) != settings.get("mask_px", max(im.size)):
        raise CheckFailed(f"{mask['file']} long side {max(im.size)} px, [snow] mask_px {settings.get('mask_px')}")
    if not (np.array_equal(rgba[:, :, 0], rgba[:, :, 1]) and np.array_equal(rgba[:, :, 0], rgba[:, :, 2])):
        raise CheckFailed(f"{mask['file']} is not grey")
    coverage = float((rgba[:, :, 0] >= 128).mean())
    reported = snow["analysis"]["mask_coverage"]
    if reported is None or abs(coverage - reported) > 1e-9:
        raise CheckFailed(f"{mask['file']}: {coverage:.6f} of it at weight >= 1/2, the report says {reported}")

    path = scene_dir / snow["terrain"]
    tg = pygltflib.GLTF2().load(str(path))
    tb = gltf_buffers(tg, path)
    depth = settings["cover"]["max_depth_m"]
    weights = []
    for mesh in tg.meshes:
        for prim in mesh.primitives:
            a = getattr(prim.attributes, "_SNOW", None)
            if a is None:
                raise CheckFailed(f"{path.name}: mesh {mesh.name!r} has a primitive without _SNOW")
            w = read_accessor(tg, tb, a)
            if len(w) != tg.accessors[prim.attributes.POSITION].count:
                raise CheckFailed(f"{path.name}: _SNOW count differs from POSITION's")
            if w[:, 0].min() < 0 or w[:, 0].max() > 1 or np.abs(w[:, 1] - w[:, 0] * depth).max() > 1e-5 * max(depth, 1):
                raise CheckFailed(f"{path.name}: _SNOW weights outside 0..1 or depth != weight x {depth} m")
            weights.append(w[:, 0])
    if not weights:
        raise CheckFailed(f"{path.name} has no primitives")
    weights = np.concatenate(weights)
    if settings.get("layer"):
        geom = load_geometry(scene_dir / "snow/snow_layer.glb")
        if geom.face_count != snow["layer_triangles"]:
            raise CheckFailed(f"snow_layer.glb has {geom.face_count} triangles, the manifest says {snow['layer_triangles']}")
    facts.append(f"mask {im.size[0]}x{im.size[1]} ({coverage:.1%} covered, as reported), _SNOW on {len(weights)} vertices "
                 f"(mean {weights.mean():.3f})")

    # thinning: only grass and flowers
    for sp in ((report.get("stages") or {}).get("scatter") or {}).get("species", []):
        if sp["kind"] in ("tree", "mesh") and sp["rules"].get("snow", 0):
            raise CheckFailed(f"species {sp['name']} ({sp['kind']}) has {sp['rules']['snow']} instances thinned by snow")
    return facts


def snow_self_test() -> list[tuple[str, bool, str]]:
    """The volume check on a made-up emitter: flakes inside pass, each kind of stray flake fails."""
    emitter = {"near_radius_m": 10.0, "fall_height_m": 20.0, "far": {"outer_radius_m": 40.0, "view_angle_deg": 90.0}}
    far = np.array([False, False, True, True])
    good = np.array([[3.0, 1.0, -4.0], [0.0, 19.9, 9.99], [0.0, 5.0, -39.0], [20.0, 0.0, -21.0]])
    cases = [("snow volume good", good, True)]
    for name, row, col, value in [("snow near flake outside r1", 1, 2, 10.5), ("snow flake above fall height", 0, 1, 20.5),
                                  ("snow far flake behind the camera", 2, 2, 39.0), ("snow far flake beyond r2", 3, 0, 40.0)]:
        bad = good.copy()
        bad[row, col] = value
        cases.append((name, bad, False))
    out = []
    for name, xyz, expect_ok in cases:
        problems = particles_outside_volume(emitter, far, xyz)
        out.append((name, (not problems) == expect_ok, "; ".join(problems) or "passed"))
    return out


def chunk_self_test(d: Path) -> list[tuple[str, bool, str]]:
    """The chunk-square check on a made-up chunk of 2 × 2 cells: two top faces filling its square
    pass; a vertex past the square and a missing face (a hole) fail."""
    import struct

    def write(path: Path, positions: list, triangles: list) -> Path:
        pos = np.asarray(positions, dtype="<f4").tobytes()
        idx = np.asarray(triangles, dtype="<u4").ravel().tobytes()
        doc = {"asset": {"version": "2.0"}, "buffers": [{"byteLength": len(pos) + len(idx)}],
               "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": len(pos)},
                               {"buffer": 0, "byteOffset": len(pos), "byteLength": len(idx)}],
               "accessors": [{"bufferView": 0, "componentType": 5126, "count": len(positions), "type": "VEC3"},
                             {"bufferView": 1, "componentType": 5125, "count": 3 * len(triangles), "type": "SCALAR"}],
               "meshes": [{"name": "t_chunk_0_0", "primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
               "nodes": [{"name": "t_chunk_0_0", "mesh": 0, "extras": {"sample_min": [0, 0], "sample_max": [2, 2]}}]}
        text = json.dumps(doc).encode()
        text += b" " * (-len(text) % 4)
        binary = pos + idx
        path.write_bytes(struct.pack("<III", 0x46546C67, 2, 28 + len(text) + len(binary))
                         + struct.pack("<II", len(text), 0x4E4F534A) + text
                         + struct.pack("<II", len(binary), 0x004E4942) + binary)
        return path

    d.mkdir(parents=True, exist_ok=True)
    corners = [[0, 1, 0], [0, 1, 2], [2, 1, 0], [2, 1, 2]]  # (x, y, z); cell 1 m
    faces = [[0, 1, 2], [2, 1, 3]]  # counter-clockwise seen from +Y
    cases = [("chunk fills its square", write(d / "good.glb", corners, faces), True),
             ("chunk vertex past its square", write(d / "past.glb", corners[:3] + [[2.5, 1, 2]], faces), False),
             ("chunk with a hole", write(d / "hole.glb", corners, faces[:1]), False)]
    out = []
    for name, path, expect_ok in cases:
        try:
            detail = f"passed ({check_chunk_squares(path, 1.0)} chunk)"
            ok = True
        except CheckFailed as e:
            ok, detail = False, f"failed: {e}"
        out.append((name, ok == expect_ok, detail))
    return out


def scene_main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description="check a scene folder written by `verdant build`")
    parser.add_argument("--scene", required=True, help="the scene folder (holding manifest.json)")
    parser.add_argument("--thumb", help="render a thumbnail of the primary terrain file here")
    parser.add_argument("--summary-tsv", help="append 'scene<TAB>status<TAB>tris<TAB>verts<TAB>placements' to this file")
    args = parser.parse_args(argv)
    name = Path(args.scene).name
    return run_and_report(name, lambda: check_scene(Path(args.scene), Path(args.thumb) if args.thumb else None), args.summary_tsv, 3)


# ------------------------------------------------------------------------------------- placements mode
INSTANCING = "EXT_mesh_gpu_instancing"
PLACEMENT_HEADER = "x,y,z,qx,qy,qz,qw,sx,sy,sz,yaw_deg,tile,variant"
RAY_SAMPLE = 20_000          # instances ray-cast per species (all of them below this)
HEIGHT_TOL_GLB_M = 1e-3      # |y (f32, scene.glb) - terrain hit|
HEIGHT_TOL_CSV_M = 1e-4      # |y (f64, CSV) - terrain hit| (issue 4: exact barycentric height)
SPACING_REL_TOL = 1e-6
INSTANCE_ACCESSORS = {"TRANSLATION": "VEC3", "ROTATION": "VEC4", "SCALE": "VEC3"}


def read_placements_csv(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(n, 11) float64 (x..yaw_deg, parsed exactly), (n,) int64 tiles and (n,) int64 variants; the
    header must be exact. A `.bin` table (`[scatter] table = "binary"`) is read by its layout."""
    if path.suffix == ".bin":
        return read_placements_bin(path)
    text = path.read_text()
    header, _, body = text.partition("\n")
    if header != PLACEMENT_HEADER:
        raise CheckFailed(f"{path.name}: header {header!r}, expected {PLACEMENT_HEADER!r}")
    if not body.strip():
        return np.zeros((0, 11)), np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    if not body.endswith("\n"):
        raise CheckFailed(f"{path.name}: the last row has no line end")
    fields = body[:-1].replace("\n", ",").split(",")
    rows = body.count("\n")
    if len(fields) != rows * 13:
        raise CheckFailed(f"{path.name}: {len(fields)} fields in {rows} rows, expected 13 a row")
    cells = np.array(fields, dtype=object).reshape(rows, 13)
    try:
        values = cells[:, :11].astype(np.float64)
        tiles = cells[:, 11].astype(np.int64)
        variants = cells[:, 12].astype(np.int64)
    except ValueError as e:
        raise CheckFailed(f"{path.name}: a cell is not a number ({e})") from None
    if not np.all(np.isfinite(values)):
        raise CheckFailed(f"{path.name}: some values are NaN or infinite")
    return values, tiles, variants


def read_placements_bin(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A binary placement table (src/export/table_bin.rs): `VPLT`, version 1, u64 rows, then the
    arrays position f64x3, rotation f32x4, scale f32x3, yaw f32, tile u32, variant u32."""
    data = path.read_bytes()
    if data[:4] != b"VPLT" or int.from_bytes(data[4:8], "little") != 1:
        raise CheckFailed(f"{path.name}: not a version 1 binary placement table")
    n = int.from_bytes(data[8:16], "little")
    if len(data) != 16 + 64 * n:
        raise CheckFailed(f"{path.name}: {n} rows need {16 + 64 * n} bytes, the file has {len(data)}")
    o = 16
    def take(dtype, k):
        nonlocal o
        a = np.frombuffer(data, dtype=dtype, count=n * k, offset=o).reshape(n, k)
        o += a.nbytes
        return a
    pos, rot, scale = take("<f8", 3), take("<f4", 4), take("<f4", 3)
    yaw, tiles, variants = take("<f4", 1), take("<u4", 1), take("<u4", 1)
    values = np.concatenate([pos, rot.astype(np.float64), scale.astype(np.float64), yaw.astype(np.float64)], axis=1)
    if not np.all(np.isfinite(values)):
        raise CheckFailed(f"{path.name}: some values are NaN or infinite")
    return values, tiles[:, 0].astype(np.int64), variants[:, 0].astype(np.int64)


def terrain_of_scene(gltf, buffers) -> trimesh.Trimesh:
    """The triangles of scene.glb's default scene without the instanced nodes (the terrain)."""
    positions, faces = [], []

    def visit(node_index: int, parent: np.ndarray, depth: int) -> None:
        if depth > 256:
            raise CheckFailed("node hierarchy deeper than 256 (a cycle?)")
        node = gltf.nodes[node_index]
        if INSTANCING in (node.extensions or {}):
            return
        world = parent @ node_matrix(node)
        if node.mesh is not None:
            for prim in gltf.meshes[node.mesh].primitives:
                local = read_accessor(gltf, buffers, prim.attributes.POSITION)
                idx = (read_accessor(gltf, buffers, prim.indices).reshape(-1).astype(np.int64)
                       if prim.indices is not None else np.arange(len(local)))
                tris = triangles_of(prim.mode if prim.mode is not None else 4, idx)
                if tris is None:
                    continue
                positions.append((np.hstack([local, np.ones((len(local), 1))]) @ world.T)[:, :3])
                faces.append(tris + sum(len(p) for p in positions[:-1]))
        for child in node.children or []:
            visit(child, world, depth + 1)

    scene = gltf.scenes[gltf.scene if gltf.scene is not None else 0]
    for root in scene.nodes or []:
        visit(root, np.eye(4), 0)
    if not positions:
        raise CheckFailed("scene.glb has no terrain triangles (every mesh node is instanced)")
    return trimesh.Trimesh(np.concatenate(positions), np.concatenate(faces), process=False)


def ray_heights(terrain: trimesh.Trimesh, xz: np.ndarray) -> np.ndarray:
    """Height of the first terrain triangle hit by a ray straight down at each (x, z); NaN on a miss.
    Triangles seen edge-on from above (skirts, walls) or degenerate cannot be hit and are left out."""
    from trimesh.ray.ray_triangle import RayMeshIntersector

    tri = terrain.triangles
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area2 = np.linalg.norm(cross, axis=1)
    keep = (area2 > 1e-12) & (np.abs(cross[:, 1]) > 1e-9 * np.maximum(area2, 1e-300))
    surface = trimesh.Trimesh(terrain.vertices, terrain.faces[keep], process=False)
    caster = RayMeshIntersector(surface)
    top = float(terrain.bounds[1][1]) + 10.0
    out = np.full(len(xz), np.nan)
    for start in range(0, len(xz), 4096):
        part = xz[start:start + 4096]
        origins = np.column_stack([part[:, 0], np.full(len(part), top), part[:, 1]])
        directions = np.tile([0.0, -1.0, 0.0], (len(part), 1))
        _, ray, loc = caster.intersects_id(origins, directions, multiple_hits=False, return_locations=True)
        out[start + np.asarray(ray, dtype=np.int64)] = loc[:, 1] if len(ray) else []
    return out


def mix64(z: np.ndarray) -> np.ndarray:
    """verdant's random::mix64 (splitmix64's finaliser) on uint64 arrays (numpy wraps like Rust)."""
    with np.errstate(over="ignore"):
        z = z + np.uint64(0x9E3779B97F4A7C15)
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


def variants_of(x: np.ndarray, z: np.ndarray, n: int) -> np.ndarray:
    """The variant each row shows: mix64(bits(x) ^ mix64(bits(z))), scaled to n (docs/scene.md)."""
    h = mix64(np.ascontiguousarray(x, dtype=np.float64).view(np.uint64)
              ^ mix64(np.ascontiguousarray(z, dtype=np.float64).view(np.uint64)))
    with np.errstate(over="ignore"):
        return (((h >> np.uint64(32)) * np.uint64(n)) >> np.uint64(32)).astype(np.int64)


def rotate_up(q: np.ndarray, up: np.ndarray) -> np.ndarray:
    """(n, 3): each unit quaternion q (x, y, z, w) applied to (0, up, 0)."""
    x, y, z, w = (q[:, k] for k in range(4))
    return np.stack([2 * (x * y - w * z) * up, (1 - 2 * (x * x + z * z)) * up, 2 * (y * z + w * x) * up], 1)


def rotate_vec(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(n, 3): each unit quaternion q (x, y, z, w) applied to the row of v: v + 2w (q × v) + 2 q × (q × v)."""
    u, w = q[:, 0:3], q[:, 3:4]
    t = 2 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def impostor_views(rows: np.ndarray, eye, impostor: dict) -> np.ndarray:
    """The baked impostor view each row shows to the eye, as docs/scene.md documents it:
    k = round(atan2(dx, dz) / step) mod views, (dx, dz) from the instance's centre to the eye in the
    instance's own frame (its rotation and scale undone)."""
    p = rows[:, 0:3].astype(np.float32).astype(np.float64)
    q = rows[:, 3:7].astype(np.float32).astype(np.float64)
    s = rows[:, 7:10].astype(np.float32).astype(np.float64)
    centre = p + rotate_vec(q, s * np.asarray(impostor["centre"], dtype=np.float64))
    d = np.asarray(eye, dtype=np.float64) - centre
    local = rotate_vec(q * np.array([-1.0, -1.0, -1.0, 1.0]), d) / s
    k = np.round(np.degrees(np.arctan2(local[:, 0], local[:, 2])) / impostor["azimuth_step_deg"])
    return np.mod(k.astype(np.int64), int(impostor["views"]))


def replay_view(rows: np.ndarray, table_variants: np.ndarray, chain: dict, view: dict,
                cull: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """What the first view draws of a species, recomputed from its table rows: per row the chain's
    variant (the row's `variant` column through the chain's `pick`), the level (-1: culled), the
    distance, and the distance to the nearest threshold (relative), so rows exactly at a switch may
    go either way."""
    n = len(rows)
    pick = np.asarray(chain.get("pick") or list(range(len(chain["variants"]))), dtype=np.int64)
    if n and (table_variants.min() < 0 or table_variants.max() >= len(pick)):
        raise CheckFailed(f"variant column {table_variants.min()}..{table_variants.max()}, the chain picks from {len(pick)}")
    variants = pick[table_variants]
    p = rows[:, 0:3].astype(np.float32).astype(np.float64)
    q = rows[:, 3:7].astype(np.float32).astype(np.float64)
    s = rows[:, 8].astype(np.float32).astype(np.float64)
    centre = p + rotate_up(q, chain["centre_y_m"] * s)
    d = np.linalg.norm(centre - np.asarray(view["camera"]["eye"], dtype=np.float64), axis=1)
    factor = view["distance_factor"]
    limit = cull["distance_m"] * factor * s if cull["scales_with_view"] else np.full(n, cull["distance_m"])
    level = np.zeros(n, dtype=np.int64)
    margin = np.abs(d - limit) / np.maximum(d, 1e-9)
    for v, levels in enumerate(chain["variants"]):
        sel = variants == v
        for k, lv in enumerate(levels):
            if k == 0:
                continue
            t = lv["switch_distance_m"] * factor * s[sel]
            level[np.nonzero(sel)[0][t <= d[sel]]] = k
            margin[sel] = np.minimum(margin[sel], np.abs(d[sel] - t) / np.maximum(d[sel], 1e-9))
    level[d > limit] = -1
    return variants, level, d, margin


def check_placements(scene_dir: Path, manifest: dict | None = None, report: dict | None = None,
                     verbose: bool = True) -> list[str]:
    """Check placements/<species>.csv and .json (counts, tiles, AABBs, spacing, exclusions, heights on the
    terrain as written), then replay the first view from the tables: every row's variant, level and cull
    recomputed here from manifest.view (camera, chains, cull distances) must give exactly scene.glb's
    EXT_mesh_gpu_instancing nodes (mesh per node, transforms per instance as f32). Returns facts."""
    import pygltflib
    from scipy.spatial import cKDTree

    if manifest is None:
        manifest = json.loads((scene_dir / "manifest.json").read_text())
    if report is None and (scene_dir / "report.json").is_file():
        report = json.loads((scene_dir / "report.json").read_text())
    scatter = manifest.get("scatter")
    if not scatter:
        raise CheckFailed("manifest.json has no scatter section")
    view_m = manifest.get("view")
    if not view_m:
        raise CheckFailed("manifest.json has a scatter section but no view section (scene.glb)")
    settings = {s["name"]: s for s in manifest.get("settings", {}).get("species", [])}
    listed = [s["name"] for s in scatter["species"]]
    if listed != list(settings):
        raise CheckFailed(f"manifest scatter species {listed} differ from settings.species {list(settings)}")
    glb_path = scene_dir / view_m.get("scene", "scene.glb")
    gltf = pygltflib.GLTF2().load(str(glb_path))
    buffers = gltf_buffers(gltf, glb_path)
    view = view_m["views"][0]

    # the extension is declared used and required (a viewer without it would draw one instance)
    used, required = set(gltf.extensionsUsed or []), set(gltf.extensionsRequired or [])
    instanced = [i for i, n in enumerate(gltf.nodes) if INSTANCING in (n.extensions or {})]
    if instanced and not (INSTANCING in used and INSTANCING in required):
        raise CheckFailed(f"{glb_path.name}: {INSTANCING} is used by {len(instanced)} nodes but "
                          f"extensionsUsed={sorted(used)}, extensionsRequired={sorted(required)}")

    parent_of = {}
    for i, n in enumerate(gltf.nodes):
        for c in n.children or []:
            parent_of[c] = i
    scene = gltf.scenes[gltf.scene if gltf.scene is not None else 0]
    roots = {gltf.nodes[r].name: r for r in scene.nodes or []}

    # every instanced node: FLOAT accessors of equal count, unit quaternions, under its species root
    instances = {}  # node index -> (translations, rotations, scales) as float32
    for i in instanced:
        node = gltf.nodes[i]
        attrs = node.extensions[INSTANCING].get("attributes", {})
        if set(attrs) != set(INSTANCE_ACCESSORS):
            raise CheckFailed(f"node {node.name!r}: {INSTANCING} attributes {sorted(attrs)}, "
                              f"expected {sorted(INSTANCE_ACCESSORS)}")
        arrays = {}
        for key, want_type in INSTANCE_ACCESSORS.items():
            acc = gltf.accessors[attrs[key]]
            if acc.componentType != 5126 or acc.type != want_type or acc.normalized:
                raise CheckFailed(f"node {node.name!r} {key}: accessor {attrs[key]} is componentType "
                                  f"{acc.componentType} {acc.type}, expected FLOAT (5126) {want_type}")
            arrays[key] = read_accessor(gltf, buffers, attrs[key]).astype(np.float32)  # exact: f32 in, f32 out
        counts = {k: len(v) for k, v in arrays.items()}
        if len(set(counts.values())) != 1 or not counts["TRANSLATION"]:
            raise CheckFailed(f"node {node.name!r}: instance accessor counts {counts} are not equal and > 0")
        norms = np.linalg.norm(arrays["ROTATION"].astype(np.float64), axis=1)
        if np.max(np.abs(norms - 1)) > 1e-5:
            k = int(np.argmax(np.abs(norms - 1)))
            raise CheckFailed(f"node {node.name!r} instance {k}: rotation {arrays['ROTATION'][k].tolist()} "
                              f"has length {norms[k]:.7f}, not 1")
        if node.mesh is None:
            raise CheckFailed(f"node {node.name!r} has {INSTANCING} but no mesh")
        instances[i] = (arrays["TRANSLATION"], arrays["ROTATION"], arrays["SCALE"])

    # the view's terrain (chunks at their levels) has the triangles the report counts; heights are
    # checked against the finest terrain as written (terrain.files), which the placements lie on
    drawn_terrain = terrain_of_scene(gltf, buffers)
    want_tris = view["terrain"]["triangles"]
    if len(drawn_terrain.faces) != want_tris:
        raise CheckFailed(f"{glb_path.name}: the terrain has {len(drawn_terrain.faces)} triangles, manifest "
                          f"view.views[0].terrain.triangles says {want_tris}")
    terrain = drawn_terrain
    terrain_files = [f for f in (manifest.get("terrain") or {}).get("files", []) if f.endswith((".glb", ".gltf"))]
    if terrain_files and view["terrain"]["chunks_per_level"][1:] and any(view["terrain"]["chunks_per_level"][1:]):
        t_path = scene_dir / terrain_files[0]
        t_gltf = pygltflib.GLTF2().load(str(t_path))
        terrain = terrain_of_scene(t_gltf, gltf_buffers(t_gltf, t_path))

    facts, xz_of, claimed = [], {}, set()
    report_species = {s["name"]: s for s in ((report or {}).get("stages", {}).get("scatter") or {}).get("species", [])}
    view_species = {s["name"]: s for s in view["species"]}
    drawn_total = 0
    for entry in scatter["species"]:
        name = entry["name"]
        spec = settings[name]
        csv_path = scene_dir / entry.get("table", f"placements/{name}.csv")
        values, tiles, table_variants = read_placements_csv(csv_path)
        n = len(values)

        # the first view, replayed from the table
        chain = view_m.get("chains", {}).get(name)
        vs = view_species.get(name)
        root = roots.get(name)
        if chain is None or vs is None or vs.get("cull") is None:
            if root is not None and gltf.nodes[root].children:
                raise CheckFailed(f"{name}: has no chain in the manifest but instanced nodes in scene.glb")
            drawn = 0
        else:
            if root is None:
                raise CheckFailed(f"{glb_path.name}: no root node named {name!r} (roots: {sorted(roots)})")
            if root in parent_of:
                raise CheckFailed(f"{name}: species node is not a root node")
            # each row names its variant: the documented hash of its x and z over the chain's picks
            pick_n = len(chain.get("pick") or chain["variants"])
            if n and not np.array_equal(table_variants, variants_of(values[:, 0], values[:, 2], pick_n)):
                raise CheckFailed(f"{name}: the variant column is not the hash of x and z over {pick_n} variants")
            variants, level, _, margin = replay_view(values, table_variants, chain, view, vs["cull"])
            expected = {}
            for v in range(len(chain["variants"])):
                for k in range(len(chain["variants"][v])):
                    sel = (variants == v) & (level == k)
                    if not sel.any():
                        continue
                    # an impostor level: one node per baked view the rows show (docs/scene.md)
                    lv = chain["variants"][v][k]
                    impostor = None
                    if lv.get("file") and (scene_dir / lv["file"]).is_file():
                        lv_gltf = pygltflib.GLTF2().load(str(scene_dir / lv["file"]))
                        lv_mesh = next((m for m in lv_gltf.meshes if m.name == lv["mesh"]), None)
                        impostor = ((lv_mesh.extras or {}) if lv_mesh else {}).get("verdant_impostor")
                    if impostor is None:
                        expected[(v, k, None)] = values[sel]
                        continue
                    shown = impostor_views(values[sel], view["camera"]["eye"], impostor)
                    for b in np.unique(shown):
                        expected[(v, k, int(b))] = values[sel][shown == b]
            got = {}
            for c in gltf.nodes[root].children or []:
                child = gltf.nodes[c]
                ex = child.extras or {}
                if c not in instances or ex.get("species") != name or "variant" not in ex or "level" not in ex:
                    raise CheckFailed(f"{name}: child node {child.name!r} is not an instanced node with extras "
                                      f"species/variant/level")
                v, k = int(ex["variant"]), int(ex["level"])
                b = ex.get("verdant_impostor_view")
                b = None if b is None else int(b)
                want_mesh = chain["variants"][v][k]["mesh"]
                shown_mesh = want_mesh if b is None else f"{want_mesh}_view{b}"
                if gltf.meshes[child.mesh].name != shown_mesh or ex.get("mesh") != want_mesh:
                    raise CheckFailed(f"{name}: node {child.name!r} (variant {v}, LOD{k}) shows mesh "
                                      f"{gltf.meshes[child.mesh].name!r}, the chain says {shown_mesh!r}")
                if not np.allclose(node_matrix(child), np.eye(4), atol=0):
                    raise CheckFailed(f"{name}: node {child.name!r} has a transform; instances are world positions")
                if (v, k, b) in got:
                    raise CheckFailed(f"{name}: two nodes for variant {v} LOD{k} (impostor view {b})")
                got[(v, k, b)] = np.concatenate(instances[c], axis=1)
                claimed.add(c)
            borderline = int((margin < 1e-9).sum())
            keys = sorted(set(expected) | set(got), key=lambda t: (t[0], t[1], -1 if t[2] is None else t[2]))
            mismatched = []
            for key in keys:
                want = expected.get(key, np.zeros((0, 11)))
                want32 = want[:, 0:10].astype(np.float32)
                have = got.get(key, np.zeros((0, 10), np.float32))
                a = want32[np.lexsort(want32.T[::-1])]
                b = have[np.lexsort(have.T[::-1])]
                if a.shape != b.shape or not np.array_equal(a, b):
                    mismatched.append((key, len(a), len(b)))
            moved = sum(abs(x[1] - x[2]) for x in mismatched)
            if mismatched and (moved > 2 * borderline or any(w == h for _, w, h in mismatched)):
                key, w, h = mismatched[0]
                raise CheckFailed(f"{name}: replaying the table gives {w} instances at variant {key[0]} LOD{key[1]}, "
                                  f"scene.glb has {h} ({len(mismatched)} groups differ, {borderline} rows at a threshold)")
            drawn = sum(len(x) for x in got.values())
            if drawn != vs["drawn"] or n - drawn != vs["culled"]:
                raise CheckFailed(f"{name}: scene.glb draws {drawn} of {n} rows, the report says {vs['drawn']} drawn, "
                                  f"{vs['culled']} culled")
            glb_all = np.concatenate(list(got.values())) if got else np.zeros((0, 10), np.float32)
        drawn_total += drawn

        # the table itself
        if n and np.max(np.abs(np.linalg.norm(values[:, 3:7], axis=1) - 1)) > 1e-5:
            raise CheckFailed(f"{name}: CSV quaternions are not unit length")
        if n and (np.any(values[:, 7:10] <= 0)):
            raise CheckFailed(f"{name}: CSV has non-positive scales")
        lo_s, hi_s = spec["scale"]
        if n and (values[:, 7:10].min() < np.float32(lo_s) * (1 - 1e-6) or values[:, 7:10].max() > np.float32(hi_s) * (1 + 1e-6)):
            raise CheckFailed(f"{name}: scales {values[:, 7:10].min():.4g}..{values[:, 7:10].max():.4g} outside {spec['scale']}")
        order = np.argsort(tiles, kind="stable")
        in_tile_order = bool(np.all(order == np.arange(n)))

        # the JSON summary: count, per-tile counts and AABBs
        summary = json.loads((scene_dir / entry.get("summary", f"placements/{name}.json")).read_text())
        if summary.get("count") != n or summary.get("stats", {}).get("count") != n or entry.get("count") != n:
            raise CheckFailed(f"{name}: {n} CSV rows, but JSON count {summary.get('count')}, "
                              f"stats.count {summary.get('stats', {}).get('count')}, manifest {entry.get('count')}")
        csv_tiles, csv_counts = np.unique(tiles, return_counts=True)
        per_tile = {int(p["tile"]): p for p in summary["stats"].get("per_tile", []) if p["count"]}
        if sorted(per_tile) != csv_tiles.tolist() or any(per_tile[int(k)]["count"] != c for k, c in zip(csv_tiles, csv_counts)):
            raise CheckFailed(f"{name}: JSON per-tile counts {[(k, p['count']) for k, p in sorted(per_tile.items())][:8]}… "
                              f"differ from the CSV's {list(zip(csv_tiles.tolist(), csv_counts.tolist()))[:8]}…")
        for k in csv_tiles:
            rows = values[tiles == k][:, 0:3]
            p = per_tile[int(k)]
            if not (np.allclose(rows.min(axis=0), p["aabb_min"], rtol=0, atol=1e-9)
                    and np.allclose(rows.max(axis=0), p["aabb_max"], rtol=0, atol=1e-9)):
                raise CheckFailed(f"{name}: tile {k} AABB {p['aabb_min']}..{p['aabb_max']} in the JSON, "
                                  f"{rows.min(axis=0).tolist()}..{rows.max(axis=0).tolist()} in the CSV")
        if entry.get("tiles") is not None and entry["tiles"] < len(csv_tiles):
            raise CheckFailed(f"{name}: manifest says {entry['tiles']} tiles, the CSV uses {len(csv_tiles)}")

        # on the surface: a ray straight down at (x, z) hits the terrain at y (CSV f64 and glb f32)
        if n:
            sample = np.unique(np.linspace(0, n - 1, min(n, RAY_SAMPLE)).round().astype(np.int64))
            hits = ray_heights(terrain, values[sample][:, [0, 2]])
            missed = np.isnan(hits)
            if missed.any():
                k = sample[np.argmax(missed)]
                raise CheckFailed(f"{name}: {int(missed.sum())} of {len(sample)} sampled instances are not above the "
                                  f"terrain, e.g. ({values[k, 0]:.3f}, {values[k, 2]:.3f})")
            err_glb = float(np.max(np.abs(values[sample][:, 1].astype(np.float32).astype(np.float64) - hits)))
            err_csv = float(np.max(np.abs(values[sample][:, 1] - hits)))
            if err_glb > HEIGHT_TOL_GLB_M or err_csv > HEIGHT_TOL_CSV_M:
                k = sample[int(np.argmax(np.abs(values[sample][:, 1] - hits)))]
                raise CheckFailed(f"{name}: instances are off the terrain: max |y - hit| {err_glb:.3g} m (glb, "
                                  f"limit {HEIGHT_TOL_GLB_M:g}), {err_csv:.3g} m (CSV, limit {HEIGHT_TOL_CSV_M:g}); "
                                  f"worst at ({values[k, 0]:.3f}, {values[k, 2]:.3f})")
        else:
            sample, err_glb, err_csv = np.zeros(0), 0.0, 0.0

        # spacing: Poisson species at least min_spacing apart (x/z) over all instances, all tiles
        xz = values[:, [0, 2]]
        xz_of[name] = xz
        min_pair = float(cKDTree(xz).query(xz, k=2)[0][:, 1].min()) if n >= 2 else math.inf
        reported = summary["stats"].get("min_pair_distance_m")
        if reported is not None and n >= 2 and abs(reported - min_pair) > 1e-9 * max(1.0, min_pair):
            raise CheckFailed(f"{name}: JSON min_pair_distance_m {reported} but the CSV's is {min_pair}")
        if spec["placement"] == "poisson" and min_pair < spec["min_spacing_m"] * (1 - SPACING_REL_TOL):
            raise CheckFailed(f"{name}: two instances {min_pair:.6f} m apart, min_spacing is {spec['min_spacing_m']} m")
        # exclusions: nothing within radius of the named (earlier, or the same) species
        excl_facts = []
        for ex in spec.get("exclusions", []):
            other, radius = ex["species"], ex["radius_m"]
            if other == name:
                d = min_pair
            else:
                if other not in xz_of:
                    raise CheckFailed(f"{name}: excludes {other!r}, which is not placed before it")
                d = float(cKDTree(xz_of[other]).query(xz)[0].min()) if n and len(xz_of[other]) else math.inf
            if d < radius * (1 - SPACING_REL_TOL):
                raise CheckFailed(f"{name}: an instance {d:.6f} m from a {other!r}, exclusion radius {radius} m")
            excl_facts.append(f"{d:.3f} m from {other} (>= {radius})")
        rs = report_species.get(name)
        if rs is not None and rs.get("count") != n:
            raise CheckFailed(f"{name}: report.json count {rs.get('count')}, CSV {n}")
        line = (f"{name}: {n} rows in {len(csv_tiles)} tiles{'' if in_tile_order else ' (not in tile order)'}, "
                f"first view draws {drawn} (replayed from the table = scene.glb); "
                f"ray-cast {len(sample)}: max |dy| glb {err_glb:.2e} m, CSV {err_csv:.2e} m; "
                f"min pair {min_pair:.4f} m" + (f" >= {spec['min_spacing_m']}" if spec["placement"] == "poisson" else "")
                + (f"; exclusion {', '.join(excl_facts)}" if excl_facts else ""))
        if verbose:
            print(f"      {line}")
        facts.append(line)
    stray = sorted(set(instanced) - claimed)
    if stray:
        raise CheckFailed(f"{glb_path.name}: instanced nodes outside the species nodes: "
                          f"{[gltf.nodes[i].name for i in stray][:5]}")
    total = sum(len(x) for x in xz_of.values())
    return [f"placements of {len(xz_of)} species ({total} rows) on the terrain; the first view "
            f"({view['triangles']} triangles, {view['draw_calls']} draw calls) replayed from the tables = "
            f"scene.glb's {drawn_total} instances"]


SELF_TEST_EYE = [16.0, 12.0, 40.0]
SELF_TEST_CHAINS = {
    # name: (variants × level switch distances, centre_y, cull (distance, scales_with_view))
    "tree": ([[0.0, 20.0], [0.0, 24.0]], 1.0, (1000.0, False)),
    "grass": ([[0.0, 25.0]], 0.1, (24.0, True)),
}


def self_test_selection(row: np.ndarray, switch_by_variant: list[list[float]], centre_y: float,
                        cull: tuple[float, bool]) -> tuple[int, int]:
    """(variant, level or -1 when culled) of one row for the synthetic scene, written out scalar by scalar
    (the checker's vectorised replay must agree with it)."""
    import struct
    m = (1 << 64) - 1

    def mix(z: int) -> int:
        z = (z + 0x9E3779B97F4A7C15) & m
        z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & m
        z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & m
        return z ^ (z >> 31)

    bits = lambda v: struct.unpack("<Q", struct.pack("<d", float(v)))[0]  # noqa: E731
    h = mix(bits(row[0]) ^ mix(bits(row[2])))
    variant = ((h >> 32) * len(switch_by_variant)) >> 32
    f32 = lambda v: float(np.float32(v))  # noqa: E731
    x, y, z, w = (f32(c) for c in row[3:7])
    s = f32(row[8])
    up = centre_y * s
    centre = [f32(row[0]) + 2 * (x * y - w * z) * up, f32(row[1]) + (1 - 2 * (x * x + z * z)) * up,
              f32(row[2]) + 2 * (y * z + w * x) * up]
    d = math.dist(centre, SELF_TEST_EYE)
    limit = cull[0] * s if cull[1] else cull[0]
    if d > limit:
        return variant, -1
    level = max(k for k, t in enumerate(switch_by_variant[variant]) if t * s <= d)
    return variant, level


def write_instanced_scene(d: Path, species: list[dict], required: bool = True, json_delta: int = 0,
                          glb_shift: float = 0.0, wrong_level: bool = False, draw_culled: bool = False) -> Path:
    """A tiny scene folder as `verdant build` writes it (terrain on the plane y = 0.1 x + 0.05 z + 3;
    placements CSV/JSON; scene.glb as the first view draws them: one instanced node per species, variant
    and level; a manifest with the view and the chains) for the self-test. `species`: dicts with name,
    placement, min_spacing_m, exclusions, rows ((n, 11) f64 x..yaw_deg), tiles ((n,) int). Broken on
    purpose: `glb_shift` moves the first drawn instance, `wrong_level` draws one at the next level,
    `draw_culled` draws a culled row."""
    import pygltflib

    d.mkdir(parents=True, exist_ok=True)
    (d / "placements").mkdir(exist_ok=True)
    n_side, cell = 9, 4.0
    i, j = np.meshgrid(np.arange(n_side), np.arange(n_side), indexing="xy")
    x, z = (i * cell).ravel(), (j * cell).ravel()
    verts = np.stack([x, 0.1 * x + 0.05 * z + 3, z], 1).astype(np.float32)
    a = (np.arange(n_side - 1)[None, :] + n_side * np.arange(n_side - 1)[:, None]).ravel()
    faces = np.concatenate([np.stack([a, a + n_side, a + 1], 1), np.stack([a + 1, a + n_side, a + n_side + 1], 1)])
    blob = bytearray()
    views, accessors = [], []

    def add(array: np.ndarray, acc_type: str, component: int, target=None) -> int:
        while len(blob) % 4:
            blob.append(0)
        views.append(pygltflib.BufferView(buffer=0, byteOffset=len(blob), byteLength=array.nbytes, target=target))
        blob.extend(array.tobytes())
        extra = {}
        if acc_type == "VEC3" and component == 5126:
            extra = dict(min=array.min(axis=0).tolist(), max=array.max(axis=0).tolist())
        accessors.append(pygltflib.Accessor(bufferView=len(views) - 1, componentType=component, type=acc_type,
                                            count=len(array), **extra))
        return len(accessors) - 1

    pos = add(verts, "VEC3", 5126, 34962)
    idx = add(faces.astype(np.uint32).ravel(), "SCALAR", 5125, 34963)
    meshes = [pygltflib.Mesh(name="terrain", primitives=[pygltflib.Primitive(attributes=pygltflib.Attributes(POSITION=pos), indices=idx)])]
    marker = np.array([[0, 0, 0], [0.2, 0, 0], [0, 1, 0]], dtype=np.float32)
    mpos = add(marker, "VEC3", 5126, 34962)
    nodes = [pygltflib.Node(name="terrain", mesh=0)]
    roots = [0]
    scatter, settings, chains, view_species = [], [], {}, []
    shifted = False
    for sp in species:
        rows, tiles = sp["rows"], sp["tiles"]
        switch, centre_y, cull = SELF_TEST_CHAINS[sp["name"]]
        chain = dict(variants=[[dict(file="species/x.glb", mesh=f"{sp['name']}_v{v}_LOD{k}", triangles=1, switch_distance_m=t)
                                for k, t in enumerate(levels)] for v, levels in enumerate(switch)],
                     height_m=2 * centre_y, centre_y_m=centre_y)
        chains[sp["name"]] = chain
        groups: dict[tuple[int, int], list[np.ndarray]] = {}
        culled = 0
        for r in rows:
            v, k = self_test_selection(r, switch, centre_y, cull)
            if k < 0 and draw_culled and sp["name"] == "grass":
                k, draw_culled = 0, False
            if k < 0:
                culled += 1
                continue
            if wrong_level and sp["name"] == "tree" and len(switch[v]) > 1:
                k, wrong_level = 1 - k, False
            groups.setdefault((v, k), []).append(r)
        children = []
        for (v, k), sel in sorted(groups.items()):
            sel = np.array(sel)
            tr = sel[:, 0:3].astype(np.float32)
            if glb_shift and not shifted:
                tr[0, 1] += glb_shift
                shifted = True
            meshes.append(pygltflib.Mesh(name=f"{sp['name']}_v{v}_LOD{k}",
                                         primitives=[pygltflib.Primitive(attributes=pygltflib.Attributes(POSITION=mpos))]))
            ext = {"attributes": {"TRANSLATION": add(tr, "VEC3", 5126),
                                  "ROTATION": add(sel[:, 3:7].astype(np.float32), "VEC4", 5126),
                                  "SCALE": add(sel[:, 7:10].astype(np.float32), "VEC3", 5126)}}
            nodes.append(pygltflib.Node(name=f"{sp['name']}_v{v}_LOD{k}", mesh=len(meshes) - 1, extensions={INSTANCING: ext},
                                        extras=dict(species=sp["name"], variant=v, level=k, mesh=f"{sp['name']}_v{v}_LOD{k}")))
            children.append(len(nodes) - 1)
        nodes.append(pygltflib.Node(name=sp["name"], children=children))
        roots.append(len(nodes) - 1)
        drawn = sum(len(g) for g in groups.values())
        view_species.append(dict(name=sp["name"], placed=len(rows), drawn=drawn, culled=len(rows) - drawn,
                                 cull=dict(distance_m=cull[0], scales_with_view=cull[1])))
        # each row's variant column: the documented hash of x and z (written scalar by scalar)
        lines = [PLACEMENT_HEADER] + [",".join([*(repr(float(v)) for v in r), str(int(t)),
                                                 str(self_test_selection(r, switch, centre_y, cull)[0])])
                                       for r, t in zip(rows, tiles)]
        (d / "placements" / f"{sp['name']}.csv").write_text("\n".join(lines) + "\n")
        per_tile = [dict(tile=int(t), count=int((tiles == t).sum()),
                         aabb_min=rows[tiles == t][:, 0:3].min(axis=0).tolist(),
                         aabb_max=rows[tiles == t][:, 0:3].max(axis=0).tolist()) for t in sorted(set(tiles.tolist()))]
        (d / "placements" / f"{sp['name']}.json").write_text(json.dumps(dict(
            species=sp["name"], count=len(rows) + json_delta, stats=dict(count=len(rows) + json_delta, per_tile=per_tile))))
        scatter.append(dict(name=sp["name"], count=len(rows), table=f"placements/{sp['name']}.csv",
                            summary=f"placements/{sp['name']}.json", tiles=len(per_tile)))
        settings.append(dict(name=sp["name"], placement=sp["placement"], min_spacing_m=sp["min_spacing_m"],
                             scale=[0.5, 2.0], exclusions=sp.get("exclusions", [])))
    gl = pygltflib.GLTF2(asset=pygltflib.Asset(version="2.0"), scene=0, scenes=[pygltflib.Scene(nodes=roots)],
                         extensionsUsed=[INSTANCING], extensionsRequired=[INSTANCING] if required else [],
                         nodes=nodes, meshes=meshes, buffers=[pygltflib.Buffer(byteLength=len(blob))],
                         bufferViews=views, accessors=accessors)
    gl.set_binary_blob(bytes(blob))
    gl.save_binary(str(d / "scene.glb"))
    view = dict(camera=dict(name="view0", eye=SELF_TEST_EYE, forward=[0, 0, -1], fov_y_deg=60, size_px=[1920, 1080]),
                distance_factor=1.0, terrain=dict(chunks_per_level=[1], triangles=len(faces), full_detail_triangles=len(faces)),
                species=view_species, triangles=0, draw_calls=0, full_detail_triangles=0, full_detail_draw_calls=0)
    (d / "manifest.json").write_text(json.dumps(dict(
        scene=d.name, scatter=dict(scene="scene.glb", species=scatter), terrain=dict(output_triangles=len(faces)),
        view=dict(scene="scene.glb", bytes=0, views=[view], chains=chains), settings=dict(species=settings))))
    return d


def placement_self_test(d: Path) -> list[tuple[str, bool, str]]:
    """The placements check on a synthetic scene: the good one passes, each broken one fails."""
    def rows_at(xz: np.ndarray, dy: float = 0.0) -> np.ndarray:
        yaw = np.linspace(0, 3, len(xz))
        q = np.stack([np.zeros(len(xz)), np.sin(yaw / 2), np.zeros(len(xz)), np.cos(yaw / 2)], 1)
        y = 0.1 * xz[:, 0] + 0.05 * xz[:, 1] + 3 + dy
        s = np.full((len(xz), 3), 1.25)
        return np.column_stack([xz[:, 0], y, xz[:, 1], q, s, np.degrees(yaw)])

    trees_xz = np.array([[3.3, 4.1], [9.7, 5.2], [20.5, 21.25], [27.1, 9.9]])
    grass_xz = np.array([[1.0, 1.0], [6.5, 6.5], [15.0, 3.0], [22.2, 30.0], [30.0, 30.0], [14.0, 25.0]])
    tile_of = lambda xz: (xz[:, 0] >= 16).astype(np.int64) + 2 * (xz[:, 1] >= 16).astype(np.int64)  # noqa: E731

    def species(trees=trees_xz, grass=grass_xz, tree_dy=0.0, shuffle=False):
        g_rows, g_tiles = rows_at(grass), tile_of(grass)
        if shuffle:  # CSV rows not in tile order: the writer's grouping (stable by tile) must still match
            g_rows, g_tiles = g_rows[::-1].copy(), g_tiles[::-1].copy()
        return [dict(name="tree", placement="poisson", min_spacing_m=5.0, rows=rows_at(trees, tree_dy), tiles=tile_of(trees)),
                dict(name="grass", placement="jittered", min_spacing_m=0.0, rows=g_rows, tiles=g_tiles,
                     exclusions=[dict(species="tree", radius_m=1.5)])]

    close_trees = trees_xz.copy()
    close_trees[1] = close_trees[0] + [3.0, 0.0]
    grass_near_tree = grass_xz.copy()
    grass_near_tree[1] = trees_xz[1] + [0.5, 0.5]
    cases = [
        ("placements good", write_instanced_scene(d / "good", species()), True),
        ("placements good, CSV not in tile order", write_instanced_scene(d / "shuffled", species(shuffle=True)), True),
        ("placements not required", write_instanced_scene(d / "notreq", species(), required=False), False),
        ("placements glb != CSV", write_instanced_scene(d / "shift", species(), glb_shift=0.01), False),
        ("placements drawn at the wrong level", write_instanced_scene(d / "level", species(), wrong_level=True), False),
        ("placements culled row drawn", write_instanced_scene(d / "culled", species(), draw_culled=True), False),
        ("placements off the terrain", write_instanced_scene(d / "off", species(tree_dy=0.01)), False),
        ("placements poisson too close", write_instanced_scene(d / "close", species(trees=close_trees)), False),
        ("placements exclusion broken", write_instanced_scene(d / "excl", species(grass=grass_near_tree)), False),
        ("placements JSON count", write_instanced_scene(d / "count", species(), json_delta=1), False),
    ]
    out = []
    for name, folder, expect_ok in cases:
        try:
            check_placements(folder, verbose=False)
            ok, detail = True, "passed"
        except CheckFailed as e:
            ok, detail = False, f"failed: {e}"
        out.append((name, ok == expect_ok, detail))
    return out


def placements_main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description="check a built scene's placements against scene.glb and the terrain")
    parser.add_argument("--placements", required=True, metavar="SCENE_DIR", help="the scene folder (out/<scene>/)")
    args = parser.parse_args(argv)
    name = Path(args.placements).name
    try:
        facts = check_placements(Path(args.placements))
        print(f"OK    {name}: {'; '.join(facts)}")
        return 0
    except CheckFailed as e:
        print(f"FAIL  {name}: {e}", file=sys.stderr)
    except (OSError, ValueError, KeyError, TypeError) as e:
        print(f"FAIL  {name}: could not read/check ({type(e).__name__}: {e})", file=sys.stderr)
    return 1


def main() -> int:
    if sys.argv[1:] == ["--self-test"]:
        return self_test()
    if "--scene" in sys.argv[1:]:
        return scene_main(sys.argv[1:])
    if "--placements" in sys.argv[1:]:
        return placements_main(sys.argv[1:])
    if sys.argv[1:2] == ["--tiles"] and len(sys.argv) == 3:
        d = Path(sys.argv[2])
        return run_and_report(d.name, lambda: ("; ".join(check_tiles(d, json.loads((d / "manifest.json").read_text()))), 0, 0),
                              None, 2)
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("file", help="a .glb, .gltf or .obj written by verdant")
    parser.add_argument("--report", required=True, help="the JSON report written with --report")
    parser.add_argument("--watertight", action="store_true", help="require a closed solid of positive volume")
    parser.add_argument("--thumb", help="render a 512x384 thumbnail PNG here and check it is not empty")
    parser.add_argument("--summary-tsv", help="append 'file<TAB>status<TAB>tris<TAB>verts' to this file")
    args = parser.parse_args()
    name = Path(args.file).name

    def checked():
        summary, tris, verts = check_file(args)
        return (f"{name}: {summary}", tris, verts)

    return run_and_report(name, checked, args.summary_tsv, 2)


if __name__ == "__main__":
    sys.exit(main())
