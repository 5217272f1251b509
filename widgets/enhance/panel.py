"""``EnhancePanel``: the Enhance tab — detail from a performance database and data-driven retiming (issue 18).

*Detail database*: build one from the face's own procedural detailed
performance (on a Loop-subdivided copy — the finer database §5 expects — or on
the face's own mesh; :func:`workbench.enhance.performance.procedural_database`)
or load a saved one (``.npz``, :meth:`PerformanceDatabase.load`); a progress bar
while it encodes; *Save database*. The *Enhanced* preview check box turns the
enhancement layer on and off (``model.enhance.set_preview``: one undo step, and
undo/redo move the box). *Bake enhanced take* enhances every frame of the
timeline at the database's resolution and writes it (PC2, MDD, OBJ sequence,
Alembic, baked glTF, USD — by the file suffix).

*Retime from performance*: pick two key times on the timeline, then key the
in-betweens with the timing of the best-matching motion (§6.2;
``model.enhance.retime``: one undo step) from the detailed performance, the
Capture tab's tracked take or an animation file (glTF, weights or Live Link
Face CSV; an Alembic point cache on this face's mesh is matched in mesh space), optionally *extended to the full matched motion*;
the plot after Fig. 7 shows linear, retimed and database curves of the shape
that changes most.
"""

from __future__ import annotations

import html
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import ipywidgets as W
import numpy as np

from widgets.enhance.plots import retime_plot_png
from widgets.panels.base import ModelPanel, button
from widgets.panels.progress import ProgressRow

__all__ = ["EnhancePanel"]

SOURCES = (
    ("procedural performance, one subdivision finer", "procedural-finer"),
    ("procedural performance, this mesh", "procedural"),
    ("database file (.npz)", "file"),
)


class EnhancePanel(ModelPanel):
    """The Enhance tab (see the module docstring).

    Parameters
    ----------
    model : workbench.FaceModel
    errors : ipywidgets.Output or ErrorSink, optional
    before_edit : iterable of callables
    selected_keys : callable, optional
        Returns the timeline's selected keys ``[(track, index), ...]``.
    capture_result : callable, optional
        Returns the Capture tab's tracked take (a ``TrackResult``) or None.

    Attributes
    ----------
    performance : ProceduralPerformance or None
        The procedural performance the database was built from (its weights are a retiming take).
    last_take : EnhancedTake or None
    last_retime : RetimeResult or None
    """

    def __init__(self, model: Any, *, errors: Any = None, before_edit: Any = (),
                 selected_keys: Callable[[], Any] | None = None,
                 capture_result: Callable[[], Any] | None = None) -> None:
        super().__init__(model, errors=errors, before_edit=before_edit, layout=W.Layout(width="100%"))
        self.selected_keys = selected_keys
        self.capture_result = capture_result
        self.performance: Any = None
        self.last_take: Any = None
        self.last_retime: Any = None
        self.source = W.Dropdown(options=SOURCES, value="procedural-finer", description="from",
                                 layout=W.Layout(width="420px"), style={"description_width": "50px"})
        self.source.add_class("fwb-enhance-source")
        self.n_frames = W.BoundedIntText(value=60, min=2, max=2000, description="frames",
                                         layout=W.Layout(width="150px"), style={"description_width": "50px"})
        self.n_frames.add_class("fwb-enhance-frames")
        self.path = W.Text(placeholder="database.npz", layout=W.Layout(width="260px"))
        self.path.add_class("fwb-enhance-path")
        self.build_button = button("Build database", "fwb-enhance-build",
                                   "Encode the detail database (Bermano et al. 2014 §4)", "database")
        self.save_button = button("Save database", "fwb-enhance-save", "Write the database as .npz", "save")
        self.progress = ProgressRow("fwb-enhance-progress", "fwb-enhance-status")
        self.info = W.HTML("<i>No database.</i>")
        self.info.add_class("fwb-enhance-info")
        self.preview = W.Checkbox(value=False, description="Enhanced preview", indent=False,
                                  tooltip="Show the face with the database's detail (an undoable switch)")
        self.preview.add_class("fwb-enhance-preview")
        self.bake_path = W.Text(value="enhanced.glb", layout=W.Layout(width="220px"))
        self.bake_path.add_class("fwb-enhance-bake-path")
        self.bake_button = button("Bake enhanced take", "fwb-enhance-bake",
                                  "Enhance every frame of the timeline at the database's resolution and write it "
                                  "(.glb .usdc .pc2 .mdd .obj .abc)", "film")
        self.retime_source = W.Dropdown(options=[("the detailed performance", "performance"),
                                                 ("the Capture tab's take", "capture"),
                                                 ("an animation file (.glb / .csv / .abc)", "file")],
                                        value="performance", description="from", layout=W.Layout(width="320px"),
                                        style={"description_width": "50px"})
        self.retime_source.add_class("fwb-enhance-retime-source")
        self.retime_path = W.Text(placeholder="take.glb / take.csv (Live Link Face, weights) / take.abc (point cache)",
                                  layout=W.Layout(width="320px"))
        self.retime_path.add_class("fwb-enhance-retime-path")
        self.extend = W.Checkbox(value=False, description="extend to the full matched motion", indent=False)
        self.extend.add_class("fwb-enhance-extend")
        self.timing = W.Dropdown(options=[("auto: a close match, else the take's transitions", "auto"),
                                          ("the closest match (§6.2)", "closest"),
                                          ("the take's transitions blended", "take")],
                                 value="auto", description="timing", layout=W.Layout(width="420px"),
                                 style={"description_width": "50px"})
        self.timing.add_class("fwb-enhance-timing")
        self.retime_button = button("Retime selected keys", "fwb-enhance-retime",
                                    "Bermano et al. 2014 §6.2: key the in-betweens of the two selected key times "
                                    "with a performance's timing (one undo step)", "clock-o")
        self.plot = W.Image(format="png", layout=W.Layout(width="100%", display="none"))
        self.plot.add_class("fwb-enhance-plot")
        g = self.guard
        self.build_button.on_click(g("build database")(lambda _b: self.build()))
        self.save_button.on_click(g("save database")(lambda _b: self.save(self.path.value)))
        self.bake_button.on_click(g("bake enhanced take")(lambda _b: self.bake(self.bake_path.value)))
        self.retime_button.on_click(g("retime from performance")(lambda _b: self.retime_selected()))
        self.preview.observe(g("enhanced preview")(self._on_preview_box), "value")
        self.source.observe(g("database source")(lambda _c: self.refresh()), "value")
        self.retime_source.observe(g("retime source")(lambda _c: self.refresh()), "value")
        self.listen(model.events.enhancement, self.refresh, "enhance panel")
        self.children = [
            W.HTML("<b>Detail database</b>"),
            W.HBox([self.source, self.n_frames]),
            W.HBox([self.path, self.build_button, self.save_button]),
            self.progress, self.info, self.preview,
            W.HTML("<b>Bake</b>"), W.HBox([self.bake_path, self.bake_button]),
            W.HTML("<b>Retime from performance</b>"),
            W.HBox([self.retime_source, self.extend]), self.timing, self.retime_path, self.retime_button, self.plot,
        ]
        self.refresh()

    # ------------------------------------------------------------------ database
    def build(self) -> Any:
        """Build (procedural) or load (file) the database per :attr:`source`, and use it (one undo step)."""
        from workbench.enhance import PerformanceDatabase
        from workbench.enhance.performance import procedural_database

        kind = self.source.value
        self.flush()
        t0 = time.perf_counter()
        self.progress.start("<i>building the database ...</i>")
        try:
            if kind == "file":
                p = Path(str(self.path.value).strip())
                if not str(self.path.value).strip():
                    raise ValueError("Load database: type the path of a .npz database first")
                db = PerformanceDatabase.load(p)
                source = p.name
                self.performance = None
            else:
                perf = procedural_database(self.model, n_frames=int(self.n_frames.value),
                                           levels=1 if kind == "procedural-finer" else 0, progress=self.progress)
                db, source, self.performance = perf.database, "procedural performance", perf
            self.model.enhance.set_database(db, source=source)
        except Exception as exc:
            self.progress.fail(f"database failed: {exc}")
            raise
        self.progress.finish(f"database of {db.n_frames_} frames on {db.neutral_.shape[0]:,} vertices in "
                             f"{time.perf_counter() - t0:.1f} s")
        return db

    def save(self, path: str) -> Path:
        """Write the current database to ``path`` (``.npz``)."""
        db = self.model.enhance.database
        if db is None:
            raise ValueError("Save database: build or load one first")
        p = Path(str(path).strip() or "database.npz")
        if p.suffix.lower() != ".npz":
            raise ValueError(f"Save database: {p.name}: expected a .npz path")
        db.save(p)
        self.progress.finish(f"saved the database to {html.escape(str(p))}")
        return p

    def _on_preview_box(self, change: dict) -> None:
        if bool(change["new"]) != self.model.enhance.preview:
            self.flush()
            try:
                self.model.enhance.set_preview(bool(change["new"]))
            finally:
                self.refresh()

    # ------------------------------------------------------------------ bake
    def bake(self, path: str) -> list[Path]:
        """Enhance the timeline's frames at the database's resolution and write them to ``path``."""
        p = Path(str(path).strip())
        if not str(path).strip():
            raise ValueError("Bake: type an output path (.glb, .usdc, .pc2, .mdd, .obj, .abc)")
        t0 = time.perf_counter()
        self.progress.start("<i>enhancing the timeline ...</i>")
        try:
            take = self.model.enhance.enhance_timeline(progress=self.progress)
            files = list(take.export(p))
        except Exception as exc:
            self.progress.fail(f"bake failed: {exc}")
            raise
        self.last_take = take
        dt = time.perf_counter() - t0
        n = len(take.times)
        self.progress.finish(f"baked {n} enhanced frames ({take.frames.shape[1]:,} vertices) to "
                             f"{html.escape(', '.join(f.name for f in files[:3]))} in {dt:.1f} s "
                             f"({dt / max(n, 1):.2f} s/frame)")
        return files

    # ------------------------------------------------------------------ retime
    def _takes(self) -> list[Any]:
        if self.retime_source.value == "file":
            from workbench.animation.importers import read_animation

            text = str(self.retime_path.value).strip()
            if not text:
                raise ValueError("Retime: type the path of an animation (.glb/.gltf, or a weights / Live Link CSV)")
            p = Path(text)
            if p.suffix.lower() == ".abc":  # a point cache: mesh space (its frames on this face's mesh)
                from workbench.core.shapes import UNIT_TO_METRES
                from workbench.io.alembic import read_alembic

                face = read_alembic(p)
                if face.frames is None:
                    raise ValueError(f"Retime: {p.name} holds no animated frames")
                scale = UNIT_TO_METRES[face.units] / self.model.metadata.metres_per_unit if face.units else 1.0
                return [np.asarray(face.frames.positions, np.float64) * scale]
            md = self.model.metadata
            return [read_animation(p, self.model.shape_names, up_axis=md.up_axis, front_axis=md.front_axis)]
        if self.retime_source.value == "capture":
            res = self.capture_result() if self.capture_result is not None else None
            if res is None:
                raise ValueError("Retime: track a take in the Capture tab first, or retime from the detailed performance")
            return [res]
        if self.performance is None:
            raise ValueError("Retime: build the procedural performance database first (its motion gives the timing)")
        return [self.performance.weights]

    def retime_selected(self) -> Any:
        """Retime between the two selected key times (one undo step); draws the Fig. 7 plot."""
        from workbench.enhance.facet import mesh_takes, weight_takes

        keys = list(self.selected_keys() if self.selected_keys is not None else [])
        tracks = self.model.slot("tracks").tracks
        times = sorted({float(tracks[tn].keys[int(i)].time) for tn, i in keys if tn in tracks})
        if len(times) != 2:
            raise ValueError(f"Retime: select keys at exactly two times on the timeline (selected: {times})")
        takes = self._takes()
        self.flush()
        extend = bool(self.extend.value)
        res = self.model.enhance.retime(times[0], times[1], takes, extend=extend, method=str(self.timing.value))
        self.last_retime = res
        derived = set(self.model.shape_tools.correctives)
        names = [n for n in self.model.shape_names if n not in derived]
        j = int(np.argmax(np.abs(res.frames[-1] - res.frames[0])))
        meshes = mesh_takes(takes, self.model.n_vertices)
        # the database motion's progress along its chord is drawn; point caches are flattened to vectors
        fps = self.model.slot("tracks").fps
        seqs = [x.reshape(len(x), -1) for x in meshes] if meshes is not None else weight_takes(takes, names, fps)
        self.plot.value = retime_plot_png(res, seqs, times[0], times[1], shape=j, name=names[j], extended=extend)
        self.plot.layout.display = None
        self.progress.finish(f"retimed {times[0]:g}–{times[1]:g} s: {res.describe()} (undo: one step)")
        return res

    # ------------------------------------------------------------------ display
    def refresh(self, *_: Any) -> None:
        st = self.model.enhance.state
        db = st.database
        if db is None:
            self.info.value = "<i>No database.</i>"
        else:
            corr = st.correspondence
            self.info.value = (
                f"<b>{html.escape(st.source or 'database')}</b>: {db.n_frames_} frames on {db.neutral_.shape[0]:,} "
                f"vertices, {db.n_patches_} patches, regions {html.escape(', '.join(db.region_names_))}; "
                f"this face → database: {corr.kind if corr is not None else '-'}"
            )
        if self.preview.value != st.enabled:
            self.preview.value = st.enabled
        self.preview.disabled = db is None
        self.save_button.disabled = db is None
        self.bake_button.disabled = db is None
        self.n_frames.disabled = self.source.value == "file"
        self.retime_path.layout.display = None if self.retime_source.value == "file" else "none"
        self.path.placeholder = "database.npz (to load)" if self.source.value == "file" else "database.npz (to save)"
        self.build_button.description = "Load database" if self.source.value == "file" else "Build database"
