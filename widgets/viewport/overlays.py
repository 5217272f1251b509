"""What the viewport draws over the face from Python: free points and the feature graph.

:class:`OverlayAPI` is mixed into :class:`widgets.viewport.widget.Viewport`
(kept apart so the widget's module stays readable): the Capture tab's markers,
landmarks or point cloud (:meth:`set_overlay_points`) and a feature graph
(Bickel et al. 2008 §5.1) coloured by strain (:meth:`set_feature_graph`,
:meth:`set_feature_strain`). The values are checked here and sent as the
widget's byte traits (``_overlay_points``, ``_feature_edges``, ...).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from widgets.viewport.common import f32_bytes


class OverlayAPI:
    """Free points and the feature graph over the face (mixed into ``Viewport``)."""

    sync: Any
    _model: Any
    _overlay_points: bytes
    _overlay_colors: bytes
    _feature_edges: bytes
    _feature_strain: bytes

    if TYPE_CHECKING:  # the widget's (a definition here would shadow it)

        def hold_sync(self) -> Any: ...

    @property
    def overlay_points(self) -> np.ndarray:
        """(p, 3) float32: the free points drawn over the face (finite ones only)."""
        return np.frombuffer(self._overlay_points, dtype="<f4").reshape(-1, 3).copy()

    def set_overlay_points(self, points: Any, colors: Any = None) -> int:
        """Draw free points over the face (None or empty: none); returns how many are drawn.

        ``points`` (p, 3) in model units; rows with NaN (an occluded marker) are
        not drawn. ``colors``: one sRGB colour (3,) or one per point (p, 3), in
        [0, 1]; default green.
        """
        if points is None:
            P = np.zeros((0, 3), np.float32)
        else:
            P = np.asarray(points, dtype=np.float64)
            if P.ndim != 2 or P.shape[1] != 3:
                raise ValueError(f"Viewport.set_overlay_points: points must be (p, 3), got {P.shape}")
        keep = np.isfinite(P).all(axis=1)
        C = b""
        if colors is not None:
            c = np.asarray(colors, dtype=np.float64)
            if c.shape == (3,):
                c = np.broadcast_to(c, P.shape)
            if c.shape != P.shape or not np.isfinite(c).all():
                raise ValueError(
                    f"Viewport.set_overlay_points: colors must be (3,) or {P.shape} in [0, 1], got {c.shape}"
                )
            C = (np.clip(c[keep], 0.0, 1.0) * 255 + 0.5).astype(np.uint8).tobytes()
        with self.hold_sync():
            self._overlay_points = f32_bytes(P[keep])
            self._overlay_colors = C
        return int(keep.sum())

    # ------------------------------------------------------- feature graph overlay
    # A feature graph (Bickel et al. 2008 §5.1): the edges on which a layer measures
    # strain, coloured by strain. The viewport does not know the layer; its panel feeds it.

    @property
    def feature_updates_sent(self) -> int:
        """Strain updates sent (tests, benchmarks)."""
        return self.sync.feature_updates_sent

    @property
    def feature_edges(self) -> np.ndarray:
        """(F, 2) uint32 vertex ids of the drawn feature-graph edges (empty: none)."""
        return np.frombuffer(self._feature_edges, dtype="<u4").reshape(-1, 2).copy()

    @property
    def feature_strain(self) -> np.ndarray:
        """(F,) float32 strain of each edge as last sent to the front end."""
        return np.frombuffer(self._feature_strain, dtype="<f4").copy()

    def set_feature_graph(self, vertex_pairs: Any) -> None:
        """Draw line segments between vertex pairs (F, 2) (None or empty: no graph).

        Resets the strain to zero (every edge grey) until :meth:`set_feature_strain`.
        """
        n = self._model.n_vertices
        pairs = np.zeros((0, 2), np.int64) if vertex_pairs is None else np.asarray(vertex_pairs)
        pairs = pairs.astype(np.int64).reshape(-1, 2)
        if pairs.size and (pairs.min() < 0 or pairs.max() >= n):
            raise ValueError(f"Viewport.set_feature_graph: vertex ids must be in 0..{n - 1}")
        self.sync.set_feature_graph(pairs)

    def set_feature_strain(self, strain: Any) -> bool:
        """Colour the edges by ``strain`` (F,): relative stretch ``(l - l0) / l0``.

        Sent only when some edge changed by more than
        :data:`~widgets.viewport.common.STRAIN_TOLERANCE` (or returned to exactly
        zero) and the overlay is shown; returns True when an update was sent.
        """
        f = np.asarray(strain, dtype=np.float32).reshape(-1)
        count = len(self._feature_edges) // 8
        if f.size != count:
            raise ValueError(
                f"Viewport.set_feature_strain: expected {count} values (one per edge), got {f.size}"
            )
        if not np.isfinite(f).all():
            raise ValueError("Viewport.set_feature_strain: strain contains NaN/inf")
        return self.sync.set_feature_strain(f)
