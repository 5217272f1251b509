"""A detailed performance of any rigged face, for a database when no scans are at hand.

The procedural wrinkles of :mod:`workbench.methods.wrinkles.examples` put onto
the face's own expressions (sculpted in the sample head's frame — decimetres,
+y up, +z front — so any units and axes work; the wrinkles are placed by the
sample's landmarks, so a face far from the sample's shape needs its own scans): the six example expressions and the frames of a
generated performance (:func:`~workbench.methods.wrinkles.examples.performance_weights`),
on the face's mesh or on its Loop subdivision (``levels``: the 80k head from the
25k one, as §5 enhances a low-resolution input from a high-resolution database).
:func:`procedural_database` encodes it with the paper's four voluntary regions
(found from the frames' motion, :mod:`workbench.enhance.motion_regions`) and returns the
weights of the performance as a take for *Retime from performance*.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.enhance.database import PerformanceDatabase
from workbench.enhance.motion_regions import motion_regions, voluntary_cores_from_motion
from workbench.enhance.voluntary import face_voluntary_cores, voluntary_region_weights

if TYPE_CHECKING:
    from workbench.core.state import FaceState

__all__ = ["ProceduralPerformance", "procedural_database"]

Progress = Callable[[float, str], Any]


@dataclass
class ProceduralPerformance:
    """What :func:`procedural_database` made.

    Attributes
    ----------
    database : PerformanceDatabase
    weights : (T, k) float64
        The generated performance's blendshape weights in ``shape_names`` order
        (without the six example expressions, which are poses, not motion): a take
        for :meth:`EnhanceFacet.retime`.
    shape_names : list of str
    fps : float
        The rate the performance was generated at.
    """

    database: PerformanceDatabase
    weights: NDArray[np.float64]
    shape_names: list[str]
    fps: float = 30.0


def procedural_database(
    model: FaceState,
    *,
    n_frames: int = 60,
    levels: int = 0,
    lambda_dt: float = 125.0,
    regions: bool | str = "motion",
    seed: int = 7,
    progress: Progress | None = None,
) -> ProceduralPerformance:
    """Encode a procedural detailed performance of ``model`` (on its mesh, or ``levels`` Loop steps finer).

    Parameters
    ----------
    model : FaceModel
        A rig with ARKit-like shapes (any spelling; split halves are fine).
    n_frames : int
        Frames of the generated performance (plus the six example expressions).
    levels : int
        Loop subdivisions of the database mesh (0: the model's own mesh).
    lambda_dt : float
        Curvature-flow step in mm² (the paper's 125).
    regions : {"motion", "names"} or bool
        The four voluntary regions (mouth and brows, left and right): ``"motion"``
        (or True) clusters the performance's own frames by how they move
        (:func:`~workbench.enhance.motion_regions.motion_regions`, no shape names
        needed), ``"names"`` takes the vertices the brow and mouth shapes move most
        (:func:`~workbench.enhance.voluntary.face_voluntary_cores`); False: one
        region. Motion is the default: it needs no names, and on the §7 validation
        it does as well as names (error 0.833 both on the sample head; 0.699 vs
        0.663 on a warped head on another mesh, detail band 0.329 vs 0.330;
        one region 0.841 / 1.061, ``benchmarks/bench_enhance_regions.py``).
    seed : int
        Seed of the generated performance.
    progress : callable(fraction, message), optional

    Raises
    ------
    ValueError
        ``n_frames`` < 2, ``levels`` not in 0..2 or ``regions`` not one of the above;
        the rig has none of the example expressions' shapes.
    """
    from workbench.arkit import rig_weights
    from workbench.core.shapes import BlendShape, ModelMetadata
    from workbench.geometry.axes import face_axes
    from workbench.geometry.subdivision import subdivide_model
    from workbench.methods.wrinkles.examples import (
        EXAMPLE_POSES,
        WrinkleSculptor,
        performance_weights,
    )
    from workbench.model import FaceModel

    if int(n_frames) < 2:
        raise ValueError(f"procedural_database: n_frames must be >= 2, got {n_frames!r}")
    if int(levels) not in (0, 1, 2):
        raise ValueError(f"procedural_database: levels must be 0, 1 or 2, got {levels!r}")
    if regions not in (True, False, "motion", "names"):
        raise ValueError(f"procedural_database: regions must be 'motion', 'names', True or False, got {regions!r}")
    say = progress or (lambda f, msg: None)
    say(0.0, "preparing the detailed face")
    # the wrinkles are laid out in the sample head's frame (decimetres, +y up, +z front):
    # sculpt a copy turned and scaled into it, and bring the frames back
    axes = face_axes(model)
    scale = float(model.metadata.metres_per_unit) / 0.1

    def to_sample(P: ArrayLike) -> NDArray[np.float64]:
        return np.asarray(P, np.float64) @ axes.T * scale

    def from_sample(P: NDArray[Any]) -> NDArray[np.float64]:
        return (np.asarray(P, np.float64) / scale) @ axes

    canonical = FaceModel(
        to_sample(model.vertices), model.faces,
        [BlendShape(s.name, to_sample(s.delta).astype(np.float32), slider_min=s.slider_min, slider_max=s.slider_max)
         for s in model.shapes],
        component_labels=model.component_labels, component_names=model.component_names,
        metadata=ModelMetadata(name=model.metadata.name, units="dm"),
    )
    fine: Any = subdivide_model(canonical, int(levels)) if levels else canonical
    sculptor = WrinkleSculptor(fine)
    poses = list(EXAMPLE_POSES.values()) + performance_weights(int(n_frames), seed=seed)
    names = list(model.shape_names)
    weights = np.zeros((len(poses), len(names)))
    index = {n: j for j, n in enumerate(names)}
    for i, w in enumerate(poses):
        own, _ = rig_weights(w, names)
        for name, value in own.items():
            weights[i, index[name]] = value
    if not np.any(weights):
        raise ValueError("procedural_database: the rig has none of the example expressions' shapes")
    frames = np.empty((len(poses), fine.n_vertices, 3), np.float32)
    for i, w in enumerate(poses):
        if i % 8 == 0:
            say(0.4 * i / len(poses), f"sculpting detailed frame {i + 1} of {len(poses)}")
        frames[i] = from_sample(sculptor.detailed(w))
    V = from_sample(fine.vertices)
    F = np.asarray(fine.faces, np.int64)
    mpu = float(model.metadata.metres_per_unit)
    region_w = None
    if regions == "names":
        cores = face_voluntary_cores(fine)
    elif regions:
        say(0.4, "finding the voluntary regions from the motion")
        cores = voluntary_cores_from_motion(V, motion_regions(V, F, frames), axes)
    if regions:
        # σ 1 cm, in model units
        region_w = voluntary_region_weights(V, F, cores, sigma=0.01 / mpu)
    db = PerformanceDatabase.from_frames(
        from_sample(sculptor.detail_of(fine.vertices)), F, frames, regions=region_w, lambda_dt=lambda_dt, metres_per_unit=mpu,
        progress=lambda f, msg: say(0.4 + 0.6 * f, msg),
    )
    return ProceduralPerformance(db, weights[len(EXAMPLE_POSES):], names)
