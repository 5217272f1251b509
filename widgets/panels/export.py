"""``ExportPanel``: write the model's animation to glTF/USD/point caches/CSV, or import one.

A thin form over :func:`workbench.export.export` (Export) and
:func:`workbench.io.animation.read_file_animation` + ``model.timeline.set`` (Import):
format, fps, bake and path fields, a button, and a result area listing the
files written (with sizes), how each editing layer went in, the writer's notes
(e.g. the Live Link layout's missing or left-out shapes), or the error message.
Nothing here knows a file format; the panel only picks the suffix the export
registry dispatches on, and for a .csv the layout (``style``: plain columns or
Epic's Live Link Face take for Unreal). Imports read head-pose columns about
the model's own up/front axes (``model.metadata``).

Exports run synchronously in the comm handler (the kernel is busy meanwhile):
they take well under a few seconds for the sample head, the files are complete
when the result is shown, and there is no second writer to race with.

Why hand-written: a handful of ipywidgets; no file-dialog widget exists that
works in every front end without an extension, so paths are typed (relative
paths are relative to the kernel's working directory; the result shows the
absolute path).
"""

from __future__ import annotations

import html
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import ipywidgets as W

from widgets.panels.base import ModelPanel

__all__ = ["CSV_LAYOUTS", "FORMAT_CHOICES", "ExportPanel"]

#: dropdown label -> (format key, file suffix)
FORMAT_CHOICES: dict[str, tuple[str, str]] = {
    "glTF binary (.glb)": ("glb", ".glb"),
    "USD crate (.usdc)": ("usdc", ".usdc"),
    "USD text (.usda)": ("usda", ".usda"),
    "PC2 point cache (.pc2)": ("pc2", ".pc2"),
    "MDD point cache (.mdd)": ("mdd", ".mdd"),
    "OBJ sequence (one .obj per frame)": ("obj", ".obj"),
    "CSV weights (.csv)": ("csv", ".csv"),
    "FBX, shape keys (.fbx, through Blender)": ("fbx", ".fbx"),
    "Alembic point cache (.abc, through Blender)": ("abc", ".abc"),
}
_SUFFIXES = {suffix for _, suffix in FORMAT_CHOICES.values()} | {".gltf", ".usd"}
#: CSV layout dropdown: label -> ``style`` of :func:`workbench.export.csv.write`
CSV_LAYOUTS: dict[str, str] = {"plain": "plain", "Live Link Face (Unreal)": "livelink"}
_MAX_LISTED = 6


def _size(n: int) -> str:
    for unit in ("B", "kB", "MB", "GB"):
        if n < 1024 or unit == "GB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024  # type: ignore[assignment]
    return f"{n} B"


def files_html(paths: list[Path]) -> str:
    """HTML list of written files with sizes (long sequences shortened)."""
    shown = paths if len(paths) <= _MAX_LISTED else [*paths[:3], None, *paths[-2:]]
    items = []
    for p in shown:
        if p is None:
            items.append(f"<li>… {len(paths) - 5} more …</li>")
            continue
        size = _size(p.stat().st_size) if p.exists() else "missing"
        items.append(f"<li><code>{html.escape(str(p))}</code> ({size})</li>")
    total = sum(p.stat().st_size for p in paths if p.exists())
    return (
        f"<div class='fwb-export-files'>Wrote {len(paths)} file{'s' if len(paths) != 1 else ''}"
        f" ({_size(total)}):<ul style='margin:2px 0'>{''.join(items)}</ul></div>"
    )


_ENCODING_TEXT = {
    "linear": "exact, as morph targets / blend shapes",
    "baked": "baked frame by frame (exact at every frame)",
    "omitted": "not in this format",
}


def layers_html(layers: Any) -> str:
    """HTML list of how each active editing layer went into the file (inactive ones left out)."""
    items = [
        f"<li><b>{html.escape(r.name)}</b>: {html.escape(_ENCODING_TEXT.get(r.encoding, r.encoding))}"
        f"<span style='color:#667085'> — {html.escape(r.detail)}</span></li>"
        for r in layers
        if r.encoding != "inactive"
    ]
    if not items:
        return ""
    warn = any(r.encoding == "omitted" for r in layers)
    colour = "#b54708" if warn else "inherit"
    return (
        f"<div class='fwb-export-layers' style='color:{colour}'>Editing layers:"
        f"<ul style='margin:2px 0'>{''.join(items)}</ul></div>"
    )


def notes_html(notes: Iterable[str]) -> str:
    """HTML list of the writer's notes (what a layout left out or changed); "" without notes."""
    items = [f"<li>{html.escape(n)}</li>" for n in notes]
    if not items:
        return ""
    return (
        "<div class='fwb-export-notes' style='color:#b54708'>Notes:"
        f"<ul style='margin:2px 0'>{''.join(items)}</ul></div>"
    )


def _error_html(text: str) -> str:
    return f"<div class='fwb-export-error' style='color:#b42318'>{html.escape(text)}</div>"


class ExportPanel(ModelPanel):
    """Export / import panel for ``model.tracks``.

    Parameters
    ----------
    model : workbench.FaceModel
    path : str
        Initial output path (its suffix follows the format dropdown).
    errors : ipywidgets.Output, optional
        Where unexpected tracebacks go (expected errors show in the panel).
    before_edit : iterable of callables, optional
        Called before an export or import, after
        :func:`widgets._threading.close_interactions` ended the interactions
        other widgets hold open on the model (an import right after a slider
        drag is an undo step of its own; an export writes the settled state).

    Attributes
    ----------
    last_written : list of Path
        Files written by the last successful export.
    """

    def __init__(
        self,
        model: Any,
        *,
        path: str = "animation.glb",
        errors: W.Output | None = None,
        before_edit: Iterable[Callable[[], Any]] = (),
    ) -> None:
        super().__init__(model, errors=errors, before_edit=before_edit)
        self.last_written: list[Path] = []
        self.format = W.Dropdown(
            options=list(FORMAT_CHOICES), value="glTF binary (.glb)", description="Format"
        )
        self.fps = W.BoundedFloatText(
            value=float(model.tracks.fps), min=1.0, max=1000.0, step=1.0, description="fps",
            layout=W.Layout(width="160px"),
        )  # fmt: skip
        self.bake = W.Checkbox(
            value=False,
            description="Bake (resample every frame)",
            indent=False,
            layout=W.Layout(width="auto"),
            style={"description_width": "initial"},  # the whole label, not a cut default width
        )
        self.csv_layout = W.Dropdown(
            options=list(CSV_LAYOUTS.items()),
            value="plain",
            description="CSV layout",
            tooltip="Live Link Face: the iPhone app's take layout (52 ARKit columns + head and "
            "eye angles) that Unreal's Live Link Face importer reads",
            style={"description_width": "initial"},
            layout=W.Layout(width="300px"),
        )
        self.path = W.Text(value=path, description="Path", layout=W.Layout(width="420px"))
        self.export_button = W.Button(description="Export", button_style="primary", icon="download")
        self.result = W.HTML("")
        self.import_path = W.Text(
            value="", placeholder="animation.csv or .glb/.gltf", description="Import",
            layout=W.Layout(width="420px"),
        )  # fmt: skip
        self.import_button = W.Button(
            description="Import animation", icon="upload", layout=W.Layout(width="auto")
        )
        self.import_result = W.HTML("")
        for w, cls in (
            (self.format, "fwb-export-format"),
            (self.fps, "fwb-export-fps"),
            (self.bake, "fwb-export-bake"),
            (self.csv_layout, "fwb-export-csv-layout"),
            (self.path, "fwb-export-path"),
            (self.export_button, "fwb-export-button"),
            (self.result, "fwb-export-result"),
            (self.import_path, "fwb-import-path"),
            (self.import_button, "fwb-import-button"),
            (self.import_result, "fwb-import-result"),
        ):
            w.add_class(cls)
        g = self.errors.guard
        self.format.observe(g("export format")(self._on_format), "value")
        self.export_button.on_click(g("export")(lambda _b: self.do_export()))
        self.import_button.on_click(g("import animation")(lambda _b: self.do_import()))
        self.listen(model.events.tracks, self._sync_fps, "export panel fps")
        self.children = [
            W.HTML("<b>Export animation</b>"),
            # wraps: the tab is narrower than format + fps + the Bake label
            W.HBox([self.format, self.fps, self.bake], layout=W.Layout(flex_flow="row wrap")),
            self.csv_layout,
            W.HBox([self.path, self.export_button]),
            self.result,
            W.HTML(
                "<b>Import animation</b> (CSV of per-frame weights or a Live Link Face take, "
                "glTF weights animation)"
            ),
            W.HBox([self.import_path, self.import_button]),
            self.import_result,
        ]
        self.add_class("fwb-export-panel")
        self._show_csv_layout()

    # ----------------------------------------------------------------- actions
    @property
    def suffix(self) -> str:
        return FORMAT_CHOICES[self.format.value][1]

    @property
    def csv_style(self) -> str:
        """The ``style`` a .csv export is written in ("plain" or "livelink")."""
        return str(self.csv_layout.value)

    def _on_format(self, change: Any) -> None:
        p = Path(self.path.value or "animation")
        stem = p.with_suffix("") if p.suffix.lower() in _SUFFIXES else p
        self.path.value = str(stem) + self.suffix
        self._show_csv_layout()

    def _show_csv_layout(self) -> None:
        self.csv_layout.layout.display = "" if self.suffix == ".csv" else "none"

    def _sync_fps(self, *_args: Any) -> None:
        # follow the timeline's fps until the user typed another one
        self.fps.value = float(self.model.tracks.fps)

    def do_export(self) -> list[Path]:
        """Export ``model.tracks`` as the form says; show and return the files (or the error)."""
        from workbench.animation.curves import TrackError
        from workbench.export import ExportError, export

        path = Path(self.path.value.strip() or f"animation{self.suffix}").expanduser()
        if path.suffix.lower() != self.suffix:
            path = path.with_suffix(self.suffix)
        self.flush()
        self.result.value = f"Exporting {html.escape(str(path))} …"
        options: dict[str, Any] = {"style": self.csv_style} if self.suffix == ".csv" else {}
        try:
            written = export(
                self.model,
                self.model.tracks,
                path,
                fps=float(self.fps.value),
                bake=self.bake.value,
                **options,
            )
        except (ExportError, TrackError, OSError, ValueError) as exc:
            self.result.value = _error_html(f"Export failed: {exc}")
            self.last_written = []
            return []
        self.last_written = [Path(p).resolve() for p in written]
        self.result.value = (
            files_html(self.last_written)
            + layers_html(getattr(written, "layers", ()))
            + notes_html(getattr(written, "notes", ()))
        )
        return self.last_written

    def do_import(self) -> bool:
        """Read the animation file and make it the model's timeline (one undo step).

        Head-pose columns (a Live Link Face take) are read about the model's own
        up and front axes (``model.metadata``), as the export wrote them.
        """
        from workbench.animation.curves import TrackError
        from workbench.animation.importers import AnimationImportError
        from workbench.io.animation import read_file_animation

        text = self.import_path.value.strip()
        if not text:
            self.import_result.value = _error_html(
                "Type the path of a .csv, .glb/.gltf, .fbx, .usd or .abc file."
            )
            return False
        path = Path(text).expanduser()
        self.flush()
        try:
            md = self.model.metadata
            tl = read_file_animation(
                path, self.model.shape_names, up_axis=md.up_axis, front_axis=md.front_axis
            )
            self.model.timeline.set(tl, f"Import animation {path.name}")
        except (AnimationImportError, TrackError, OSError, ValueError) as exc:
            self.import_result.value = _error_html(f"Import failed: {exc}")
            return False
        n_keys = sum(len(tr) for tr in tl.tracks.values())
        head = " (with the head pose)" if tl.head_pose is not None else ""
        self.import_result.value = (
            f"Imported {len(tl.tracks)} tracks{head}, {n_keys} keys, {tl.start:g}–{tl.end:g} s "
            f"at {tl.fps:g} fps from <code>{html.escape(str(path))}</code> (undo restores the old keys)"
        )
        return True
