"""Files written by main before the core redesign load unchanged (issue: Step 1 of 7).

``tests/data/main_v2/*.fwb`` were written by ``make_fixtures.py`` at commit
2a588e5 together with what they evaluated to then; today's code must read every
slot back and give the same vertices, bit for bit.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import workbench

DATA = Path(__file__).parent / "data" / "main_v2"


@pytest.mark.parametrize("name", ["handles", "regions_paint", "timeline"])
def test_main_files_evaluate_as_they_did(name: str) -> None:
    model = workbench.load(DATA / f"{name}.fwb")
    want = np.load(DATA / f"{name}.expected.npz")
    if "evaluate" in want.files:
        # the paint layer now takes its base from the mesh below it ((blend + regions) - neutral
        # instead of (blend - neutral) + regions): float32 sums in another order, <= 2 ulp apart
        np.testing.assert_array_max_ulp(model.evaluate(), want["evaluate"], maxulp=2)
    for key in want.files:
        if key.startswith("evaluate_at_"):
            t = float(key.removeprefix("evaluate_at_"))
            np.testing.assert_array_equal(model.evaluate_at(t), want[key], err_msg=f"t={t}")


def test_main_files_keep_their_edits() -> None:
    h = workbench.load(DATA / "handles.fwb")
    assert len(h.handles) > 60 and np.count_nonzero(h.handles.offsets.any(axis=1)) == 2
    assert h.shape("eyeBlinkLeft").mute and h.shape("browInnerUp").vertex_mask is not None
    assert h.shape("extra").slider_min == -1.0 and h.weights["extra"] == -0.5
    assert h.weights["mouthSmileLeft"] == pytest.approx(0.7)

    r = workbench.load(DATA / "regions_paint.fwb")
    assert set(r.expressions) == {"smileL", "brows"}
    assert set(r.paint) == {"smileL", "brows"}
    assert r.regions.state is not None and r.regions.weights is not None
    # the region weights and the paint really move the face (the file is not trivial)
    assert np.abs(r.evaluate() - r.vertices).max() > 1e-3

    t = workbench.load(DATA / "timeline.fwb")
    assert t.time == 0.0  # the time is not saved; the keys are
    assert t.tracks.head_pose is not None and t.tracks.handles is not None
    assert {"jawOpen", "mouthSmileLeft", "browInnerUp"} <= set(t.tracks.weight_tracks)
    assert not np.array_equal(t.evaluate_at(0.25), t.evaluate_at(1.5))
