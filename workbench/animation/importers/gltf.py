"""Reading the morph-weight animations of a glTF/GLB file into keys.

Every ``weights`` channel of an animation; ``LINEAR`` → linear keys, ``STEP``
→ step keys, ``CUBICSPLINE`` → Bézier keys with user tangents (exact: glTF's
Hermite tangents are our slopes). The decoding reuses the checked accessor
reader of :mod:`workbench.io.gltf` (pygltflib has no accessor decoding).
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from workbench.animation.curves import Interpolation, Key, Track, TrackError, weight_track_name
from workbench.animation.importers.errors import AnimationImportError
from workbench.animation.importers.names import _resolve_columns
from workbench.animation.tracks import Timeline

#: the morph targets our exporters write for a layer's keyed controls (``"<prefix>:basis<i>"``)
_CONTROLS_TARGET = re.compile(r"[^:]+:basis[0-9]+")

__all__ = ["read_gltf_animation"]


def read_gltf_animation(
    path: str | Path,
    shape_names: Sequence[str],
    *,
    animation: int | str | None = None,
    fps: float = 30.0,
    on_unknown: str = "error",
) -> Timeline:
    """Read the morph-weight channels of a glTF animation into keys.

    Parameters
    ----------
    path : str or Path
        .glb or .gltf.
    shape_names : sequence of str
        The model's shape names; targets are matched by ``mesh.extras.targetNames``
        (exact, else ARKit meaning). Targets named ``<prefix>:basis<i>`` (the
        keyed controls of a layer, written by :mod:`workbench.export.gltf`) are skipped.
    animation : int or str, optional
        Animation index or name (default: the first one with a weights channel).
    fps : float
        Frame rate of the returned timeline.
    on_unknown : {"error", "ignore"}
        What to do with targets that match no shape.

    Raises
    ------
    AnimationImportError
        No weights animation, unnamed targets, unknown names, NaN values,
        non-increasing times, output counts that do not match.
    """
    from workbench.geometry.mesh_checks import MeshFormatError
    from workbench.io.gltf.container import read_container
    from workbench.io.gltf.document import Gltf

    p = Path(path)
    src = str(p)
    try:
        doc, bin_chunk = read_container(p)
        g = Gltf(doc, src, bin_chunk, p.parent)
        return _gltf_timeline(g, src, shape_names, animation, fps, on_unknown)
    except MeshFormatError as exc:
        raise AnimationImportError(src, exc.detail) from None


def _same_keys(a: Track, b: Track) -> bool:
    """Keys equal in time, value, interpolation and tangents."""
    return len(a.keys) == len(b.keys) and all(
        ka.time == kb.time
        and ka.interpolation == kb.interpolation
        and np.array_equal(ka.value, kb.value)
        and np.array_equal(ka.in_tangent, kb.in_tangent)
        and np.array_equal(ka.out_tangent, kb.out_tangent)
        for ka, kb in zip(a.keys, b.keys, strict=True)
    )


def _fallback_target_names(mesh: Any, mesh_index: Any, shape_names: Sequence[str]) -> list[str]:
    """Names the glTF reader gives targets without ``extras.targetNames``.

    ``target_<i>``, or ``<mesh>_target_<i>`` when several meshes had unnamed
    targets (:mod:`workbench.io.gltf.reader`); the one the model has wins.
    """
    targets = (mesh.get("primitives") or [{}])[0].get("targets") or []
    label = mesh.get("name") if isinstance(mesh.get("name"), str) else f"mesh_{mesh_index}"
    known = set(shape_names)
    out = []
    for i in range(len(targets)):
        plain, prefixed = f"target_{i}", f"{label}_target_{i}"
        out.append(prefixed if prefixed in known and plain not in known else plain)
    return out


def _gltf_timeline(
    g: Any,
    src: str,
    shape_names: Sequence[str],
    animation: int | str | None,
    fps: float,
    on_unknown: str,
) -> Timeline:
    anims = g.array("animations")
    if not anims:
        raise AnimationImportError(src, "the file has no animations")
    ai: int | None = None
    if isinstance(animation, int):
        ai = animation
    elif isinstance(animation, str):
        names = [a.get("name") if isinstance(a, dict) else None for a in anims]
        if animation not in names:
            raise AnimationImportError(src, f"no animation named {animation!r}; names: {names}")
        ai = names.index(animation)
    else:
        for i, a in enumerate(anims):
            chans = a.get("channels", []) if isinstance(a, dict) else []
            if any(isinstance(c, dict) and (c.get("target") or {}).get("path") == "weights" for c in chans):
                ai = i
                break
        if ai is None:
            raise AnimationImportError(src, "no animation has a 'weights' channel")
    anim = g.item("animations", ai, "animations")
    afield = f"animations[{ai}]"
    samplers = anim.get("samplers", [])
    tracks: dict[str, Track] = {}
    found = False
    for c, ch in enumerate(anim.get("channels", [])):
        cfield = f"{afield}.channels[{c}]"
        target = ch.get("target") if isinstance(ch, dict) else None
        if not isinstance(target, dict) or target.get("path") != "weights":
            continue
        found = True
        node = g.item("nodes", target.get("node"), f"{cfield}.target.node")
        mesh_index = node.get("mesh")
        mesh = g.item("meshes", mesh_index, f"{cfield} node.mesh")
        extras = mesh.get("extras")
        tnames = extras.get("targetNames") if isinstance(extras, dict) else None
        if tnames is None:
            tnames = _fallback_target_names(mesh, mesh_index, shape_names)
        if not isinstance(tnames, list) or not all(isinstance(s, str) for s in tnames):
            raise AnimationImportError(
                src, f"{cfield}: the animated mesh's extras.targetNames is not a list of names"
            )
        si = ch.get("sampler")
        if not isinstance(si, int) or not 0 <= si < len(samplers):
            raise AnimationImportError(src, f"{cfield}.sampler: {si!r} is not a sampler index")
        s = samplers[si]
        sfield = f"{afield}.samplers[{si}]"
        interp = s.get("interpolation", "LINEAR")
        if interp not in ("LINEAR", "STEP", "CUBICSPLINE"):
            raise AnimationImportError(src, f"{sfield}.interpolation: unknown {interp!r}")
        T = g.accessor(s.get("input"), f"{sfield}.input", types=("SCALAR",))[:, 0]
        out = g.accessor(s.get("output"), f"{sfield}.output", types=("SCALAR",))[:, 0]
        nk, nt = T.size, len(tnames)
        per = 3 if interp == "CUBICSPLINE" else 1
        if out.size != nk * nt * per:
            raise AnimationImportError(
                src,
                f"{sfield}.output: has {out.size} values, expected {nk} keys x {nt} targets"
                f"{' x 3' if per == 3 else ''} = {nk * nt * per}",
            )
        if not np.isfinite(T).all() or not np.isfinite(out).all():
            raise AnimationImportError(src, f"{sfield}: NaN/inf in input times or output weights")
        bad = np.flatnonzero(np.diff(T) <= 0)
        if bad.size:
            i = int(bad[0])
            raise AnimationImportError(
                src,
                f"{sfield}.input: key {i + 1} time {T[i + 1]:.6g} s does not come after key {i} "
                f"({T[i]:.6g} s); times must be strictly increasing",
            )
        out = out.reshape(nk, per, nt)
        cols = [n for n in tnames if not _CONTROLS_TARGET.fullmatch(n)]
        mapping = _resolve_columns(cols, shape_names, src, on_unknown)
        mode: Interpolation = "step" if interp == "STEP" else "linear"
        for ci, shape in mapping:
            t_idx = tnames.index(cols[ci])
            if per == 3:
                keys = tuple(
                    Key(
                        float(T[k]),
                        float(out[k, 1, t_idx]),
                        "bezier",
                        float(out[k, 0, t_idx]),
                        float(out[k, 2, t_idx]),
                        "user",
                    )
                    for k in range(nk)
                )
            else:
                keys = tuple(Key(float(T[k]), float(out[k, 0, t_idx]), mode) for k in range(nk))
            name = weight_track_name(shape)
            try:
                track = Track(name, keys)
            except TrackError as exc:
                raise AnimationImportError(src, f"{sfield}: {exc}") from None
            # head, teeth and eyes as separate meshes animate a shared shape once each
            if name in tracks and not _same_keys(tracks[name], track):
                raise AnimationImportError(
                    src,
                    f"{cfield}: animates {shape!r} differently from an earlier channel; "
                    "meshes that share a shape must key it alike",
                )
            tracks[name] = track
    if not found:
        raise AnimationImportError(src, f"{afield} has no 'weights' channel")
    tl = Timeline(fps=fps, tracks=tracks)
    return tl.fit_range()
