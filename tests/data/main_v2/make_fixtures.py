"""Writes the ``.fwb`` files of ``tests/data/main_v2/`` with the code of main before the core redesign.

Run once at commit 2a588e5 (``python tests/data/main_v2/make_fixtures.py``); the
files and the meshes they evaluate to (``*.expected.npz``) are committed, and
``tests/test_fileformat_compat.py`` loads them with today's code and checks that
every slot comes back and the face evaluates to the same vertices. Kept to show how
the files were made; it does not need to run again.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from workbench.handle_presets import default_face_handles
from workbench.paint import Brush
from workbench.tracks import head_rotation_from_euler

import workbench
from workbench.model import FaceModel

HERE = Path(__file__).parent
KEEP = ["jawOpen", "mouthSmileLeft", "mouthSmileRight", "browInnerUp", "eyeBlinkLeft", "browDownLeft"]


def small_head() -> FaceModel:
    """The sample head with six of its shapes (keeps the files small)."""
    full = workbench.load_sample("head")
    shapes = [full.shape(n) for n in KEEP]
    return FaceModel(
        full.vertices, full.faces, shapes, polygons=full.polygons,
        component_labels=full.component_labels, component_names=full.component_names,
        metadata=full.metadata,
    )


def expected(model: FaceModel, times: list[float]) -> dict[str, np.ndarray]:
    # with keys, the live state depends on the time, which is not saved: only evaluate_at then
    out = {} if times else {"evaluate": np.array(model.evaluate())}
    for t in times:
        out[f"evaluate_at_{t:g}"] = np.array(model.evaluate_at(t))
    return out


def main() -> None:
    # 1. shapes, weights, handles with offsets, stiffness, a masked + muted shape
    m = small_head()
    m.set_weights({"jawOpen": 0.4, "mouthSmileLeft": 0.7})
    m.set_shape_mask("browInnerUp", np.linspace(0, 1, m.n_vertices))
    m.add_shape("extra", np.full((m.n_vertices, 3), 0.001), slider_min=-1.0, slider_max=2.0, weight=-0.5)
    m.set_shape_mute("eyeBlinkLeft", True)
    m.set_handles(default_face_handles(m))
    # not the stiffness: main did not save it (the redesign does)
    m.move_handle(3, [0.0, 0.05, 0.01], symmetric=True)
    m.save(HERE / "handles.fwb")
    np.savez(HERE / "handles.expected.npz", **expected(m, []))

    # 2. regions with weights, saved expressions, paint
    m = small_head()
    m.segment_regions(0.25)
    m.set_weights({"mouthSmileLeft": 1.0, "jawOpen": 0.3})
    m.save_expression("smileL")
    m.set_weights({"browInnerUp": 1.0, "mouthSmileLeft": 0.0, "jawOpen": 0.0})
    m.save_expression("brows")
    m.reset_weights()
    from workbench.region_blend import RegionWeights

    st = m.regions
    rw = RegionWeights.from_global(m, st.regions, st.level)
    values = rw.values.copy()
    values[0, m.shape_names.index("jawOpen")] = 0.5
    m.set_region_weights(RegionWeights(rw.level, rw.shape_names, rw.region_names, values))
    skin = np.flatnonzero(m.component_labels == m.component_names.index("skin"))
    m.paint_stroke("smileL", skin[:400:20], Brush(radius=0.3, opacity=0.6))
    m.paint_stroke("brows", skin[2000:2400:40], Brush(radius=0.2, opacity=0.8))
    m.save(HERE / "regions_paint.fwb")
    np.savez(HERE / "regions_paint.expected.npz", **expected(m, []))

    # 3. a timeline: weight keys (step, linear, bezier), handle keys, head pose keys
    m = small_head()
    m.set_handles(default_face_handles(m))
    m.key_expression(0.0, "jawOpen", interpolation="linear")
    m.key_expression(1.0, "mouthSmileLeft")
    m.set_weight("browInnerUp", 0.8)
    m.key_weights(2.0, interpolation="step")
    m.move_handle(5, [0.02, 0.0, 0.0])
    m.key_handles(1.0)
    m.key_head_pose(0.0, head_rotation_from_euler(10.0, 0.0, 0.0), [0.0, 0.1, 0.0])
    m.key_head_pose(2.0, head_rotation_from_euler(-15.0, 5.0, 0.0), [0.0, 0.0, 0.0])
    m.set_time(0.5)
    m.save(HERE / "timeline.fwb")
    np.savez(HERE / "timeline.expected.npz", **expected(m, [0.0, 0.25, 1.0, 1.5, 2.0]))


if __name__ == "__main__":
    main()
