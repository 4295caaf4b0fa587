#!/usr/bin/env python3
"""Writes the seed corpora of the fuzz targets (fuzz/corpus/<target>/), standard library only.

Seeds are small valid inputs of every kind a target reads, made here or by verdant itself:
heightmaps in each encoding (PNG 8/16-bit gray, Terrain-RGB, Terrarium, float TIFF, .hgt, .r16),
the project's own L-systems and presets plus hand-written files in each dialect, OBJ models with a
material library and texture (the `obj \\0 mtl \\0 texture` layout of verdant::harness::obj), glTF
files verdant writes and hand-written JSON ones, placement tables. Nothing is copied from
../shared/data.

    python3 scripts/fuzz_seeds.py target/release/verdant fuzz/corpus
"""

import os
import shutil
import struct
import subprocess
import sys
import tempfile
import zlib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def png(width, height, channels, depth, rows):
    """A PNG of `rows` (lists of channel values per pixel, row-major)."""
    color_type = {1: 0, 3: 2, 4: 6}[channels]
    raw = bytearray()
    for row in rows:
        raw.append(0)  # filter: none
        for v in row:
            raw += struct.pack(">H", v) if depth == 16 else bytes([v])

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    ihdr = struct.pack(">IIBBBBB", width, height, depth, color_type, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(bytes(raw), 9)) + chunk(b"IEND", b"")


def float_tiff(width, height, values):
    """A little-endian, uncompressed, one-strip 32-bit float TIFF."""
    data = b"".join(struct.pack("<f", v) for v in values)
    entries = [
        (256, 3, 1, width), (257, 3, 1, height), (258, 3, 1, 32), (259, 3, 1, 1), (262, 3, 1, 1),
        (273, 4, 1, 0), (277, 3, 1, 1), (278, 3, 1, height), (279, 4, 1, len(data)), (339, 3, 1, 3),
    ]
    ifd_offset = 8 + len(data)
    out = bytearray(b"II*\x00" + struct.pack("<I", ifd_offset) + data)
    out += struct.pack("<H", len(entries))
    for tag, kind, count, value in entries:
        if tag == 273:
            value = 8
        out += struct.pack("<HHI", tag, kind, count) + (struct.pack("<HH", value, 0) if kind == 3 else struct.pack("<I", value))
    out += struct.pack("<I", 0)
    return bytes(out)


def hill(i, j, n):
    d = ((i - n / 2) ** 2 + (j - n / 2) ** 2) ** 0.5
    return max(0.0, 1.0 - d / (n / 2))


def heightmaps():
    n = 17
    h = [[hill(i, j, n) for i in range(n)] for j in range(n)]
    seeds = {
        "gray16.png": png(n, n, 1, 16, [[int(v * 65535) for v in row] for row in h]),
        "gray8.png": png(n, n, 1, 8, [[int(v * 255) for v in row] for row in h]),
        "flat.png": png(4, 4, 1, 8, [[7] * 4 for _ in range(4)]),
        "step.png": png(8, 3, 1, 16, [[0] * 4 + [65535] * 4 for _ in range(3)]),
    }
    for name, base, scale in (("terrain_rgb.png", 10000.0, 10.0), ("terrarium.png", 32768.0, 256.0)):
        rows = []
        for row in h:
            out = []
            for v in row:
                metres = 500.0 + 800.0 * v
                if name == "terrain_rgb.png":
                    k = int(round((metres + base) * scale))
                    out += [(k >> 16) & 255, (k >> 8) & 255, k & 255]
                else:
                    k = metres + base
                    out += [int(k // 256) & 255, int(k) & 255, int((k % 1) * 256) & 255]
            rows.append(out)
        seeds[name] = png(n, n, 3, 8, rows)
    seeds["rgba.png"] = png(3, 3, 4, 8, [[10, 10, 10, 255] * 3 for _ in range(3)])
    seeds["float.tif"] = float_tiff(n, n, [1000.0 + 50.0 * v for row in h for v in row])
    seeds["high.tif"] = float_tiff(5, 5, [8800.0 + 0.001 * k for k in range(25)])
    seeds["srtm.hgt"] = b"".join(struct.pack(">h", v) for v in (10, 20, 30, 40, -32768, 60, 70, 80, 90))
    seeds["ramp.r16"] = b"".join(struct.pack("<H", k * 1000) for k in range(16))
    return seeds


LSYSTEMS = {
    # lparser 4: recursion, angle, thickness, axiom, rules, @
    "v4_tree.ls": b"5\n22\n20\nA\nA=F[&+A]////[&+A]/////[&+A]\nF=!F\n@\n",
    "v4_leaf.ls": b"3\n30\n10\nX\nX=F[+X]F[-X]+X{.f.f.}\nF=FF\n@\n",
    # lparser 5 keyword format
    "v5_fork.ls": b"recursion 4\nangle 30\nthickness 10\naxiom F(2)A\nrule A = !(0.7)[&(20)F A][^(20)F A]\n",
    "v5_colour.ls": b"recursion 3\nangle 45\ncolor 3 200 40 40\naxiom c(3)FX\nrule X = [+FX][-FX]L\nrule L = {.f.-f.-f.}\n",
    # the point-sprite thesis' stochastic format
    "ls_stochastic.ls": b"3-2-2\nX(50)=F[+X]F[-X]\nX(50)=F[-X]+X\nF=FF\n",
}


def lsystems():
    seeds = dict(LSYSTEMS)
    for path in list((ROOT / "src/lsystem/library").glob("*.ls")) + list((ROOT / "presets/lsystems").glob("*.ls")):
        seeds["project_" + path.name] = path.read_bytes()
    return seeds


def presets(verdant, tmp):
    seeds = {path.name: path.read_bytes() for path in (ROOT / "presets").glob("*.toml")}
    template = tmp / "template.toml"
    subprocess.run([verdant, "-q", "preset", "new", "seed", "--output", str(template)], check=True)
    seeds["template.toml"] = template.read_bytes()
    seeds["minimal.toml"] = b'[scene]\nname = "tiny"\n\n[terrain]\nprocedural = { size = 65, cell = 2.0, seed = 3 }\n'
    return seeds


CUBE_OBJ = b"""mtllib model.mtl
o cube
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 0 0 1
v 1 0 1
v 1 1 1
v 0 1 1
vt 0 0
vt 1 0
vt 1 1
vt 0 1
vn 0 0 -1
usemtl bark
f 1/1/1 4/4/1 3/3/1 2/2/1
f 5/1 6/2 7/3 8/4
f 1 2 6 5
f 2 3 7 6
f 3 4 8 7
f 4 1 5 8
"""
CUBE_MTL = b"newmtl bark\nKd 0.5 0.35 0.2\nd 1\nmap_Kd texture.png\n"


def objs(verdant, tmp):
    texture = png(2, 2, 3, 8, [[200, 10, 10, 10, 200, 10], [10, 10, 200, 200, 200, 200]])
    seeds = {
        "cube.bin": CUBE_OBJ + b"\0" + CUBE_MTL + b"\0" + texture,
        "cube_no_mtl.bin": CUBE_OBJ.replace(b"mtllib model.mtl\n", b""),
        "triangle.bin": b"v 0 0 0\nv 1 0 0\nv 0 0 1\nf 1 3 2\n",
    }
    out = tmp / "model.obj"
    subprocess.run([verdant, "-q", "tree", "builtin:bush", "--lods", "1", "-o", str(out)], check=True)
    seeds["bush.bin"] = out.read_bytes() + b"\0" + (tmp / "model.mtl").read_bytes() + b"\0" + texture
    return seeds


def gltfs(verdant, tmp, maps):
    seeds = {}
    src = tmp / "hill.png"
    src.write_bytes(maps["gray16.png"])
    for name in ("terrain.glb", "terrain.gltf"):
        subprocess.run([verdant, "-q", "terrain", str(src), "--max-error", "0.5", "-o", str(tmp / name)], check=True)
        seeds[name] = (tmp / name).read_bytes()
    # KHR_mesh_quantization and EXT_meshopt_compression: the validator decodes both
    for name, flag in (("terrain_quantized.glb", "--quantize"), ("terrain_compressed.glb", "--compress")):
        subprocess.run([verdant, "-q", "terrain", str(src), "--max-error", "0.5", flag, "-o", str(tmp / name)], check=True)
        seeds[name] = (tmp / name).read_bytes()
    subprocess.run([verdant, "-q", "tree", "builtin:bush", "--lods", "1", "-o", str(tmp / "bush.glb")], check=True)
    seeds["bush.glb"] = (tmp / "bush.glb").read_bytes()
    # a triangle in a data: buffer (3 f32 positions, then 3 u16 indices)
    import base64
    buf = struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 0, 1) + struct.pack("<3H", 0, 2, 1) + b"\0\0"
    uri = "data:application/octet-stream;base64," + base64.b64encode(buf).decode()
    seeds["triangle.gltf"] = (
        '{"asset":{"version":"2.0"},"scene":0,"scenes":[{"nodes":[0]}],"nodes":[{"mesh":0,"children":[]}],'
        '"meshes":[{"primitives":[{"attributes":{"POSITION":0},"indices":1}]}],'
        '"accessors":[{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,0,1]},'
        '{"bufferView":1,"componentType":5123,"count":3,"type":"SCALAR"}],'
        '"bufferViews":[{"buffer":0,"byteLength":36},{"buffer":0,"byteOffset":36,"byteLength":6}],'
        '"buffers":[{"byteLength":44,"uri":"' + uri + '"}]}'
    ).encode()
    return seeds


def placements_bin():
    """Binary tables (verdant::export::table_bin): magic, version, row count, then the arrays."""
    import struct
    rows = [((0.5, 12.25, 3.0), (0.0, 0.38268343, 0.0, 0.9238795), (1.0, 1.0, 1.0), 45.0, 0, 0),
            ((-0.0, 1e-7, 123456.789), (0.0, -0.0, 0.0, 1.0), (0.8, 1.2, 0.8), 0.0, 17, 2)]
    def table(rows):
        out = b"VPLT" + struct.pack("<IQ", 1, len(rows))
        out += b"".join(struct.pack("<3d", *r[0]) for r in rows)
        out += b"".join(struct.pack("<4f", *r[1]) for r in rows)
        out += b"".join(struct.pack("<3f", *r[2]) for r in rows)
        out += b"".join(struct.pack("<f", r[3]) for r in rows)
        out += b"".join(struct.pack("<I", r[4]) for r in rows)
        out += b"".join(struct.pack("<I", r[5]) for r in rows)
        return out
    return {"two.bin": table(rows), "empty.bin": table([])}


def placements():
    header = b"x,y,z,qx,qy,qz,qw,sx,sy,sz,yaw_deg,tile,variant\n"
    rows = [
        b"0.5,12.25,3.0,0.0,0.38268343,0.0,0.9238795,1.0,1.0,1.0,45.0,0,0",
        b"-0.0,1e-7,123456.789,0.0,-0.0,0.0,1.0,0.8,1.2,0.8,0.0,17,2",
        b"8191.999,8800.001,0.001,0.0,1.0,0.0,0.0,2.5,2.5,2.5,180.0,4294967295,4294967295",
    ]
    return {"three.csv": header + b"\n".join(rows) + b"\n", "header.csv": header}


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    verdant, out = os.path.abspath(sys.argv[1]), Path(sys.argv[2])
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        maps = heightmaps()
        corpora = {
            "heightmap": maps,
            "lsystem": lsystems(),
            "preset": presets(verdant, tmp),
            "obj": objs(verdant, tmp),
            "gltf": gltfs(verdant, tmp, maps),
            "placements": placements(),
            "placements_bin": placements_bin(),
        }
        for target, seeds in corpora.items():
            folder = out / target
            folder.mkdir(parents=True, exist_ok=True)
            for name, data in seeds.items():
                (folder / name).write_bytes(data)
            print(f"{target}: {len(seeds)} seeds in {folder}")


if __name__ == "__main__":
    main()
