"""``Viewport.set_overlay_points``: free points over the face (what is sent, what is refused)."""

from __future__ import annotations

import numpy as np
import pytest

import workbench

pytestmark = pytest.mark.ui


def test_overlay_points_send_finite_rows_with_their_colours() -> None:
    from widgets import Viewport

    model = workbench.load_sample("head")
    vp = Viewport(model, height=200)
    try:
        P = np.array([[0.0, 7.0, 1.0], [np.nan, 0.0, 0.0], [0.5, 7.5, 1.2]])
        assert vp.set_overlay_points(P, colors=[[1, 0, 0], [0, 1, 0], [0, 0, 1]]) == 2
        np.testing.assert_allclose(vp.overlay_points, P[[0, 2]], rtol=1e-6)
        assert np.frombuffer(vp._overlay_colors, np.uint8).reshape(-1, 3).tolist() == [[255, 0, 0], [0, 0, 255]]
        assert vp.set_overlay_points(P[:1], colors=(0.2, 0.4, 0.6)) == 1
        assert list(np.frombuffer(vp._overlay_colors, np.uint8)) == [51, 102, 153]
        assert vp.set_overlay_points(None) == 0 and vp.overlay_points.shape == (0, 3)
        with pytest.raises(ValueError, match=r"points must be \(p, 3\)"):
            vp.set_overlay_points(np.zeros((4, 2)))
        with pytest.raises(ValueError, match="colors must be"):
            vp.set_overlay_points(P, colors=np.zeros((2, 3)))
    finally:
        vp.close()
