"""Peer for bench_shell.py: Blender's Laplacian Deform modifier, run with Blender's own Python.

Run by bench_shell.py as ``<bpy python> blender_laplacian_peer.py IN.npz`` (bpy
in its own venv, see .ci/workbench); prints one JSON line. Not importable
from the workbench venv (it imports bpy) and it never imports workbench.

The set-up is the one Blender's manual describes for Laplacian Deform: the
handle vertices are the modifier's anchor vertex group, and a Hook modifier
before it moves the dragged handle's vertex with an Empty. One "drag update"
moves the Empty and re-evaluates the depsgraph, then reads the deformed
positions (what a viewport needs); the Bind is timed separately (it factors
the system once, like our precompute). Blender's anchors are least-squares
rows, not hard constraints: the JSON reports how far the dragged handle and the
other anchors end up from where they were put (ours interpolates them exactly).
"""

from __future__ import annotations

import json
import statistics
import sys
import time

import bpy
import numpy as np


def main(path: str) -> None:
    data = np.load(path)
    V, F, H = data["V"].astype(np.float64), data["F"].astype(np.int64), data["H"].astype(np.int64)
    dragged = int(data["dragged"])
    repeat = int(data["repeat"])
    bpy.ops.wm.read_factory_settings(use_empty=True)
    mesh = bpy.data.meshes.new("face")
    mesh.vertices.add(len(V))
    mesh.vertices.foreach_set("co", V.ravel())
    mesh.loops.add(F.size)
    mesh.loops.foreach_set("vertex_index", F.ravel())
    mesh.polygons.add(len(F))
    mesh.polygons.foreach_set("loop_start", np.arange(0, F.size, 3))
    mesh.update()
    obj = bpy.data.objects.new("face", mesh)
    bpy.context.scene.collection.objects.link(obj)
    group = obj.vertex_groups.new(name="anchors")
    group.add([int(i) for i in H], 1.0, "REPLACE")

    empty = bpy.data.objects.new("handle", None)
    bpy.context.scene.collection.objects.link(empty)
    # the Empty starts at the origin with an identity hook inverse, so its location is
    # the handle's offset
    hook = obj.modifiers.new("Hook", "HOOK")
    hook.object = empty
    hook.vertex_indices_set([dragged])
    hook.center = tuple(V[dragged])
    lap = obj.modifiers.new("LaplacianDeform", "LAPLACIANDEFORM")
    lap.vertex_group = "anchors"
    lap.iterations = 1

    bpy.context.view_layer.objects.active = obj
    obj.select_set(True)
    t0 = time.perf_counter()
    with bpy.context.temp_override(object=obj, active_object=obj):
        bpy.ops.object.laplaciandeform_bind(modifier="LaplacianDeform")
    dg = bpy.context.evaluated_depsgraph_get()
    dg.update()
    bind_s = time.perf_counter() - t0

    out = np.empty(len(V) * 3)
    ts = []
    for i in range(repeat + 1):
        empty.location = (0.0, 0.01 * (1 + i % 7), 0.0)
        t0 = time.perf_counter()
        dg.update()
        ev = obj.evaluated_get(dg)
        ev.data.vertices.foreach_get("co", out)
        if i:
            ts.append(time.perf_counter() - t0)
    P = out.reshape(-1, 3)
    # sanity: the hooked handle sits at its offset, the other anchors stay
    moved = float(np.linalg.norm(P - V, axis=1).max())
    offset = 0.01 * (1 + repeat % 7)
    err_handle = float(abs(P[dragged, 1] - V[dragged, 1] - offset))
    others = np.setdiff1d(H, [dragged])
    err_anchors = float(np.abs(P[others] - V[others]).max())
    print(json.dumps({"bind_s": bind_s, "update_ms": statistics.median(ts) * 1e3, "max_move": moved,
                      "handle_error": err_handle, "handle_reached": 1.0 - err_handle / offset, "anchor_error": err_anchors,
                      "blender": bpy.app.version_string}))


if __name__ == "__main__":
    main(sys.argv[-1])
