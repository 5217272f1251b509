"""Generated test data with a known answer: faces the methods have not seen, and small grids.

One public home for the faces that tests, benchmarks and tutorials check the
methods on (issue 27), all made from a rig such as
``workbench.load_sample("head")`` at any resolution, deterministic given a
seed, nothing downloaded:

* :mod:`~workbench.testing.faces` — :class:`GeneratedFace` (a face plus the
  exact map from its source, so its true shapes are known) and the builders:
  warped, remeshed, renumbered, with a bust, cropped, with a hole, with open
  mouth and eyes, in other proportions, with other motions for the same shapes;
* :mod:`~workbench.testing.conventions` — the same face in other units, with
  renamed / split shapes and unnamed parts, or unlike the source in every way
  at once (:func:`foreign_face`);
* :mod:`~workbench.testing.warps` — smooth warps (:class:`SmoothWarp`,
  :class:`LocalScale`, :func:`random_warp`, :func:`compose`);
* :mod:`~workbench.testing.meshes` — the array-level surgery (:func:`split_remesh`,
  :func:`add_bust`, :func:`cut_hole`, ...);
* :mod:`~workbench.testing.grids` — tiny hand-checkable grids;
* :mod:`~workbench.testing.takes` — capture takes that behave like a real phone take
  (dense, co-articulated, asymmetric, noisy weights; markers under head motion) and
  their statistics against the measured real take (:data:`REAL_TAKE`).

Nothing in the methods imports this package.
"""

from __future__ import annotations

from workbench.testing.conventions import (
    STYLES,
    foreign_face,
    in_units,
    rename_shape,
    renamed_shapes,
    split_sides,
    unnamed_parts,
)
from workbench.testing.faces import (
    GeneratedFace,
    cropped,
    opened,
    proportions_warp,
    remeshed,
    renumbered,
    restyled_shapes,
    warped,
    with_bust,
    with_hole,
)
from workbench.testing.grids import (
    grid_polygons,
    grid_quads,
    grid_triangles,
    grid_vertices,
    two_bump_grid,
)
from workbench.testing.meshes import (
    add_bust,
    cut_hole,
    keep_vertices,
    permute_vertices,
    split_remesh,
)
from workbench.testing.takes import (
    REAL_TAKE,
    TakeStatistics,
    calibration_head_motion,
    calibration_session,
    realistic_take,
    realistic_weights,
    take_markers,
    take_statistics,
)
from workbench.testing.warps import (
    Composed,
    LocalScale,
    SmoothWarp,
    Warp,
    capture_actor_warp,
    compose,
    identity,
    random_warp,
    sample_head_warp,
    unit_factor,
)

__all__ = [
    "REAL_TAKE",
    "STYLES",
    "Composed",
    "GeneratedFace",
    "LocalScale",
    "SmoothWarp",
    "TakeStatistics",
    "Warp",
    "add_bust",
    "calibration_head_motion",
    "calibration_session",
    "capture_actor_warp",
    "compose",
    "cropped",
    "cut_hole",
    "foreign_face",
    "grid_polygons",
    "grid_quads",
    "grid_triangles",
    "grid_vertices",
    "identity",
    "in_units",
    "keep_vertices",
    "opened",
    "permute_vertices",
    "proportions_warp",
    "random_warp",
    "realistic_take",
    "realistic_weights",
    "remeshed",
    "rename_shape",
    "renamed_shapes",
    "renumbered",
    "restyled_shapes",
    "sample_head_warp",
    "split_remesh",
    "split_sides",
    "take_markers",
    "take_statistics",
    "two_bump_grid",
    "unit_factor",
    "unnamed_parts",
    "warped",
    "with_bust",
    "with_hole",
]
