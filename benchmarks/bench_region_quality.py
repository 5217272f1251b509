"""Benchmark: do the blend regions follow the face's features, on named and unnamed rigs? (issue 15, item 5)

Run: .venv/bin/python benchmarks/bench_region_quality.py [--threshold 0.25]

Measured, before and after the change, on three rigs built from the sample head:

* ``named``    — the sample as shipped (components "skin", "eye_left", ...);
* ``unnamed``  — the same mesh with the components renamed "mesh_0", "mesh_1", ...
  (what many exporters write);
* ``warped``   — unnamed, every quad split along its other diagonal and the
  rig under a mirror-symmetric smooth warp (Gaussian bumps up to 2 % of the
  head's size and a scale of up to 7 % per axis; shapes carried exactly).

The rigs come from :mod:`workbench.testing` (the tests check the same ones).

1. **Feature shares.** For one-sided features (a brow, a lid, a mouth corner)
   the share of a shape's strongly moving vertices (moved ≥ half its largest
   displacement) inside the single region holding most of them, per hierarchy
   level (0 = finest), and the share left in the background
   (:func:`workbench.methods.regions.segmentation.feature_share`). Goal: ≥ 0.70 at
   every level.
2. **Eyeball drift.** The largest eyeball displacement when the left brow handle
   (``brows_L_2`` of the default handles, or a lone handle on the same vertex)
   is raised by 1 cm. Goal: the unnamed rig equals the named one.

*Before* reproduces the previous behaviour in this run: component roles from
names only (an unnamed part is skin for the regions and "rigid" for the shell)
and fine regions keyed by each vertex's dominant shape alone
(``keep_features=False``). *After* is the code as it is: roles from
:func:`workbench.geometry.parts.component_roles` and fine-piece borders moved so
features stay whole (``keep_features=True``).
"""

from __future__ import annotations

import argparse
import contextlib
import time
from collections.abc import Iterator

import numpy as np

import workbench
import workbench.methods.regions.segmentation as seg
from workbench.geometry.parts import model_part_roles, role_from_name
from workbench.methods.handles.presets import default_face_handles
from workbench.methods.handles.shell import ShellDeformer
from workbench.model import FaceModel
from workbench.testing import random_warp, unnamed_parts, warped

FEATURES = (
    "browDownLeft", "browOuterUpLeft", "eyeBlinkLeft", "eyeSquintLeft", "eyeWideLeft", "cheekSquintLeft",
    "noseSneerLeft", "mouthSmileLeft", "mouthFrownLeft", "mouthDimpleLeft", "mouthStretchLeft",
    "mouthPressLeft", "mouthUpperUpLeft", "mouthLowerDownLeft",
    "browDownRight", "eyeBlinkRight", "mouthSmileRight",
)
TARGET = 0.70


def warped_rig(base: FaceModel) -> FaceModel:
    """The ``warped`` rig: unnamed, quads cut along their other diagonal, a mirror-symmetric smooth warp."""
    warp = random_warp(base.vertices, seed=0, symmetric=True, strength=0.02, anisotropy=0.07)
    return unnamed_parts(warped(base, warp, retriangulate=True).model)


def names_only_roles(model: FaceModel) -> tuple[str, ...]:
    """The previous rule: what the names say; anything else is segmented like skin."""
    return tuple(role_from_name(nm) or "skin" for nm in model.component_names)


@contextlib.contextmanager
def before() -> Iterator[None]:
    seg.model_part_roles = names_only_roles  # type: ignore[assignment]
    try:
        yield
    finally:
        seg.model_part_roles = model_part_roles


def shares(model: FaceModel, threshold: float, keep: bool) -> tuple[dict[str, list[tuple[float, float]]], float]:
    t0 = time.perf_counter()
    R = seg.segment_blend_regions(model, threshold, keep_features=keep)
    dt = time.perf_counter() - t0
    return {f: [seg.feature_share(model, R, f, lv) for lv in range(R.n_levels)] for f in FEATURES}, dt


def eyeball_drift(model: FaceModel, roles: list[str] | None, lone: bool) -> float:
    """mm of the largest eyeball displacement for a 1 cm raise of the left brow handle."""
    hs = default_face_handles(model)
    j = hs.names.index("brows_L_2")
    handles = hs.vertices[[j]] if lone else hs.vertices
    d = ShellDeformer(model.vertices, model.faces, handles, component_labels=model.component_labels,
                      component_names=model.component_names, component_roles=roles)
    off = np.zeros((len(handles), 3))
    off[0 if lone else j, 1] = 0.01 / model.metadata.metres_per_unit
    u = d.displacement(off)
    eyes = np.isin(model.component_labels,
                   [i for i, r in enumerate(model_part_roles(model)) if r.startswith("eyeball")])
    return float(np.abs(u[eyes]).max()) * model.metadata.metres_per_unit * 1e3


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--threshold", type=float, default=0.25)
    args = ap.parse_args()
    head = workbench.load_sample("head")
    rigs = {"named": head, "unnamed": unnamed_parts(head), "warped": warped_rig(head)}
    print(f"component roles (names first, else geometry), t = {args.threshold}:")
    for label, m in rigs.items():
        print(f"  {label:8s} {m.component_names[:3]}... -> {list(model_part_roles(m))}")

    print(f"\nshare of each feature's strongly moving vertices in its best region, per level "
          f"(background share in brackets); goal >= {TARGET:.2f}")
    fails: dict[str, int] = {}
    for label, m in rigs.items():
        with before():
            old, t_old = shares(m, args.threshold, keep=False)
        new, t_new = shares(m, args.threshold, keep=True)
        print(f"\n{label}: segmentation {t_old * 1e3:.0f} ms before, {t_new * 1e3:.0f} ms after")
        print(f"  {'feature':20s} | {'before: level 0 / 1 / 2':34s} | {'after: level 0 / 1 / 2':34s}")
        for f in FEATURES:
            cells = []
            for res in (old[f], new[f]):
                cells.append(" ".join(f"{a:.2f}[{b:.2f}]" for a, b in res))
            ok = min(a for a, _ in new[f]) >= TARGET
            fails[label] = fails.get(label, 0) + (not ok)
            print(f"  {f:20s} | {cells[0]:34s} | {cells[1]:34s} {'' if ok else '  < goal'}")
        worst_old = min(min(a for a, _ in old[f]) for f in FEATURES)
        worst_new = min(min(a for a, _ in new[f]) for f in FEATURES)
        print(f"  worst share: {worst_old:.2f} before, {worst_new:.2f} after")

    print("\neyeball drift for a 1 cm raise of the left brow handle (mm):")
    print(f"  {'rig':8s} {'handles':14s} {'before':>8s} {'after':>8s}")
    for label in ("named", "unnamed"):
        m = rigs[label]
        old_roles = list(names_only_roles(m))  # an unnamed part: "skin" by role, "rigid" in the shell
        for lone in (False, True):
            b = eyeball_drift(m, old_roles, lone)
            a = eyeball_drift(m, None, lone)
            print(f"  {label:8s} {'lone handle' if lone else 'default (70)':14s} {b:8.3f} {a:8.3f}")
    print(f"\nfeatures below the goal after: {fails}")


if __name__ == "__main__":
    main()
