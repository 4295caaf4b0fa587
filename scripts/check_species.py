#!/usr/bin/env python3
"""Independent checks of a built scene's generated plants (species/ and atlases/).

For every grass species (`species/<name>_LOD<n>.glb`):
- each LoD re-imports with trimesh, has MASK double-sided textured materials, and the triangle
  counts strictly decrease from LoD0 to the last level;
- every LoD carries `_WIND` (docs/wind.md), read with pygltflib: within its ranges, bend weight 0 at
  the ground and growing with height; no COLOR_0 (it would darken the blades and cut their alpha);
- pyrender (offscreen EGL) renders every LoD from the same cameras (45° and 75° above the horizon):
  every render is non-empty and its silhouette is similar to LoD0's (IoU ≥ MIN_IOU, covered area
  within a factor MAX_AREA_RATIO);
- `<name>.glb` has MSFT_lod on its root nodes with screen coverages that never increase;
- the atlas mip chain (`atlases/<name>.png`, `<name>_mip<k>.png`) halves in size per level and keeps
  level 0's alpha coverage (texels ≥ the material's alphaCutoff) within MIP_TOLERANCE on every
  level whose sides are at least MIP_MIN_SIDE texels (below that a level has too few texels
  for one alpha scale to match a coverage within 2 %: a 16×16 level has 256).
For every flower species (`species/<name>.glb` without LoD files): it re-imports, renders non-empty.
For every L-system tree species (variants `species/<name>_v<k>…`) and every mesh species (an OBJ
model, `species/<name>…`), as the manifest's `look` says:
- each variant's LoDs re-import with trimesh, triangle counts strictly decrease, every face index is
  in range and every position finite;
- `<name>_v<k>.glb` has MSFT_lod with coverages that never increase;
- pyrender renders every LoD non-empty; the mesh levels (simplified, cards, decimated) keep a silhouette like
  LoD0's (IoU ≥ MIN_IOU) — the billboard and impostor levels are textured cards whose alpha
  pyrender's flat render does not cut, so for them only non-emptiness is checked;
- the variant's atlas mips keep their alpha coverage (as for grass);
- tree levels carry `_WIND` (and the full and simplified ones `_WIND_BRANCH`), OBJ models none.
Flowers carry `_WIND` too.

Usage: check_species.py SCENE_DIR [--summary-tsv FILE]   (exit 1 on any failure)
"""
from __future__ import annotations

import json
import os
import sys
from pathlib import Path

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
import numpy as np  # noqa: E402

if not hasattr(np, "infty"):  # pyrender 0.1.45 still uses np.infty
    np.infty = np.inf
import pygltflib  # noqa: E402
import trimesh  # noqa: E402
from PIL import Image  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from check_outputs import gltf_buffers, read_accessor  # noqa: E402

MIN_IOU = 0.15
MAX_AREA_RATIO = 4.0
MIP_TOLERANCE = 0.02
MIP_MIN_SIDE = 32
RENDER_PX = 256
ELEVATIONS_DEG = (45.0, 75.0)


class CheckFailed(Exception):
    pass


def look_at(eye: np.ndarray, target: np.ndarray) -> np.ndarray:
    f = target - eye
    f /= np.linalg.norm(f)
    right = np.cross(f, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, f)
    pose = np.eye(4)
    pose[:3, 0], pose[:3, 1], pose[:3, 2], pose[:3, 3] = right, up, -f, eye
    return pose


class Renderer:
    def __init__(self):
        import pyrender
        self.pyrender = pyrender
        self.r = pyrender.OffscreenRenderer(RENDER_PX, RENDER_PX)

    def silhouettes(self, scene: trimesh.Scene, centre: np.ndarray, radius: float) -> list[np.ndarray]:
        pr = self.pyrender
        out = []
        for el in ELEVATIONS_DEG:
            ps = pr.Scene.from_trimesh_scene(scene, bg_color=[0, 0, 0, 0], ambient_light=[1.0, 1.0, 1.0])
            e = np.radians(el)
            eye = centre + 2.6 * radius * np.array([0.3 * np.cos(e), np.sin(e), np.cos(e)])
            ps.add(pr.PerspectiveCamera(yfov=np.radians(40.0)), pose=look_at(eye, centre))
            colour, _ = self.r.render(ps, flags=pr.RenderFlags.FLAT)
            out.append(colour.max(axis=2) > 8)
        return out


def triangles(scene: trimesh.Scene) -> int:
    return sum(len(g.faces) for g in scene.dump())


def check_materials(gltf: pygltflib.GLTF2, name: str) -> None:
    if not gltf.materials:
        raise CheckFailed(f"{name}: no materials")
    for m in gltf.materials:
        if m.alphaMode != "MASK" or not m.doubleSided:
            raise CheckFailed(f"{name}: material {m.name!r} is {m.alphaMode}, doubleSided={m.doubleSided}; expected MASK, double-sided")
        if m.pbrMetallicRoughness is None or m.pbrMetallicRoughness.baseColorTexture is None:
            raise CheckFailed(f"{name}: material {m.name!r} has no base colour texture")


def check_wind(path: Path, branch: bool = False, required: bool = True) -> str:
    """docs/wind.md, read back from the file: `_WIND` (VEC4) on every primitive (none on a model
    that does not sway: `required=False`), within its ranges, the bend weight 0 at the ground and
    one non-decreasing function of height across each mesh; `_WIND_BRANCH` too when `branch`; no
    COLOR_0 unless it is an opaque colour."""
    gltf = pygltflib.GLTF2().load(str(path))
    buffers = gltf_buffers(gltf, path)
    checked = 0
    for mesh in gltf.meshes:
        heights, bends = [], []
        for p in mesh.primitives:
            attrs = p.attributes.__dict__ if hasattr(p.attributes, "__dict__") else dict(p.attributes)
            pos = read_accessor(gltf, buffers, attrs["POSITION"]).astype(np.float64)
            colour_index = attrs.get("COLOR_0")
            if colour_index is not None:
                colour = read_accessor(gltf, buffers, colour_index).astype(np.float64)
                if colour.shape[1] == 4 and np.any(colour[:, 3] != 1.0):
                    raise CheckFailed(f"{path.name}: mesh {mesh.name!r} has COLOR_0 with alpha below 1 (glTF multiplies it into the material's alpha)")
                if colour.min() < 0 or colour.max() > 1:
                    raise CheckFailed(f"{path.name}: COLOR_0 outside 0..1")
            wind_index = attrs.get("_WIND")
            if not required:
                if wind_index is not None:
                    raise CheckFailed(f"{path.name}: mesh {mesh.name!r} of a model that does not sway has _WIND")
                continue
            if wind_index is None:
                raise CheckFailed(f"{path.name}: mesh {mesh.name!r} lacks _WIND")
            wind = read_accessor(gltf, buffers, wind_index).astype(np.float64)
            if wind.shape != (len(pos), 4):
                raise CheckFailed(f"{path.name}: _WIND {wind.shape} for {len(pos)} vertices")
            lo = np.array([0, 0, 1e-9, 0])
            hi = np.array([1, 2 * np.pi, 4, 1])
            if np.any(wind < lo) or np.any(wind > hi):
                raise CheckFailed(f"{path.name}: _WIND outside (0..1, 0..2π, 0..4 Hz, 0..1)")
            if branch:
                b_index = attrs.get("_WIND_BRANCH")
                if b_index is None:
                    raise CheckFailed(f"{path.name}: mesh {mesh.name!r} lacks _WIND_BRANCH")
                b = read_accessor(gltf, buffers, b_index).astype(np.float64)
                if b.shape != (len(pos), 4) or np.any(b[:, [0, 2]] < 0) or np.any(b[:, [0, 2]] > 1) or np.any(b[:, [1, 3]] < 0) or np.any(b[:, [1, 3]] > 2 * np.pi):
                    raise CheckFailed(f"{path.name}: _WIND_BRANCH outside (0..1, 0..2π, 0..1, 0..2π)")
            heights.append(pos[:, 1])
            bends.append(wind[:, 0])
            checked += len(pos)
        if heights:
            y, w = np.concatenate(heights), np.concatenate(bends)
            order = np.lexsort((w, y))
            if np.any(np.diff(w[order]) < -1e-6):
                raise CheckFailed(f"{path.name}: mesh {mesh.name!r}: the bend weight does not grow with height")
            ground = np.abs(y) < 1e-6
            if ground.any() and np.max(w[ground]) > 1e-6:
                raise CheckFailed(f"{path.name}: mesh {mesh.name!r}: the bend weight is not 0 at the ground")
    return f"wind ok on {checked} vertices" if required else "no wind data (does not sway)"


def check_lod_chain(path: Path, levels: int) -> str:
    gltf = pygltflib.GLTF2().load(str(path))
    used = set(gltf.extensionsUsed or [])
    if "MSFT_lod" not in used:
        raise CheckFailed(f"{path.name}: MSFT_lod not in extensionsUsed")
    roots = gltf.scenes[gltf.scene or 0].nodes
    for r in roots:
        node = gltf.nodes[r]
        ids = (node.extensions or {}).get("MSFT_lod", {}).get("ids", [])
        cov = (node.extras or {}).get("MSFT_screencoverage", [])
        if len(ids) != levels - 1 or len(cov) != levels:
            raise CheckFailed(f"{path.name}: node {node.name!r} has {len(ids)} LoD ids and {len(cov)} coverages, expected {levels - 1} and {levels}")
        if any(b > a for a, b in zip(cov, cov[1:])):
            raise CheckFailed(f"{path.name}: node {node.name!r} screen coverages increase: {cov}")
    return f"MSFT_lod on {len(roots)} nodes"


def alpha_coverage(png: Path, cutoff: float) -> tuple[float, tuple[int, int]]:
    img = np.asarray(Image.open(png).convert("RGBA"))
    return float(np.mean(img[:, :, 3].astype(np.float64) / 255.0 >= np.float32(cutoff))), (img.shape[1], img.shape[0])


def check_mips(atlases: Path, stem: str, cutoff: float) -> str:
    base = atlases / f"{stem}.png"
    if not base.is_file():
        raise CheckFailed(f"{base} is missing")
    c0, (w, h) = alpha_coverage(base, cutoff)
    if c0 <= 0:
        raise CheckFailed(f"{base.name}: no texel reaches the alpha cutoff {cutoff}")
    worst, k = 0.0, 1
    while (atlases / f"{stem}_mip{k}.png").is_file():
        ck, (wk, hk) = alpha_coverage(atlases / f"{stem}_mip{k}.png", cutoff)
        if (wk, hk) != (max(1, w >> k), max(1, h >> k)) and (wk, hk) != (max(1, -(-w // 2 ** k)), max(1, -(-h // 2 ** k))):
            raise CheckFailed(f"{stem}_mip{k}.png is {wk}×{hk}; level 0 is {w}×{h}")
        if min(wk, hk) >= MIP_MIN_SIDE:
            rel = abs(ck - c0) / c0
            worst = max(worst, rel)
            if rel > MIP_TOLERANCE:
                raise CheckFailed(f"{stem}_mip{k}.png: alpha coverage {ck:.4f} vs level 0's {c0:.4f} ({rel:.1%} > {MIP_TOLERANCE:.0%})")
        k += 1
    if k == 1:
        raise CheckFailed(f"{stem}: no mip levels written")
    return f"{stem}: {k} levels, coverage within {worst:.2%}"


def check_grass(species: Path, atlases: Path, name: str, renderer: Renderer | None) -> list[str]:
    facts = []
    lods = []
    n = 0
    while (species / f"{name}_LOD{n}.glb").is_file():
        lods.append(species / f"{name}_LOD{n}.glb")
        n += 1
    scenes = [trimesh.load(p, force="scene") for p in lods]
    tris = [triangles(s) for s in scenes]
    if any(b >= a for a, b in zip(tris, tris[1:])):
        raise CheckFailed(f"{name}: LoD triangle counts do not strictly decrease: {tris}")
    facts.append(f"triangles {tris}")
    cutoff = None
    for p in lods:
        g = pygltflib.GLTF2().load(str(p))
        check_materials(g, p.name)
        cutoff = g.materials[0].alphaCutoff if g.materials[0].alphaCutoff is not None else 0.5
    facts.append(", ".join(f"LOD{k} {check_wind(p)}" for k, p in enumerate(lods)))
    facts.append(check_lod_chain(species / f"{name}.glb", len(lods)))
    if renderer is not None:
        b = scenes[0].bounds
        centre, radius = b.mean(axis=0), float(np.linalg.norm(b[1] - b[0]) / 2)
        ref = renderer.silhouettes(scenes[0], centre, radius)
        summary = []
        for k, s in enumerate(scenes):
            sil = ref if k == 0 else renderer.silhouettes(s, centre, radius)
            for view, (a, r) in enumerate(zip(sil, ref)):
                area = a.mean()
                if area < 0.002:
                    raise CheckFailed(f"{lods[k].name}: the pyrender render from view {view} is empty ({area:.4f} of the pixels)")
                iou = (a & r).sum() / max(1, (a | r).sum())
                ratio = area / max(r.mean(), 1e-9)
                if k and (iou < MIN_IOU or not (1 / MAX_AREA_RATIO <= ratio <= MAX_AREA_RATIO)):
                    raise CheckFailed(f"{lods[k].name}: silhouette from view {view} unlike LoD0's (IoU {iou:.3f}, area ratio {ratio:.2f})")
                if k:
                    summary.append(f"{iou:.2f}")
        facts.append(f"pyrender silhouettes vs LoD0 IoU {', '.join(summary)}")
    facts.append(check_mips(atlases, name, cutoff))
    facts.append(check_mips(atlases, f"{name}_blade", cutoff))
    if not (atlases / f"{name}_density.png").is_file():
        raise CheckFailed(f"{name}_density.png is missing")
    return facts


def check_flower(species: Path, atlases: Path, name: str, renderer: Renderer | None) -> list[str]:
    path = species / f"{name}.glb"
    scene = trimesh.load(path, force="scene")
    g = pygltflib.GLTF2().load(str(path))
    check_materials(g, path.name)
    facts = [f"{len(g.nodes)} variants, {triangles(scene)} triangles", check_wind(path)]
    if renderer is not None:
        b = scene.bounds
        for view, sil in enumerate(renderer.silhouettes(scene, b.mean(axis=0), float(np.linalg.norm(b[1] - b[0]) / 2))):
            if sil.mean() < 0.002:
                raise CheckFailed(f"{path.name}: the pyrender render from view {view} is empty")
    facts.append(check_mips(atlases, name, g.materials[0].alphaCutoff or 0.5))
    return facts


def check_chains(species: Path, atlases: Path, stems: list[str], kinds_of: dict, renderer: Renderer | None, sways: bool) -> list[str]:
    """`kinds_of[(stem, level)]` is the level's kind from the manifest ("full", "simplified", …);
    `sways`: an L-system tree (wind data on every level, branch data on the full and simplified ones),
    not an OBJ model (none)."""
    facts = []
    for stem in stems:
        k = stem
        lods = []
        while (species / f"{stem}_LOD{len(lods)}.glb").is_file():
            lods.append(species / f"{stem}_LOD{len(lods)}.glb")
        if not lods:
            raise CheckFailed(f"{stem}_LOD0.glb is missing")
        scenes = [trimesh.load(p, force="scene") for p in lods]
        for p, s in zip(lods, scenes):
            for g in s.dump():
                if not np.all(np.isfinite(g.vertices)):
                    raise CheckFailed(f"{p.name}: non-finite positions")
                if len(g.faces) and (g.faces.min() < 0 or g.faces.max() >= len(g.vertices)):
                    raise CheckFailed(f"{p.name}: face index out of range")
        tris = [triangles(s) for s in scenes]
        if any(b >= a for a, b in zip(tris, tris[1:])):
            raise CheckFailed(f"{stem}: LoD triangle counts do not strictly decrease: {tris}")
        facts.append(f"{k} triangles {tris}")
        facts.append(check_lod_chain(species / f"{stem}.glb", len(lods)))
        kinds = [kinds_of.get((stem, level), "") for level in range(len(lods))]
        winds = [check_wind(p, branch=kinds[level] in ("full", "simplified"), required=sways) for level, p in enumerate(lods)]
        facts.append(f"{k} " + ("; ".join(sorted(set(w.split(" on ")[0] for w in winds)))))
        if renderer is not None:
            b = scenes[0].bounds
            centre, radius = b.mean(axis=0), float(np.linalg.norm(b[1] - b[0]) / 2)
            ref = renderer.silhouettes(scenes[0], centre, radius)
            summary = []
            for level, s in enumerate(scenes):
                sil = ref if level == 0 else renderer.silhouettes(s, centre, radius)
                for view, (a, r) in enumerate(zip(sil, ref)):
                    if a.mean() < 0.002:
                        raise CheckFailed(f"{lods[level].name}: the pyrender render from view {view} is empty ({a.mean():.4f} of the pixels)")
                    iou = (a & r).sum() / max(1, (a | r).sum())
                    if level and kinds[level] in ("simplified", "cards", "decimated"):
                        if iou < MIN_IOU:
                            raise CheckFailed(f"{lods[level].name}: silhouette from view {view} unlike LoD0's (IoU {iou:.3f})")
                        summary.append(f"{iou:.2f}")
            facts.append(f"{k} pyrender IoU vs LoD0 {', '.join(summary)}")
        if len(lods) > 3:
            g = pygltflib.GLTF2().load(str(lods[3]))
            cutoff = g.materials[0].alphaCutoff if g.materials and g.materials[0].alphaCutoff is not None else 0.5
            facts.append(check_mips(atlases, stem, cutoff))
    return facts


def main(argv: list[str]) -> int:
    if not argv or argv[0].startswith("-"):
        print(__doc__)
        return 2
    scene_dir = Path(argv[0])
    tsv = Path(argv[argv.index("--summary-tsv") + 1]) if "--summary-tsv" in argv else None
    species, atlases = scene_dir / "species", scene_dir / "atlases"
    manifest = json.loads((scene_dir / "manifest.json").read_text())
    plants = manifest.get("plants") or []
    if not plants:
        print(f"{scene_dir.name}: no generated plants")
        return 0
    try:
        renderer = Renderer()
    except Exception as e:  # noqa: BLE001 — reported, and a failure: the check needs it
        print(f"FAIL {scene_dir.name}: pyrender offscreen rendering is unavailable: {e}")
        return 1
    failed = 0
    for p in plants:
        name = p["name"]
        try:
            look = p.get("look")
            if look in ("tree", "mesh"):
                kinds_of = {(Path(lod["file"]).stem.rsplit("_LOD", 1)[0], lod["level"]): lod.get("kind", "") for lod in p.get("lods", [])}
                stems = sorted({stem for stem, _ in kinds_of})
                if not stems:
                    raise CheckFailed(f"{name}: the manifest lists no LoD files")
                facts = check_chains(species, atlases, stems, kinds_of, renderer, sways=look == "tree")
            elif (species / f"{name}_LOD0.glb").is_file():
                facts = check_grass(species, atlases, name, renderer)
            else:
                facts = check_flower(species, atlases, name, renderer)
            print(f"ok   {scene_dir.name}/{name}: " + "; ".join(facts))
            status = "ok"
        except CheckFailed as e:
            print(f"FAIL {scene_dir.name}/{name}: {e}")
            failed += 1
            status = "FAIL"
        if tsv:
            with tsv.open("a") as f:
                f.write(f"{scene_dir.name}/{name}\t{status}\n")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
