"""Compressed and restructured .glb files made by real writers load as the uncompressed source.

The source (``tests/tools/face_gltf.py``) is the CC0 sample head as a
three.js-style scene: head, teeth and eyes as three meshes on rotated and
scaled nodes under a translated root, per-mesh ``extras.targetNames``, a
textured material and a LINEAR weights animation per mesh. Writers nobody here
wrote turn it into what users bring (generated at test time, in a temporary
folder):

* gltfpack 1.3 (npm): ``EXT_meshopt_compression`` / ``KHR_meshopt_compression``
  + ``KHR_mesh_quantization`` (14-bit integer or normalized positions, or
  floats through the exponential filter), dequantization in extra nodes,
  8-bit weights resampled at 30 Hz. The npm build has no BasisU encoder, so a
  ``KHR_texture_basisu`` texture is added to its output the way three.js-style
  files carry one (see :func:`add_basisu_texture`).
* glTF-Transform 4.5.1 (npm): ``draco`` (``KHR_draco_mesh_compression``),
  ``sparse`` (sparse morph targets), ``quantize`` (normalized 14-bit positions,
  dequantization folded into the node transforms).
* Blender 5.0's exporter (bpy in ``$WORKBENCH_BPY_PYTHON``): plain and Draco.

Each decoded vertex is matched to its source vertex (nearest neighbour on
position + every delta: writers reorder vertices) and compared in the node's
local frame, where the writers quantize, against a bound computed by hand
from the bit depth and the quantization volume each writer documents.
The tools are installed by ``bash .ci/workbench test`` (``npm ci`` in
``tests/tools``); without them these tests skip locally and fail under CI.
"""

from __future__ import annotations

import logging
import re
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from ci_env import in_ci
from scipy.optimize import linear_sum_assignment
from scipy.spatial import cKDTree

import workbench
from workbench.animation.importers import read_gltf_animation
from workbench.io.base import ImportedFace
from workbench.io.gltf import read_gltf

TOOLS = Path(__file__).resolve().parent / "tools"
sys.path.insert(0, str(TOOLS))
from face_gltf import (  # noqa: E402
    KEY_TIMES,
    SHAPES,
    FaceSource,
    face_source,
    keyed_weight,
    local_delta,
    local_vertices,
    world_matrix,
)
from gltf_writers import ToolMissing, glb_json, source_glb, written  # noqa: E402

SLACK = 2e-6  # float32 rounding of coordinates up to ~4.4 m through a few operations


def _missing(what: str) -> None:
    msg = f"{what} (needed by the glTF writer tests)"
    if in_ci():
        pytest.fail(msg + " is missing under CI=true", pytrace=False)
    pytest.skip(msg + " is not available")


def writer_file(kind: str) -> Path:
    """The source re-written by ``kind`` (cached; skip locally / fail in CI if the tool is missing)."""
    try:
        return written(kind)
    except ToolMissing as exc:
        _missing(str(exc))
        raise


@pytest.fixture(scope="session")
def source() -> FaceSource:
    return face_source()


# ---- matching and bounds ---------------------------------------------------------------


def match(face: ImportedFace, src: FaceSource) -> np.ndarray:
    """Source vertex of each decoded vertex (a bijection), by position and all deltas.

    Nearest neighbours first; where quantization makes two decoded vertices
    claim the same source vertex, those and their 8 nearest candidates are
    assigned jointly (least total distance).
    """
    d = dict(face.shapes)
    feat_src = np.concatenate([src.vertices()] + [src.delta(s) for s in SHAPES], axis=1)
    feat = np.concatenate([face.vertices] + [d[s] for s in SHAPES], axis=1)
    assert face.n_vertices == feat_src.shape[0]
    dist, cand = cKDTree(feat_src).query(feat, k=8)
    ix = cand[:, 0].copy()
    uniq, counts = np.unique(ix, return_counts=True)
    clash = np.flatnonzero(counts[np.searchsorted(uniq, ix)] > 1)
    if clash.size:
        cols = np.unique(cand[clash])
        cost = np.full((clash.size, cols.size), 1e9)
        for r, i in enumerate(clash):
            cost[r, np.searchsorted(cols, cand[i])] = dist[i]
        rows, picked = linear_sum_assignment(cost)
        ix[clash[rows]] = cols[picked]
    assert np.unique(ix).size == ix.size, "decoded vertices do not match source vertices one to one"
    return ix


def local_errors(face: ImportedFace, src: FaceSource, ix: np.ndarray) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per part: largest |error| per local axis of positions and of deltas (source's local frame)."""
    d = dict(face.shapes)
    part_of = src.part_of_vertex()[ix]
    starts = np.cumsum([0] + [len(p.vertices) for p in src.parts])
    out = {}
    for k, part in enumerate(src.parts):
        rows = part_of == k
        local_ix = ix[rows] - starts[k]
        M = world_matrix(part.name)
        Minv = np.linalg.inv(M)
        dec = face.vertices[rows] @ Minv[:3, :3].T + Minv[:3, 3]
        pos_err = np.abs(dec - local_vertices(part)[local_ix]).max(0)
        delta_err = np.zeros(3)
        for s in SHAPES:
            want = local_delta(part, s)[local_ix] if s in part.shapes else 0.0
            delta_err = np.maximum(delta_err, np.abs(d[s][rows] @ Minv[:3, :3].T - want).max(0))
        out[part.name] = (pos_err, delta_err)
    return out


def _deltas(part: Any) -> list[np.ndarray]:
    return [local_delta(part, s) for s in part.shapes]


def gltfpack_bound(src: FaceSource, bits: int = 14, normalized: bool = False) -> dict[str, tuple[float, float]]:
    """gltfpack -vp 14: one grid for all meshes; positions and deltas round to it.

    Grid (gltfpack ``prepareQuantizationPosition``): the box of all positions,
    each mesh's box padded by its largest |delta| per axis; step = the box's
    largest side / (2^14 - 1); rounding to nearest: 0.5 step. The padding is
    bounded above by the sum over meshes. With normalized positions (-vpn)
    deltas are SHORT normalized against a UNSIGNED_SHORT range: their grid is
    65535/32767 ~ 2 steps, so 1 step.
    """
    P = np.concatenate([local_vertices(p) for p in src.parts])
    pad = sum(np.abs(np.concatenate(_deltas(p))).max(0) for p in src.parts)
    extent = float((P.max(0) - P.min(0) + 2 * pad).max())
    step = extent / (2**bits - 1)
    b = 0.5 * step + SLACK
    bd = 0.5 * step * (65535 / 32767 if normalized else 1.0) + SLACK
    return {p.name: (b, bd) for p in src.parts}


def gltfpack_float_bound(src: FaceSource, bits: int = 14) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """gltfpack -vpf -cc: exponential filter, one exponent per axis and stream, 15-bit mantissas.

    value = m * 2^e with e = (largest frexp exponent on that axis) - 14, m rounded: 0.5 * 2^e.
    """

    def half_ulp(a: np.ndarray) -> np.ndarray:
        _, e = np.frexp(np.abs(a).max(0))
        return 0.5 * np.ldexp(1.0, e - bits) + SLACK

    out = {}
    for p in src.parts:
        dmax = np.max([half_ulp(d) for d in _deltas(p)], axis=0) if p.shapes else np.full(3, SLACK)
        out[p.name] = (half_ulp(local_vertices(p)), dmax)
    return out


def draco_bound(src: FaceSource, bits: int = 14) -> dict[str, tuple[float, float]]:
    """Draco (glTF-Transform, Blender: 14-bit positions, one grid per mesh): 0.5 * largest side / (2^14 - 1).

    Morph targets are not Draco-compressed: exact.
    """
    out = {}
    for p in src.parts:
        P = local_vertices(p)
        out[p.name] = (0.5 * float((P.max(0) - P.min(0)).max()) / (2**bits - 1) + SLACK, SLACK)
    return out


def quantize_bound(src: FaceSource, bits: int = 14) -> dict[str, tuple[float, float]]:
    """glTF-Transform ``quantize``: normalized SHORT, 13 magnitude bits, bit-replicated to 15.

    Volume per mesh: the box of positions grown by min/max(rel, 2 rel, 0) of the
    deltas; scale s = half its largest side; positions and deltas are stored
    as round(|x| / s * 8191) with the top bits copied into the 2 low bits, read
    back as / 32767: error <= s * (0.5 / 8191 + the largest replication error).
    """
    q = np.arange(2 ** (bits - 1))
    rep = np.abs(q / (2 ** (bits - 1) - 1) - ((q << 2) | (q >> (bits - 3))) / 32767.0).max()
    out = {}
    for p in src.parts:
        P = local_vertices(p)
        D = np.concatenate(_deltas(p))
        lo = np.minimum(P.min(0), np.minimum(np.minimum(D.min(0), 2 * D.min(0)), 0))
        hi = np.maximum(P.max(0), np.maximum(np.maximum(D.max(0), 2 * D.max(0)), 0))
        s = float(((hi - lo) / 2).max())
        b = s * (0.5 / (2 ** (bits - 1) - 1) + rep) + SLACK
        out[p.name] = (b, b)
    return out


def exact_bound(src: FaceSource) -> dict[str, tuple[float, float]]:
    return {p.name: (SLACK, SLACK) for p in src.parts}


BOUNDS: dict[str, Callable[[FaceSource], dict[str, Any]]] = {
    "gltfpack": gltfpack_bound,
    "gltfpack-khr": gltfpack_bound,
    "gltfpack-normalized": lambda src: gltfpack_bound(src, normalized=True),
    "gltfpack-float": gltfpack_float_bound,
    "draco": draco_bound,
    "sparse": exact_bound,
    "quantize": quantize_bound,
    "blender": exact_bound,
    "blender-draco": draco_bound,
}
#: extensions each writer must have used (so the test covers what it claims)
REQUIRED = {
    "gltfpack": {"EXT_meshopt_compression", "KHR_mesh_quantization", "KHR_texture_basisu"},
    "gltfpack-khr": {"KHR_meshopt_compression", "KHR_mesh_quantization"},
    "gltfpack-normalized": {"EXT_meshopt_compression", "KHR_mesh_quantization"},
    "gltfpack-float": {"EXT_meshopt_compression"},
    "draco": {"KHR_draco_mesh_compression"},
    "sparse": set(),
    "quantize": {"KHR_mesh_quantization"},
    "blender": set(),
    "blender-draco": {"KHR_draco_mesh_compression"},
}
#: largest error of an imported weight (gltfpack stores weights as 8-bit normalized)
WEIGHT_TOL = {k: (0.5 / 255 + 1e-6 if k.startswith("gltfpack") else 1e-6) for k in BOUNDS}


def writer_params() -> list[Any]:
    return [pytest.param(k, marks=pytest.mark.slow) if k.startswith("blender") else k for k in BOUNDS]


@pytest.mark.parametrize("kind", writer_params())
def test_decodes_to_the_source_within_quantization(
    kind: str, source: FaceSource, caplog: pytest.LogCaptureFixture
) -> None:
    path = writer_file(kind)
    doc = glb_json(path)
    assert REQUIRED[kind] <= set(doc.get("extensionsRequired", [])), doc.get("extensionsRequired")
    if kind == "sparse":
        assert any("sparse" in a for a in doc["accessors"])
    if kind == "gltfpack-float":
        filters = {bv.get("extensions", {}).get("EXT_meshopt_compression", {}).get("filter") for bv in doc["bufferViews"]}
        assert "EXPONENTIAL" in filters
    with caplog.at_level(logging.WARNING, logger="workbench.io.gltf"):
        face = read_gltf(path)
    if kind == "gltfpack":
        assert "skipped KHR_texture_basisu (textures/materials only" in caplog.text

    # several meshes -> parts named by their nodes; shapes merged by name across meshes
    assert sorted(face.group_names) == ["eyes", "head", "teeth"]
    labels, names = face.components()
    assert sorted(names) == ["eyes", "head", "teeth"]
    assert np.bincount(labels).tolist() == sorted((len(p.vertices) for p in source.parts), reverse=True)
    assert sorted(face.shape_names) == sorted(SHAPES)
    assert face.units == "m" and face.up_axis == "+y"

    ix = match(face, source)
    bounds = BOUNDS[kind](source)
    errors = local_errors(face, source, ix)
    for part, (pos_err, delta_err) in errors.items():
        pos_b, delta_b = bounds[part]
        assert np.all(pos_err <= pos_b), (part, pos_err, pos_b)
        assert np.all(delta_err <= delta_b), (part, delta_err, delta_b)

    # a shape that a mesh does not have is exactly zero there
    d = dict(face.shapes)
    part_of = source.part_of_vertex()[ix]
    teeth = part_of == [p.name for p in source.parts].index("teeth")
    eyes = part_of == [p.name for p in source.parts].index("eyes")
    assert not d["eyeBlinkLeft"][teeth].any() and not d["jawOpen"][eyes].any()
    assert np.abs(d["jawOpen"][teeth]).max() > 1e-3  # jawOpen is on head *and* teeth


@pytest.mark.parametrize("kind", writer_params())
def test_weights_animation_keys_onto_the_timeline(kind: str, source: FaceSource) -> None:
    path = writer_file(kind)
    model = workbench.load(path)
    tl = read_gltf_animation(path, model.shape_names)
    model.timeline.set(tl, "import")
    assert sorted(model.tracks.weight_tracks) == sorted(SHAPES)
    assert model.tracks.start == pytest.approx(0.0) and model.tracks.end == pytest.approx(1.0, abs=1e-6)
    # Blender samples its F-curves per frame (24 fps): exact there, linear in between
    times = np.arange(25) / 24.0 if kind.startswith("blender") else np.linspace(0.0, 1.0, 61)
    tol = WEIGHT_TOL[kind]
    for t in times:
        w = model.tracks.evaluate(float(t)).weights
        for s in SHAPES:
            assert abs(w[s] - keyed_weight(s, t)) <= tol, (s, t, w[s], keyed_weight(s, t))
    # the played mesh: decoded neutral + keyed weights x decoded deltas, equal to the source's
    t = float(times[len(times) // 3])
    face = read_gltf(path)
    ix = match(face, source)
    want = source.vertices()[ix] + sum(keyed_weight(s, t) * source.delta(s)[ix] for s in SHAPES)
    got = model.evaluate_at(t)
    max_delta = max(np.abs(source.delta(s)).max() for s in SHAPES)
    pos_b = max(max(np.max(b) for b in pair) for pair in BOUNDS[kind](source).values())
    # bounds are local; nodes scale by at most 2 and there are 9 shapes (|w| <= 1)
    tol_mesh = 2 * np.sqrt(3) * pos_b * (1 + len(SHAPES)) + len(SHAPES) * tol * max_delta + 1e-5
    assert np.abs(got - want).max() <= tol_mesh


def test_source_keys_are_what_the_writers_saw() -> None:
    """The uncompressed source itself: names and keys exactly as built."""
    face = read_gltf(source_glb())
    assert face.group_names == ["head", "teeth", "eyes"]
    tl = read_gltf_animation(source_glb(), face.shape_names)
    for s in SHAPES:
        keys = tl.tracks[f"weights/{s}"].keys
        np.testing.assert_allclose([k.time for k in keys], KEY_TIMES, atol=1e-7)


def test_triangles_flattened_by_quantization_are_dropped_with_a_note(
    source: FaceSource, caplog: pytest.LogCaptureFixture
) -> None:
    """gltfpack at 13 bits snaps a few slivers flat; in float data a flat triangle is an error."""
    path = writer_file("gltfpack-13bit")
    with caplog.at_level(logging.WARNING, logger="workbench.io.gltf"):
        face = read_gltf(path)
    m = re.search(r"meshes\[0\]: dropped (\d+) of 9424 triangles that quantization made zero-area", caplog.text)
    assert m is not None, caplog.text
    dropped = int(m.group(1))
    assert dropped > 0
    assert len(face.polygons) == sum(len(p.triangles) for p in source.parts) - dropped
    # only slivers can go flat: a triangle whose height is within the snapping of its corners
    step = (gltfpack_bound(source, bits=13)["head"][0] - SLACK) * 2
    head = source.parts[0]
    a, b, c = (local_vertices(head)[head.triangles[:, k]] for k in range(3))
    longest = np.sqrt(np.max([((b - a) ** 2).sum(1), ((c - b) ** 2).sum(1), ((a - c) ** 2).sum(1)], axis=0))
    height = np.linalg.norm(np.cross(b - a, c - a), axis=1) / longest
    assert dropped <= int(np.count_nonzero(height <= np.sqrt(3) * step))
    # what is left is a valid mesh: no flat triangle, every vertex still there
    assert face.n_vertices == len(source.vertices())
