"""Files written by main before the core redesign load unchanged (issue: Step 1 of 7).

``tests/data/main_v2/*.fwb`` were written by ``make_fixtures.py`` at commit
2a588e5 together with what they evaluated to then; today's code must read every
slot back and give the same vertices, up to float32 rounding.

Not bit for bit: the ``*.expected.npz`` numbers were computed on another machine,
and numpy's SIMD kernels (AVX-512 / AVX2 / SSE, chosen at run time), OpenBLAS's
kernels and the order of float32 sums differ between CPUs by an ulp here and there
(an AMD EPYC with AVX2 differed from the machine that wrote them in 269 of 15,252
values). Bit-for-bit equality is for identities within one run (evaluate ==
evaluate_at == every exporter), tested elsewhere.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import workbench

DATA = Path(__file__).parent / "data" / "main_v2"


def assert_same_face(got: np.ndarray, want: np.ndarray, msg: str = "") -> None:
    """``got`` is ``want`` up to a few float32 roundings of the face's coordinates.

    The tolerance is absolute, 4 ulp of the largest stored coordinate (8.6 dm here: 3.8e-6
    dm, 0.4 µm), and not relative per value: a vertex is a sum of float32 terms the size of
    the face (neutral + weighted deltas, then the head pose rotates all three coordinates
    together), so a coordinate near 0 carries the rounding of its 8 dm neighbours and a
    per-value ulp or rtol bound would fail there. Any real change of the evaluation moves
    vertices by far more than 0.4 µm.
    """
    assert got.dtype == want.dtype and got.shape == want.shape, msg
    atol = 4 * float(np.spacing(np.abs(want).max()))
    np.testing.assert_allclose(got, want, rtol=0, atol=atol, err_msg=msg)


@pytest.mark.parametrize("name", ["handles", "regions_paint", "timeline"])
def test_main_files_evaluate_as_they_did(name: str) -> None:
    model = workbench.load(DATA / f"{name}.fwb")
    want = np.load(DATA / f"{name}.expected.npz")
    if "evaluate" in want.files:
        # also absorbs today's order of the paint layer's float32 sums ((blend + regions) -
        # neutral instead of (blend - neutral) + regions), <= 2 ulp from main's on one machine
        assert_same_face(model.evaluate(), want["evaluate"])
    times = [k for k in want.files if k.startswith("evaluate_at_")]
    for key in times:
        t = float(key.removeprefix("evaluate_at_"))
        assert_same_face(model.evaluate_at(t), want[key], msg=f"t={t}")
    if times:
        # within this run the live state at the model's time is evaluate_at, bit for bit
        model.set_time(1.5)
        np.testing.assert_array_equal(model.evaluate(), model.evaluate_at(1.5))


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
    assert t.tracks.head_pose is not None and "handles" in t.tracks.tracks
    assert {"jawOpen", "mouthSmileLeft", "browInnerUp"} <= set(t.tracks.weight_tracks)
    assert not np.array_equal(t.evaluate_at(0.25), t.evaluate_at(1.5))
