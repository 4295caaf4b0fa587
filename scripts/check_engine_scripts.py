"""Checks the engine import scripts that cannot run on this machine (no Unreal or Unity here).

    python scripts/check_engine_scripts.py --unreal-stub PATH/unreal.py [--pair CSV_SCENE BINARY_SCENE] SCENE_DIR...

Unreal (scripts/engines/unreal/verdant_unreal.py):
- every `unreal` name and every method, property and editor property its editor part
  (class UnrealScene) uses exists in the UE 5.6 Python API (PyPI unreal-stub, generated from the
  engine; its file does not parse as Python, so names are looked up in its text);
- on every scene folder: the plan places every table row once (per species, the manifest's
  count), each variant's Static Mesh has the chain's levels with screen sizes from 1 down, and
  every instance's Unreal transform is C M C^-1 of its glTF one (C: the glTF importer's
  (x, y, z) -> (x, z, y) * 100), composed the way Unreal composes a transform (scale, rotate by
  the quaternion, translate), to 1e-5 of the row's size.
--pair: the same scene built with CSV and with binary tables (`[scatter] table = "binary"`): the
script's binary reader gives every CSV row (to 1e-6). Prints `ok` / `FAIL` lines; exits 1 on any
failure.
"""

from __future__ import annotations

import argparse
import ast
import builtins
import os
import re
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "engines", "unreal"))
import verdant_unreal  # noqa: E402

# method names of Python's own types the editor part calls (not Unreal's)
PYTHON_METHODS = {n for t in (str, list, dict) for n in dir(t)} | set(dir(builtins)) | {"path", "join", "basename"}


def report(subject: str, summary: str, problems: list[str]) -> list[str]:
    """Prints one `ok` / `FAIL` line (and the problems under it); returns the problems."""
    print(f"{'FAIL' if problems else 'ok  '}  {subject}: {summary}" + "".join(f"\n      {p}" for p in problems))
    return problems


def unreal_names(stub_text: str) -> tuple[set[str], set[str]]:
    """(module-level classes and functions, member names: methods and documented properties)."""
    top = set(re.findall(r"^(?:class|def) (\w+)", stub_text, re.M))
    members = set(re.findall(r"^    def (\w+)\(", stub_text, re.M)) | set(re.findall(r"``(\w+)``", stub_text))
    return top, members


def check_unreal_api(script: str, stub_text: str) -> list[str]:
    top, members = unreal_names(stub_text)
    tree = ast.parse(open(script, encoding="utf-8").read())
    cls = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == "UnrealScene")
    problems = []
    used_top, used_members, editor_props = set(), set(), set()
    for node in ast.walk(cls):
        if isinstance(node, ast.Attribute):
            base = node.value
            is_ue = (isinstance(base, ast.Name) and base.id in ("ue", "unreal")) or (
                isinstance(base, ast.Attribute) and base.attr == "ue"
            )
            if is_ue:
                used_top.add(node.attr)
            elif not (isinstance(base, ast.Name) and base.id in ("self", "os", "p", "level", "lv")):
                used_members.add(node.attr)
        if (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Attribute)
            and node.func.attr in ("set_editor_property", "get_editor_property")
            and node.args
            and isinstance(node.args[0], ast.Constant)
        ):
            editor_props.add(node.args[0].value)
    for name in sorted(used_top - top):
        problems.append(f"unreal.{name} is not in the UE Python API")
    for name in sorted(used_members - members - PYTHON_METHODS - {"ue", "path"}):
        problems.append(f".{name} is no method or property of the UE Python API")
    for name in sorted(editor_props - members):
        problems.append(f"editor property {name!r} is not in the UE Python API")
    return report(
        os.path.relpath(script),
        f"{len(used_top)} unreal names, {len(used_members)} members, "
        f"{len(editor_props)} editor properties looked up in the UE 5.6 API",
        problems,
    )


def quat_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (n, 3, 3) of unit quaternions (n, 4) as (x, y, z, w): v' = q v q*."""
    x, y, z, w = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def check_scene(scene_dir: str) -> list[str]:
    problems = []
    manifest = verdant_unreal.read_manifest(scene_dir)
    tables: dict[str, list] = {}

    def read(path: str) -> list:
        if path not in tables:
            tables[path] = verdant_unreal.read_table(path)
        return tables[path]

    plans = verdant_unreal.plan(scene_dir, read)
    chains = manifest.get("view", {}).get("chains", {})
    placed: dict[str, int] = {}
    for p in plans:
        placed[p.species] = placed.get(p.species, 0) + len(p.transforms)
        chain = chains[p.species]["variants"][p.variant]
        if [lv.file for lv in p.levels] != [c["file"] for c in chain]:
            problems.append(f"{p.species} v{p.variant}: levels {[lv.file for lv in p.levels]} are not the chain's")
        sizes = [lv.screen_size for lv in p.levels]
        if sizes[0] != 1.0 or any(b > a for a, b in zip(sizes, sizes[1:])) or min(sizes) <= 0.0:
            problems.append(f"{p.species} v{p.variant}: screen sizes {sizes} are not 1 then non-increasing and positive")
    for entry in manifest.get("scatter", {}).get("species", []):
        name = entry["name"]
        if name in chains and placed.get(name, 0) != entry["count"]:
            problems.append(f"{name}: {placed.get(name, 0)} instances planned, the manifest places {entry['count']}")

    # the transform of every row: glTF M = T R S; Unreal's from the converted TRS must be C M C^-1
    swap = np.array([[1.0, 0, 0], [0, 0, 1], [0, 1, 0]])
    rows_checked = 0
    worst = 0.0
    for entry in manifest.get("scatter", {}).get("species", []):
        if entry["name"] not in chains:
            continue
        rows = read(os.path.join(scene_dir, entry["table"]))
        if not rows:
            continue
        t = np.array([r.position for r in rows])
        q = np.array([r.rotation for r in rows])
        s = np.array([r.scale for r in rows])
        conv = [verdant_unreal.gltf_to_unreal(r.position, r.rotation, r.scale) for r in rows]
        t_ue = np.array([c[0] for c in conv])
        q_ue = np.array([c[1] for c in conv])
        s_ue = np.array([c[2] for c in conv])
        linear = quat_matrix(q) * s[:, None, :]  # R diag(s)
        want_linear = swap @ linear @ swap
        want_t = 100.0 * t @ swap.T
        got_linear = quat_matrix(q_ue) * s_ue[:, None, :]
        scale = np.maximum(np.abs(s).max(axis=1), 1e-9)
        err_l = (np.abs(got_linear - want_linear).max(axis=(1, 2)) / scale).max()
        err_t = (np.abs(t_ue - want_t).max(axis=1) / np.maximum(np.abs(want_t).max(axis=1), 1.0)).max()
        worst = max(worst, float(err_l), float(err_t))
        rows_checked += len(rows)
    if worst > 1e-5:
        problems.append(f"Unreal transforms differ from C M C^-1 by up to {worst:.2e}")
    return report(
        scene_dir,
        f"{len(plans)} foliage types, {sum(placed.values())} instances, "
        f"{rows_checked} rows' Unreal transforms = C M C^-1 (worst {worst:.1e})",
        problems,
    )


def check_pair(csv_dir: str, bin_dir: str) -> list[str]:
    """The same scene built with CSV and with binary tables: every species' rows read the same."""
    problems = []
    tables = []
    for d in (csv_dir, bin_dir):
        m = verdant_unreal.read_manifest(d)
        tables.append({e["name"]: os.path.join(d, e["table"]) for e in m.get("scatter", {}).get("species", [])})
    rows = 0
    for name, path in sorted(tables[0].items()):
        other = tables[1].get(name)
        if other is None or not other.endswith(".bin"):
            problems.append(f"{name}: no binary table in {bin_dir}")
            continue
        a, b = verdant_unreal.read_table(path), verdant_unreal.read_table(other)
        if len(a) != len(b):
            problems.append(f"{name}: {len(a)} CSV rows, {len(b)} binary rows")
            continue
        for r, q in zip(a, b):
            same = r.tile == q.tile and r.variant == q.variant and all(
                abs(x - y) <= 1e-6 * max(1.0, abs(x))
                for x, y in zip(r.position + r.rotation + r.scale, q.position + q.rotation + q.scale)
            )
            if not same:
                problems.append(f"{name}: CSV row {r} reads {q} from the binary table")
                break
        rows += len(a)
    return report(bin_dir, f"{rows} binary table rows read as their CSV rows", problems)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--unreal-stub", required=True, help="unreal.py of PyPI unreal-stub")
    ap.add_argument("--pair", nargs=2, metavar=("CSV_SCENE", "BINARY_SCENE"), action="append", default=[],
                    help="a scene built with CSV tables and the same with binary tables: their rows must read the same")
    ap.add_argument("scenes", nargs="+")
    a = ap.parse_args()
    with open(a.unreal_stub, encoding="utf-8-sig") as f:
        stub = f.read()
    problems = check_unreal_api(os.path.join(HERE, "engines", "unreal", "verdant_unreal.py"), stub)
    for d in a.scenes:
        problems += check_scene(d)
    for csv_dir, bin_dir in a.pair:
        problems += check_pair(csv_dir, bin_dir)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
