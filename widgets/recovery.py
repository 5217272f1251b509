"""Recover an autosaved session after a kernel crash or restart."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import ipywidgets as W

from widgets._threading import ErrorSink

__all__ = ["RecoveryPrompt", "recovery_prompt"]


class RecoveryPrompt(W.VBox):
    """ "Recover <session>" / "Start fresh" buttons; the chosen model then opens in place.

    A notebook cell cannot wait for a click (the kernel is busy until the cell
    ends), so the choice is a callback: ``build(model)`` returns the widget
    (usually a :class:`Workbench`) that replaces the buttons.

    Attributes
    ----------
    found : list of workbench.autosave.Recoverable
    model : FaceModel or None
        The chosen model (None until a button is pressed).
    app : widget or None
        What ``build`` returned.
    """

    def __init__(
        self,
        default_loader: Callable[[], Any],
        found: list[Any],
        *,
        build: Callable[[Any], Any] | None = None,
    ) -> None:
        self.default_loader = default_loader
        self.found = list(found)
        self.build = build
        self.model: Any = None
        self.app: Any = None
        self.errors = W.Output()
        self.sink = ErrorSink(self.errors)
        self.recover_buttons = []
        for i, item in enumerate(self.found):
            b = W.Button(
                description=f"Recover {item.describe()}",
                icon="history",
                button_style="warning",
                layout=W.Layout(width="auto"),
            )
            b.add_class("fwb-recover")
            b.on_click(self.sink.guard("recovering")(lambda _b, i=i: self.choose(i)))
            self.recover_buttons.append(b)
        self.fresh_button = W.Button(description="Start fresh", layout=W.Layout(width="auto"))
        self.fresh_button.add_class("fwb-start-fresh")
        self.fresh_button.on_click(self.sink.guard("starting fresh")(lambda _b: self.choose(None)))
        note = W.HTML(
            "<b>An earlier session did not close cleanly.</b> Recover its last autosave, or start fresh"
            " (the next autosave then overwrites it)."
        )
        super().__init__([note, *self.recover_buttons, self.fresh_button, self.errors])
        self.add_class("fwb-recovery")

    def choose(self, index: int | None) -> Any:
        """Load ``found[index]`` (``None``: ``default_loader()``), build the app, return the model."""
        if index is None:
            model = self.default_loader()
        else:
            from workbench.autosave import recover

            model = recover(self.found[index])
        self.model = model
        if self.build is not None:
            self.app = self.build(model)
            self.children = [self.app] if self.app is not None else []
        else:
            self.children = [
                W.HTML(f"Loaded {'recovered session' if index is not None else 'fresh model'}.")
            ]
        return model


def recovery_prompt(
    default_loader: Callable[[], Any],
    *,
    build: Callable[[Any], Any] | None = None,
    folder: Any = None,
) -> RecoveryPrompt:
    """Offer to recover autosaved sessions left by a crashed or restarted kernel.

    Parameters
    ----------
    default_loader : callable () -> FaceModel
        Loads the model to start fresh with (e.g. ``lambda: load_sample("head")``).
    build : callable (FaceModel) -> widget, optional
        Opens the chosen model, e.g. ``lambda m: Workbench(m, autosave="workbench")``;
        its widget replaces the buttons.
    folder : path, optional
        Recovery folder (default ``$WORKBENCH_RECOVERY_DIR`` or the user cache).

    Returns
    -------
    RecoveryPrompt
        Display it. With nothing to recover the default model is loaded (and
        built) at once, so ``.model`` / ``.app`` are set before it is shown.
    """
    from workbench.autosave import find_recoverable

    prompt = RecoveryPrompt(default_loader, find_recoverable(folder), build=build)
    if not prompt.found:
        prompt.choose(None)
    return prompt
