"""The Workbench's tabs: a registry the :class:`~widgets.app.Workbench` builds its tabs from.

A method family that comes with a tab names, in its registration
(``Family(tab="my_package.my_tab")``, :mod:`workbench.core.families`), the module
that registers a :class:`TabSpec` here; the Workbench imports those modules and
lays the tabs out by ``order``. The built-in tabs are the modules of this
package, named by the families they belong to (the Export tab by the timeline's).

A tab builds its panels over the Workbench (``build(wb) -> (widget, {attr:
panel})``; the panels become attributes of the Workbench: ``wb.regions``),
eagerly or the first time it is shown or read (``lazy``: segmentation and
thumbnails take seconds), and says what happens when it is shown or left
(``on_show`` / ``on_hide``: overlays, pointer modes), which viewport tool it
selects, whether a tool chosen elsewhere belongs to it (``owns_tool``) and
what it adds to the top bar.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

__all__ = ["TabSpec", "register_tab", "tab_specs"]


@dataclass(frozen=True)
class TabSpec:
    """One tab of the Workbench (see the module docstring)."""

    title: str
    order: float
    build: Callable[[Any], tuple[Any, Mapping[str, Any]]]
    #: the viewport tool the tab selects ("orbit" or a registered tool: widgets.viewport.tools)
    tool: str = "orbit"
    #: built the first time the tab is shown or one of its panels is read; until then this text
    lazy: str = ""
    on_show: Callable[[Any], None] | None = None
    on_hide: Callable[[Any], None] | None = None
    #: ``owns_tool(wb, tool)``: a tool chosen elsewhere (a mode of the tab) keeps the tab selected
    owns_tool: Callable[[Any, str], bool] | None = None
    #: ``topbar(wb) -> [widget]``: shown in the Workbench's top bar (once the tab is built)
    topbar: Callable[[Any], list[Any]] | None = None
    #: ``close(wb)``: before its panels are closed (default: nothing)
    close: Callable[[Any], None] | None = None
    #: attribute names its ``build`` returns (so a lazy tab's panels are found before it is built)
    attrs: tuple[str, ...] = field(default_factory=tuple)


_TABS: dict[str, TabSpec] = {}


def register_tab(spec: TabSpec) -> TabSpec:
    """Register (or replace, on reload) a tab by title; returns it."""
    _TABS[spec.title] = spec
    return spec


def tab_specs() -> tuple[TabSpec, ...]:
    """Every registered tab in order: the modules the method families name are imported first."""
    from workbench.core.families import families

    for f in families():
        if f.tab:
            importlib.import_module(f.tab)
    return tuple(sorted(_TABS.values(), key=lambda s: s.order))
