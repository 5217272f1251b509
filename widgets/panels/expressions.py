"""``ExpressionPanel``: one slider per blendshape, grouped by face region.

Sliders are grouped with :func:`workbench.arkit.shape_group` (brows, eyes,
cheeks, nose, mouth, jaw, tongue, other); left/right pairs
(:func:`workbench.arkit.mirror_name`) sit side by side, subject's left first.
A search box filters the sliders, a checkbox per shape mutes it, and
reset / undo / redo buttons call the model.

Undo granularity: ipywidgets sends a stream of value updates while a slider is
dragged (``continuous_update=True``, needed for a live preview) and never says
when the drag ended. The panel therefore wraps each burst in one interaction
"Drag <name>" (:class:`widgets._threading.InteractionGrouper`), which ends
when the page reports the pointer's release on the slider (the viewport's
front end does, for every slider of its page), or 0.5 s after the last
update where no page reported a press (a keyboard nudge): one drag = one undo
step, and the viewport sees cheap ``deformed(False)`` events while it lasts. Undo,
redo, reset and mute end an open burst first, and so does any other widget's
edit of the model (a timeline key, an import, a handle drag:
:func:`widgets._threading.close_interactions`), so an edit made within the
idle time is an undo step of its own.

The panel never keeps weights of its own: slider values follow
``model.events.weights`` / ``weights_changing``, so edits from Python cells or
from another panel move the sliders. An update from the model sets a slider to
the model's value, and the slider handler ignores values equal to the model's,
which breaks the feedback loop without an "updating" flag. The
browser's slider snaps a value it is sent to its 0.01 step and sends the
snapped value back — possibly after the model has moved on (a playing
timeline, a tracked take: weights off the grid). So each slider also remembers
the last few values sent to it, and a value that is one of them snapped to the
step is an echo, not a drag (without this, playing a take recorded a "Drag"
step per shape and pulled the weights onto the grid).

While a live stream drives the weights (an open interaction of kind
``"live"``: the webcam, ``widgets/live``), the sliders follow at most every
:data:`STREAM_FOLLOW_S` seconds, with the model's values at that time, and
not at all while the panel is hidden (:meth:`ExpressionPanel.set_shown`: the
Workbench's Live tab hides the Shapes tab) — they catch up when shown, or on
the first change that is not the stream's; the viewport shows every frame. A
slider is its own widget model, so mirroring every camera frame meant 52
updates a frame, each snapped to the step and echoed back by the page (a
message to the kernel, a busy/idle pair back): in the Live tab the kernel,
server and page spent more on them than on the tracking (camera → face
291 → 160 ms, 3.7 → 6.2 frames/s on the 5k head when they stopped).

Corrective (combination) shapes (``model.shape_tools.correctives``) play the
product of their drivers' weights: their sliders are disabled, carry a
"= A × B" badge and show ``model.weights[name]``, refreshed on every
``weights`` / ``weights_changing`` event (a driver's change names only the
driver) and on ``correctives``. :attr:`ExpressionPanel.selected` is the last
slider the user moved (the Shape tools' selection follows it).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from typing import Any

import ipywidgets as W
import traitlets

from widgets._threading import InteractionGrouper, UiTimer, close_interactions
from widgets.panels.base import ModelPanel
from widgets.slider_echoes import SliderEchoes

#: seconds between slider refreshes while a live stream drives the weights (see the module docstring)
STREAM_FOLLOW_S = 0.25
#: interaction kinds whose weight changes the sliders follow at :data:`STREAM_FOLLOW_S`
STREAM_KINDS = frozenset({"live"})

GROUPS = ("brows", "eyes", "cheeks", "nose", "mouth", "jaw", "tongue", "other")
_LEFT_TOKENS = {"l", "left", "lf", "lft"}
_TOKEN = re.compile(r"[A-Z]+(?![a-z])|[A-Z]?[a-z]+|\d+")


def _arkit() -> Any:
    import workbench.arkit as arkit

    return arkit


def _is_left(name: str) -> bool:
    """True if the name's side token says (subject's) left."""
    canon = _arkit().canonical_arkit_name(name)
    if canon is not None:
        return bool(canon.endswith("Left"))
    tokens = [m.group().lower() for m in _TOKEN.finditer(re.split(r"[.:|/]", name)[-1])]
    return bool(tokens) and (tokens[-1] in _LEFT_TOKENS or tokens[0] in _LEFT_TOKENS)


def css_safe(name: str) -> str:
    """Shape name usable inside a CSS class (``fwb-slider-<name>``)."""
    return re.sub(r"[^A-Za-z0-9_-]", "_", name)


def layout_rows(names: list[str]) -> dict[str, list[tuple[str, ...]]]:
    """Group shape names into rows: ``{group: [(left, right) or (name,), ...]}``.

    Order within a group follows the model's shape order (first member of a pair
    decides the row's place). Empty groups are left out.
    """
    arkit = _arkit()
    present = set(names)
    placed: set[str] = set()
    groups: dict[str, list[tuple[str, ...]]] = {g: [] for g in GROUPS}
    for nm in names:
        if nm in placed:
            continue
        group = arkit.shape_group(nm)
        if group not in groups:
            group = "other"
        other = arkit.mirror_name(nm)
        if other is not None and other in present and other not in placed and other != nm:
            pair = (nm, other) if _is_left(nm) else (other, nm)
            groups[group].append(pair)
            placed.update(pair)
        else:
            groups[group].append((nm,))
            placed.add(nm)
    return {g: rows for g, rows in groups.items() if rows}


class ExpressionPanel(ModelPanel):
    """Blendshape sliders for a FaceModel, with search, mute, reset, undo/redo.

    Parameters
    ----------
    model : workbench.FaceModel
    errors : ipywidgets.Output, optional
        Where callback errors are shown (``Workbench`` passes a shared one).
    idle_s : float
        Idle time that ends a slider drag's undo step (see module docstring).
    max_height : str
        CSS max height of the scrolling slider area.

    Attributes
    ----------
    selected : str
        Name of the last slider the user moved ("" before any).
    sliders_version : int
        Bumps whenever the sliders are rebuilt (new shapes): a viewport following
        them (:meth:`Viewport.follow_sliders`) links the new ones.
    badges : dict[str, ipywidgets.HTML]
        The "= A × B" badge of each corrective's slider.
    """

    selected = traitlets.Unicode("")
    #: bumps whenever the sliders are rebuilt (a viewport following them re-links)
    sliders_version = traitlets.Int(0)

    def __init__(
        self,
        model: Any,
        *,
        errors: W.Output | None = None,
        idle_s: float = 0.5,
        max_height: str = "440px",
    ) -> None:
        super().__init__(model, errors=errors, layout=W.Layout(width="620px", min_width="420px"))
        self.grouper = InteractionGrouper(model, idle_s=idle_s, errors=self.errors)
        self.sliders: dict[str, W.FloatSlider] = {}
        #: per slider, the last values the model sent it (echo detection, see the module docstring)
        self._echoes = SliderEchoes()
        #: names a live stream changed since the sliders last followed it, and the timer that will
        self._stream_names: set[str] = set()
        self._stream_timer: UiTimer | None = None
        #: on screen (see :meth:`set_shown`)
        self.shown = True
        self.mutes: dict[str, W.Checkbox] = {}
        self.badges: dict[str, W.HTML] = {}
        self._badge_columns: dict[str, W.VBox] = {}  # slider over badge, in a corrective's cell
        self._cells: dict[str, W.HBox] = {}
        self._rows: list[tuple[tuple[str, ...], W.Widget]] = []
        self._headers: dict[str, tuple[W.HTML, list[W.Widget]]] = {}

        self.search = W.Text(
            placeholder="search shapes…", continuous_update=True, layout=W.Layout(width="170px")
        )
        self.search.add_class("fwb-search")
        self.reset_button = W.Button(
            description="Reset", tooltip="Set every weight to 0", layout=W.Layout(width="70px")
        )
        self.reset_button.add_class("fwb-reset")
        self.history_buttons = self.undo_redo_buttons("fwb-undo", "fwb-redo")
        self.undo_button, self.redo_button = self.history_buttons.buttons
        self.body = W.VBox(
            layout=W.Layout(max_height=max_height, overflow="auto", padding="0 4px 0 0")
        )
        toolbar = W.HBox([self.search, self.reset_button, self.undo_button, self.redo_button])
        self.children = [toolbar, self.body]
        self.add_class("fwb-expression-panel")

        g = self.errors.guard
        self.search.observe(g("search")(self._on_search), "value")
        self.reset_button.on_click(g("reset")(self._on_reset))
        ev = model.events
        self.listen(ev.weights, self._on_model_weights, "ExpressionPanel weights")
        self.listen(ev.weights_changing, self._on_model_weights, "ExpressionPanel weights")
        self.listen(ev.shapes, self._on_model_shapes, "ExpressionPanel shapes")
        self.listen(ev.correctives, self._on_correctives, "ExpressionPanel correctives")
        self.on_close(self.grouper.flush)  # first: an open drag becomes its undo step
        self.on_close(self._stop_following_stream)
        self._build()

    # ------------------------------------------------------------- building
    def _build(self) -> None:
        model = self._model
        with model.lock:
            shapes = {s.name: s for s in model.shapes}
            weights = dict(model.weights)
        # the old widgets are closed only after the body shows the new ones: the page never
        # holds a container whose children the kernel has already closed
        old = self._own_widgets()
        self.sliders, self.mutes, self._rows, self._headers = {}, {}, [], {}
        self.badges, self._badge_columns, self._cells = {}, {}, {}
        children: list[W.Widget] = []
        for group, rows in layout_rows(list(shapes)).items():
            # flex "0 0 auto": inside the scrolling column, rows must keep their height
            # instead of being squeezed to fit max_height
            header = W.HTML(f"<b>{group.capitalize()}</b>", layout=W.Layout(flex="0 0 auto"))
            header.add_class("fwb-group-header")
            row_widgets = []
            for row in rows:
                cells = [self._make_cell(shapes[nm], weights.get(nm, 0.0)) for nm in row]
                box = W.HBox(cells, layout=W.Layout(width="100%", flex="0 0 auto"))
                row_widgets.append(box)
                self._rows.append((row, box))
            self._headers[group] = (header, row_widgets)
            children.append(header)
            children.extend(row_widgets)
        self.body.children = children
        for w in old:
            w.close()
        self._on_correctives()
        self._on_search()
        self.sliders_version += 1

    def _own_widgets(self) -> list[W.Widget]:
        """Every widget the body's rows are made of (closed when the rows are rebuilt or the panel closes)."""
        return [
            *(header for header, _ in self._headers.values()),
            *(box for _, box in self._rows),
            *self._cells.values(),
            *self._badge_columns.values(),
            *self.badges.values(),
            *self.mutes.values(),
            *self.sliders.values(),
        ]

    def _make_cell(self, shape: Any, value: float) -> W.Widget:
        name = shape.name
        slider = W.FloatSlider(
            value=value,
            min=shape.slider_min,
            max=shape.slider_max,
            step=0.01,
            description=name,
            description_allow_html=False,
            continuous_update=True,
            readout_format=".2f",
            style={"description_width": "104px"},
            tooltip=name,
            layout=W.Layout(width="100%", min_width="0"),
        )
        slider.add_class("fwb-slider")
        slider.add_class(f"fwb-slider-{css_safe(name)}")
        mute = W.Checkbox(
            value=shape.mute,
            indent=False,
            description="",
            tooltip=f"mute {name}",
            layout=W.Layout(width="20px", min_width="20px"),
        )
        mute.add_class("fwb-mute")
        mute.add_class(f"fwb-mute-{css_safe(name)}")
        g = self.errors.guard
        slider.observe(
            g(f"slider {name}")(lambda ch, nm=name: self._on_slider(nm, ch["new"])), "value"
        )
        mute.observe(g(f"mute {name}")(lambda ch, nm=name: self._on_mute(nm, ch["new"])), "value")
        self.sliders[name] = slider
        self.mutes[name] = mute
        cell = W.HBox([mute, slider], layout=W.Layout(width="50%", min_width="0"))
        self._cells[name] = cell
        return cell

    # ------------------------------------------------------- UI -> model
    def _on_slider(self, name: str, value: float) -> None:
        model = self._model
        with model.lock:
            if name not in model.weights or abs(model.weights[name] - value) < 1e-9:
                return  # an echo of a model update, or a shape that went away
        step = float(self.sliders[name].step or 0.0) if name in self.sliders else 0.0
        if self._echoes.is_echo(name, value, step):
            self._echoes.resend_if_stale(name, value, step, lambda: self._model.weights.get(name),
                                         lambda: self.sliders.get(name))
            return
        self._echoes.forget(name)  # the person moves this slider now: older values are not echoes
        self.selected = name
        self.grouper.touch(f"Drag {name}")
        model.set_weight(name, value)

    def _on_mute(self, name: str, mute: bool) -> None:
        model = self._model
        if name not in model.shape_names or model.shape(name).mute == bool(mute):
            return
        close_interactions(model)
        model.set_shape_mute(name, bool(mute))

    def _on_reset(self, _button: Any = None) -> None:
        close_interactions(self._model)
        self._model.reset_weights()

    def _on_search(self, _change: Any = None) -> None:
        q = self.search.value.strip().lower()
        visible_rows = set()
        for row, box in self._rows:
            show = not q or any(q in nm.lower() for nm in row)
            box.layout.display = None if show else "none"
            if show:
                visible_rows.add(id(box))
        for header, boxes in self._headers.values():
            any_visible = any(id(b) in visible_rows for b in boxes)
            header.layout.display = None if any_visible else "none"

    # ------------------------------------------------------- model -> UI
    def set_shown(self, shown: bool) -> None:
        """The panel is on screen (True) or hidden behind another tab; shown again, the sliders catch up."""
        self.shown = bool(shown)
        if self.shown and self._stream_names:
            self._follow_stream()

    def _on_model_weights(self, values: Mapping[str, float]) -> None:
        token = self._model.interaction_token
        if token is not None and token.kind in STREAM_KINDS:
            self._stream_names.update(values)
            if not self.shown:
                return
            if self._stream_timer is None or not self._stream_timer.armed:
                self._stream_timer = UiTimer(STREAM_FOLLOW_S, self.errors.guard("follow live weights")(
                    self._follow_stream))
            if self._stream_timer.armed:
                return
            self._stream_names.clear()  # no event loop (a script): follow every change at once
        elif self._stream_names:
            self._follow_stream()  # the stream ended or another edit came: catch up first
        self._set_sliders(values)

    def _follow_stream(self) -> None:
        """The sliders a live stream moved show the model's current values (the timer's turn, or catching up)."""
        names = set(self._stream_names)
        self._stop_following_stream()
        played = self._model.weights
        self._set_sliders({n: played[n] for n in names if n in played})

    def _stop_following_stream(self) -> None:
        if self._stream_timer is not None:
            self._stream_timer.cancel()
        self._stream_timer = None
        self._stream_names.clear()

    def _set_sliders(self, values: Mapping[str, float]) -> None:
        for name, v in values.items():
            s = self.sliders.get(name)
            if s is not None and s.value != v:
                self._echoes.sent(name, v)
                s.value = v
        if self.badges:  # correctives: a driver's change names only the driver
            self._show_derived()

    def _show_derived(self) -> None:
        played = self._model.weights
        for name in self.badges:
            s = self.sliders.get(name)
            if s is not None and name in played and s.value != played[name]:
                self._echoes.sent(name, played[name])
                s.value = played[name]

    def _on_correctives(self) -> None:
        """Disable the correctives' sliders and badge them "= A × B" (under the slider); enable the others."""
        import html

        rules = dict(self._model.shape_tools.correctives)
        for name, slider in self.sliders.items():
            drivers = rules.get(name)
            slider.disabled = drivers is not None
            cell, mute = self._cells.get(name), self.mutes[name]
            badge = self.badges.get(name)
            if drivers is None:
                if badge is not None:  # no longer a corrective: the plain cell again
                    del self.badges[name]
                    column = self._badge_columns.pop(name)
                    if cell is not None:
                        cell.children = (mute, slider)
                    column.close()
                    badge.close()
                continue
            text = html.escape("= " + " × ".join(drivers))
            value = (
                f"<div title='corrective: weight {text}' style='color:#06c;font-size:11px;"
                f"line-height:14px;margin-left:108px;white-space:nowrap;overflow:hidden;"
                f"text-overflow:ellipsis'>{text}</div>"
            )
            if badge is None:
                badge = W.HTML(value, layout=W.Layout(width="100%", min_width="0"))
                badge.add_class("fwb-corrective-badge")
                badge.add_class(f"fwb-corrective-badge-{css_safe(name)}")
                column = W.VBox([slider, badge], layout=W.Layout(width="100%", min_width="0"))
                self.badges[name], self._badge_columns[name] = badge, column
                if cell is not None:
                    cell.children = (mute, column)
            elif badge.value != value:
                badge.value = value
        self._show_derived()

    def _on_model_shapes(self) -> None:
        model = self._model
        with model.lock:
            shapes = {s.name: s for s in model.shapes}
            weights = dict(model.weights)
        if list(shapes) != list(self.sliders):
            self._build()
            return
        for name, shape in shapes.items():
            sl = self.sliders[name]
            if (sl.min, sl.max) != (shape.slider_min, shape.slider_max):
                # widen first so the value is never clamped by a stale range
                sl.min, sl.max = min(sl.min, shape.slider_min), max(sl.max, shape.slider_max)
                sl.value = weights[name]
                sl.min, sl.max = shape.slider_min, shape.slider_max
            self.mutes[name].value = shape.mute
            if sl.value != weights[name]:
                sl.value = weights[name]

    # ------------------------------------------------------------ closing
    def close(self) -> None:
        """End an open drag, disconnect from the model, close the child widgets."""
        try:
            super().close()
        finally:
            for w in self._own_widgets():
                w.close()
