"""The viewport's fast-interaction draft (``widgets/js/src/viewport/gpu_draft.js``), in node.

``simplifyFaces`` keeps a subset of the mesh's own vertices (so the GPU evaluates
the rig exactly there) and renumbers the triangles over them. Checked on a
curved grid whose simplification we can reason about: every kept id is an
original vertex, ids ascend, triangles reference only kept vertices and are not
degenerate, the count lands near the target, and a mesh already at or below the
target is left alone (null).
"""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from ci_env import in_ci

from workbench.testing import grid_triangles, grid_vertices

pytestmark = pytest.mark.ui

JS = Path(__file__).resolve().parents[2] / "widgets" / "js"

_SCRIPT = """
import { readFileSync } from "node:fs";
import { MeshoptSimplifier } from "meshoptimizer/simplifier";
import { simplifyFaces } from "./src/viewport/gpu_draft.js";
const { faces, positions, targets } = JSON.parse(readFileSync(0, "utf8"));
await MeshoptSimplifier.ready;
const out = targets.map((t) => {
  const d = simplifyFaces(Uint32Array.from(faces), Float32Array.from(positions), t);
  return d && { ids: Array.from(d.ids), faces: Array.from(d.faces) };
});
console.log(JSON.stringify(out));
"""


def _grid(k: int) -> tuple[np.ndarray, np.ndarray]:
    """A curved k x k grid over [-1, 1]²."""
    V = grid_vertices(k, x=(-1.0, 1.0), y=(-1.0, 1.0), height=lambda u, v: 0.3 * np.sin(2 * u) * np.cos(v))
    return V, grid_triangles(k)


def _simplify(V: np.ndarray, F: np.ndarray, targets: list[int]) -> list:
    node = shutil.which("node")
    if node is None or not (JS / "node_modules" / "meshoptimizer").is_dir():
        msg = "node and widgets/js/node_modules (npm ci --prefix widgets/js)"
        if in_ci():
            pytest.fail(msg + " are missing under CI=true", pytrace=False)
        pytest.skip(msg + " are not available")
    payload = json.dumps({"faces": F.reshape(-1).tolist(), "positions": V.reshape(-1).tolist(),
                          "targets": targets})
    proc = subprocess.run([node, "--input-type=module", "-e", _SCRIPT], input=payload,
                          capture_output=True, text=True, timeout=120, cwd=JS)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout)  # type: ignore[no-any-return]


def test_the_draft_keeps_original_vertices_and_renumbers_its_triangles() -> None:
    V, F = _grid(60)  # 6,962 triangles
    small, same = _simplify(V, F, [800, F.shape[0]])
    assert same is None, "a mesh at the target is drawn as it is"
    ids = np.asarray(small["ids"])
    faces = np.asarray(small["faces"]).reshape(-1, 3)
    assert np.all(np.diff(ids) > 0) and ids[0] >= 0 and ids[-1] < V.shape[0]
    assert 400 <= faces.shape[0] <= 1000, faces.shape
    assert faces.min() == 0 and faces.max() == ids.size - 1  # every kept vertex is used
    assert np.all((faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2]))
    # the draft's triangles, in original numbering, still cover the surface's extent
    P = V[ids[faces]]
    assert np.allclose(P[..., :2].min(axis=(0, 1)), -1) and np.allclose(P[..., :2].max(axis=(0, 1)), 1)
    # and face the same way as the triangles they replace (+z normals on this grid)
    n = np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0])
    assert (n[:, 2] > 0).mean() > 0.99
