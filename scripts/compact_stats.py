#!/usr/bin/env python3
"""What a glb holds and how far its vertices are from a reference file's: for comparing compact
outputs (verdant --quantize / --compress, gltfpack) on the same input (scripts/bench_compact.sh).

    compact_stats.py FILE.glb [--reference F32.glb] [--json]

Prints one line: total bytes, image bytes, bytes of custom attributes (`_NAME`, application data
such as verdant's wind, which gltfpack drops), triangles, vertices and, with --reference, the
largest distance (metres, world space) from any vertex of FILE to the nearest vertex of the
reference: the position error quantization added, measured the same way for any writer whatever
its vertex order (both files must hold the same meshes; a compressed file cannot be read here,
measure its uncompressed twin: meshopt compression is lossless). With --reference it also gives,
per custom attribute both files hold on the same vertices (verdant's files keep their vertex
order), the largest difference per component as an engine reads it: normalized integers times
the range the primitive's extras note (`verdant_attribute_ranges`, docs/wind.md), and that range.

World space: every node of every glTF scene (a LoD chain's coarser levels are in the second one)
with its parents' transforms; an instanced node (EXT_mesh_gpu_instancing) by its first instance.
"""
import argparse
import base64
import json
import struct
import sys

import numpy as np

COMPONENT = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
NORMALIZE = {5120: 127.0, 5121: 255.0, 5122: 32767.0, 5123: 65535.0}
WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}


def load(path):
    data = open(path, "rb").read()
    if data[:4] != b"glTF":
        raise SystemExit(f"{path}: not a GLB")
    n = struct.unpack("<I", data[12:16])[0]
    doc = json.loads(data[20:20 + n])
    rest = data[20 + n:]
    blob = rest[8:8 + struct.unpack("<I", rest[:4])[0]] if len(rest) >= 8 else b""
    buffers = []
    for b in doc.get("buffers", []):
        uri = b.get("uri")
        if uri is None:
            buffers.append(blob)
        elif uri.startswith("data:"):
            buffers.append(base64.b64decode(uri.split(",", 1)[1]))
        else:
            buffers.append(None)
    return data, doc, buffers


def accessor(doc, buffers, index):
    a = doc["accessors"][index]
    view = doc["bufferViews"][a["bufferView"]]
    if "extensions" in view and "EXT_meshopt_compression" in view["extensions"]:
        raise SystemExit("a compressed file: measure its uncompressed twin")
    dt = np.dtype(COMPONENT[a["componentType"]])
    k = WIDTH[a["type"]]
    stride = view.get("byteStride") or k * dt.itemsize
    start = view.get("byteOffset", 0) + a.get("byteOffset", 0)
    raw = np.frombuffer(buffers[view["buffer"]], np.uint8, stride * a["count"], start).reshape(-1, stride)
    v = raw[:, :k * dt.itemsize].copy().view(dt).reshape(-1, k).astype(np.float64)
    if a.get("normalized"):
        v = np.maximum(v / NORMALIZE[a["componentType"]], -1.0)
    return v


def quat_matrix(q):
    x, y, z, w = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def trs(t, r, s):
    m = np.eye(4)
    m[:3, :3] = quat_matrix(r) * np.asarray(s)[None, :]
    m[:3, 3] = t
    return m


def local(node):
    if "matrix" in node:
        return np.asarray(node["matrix"], dtype=np.float64).reshape(4, 4).T
    return trs(node.get("translation", [0, 0, 0]), node.get("rotation", [0, 0, 0, 1]), node.get("scale", [1, 1, 1]))


def world_points(doc, buffers):
    """Every mesh vertex in world space, once per node showing it (first instance of instanced nodes)."""
    out = []
    nodes = doc.get("nodes", [])
    seen = set()

    def visit(i, parent):
        if i in seen:
            return
        seen.add(i)
        node = nodes[i]
        m = parent @ local(node)
        if "mesh" in node:
            inst = node.get("extensions", {}).get("EXT_mesh_gpu_instancing")
            mi = m
            if inst:
                at = inst["attributes"]
                t = accessor(doc, buffers, at["TRANSLATION"])[0] if "TRANSLATION" in at else [0, 0, 0]
                r = accessor(doc, buffers, at["ROTATION"])[0] if "ROTATION" in at else [0, 0, 0, 1]
                s = accessor(doc, buffers, at["SCALE"])[0] if "SCALE" in at else [1, 1, 1]
                mi = m @ trs(t, r, s)
            for p in doc["meshes"][node["mesh"]]["primitives"]:
                v = accessor(doc, buffers, p["attributes"]["POSITION"])
                out.append(v @ mi[:3, :3].T + mi[:3, 3])
        for c in node.get("children", []):
            visit(c, m)

    for scene in doc.get("scenes", []):
        for r in scene.get("nodes", []):
            visit(r, np.eye(4))
    for i in range(len(nodes)):  # nodes in no scene
        visit(i, np.eye(4))
    return np.concatenate(out) if out else np.zeros((0, 3))


def view_bytes(doc, view_index):
    view = doc["bufferViews"][view_index]
    ext = view.get("extensions", {}).get("EXT_meshopt_compression")
    return ext["byteLength"] if ext else view["byteLength"]


def stats(path):
    data, doc, buffers = load(path)
    image = sum(view_bytes(doc, i["bufferView"]) for i in doc.get("images", []) if "bufferView" in i)
    custom_views = set()
    triangles = vertices = 0
    for m in doc.get("meshes", []):
        for p in m["primitives"]:
            for name, a in p["attributes"].items():
                if name.startswith("_"):
                    custom_views.add(doc["accessors"][a]["bufferView"])
            vertices += doc["accessors"][p["attributes"]["POSITION"]]["count"]
            if "indices" in p and p.get("mode", 4) == 4:
                triangles += doc["accessors"][p["indices"]]["count"] // 3
    custom = sum(view_bytes(doc, v) for v in custom_views)
    return {"bytes": len(data), "image_bytes": image, "custom_bytes": custom, "triangles": triangles,
            "vertices": vertices, "extensions": doc.get("extensionsUsed", [])}, doc, buffers


def custom_values(doc, buffers, prim, name):
    """A custom attribute as an engine reads it: normalized integers times their noted range."""
    v = accessor(doc, buffers, prim["attributes"][name])
    r = prim.get("extras", {}).get("verdant_attribute_ranges", {}).get(name)
    return (v * np.asarray(r, dtype=np.float64) if r is not None else v), r


def custom_error(doc, buffers, rdoc, rbuf):
    """Per attribute name: the largest |value - reference| per component over the primitives both
    files hold in the same order with the same vertex count, and the range noted for it (or None)."""
    err, ranges = {}, {}
    for m, rm in zip(doc.get("meshes", []), rdoc.get("meshes", [])):
        for p, rp in zip(m["primitives"], rm["primitives"]):
            for name in p["attributes"]:
                if not name.startswith("_") or name not in rp["attributes"]:
                    continue
                v, r = custom_values(doc, buffers, p, name)
                w, _ = custom_values(rdoc, rbuf, rp, name)
                if v.shape != w.shape:
                    continue
                e = np.abs(v - w).max(axis=0) if len(v) else np.zeros(v.shape[1])
                err[name] = np.maximum(err.get(name, e), e).tolist()
                if r is not None:
                    ranges[name] = r
    return err, ranges


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("file")
    ap.add_argument("--reference")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    s, doc, buffers = stats(a.file)
    if a.reference:
        from scipy.spatial import cKDTree
        _, rdoc, rbuf = load(a.reference)
        ref = world_points(rdoc, rbuf)
        pts = world_points(doc, buffers)
        d, _ = cKDTree(ref).query(pts)
        s["position_error_m"] = float(d.max()) if len(d) else 0.0
        s["custom_error"], s["custom_range"] = custom_error(doc, buffers, rdoc, rbuf)
    if a.json:
        print(json.dumps(s))
    else:
        print(" ".join(f"{k}={v}" for k, v in s.items()))


if __name__ == "__main__":
    sys.exit(main())
