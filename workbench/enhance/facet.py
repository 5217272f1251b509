"""``model.enhance``: the *Enhanced* preview (§5) and *Retime from performance* (§6.2) (Bermano et al. 2014).

Spatial enhancement: :meth:`EnhanceFacet.set_database` installs a
:class:`~workbench.enhance.database.PerformanceDatabase` and the correspondence
from the model's mesh to it (found by itself: the same mesh, a Loop subdivision
of it, or the closest points of its surface); :meth:`~EnhanceFacet.set_preview`
turns the *Enhanced* preview layer on and off (:mod:`.layer`; every exporter
then bakes it); :meth:`~EnhanceFacet.enhance_timeline` enhances every frame of
the timeline at the database's resolution (:class:`~workbench.enhance.bake.EnhancedTake`,
exported like any face). Each edit is one undo step.

Retiming:

:meth:`EnhanceFacet.retime` takes two times on the timeline (a key pair), reads
the weights there, finds the transition between them in a database of takes
(:func:`workbench.enhance.retime`: segment projection and the monotone matching
of eq. 5–6 over every take) and keys the in-betweens with the matched take's
timing — linear keys on every frame between the two times, for the shapes that
change between them — as one undo step. The database is any sequence of takes:
(T, k) weight arrays in ``model.shape_names`` order, tracked takes
(:class:`workbench.capture.TrackResult`) or timelines (sampled at their frames),
or point caches (T, n, 3) on the model's mesh — projected onto the model's own
shapes (:class:`~workbench.enhance.rig_space.RigBasis`, bounded by the sliders)
and matched in those weights, the paper's compressed space (``space="mesh"``:
in raw vertices).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from workbench.animation.tracks import Timeline, add_keys
from workbench.core.shapes import ModelError
from workbench.enhance.bake import EnhancedTake
from workbench.enhance.layer import EnhancementState
from workbench.enhance.retime import SPACES, RetimeResult, retime
from workbench.enhance.rig_space import RigBasis
from workbench.enhance.spatial import Correspondence, Progress

if TYPE_CHECKING:
    from workbench.core.state import FaceState
    from workbench.enhance.database import PerformanceDatabase

__all__ = ["EnhanceFacet", "weight_takes"]


def weight_takes(database: Any, shape_names: Sequence[str], fps: float | None = None) -> list[NDArray[np.float64]]:
    """(T_i, k) weight arrays in ``shape_names`` order from arrays, tracked takes or timelines.

    With ``fps``, takes that know their rate (timelines, tracked takes) are resampled to
    it, so that transition lengths compare with the keyed one (a 60 fps take timing a
    30 fps timeline); plain arrays are taken at ``fps`` as they are.
    """
    items = [database] if isinstance(database, Timeline) or hasattr(database, "shape_names") else list(database)
    if not items:
        raise ModelError("retime: the database has no takes")
    names = list(shape_names)
    out = []
    for i, item in enumerate(items):
        rate = getattr(item, "fps", None)
        if isinstance(item, Timeline):
            W = item.weight_matrix(names, (item if fps is None else item.replace(fps=fps)).frame_times())
        elif hasattr(item, "shape_names") and hasattr(item, "weights"):
            index = {n: j for j, n in enumerate(item.shape_names)}
            missing = [n for n in names if n not in index]
            if missing:
                raise ModelError(f"retime: database[{i}] has no weights for {missing[:5]}")
            W = np.asarray(item.weights, np.float64)[:, [index[n] for n in names]]
            if fps is not None and rate and abs(float(rate) - fps) > 1e-9 and W.shape[0] > 1:
                t = np.arange(W.shape[0]) / float(rate)
                tn = Timeline(fps=fps, end=float(t[-1])).frame_times()
                W = np.stack([np.interp(tn, t, W[:, j]) for j in range(W.shape[1])], axis=1)
        else:
            W = np.asarray(item, np.float64)
            if W.ndim != 2 or W.shape[1] != len(names):
                raise ModelError(f"retime: database[{i}] must be (T, {len(names)}) weights, got {W.shape}")
        out.append(W)
    return out


def default_correspondence(model: FaceState, database: PerformanceDatabase) -> Correspondence:
    """The model's mesh → the database's: the same mesh, a Loop subdivision of it (1–3 levels), else closest points.

    The first two are recognised by vertex count and checked on the neutral
    (within 1 % of the head size); closest points assume both meshes are in the same place and units.
    """
    from workbench.geometry.subdivision import subdivided_vertex_count

    V = np.asarray(model.vertices, np.float64)
    F = np.asarray(model.faces, np.int64)
    d0 = database.neutral_
    size = float(np.linalg.norm(np.ptp(V, axis=0))) or 1.0
    candidates: list[Correspondence] = []
    if d0.shape[0] == V.shape[0]:
        candidates.append(Correspondence.identity(V.shape[0]))
    for levels in (1, 2, 3):
        if subdivided_vertex_count(F, V.shape[0], levels) == d0.shape[0]:
            candidates.append(Correspondence.loop(F, V.shape[0], levels))
    for corr in candidates:
        if float(np.sqrt(np.mean(np.sum((corr(V[None])[0] - d0) ** 2, axis=1)))) < 0.01 * size:
            return corr
    return Correspondence.from_surface(V, F, d0, database.faces_)


def mesh_takes(database: Any, n_vertices: int) -> list[NDArray[np.float64]] | None:
    """(T_i, n, 3) point-cache takes on the model's mesh, or None when the database is weight takes."""
    items = [database] if isinstance(database, np.ndarray) else list(database) if isinstance(database, (list, tuple)) else []
    arrays = [np.asarray(x) for x in items if isinstance(x, np.ndarray)]
    if not arrays or len(arrays) != len(items) or any(x.ndim != 3 for x in arrays):
        return None
    for i, x in enumerate(arrays):
        if x.shape[1:] != (n_vertices, 3):
            raise ModelError(f"retime: database[{i}] must be ({x.shape[0]}, {n_vertices}, 3) on the model's mesh, "
                             f"got {x.shape}")
    return [x.astype(np.float64) for x in arrays]


class EnhanceFacet:
    """Performance enhancement on one model (see the module docstring).

    Keeps nothing of its own but a cache: the rig basis point caches are matched in,
    rebuilt only when the model's shapes change (their version) or other shapes are asked for.
    """

    def __init__(self, model: FaceState) -> None:
        self._model = model
        self._basis: tuple[tuple[int, tuple[str, ...]], RigBasis] | None = None

    def _rig_basis(self, names: list[str]) -> RigBasis:
        """:meth:`RigBasis.from_model` of ``names``, kept while the shapes' version and the names stay."""
        key = (self._model.version("shapes"), tuple(names))
        if self._basis is None or self._basis[0] != key:
            self._basis = (key, RigBasis.from_model(self._model, names))
        return self._basis[1]

    def __repr__(self) -> str:
        st = self.state
        db = "no database" if st.database is None else f"database of {st.database.n_frames_} frames ({st.source or '-'})"
        return f"<enhance: {db}, preview {'on' if st.enabled else 'off'}; retime(t0, t1, takes)>"

    # ------------------------------------------------------------------ spatial (§5)
    @property
    def state(self) -> EnhancementState:
        """The ``enhancement`` slot (database, correspondence, preview on/off)."""
        st: EnhancementState = self._model.slot("enhancement")
        return st

    @property
    def database(self) -> PerformanceDatabase | None:
        return self.state.database

    @property
    def preview(self) -> bool:
        """Whether the *Enhanced* preview layer is on."""
        return self.state.enabled

    def set_database(self, database: PerformanceDatabase | None, *, correspondence: Correspondence | None = None,
                     source: str = "", preview: bool | None = None) -> None:
        """Use ``database`` for enhancement (one undo step; ``None`` removes it and turns the preview off).

        Parameters
        ----------
        database : PerformanceDatabase or None
        correspondence : Correspondence, optional
            The model's mesh → the database's; default :func:`default_correspondence`.
        source : str
            Where it came from (shown by panels).
        preview : bool, optional
            Turn the *Enhanced* preview on/off in the same step (default: keep it).
        """
        m = self._model
        old = self.state
        if database is None:
            m.set_slot("enhancement", EnhancementState(), "Remove enhancement database")
            return
        corr = correspondence or default_correspondence(m, database)
        on = old.enabled if preview is None else bool(preview)
        m.set_slot("enhancement", EnhancementState(database, corr, on, source),
                   f"Enhancement database ({database.n_frames_} frames)")

    def set_preview(self, on: bool = True) -> None:
        """Turn the *Enhanced* preview on or off (one undo step)."""
        st = self.state
        if st.enabled == bool(on):
            return
        self._model.set_slot("enhancement", st.replace(enabled=bool(on)), "Enhanced preview " + ("on" if on else "off"))

    def enhance_timeline(self, times: Sequence[float] | None = None, *, progress: Progress | None = None) -> EnhancedTake:
        """Enhance the animation at the database's resolution: every frame of the timeline (or ``times``).

        Each frame is the model evaluated at that time (head pose included; the
        preview layer itself left out), mapped onto the database mesh and enhanced
        (enhancement is rotation-equivariant, so the pose stays). The model is not changed.

        Raises
        ------
        ModelError
            No database is set.
        """
        from workbench.animation.family import head_matrix
        from workbench.core.pipeline import posed_points

        m = self._model
        st = self.state
        if st.database is None or st.correspondence is None:
            raise ModelError("enhance_timeline: no database; call model.enhance.set_database(...) first")
        tl: Timeline = m.slot("tracks")
        t = np.asarray(tl.frame_times() if times is None else list(times), np.float64)
        if t.size == 0:
            raise ModelError("enhance_timeline: no frames to enhance (the timeline range is empty)")
        say = progress or (lambda f, msg: None)
        frames = np.empty((t.size, m.n_vertices, 3), np.float64)
        for i, ti in enumerate(t):
            if i % 8 == 0:
                say(0.2 * i / t.size, f"evaluating frame {i + 1} of {t.size}")
            below = np.asarray(m.evaluation_at(float(ti), below="enhance").mesh, np.float64)
            M = head_matrix(m.view_at(float(ti)))
            frames[i] = below if M is None else posed_points(below.astype(np.float32), M)
        result = st.database.enhance_result(
            frames, correspondence=st.correspondence, progress=lambda f, msg: say(0.2 + 0.8 * f, msg)
        )
        return EnhancedTake(result.frames, t, st.database.faces_, result.weights, tl.fps,
                            m.metadata.metres_per_unit, m.metadata, str(m.metadata.name or "face"))

    # ------------------------------------------------------------------ temporal (§6.2)

    def retime(self, t0: float, t1: float, database: Any, *, n_frames: int | None = None, extend: bool = False,
               method: str = "auto", space: str = "auto", label: str | None = None) -> RetimeResult:
        """Key the in-betweens of ``t0`` → ``t1`` with the timing of the best-matching take (one undo step).

        Parameters
        ----------
        t0, t1 : float
            Seconds, ``t0 < t1`` (usually two keys).
        database : sequence of takes
            Weight takes (see :func:`weight_takes`), or point caches (T_i, n, 3) on the
            model's mesh (the faces shown at ``t0`` and ``t1`` are the keys; see ``space``).
        n_frames : int, optional
            In-betweens including both ends; default one per frame of the timeline's fps.
        extend : bool
            See :func:`workbench.enhance.retime`.
        method : {"auto", "closest", "take"}
            Where the timing comes from (see :func:`workbench.enhance.retime`);
            ``RetimeResult.choice`` says which was used.
        space : {"auto", "mesh", "weights"}
            For point caches: ``"weights"`` projects the takes and the two faces
            onto the model's shapes (those the timeline keys, correctives left
            out; bounded by the sliders) and matches in those weights; ``"mesh"``
            matches the raw vertices; ``"auto"`` (default) is ``"weights"`` when the
            model has shapes. ``RetimeResult.space`` says which (``"rig"`` for the
            weights). Ignored for weight takes.

        Returns
        -------
        RetimeResult
        """
        m = self._model
        a, b = float(t0), float(t1)
        if not (np.isfinite(a) and np.isfinite(b) and b > a):
            raise ModelError(f"retime: need finite t0 < t1, got {t0!r}, {t1!r}")
        derived = set(m.shape_tools.correctives)  # type: ignore[attr-defined]
        names = [n for n in m.shape_names if n not in derived]
        tl: Timeline = m.slot("tracks")
        n = round((b - a) * tl.fps) + 1 if n_frames is None else int(n_frames)
        if n < 3:
            raise ModelError(f"retime: {t0:g}–{t1:g} s holds fewer than 3 frames at {tl.fps:g} fps (n_frames={n})")
        W = tl.weight_matrix(names, [a, b])
        changed = np.flatnonzero(np.abs(W[1] - W[0]) > 1e-9)
        if changed.size == 0:
            raise ModelError(f"retime: the weights at {a:g} s and {b:g} s are the same: nothing to retime")
        if space not in SPACES:
            raise ModelError(f"retime: space must be one of {SPACES}, got {space!r}")
        meshes = mesh_takes(database, m.n_vertices)
        if meshes is not None:
            # point caches: the keys are the faces shown at t0 and t1 (model space), matched in the model's
            # weights (space="mesh": the raw vertices)
            ends = [np.asarray(m.evaluation_at(t).mesh, np.float64) for t in (a, b)]
            basis = self._rig_basis(names) if names and space != "mesh" else None
            found = retime(meshes, ends[0], ends[1], n, extend=extend, method=method, basis=basis, space=space)
            # the timing found for the caches, keyed on the weights
            res = dataclasses.replace(found, frames=W[0][None, :] + found.s[:, None] * (W[1] - W[0])[None, :])
        else:
            res = retime(weight_takes(database, names, tl.fps), W[0], W[1], n, extend=extend, method=method)
        times = np.linspace(a, b, n)[1:-1]
        new = tl
        for j in changed:
            track = f"weights/{names[j]}"
            new = add_keys(new, track, times, res.frames[1:-1, j], interpolation="linear")
            # the key at t0 governs the segment after it: linear, so the in-betweens play as keyed;
            # the key at t1 stays as it was (it governs what follows), or is added when missing
            new = add_keys(new, track, [a], W[:1, j], interpolation="linear")
            old = tl.tracks.get(track)
            if old is None or not np.any(np.abs(old.times - b) <= 1e-9):
                new = add_keys(new, track, [b], W[1:, j], interpolation="linear")
        m.timeline.set(new, label or f"Retime {a:g}–{b:g} s from performance")  # type: ignore[attr-defined]
        return res
