"""What the panel's buttons do: one facet call each, its message or its refusal in the status line.

Each action first ends every open interaction (:meth:`ModelPanel.flush`), then
says what it did in the status line. A refusal (the facet raises
``ModelError`` / ``ValueError`` / ``KeyError`` naming the argument) changes
nothing; its message is shown in red in the status line and, as one plain line
without a traceback, in the panel's error sink.
"""

from __future__ import annotations

import html
from collections.abc import Callable

import ipywidgets as W

from widgets.panels.shape_tools.preview import _SplitPreview

_REFUSALS = (ValueError, KeyError)  # ModelError is a ValueError


def _message(exc: BaseException) -> str:
    # str(KeyError("x")) is "'x'": the facet's KeyErrors carry a sentence
    if isinstance(exc, KeyError) and exc.args:
        return str(exc.args[0])
    return str(exc)


class _ShapeActions(_SplitPreview):
    """The buttons' actions of :class:`ShapeToolsPanel` (its widgets are built there)."""

    status: W.HTML
    last_error: str
    left_name: W.Text
    right_name: W.Text
    keep: W.Checkbox
    mirror_target: W.Text
    expression: W.Dropdown
    expression_target: W.Text
    painted: W.Dropdown
    paint_target: W.Text
    driver_a: W.Dropdown
    driver_b: W.Dropdown
    corrective_name: W.Text
    corrective_source: W.Dropdown
    keep_shape: W.Checkbox
    _on_shape: Callable[..., None]

    def _run(self, what: str, action: Callable[[], str]) -> bool:
        """Flush, run ``action`` (one facet call), show its message or the refusal."""
        self.flush()
        try:
            message = action()
        except _REFUSALS as exc:
            text = _message(exc)
            self.last_error = text
            self.status.value = (
                f"<span style='color:#b00'>{html.escape(what)} refused: {html.escape(text)}</span>"
            )
            sink = self.errors
            sink.count += 1
            sink.output.append_stderr(f"[Shape tools: {what}] {text}\n")
            if sink.on_error is not None:
                sink.on_error(f"Shape tools: {what}: {text}")
            return False
        self.last_error = ""
        self.status.value = f"<span style='color:#333'>{html.escape(message)}</span>"
        return True

    def _need_shape(self, what: str) -> str:
        name = self.selected
        if name is None:
            raise ValueError(f"{what}: pick a shape first")
        return name

    def do_split(self) -> bool:
        """Split the selected shape into L/R halves (band = the slider, names = the fields)."""

        def act() -> str:
            name = self._need_shape("split")
            falloff = float(self.falloff.value)
            typed = (self.left_name.value.strip(), self.right_name.value.strip())
            names = None
            if any(typed):
                from workbench.methods.shapes.split import split_names

                default = split_names(name)
                names = (typed[0] or default[0], typed[1] or default[1])
            left, right = self._model.shape_tools.split(
                name, falloff=falloff, names=names, keep=self.keep.value
            )
            self.end_preview()
            self.left_name.value = self.right_name.value = ""
            self.select(left)
            kept = ", original kept" if self.keep.value else ""
            return (
                f"split {name} into {left} + {right} "
                f"(band {falloff:.3g} {self._model.metadata.units}{kept})"
            )

        return self._run("Split", act)

    def do_mirror(self) -> bool:
        """Mirror the selected shape into the target field's shape."""

        def act() -> str:
            name = self._need_shape("mirror")
            target = self.mirror_target.value.strip() or None
            existed = target in self._model.shape_names
            out = self._model.shape_tools.mirror(name, target=target)
            sym = self._model.shape_tools.symmetry()
            if out == name:
                what = f"flipped {name} in place"
            else:
                what = f"mirrored {name} onto {out}" + (
                    " (replaced)" if existed else " (new shape)"
                )
            return f"{what}; {100 * sym.unmatched_fraction:.1f} % of the vertices without a mirror partner"

        return self._run("Mirror", act)

    def do_mirror_expression(self) -> bool:
        """Mirror the picked saved expression into the target field's name."""

        def act() -> str:
            name = self.expression.value
            if not name:
                raise ValueError(
                    "mirror expression: no saved expression (model.expressions is empty)"
                )
            target = self.expression_target.value.strip() or None
            new = self._model.shape_tools.mirror_expression(name, target=target)
            return f"mirrored expression {name} into {new.name}"

        return self._run("Mirror expression", act)

    def do_mirror_paint(self) -> bool:
        """Paint the mirror image of the picked painted map onto the target field's expression."""

        def act() -> str:
            name = self.painted.value
            if not name:
                raise ValueError("mirror paint: nothing is painted (model.paint is empty)")
            target = self.paint_target.value.strip() or None
            self._model.shape_tools.mirror_paint(name, target=target)
            return f"mirrored the paint of {name} onto {target or name}"

        return self._run("Mirror paint", act)

    def _drivers(self) -> list[str]:
        return [d for d in (self.driver_a.value, self.driver_b.value) if d]

    def do_add_corrective(self) -> bool:
        """Add a corrective of the two drivers (name field or ``A_B``; source: empty or the handles)."""

        def act() -> str:
            drivers = self._drivers()
            name = self.corrective_name.value.strip() or None
            source = self.corrective_source.value
            shape = self._model.shape_tools.add_corrective(
                name, drivers, delta="handles" if source == "handles" else None
            )
            self.corrective_name.value = ""
            self.select(shape.name)
            how = (
                "from the handle sculpt (handles reset)"
                if source == "handles"
                else "empty: sculpt it"
            )
            return f"added corrective {shape.name} = {' × '.join(drivers)} ({how})"

        return self._run("Add corrective", act)

    def do_set_drivers(self) -> bool:
        """Make the selected shape a corrective of the two drivers."""

        def act() -> str:
            name = self._need_shape("set drivers")
            drivers = self._drivers()
            self._model.shape_tools.set_drivers(name, drivers)
            self._on_shape()
            return f"{name} is now driven by {' × '.join(drivers)}"

        return self._run("Set drivers", act)

    def do_remove_corrective(self) -> bool:
        """Remove the selected corrective (its shape and keys too, unless *keep shape*)."""

        def act() -> str:
            name = self._need_shape("remove corrective")
            keep = bool(self.keep_shape.value)
            self._model.shape_tools.remove_corrective(name, keep_shape=keep)
            return f"removed corrective {name}" + (" (kept as an ordinary shape)" if keep else "")

        return self._run("Remove corrective", act)
