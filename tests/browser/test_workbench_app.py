"""The composed Workbench in a real JupyterLab + Chromium.

Opens ``notebooks/workbench.ipynb`` (run all), checks that the viewport draws
the head, then opens each tool tab like a person (click on the tab title):
the viewport switches to the tab's tool, the tab's panel shows up, and the
shared error Output of the workbench stays empty. One screenshot per tab is
kept in ``test-artifacts/<test>/``.
"""

from __future__ import annotations

from pathlib import Path

from harness import NotebookPage

REPO = Path(__file__).resolve().parents[2]
WORKBENCH_NB = REPO / "notebooks" / "workbench.ipynb"

_ERRORS = """
import json
print(json.dumps({"errors": [o.get("text", "") for o in wb.errors.outputs],
                  "tool": wb.viewport.tool, "tab": wb.tabs.selected_index,
                  "regions_active": bool(wb.panel_built("regions") and wb.regions.active)}))
"""

#: tab title -> (viewport tool, a selector inside the tab's panel that must become visible)
_TABS = {
    "Shapes": ("orbit", ".fwb-tabs .widget-slider"),
    "Sculpt": ("sculpt", ".fwb-default-handles"),
    "Regions": ("orbit", ".fwb-region-status"),
    "Paint": ("paint", ".fwb-paint-palette .fw-thumb-button"),
    "Export": ("orbit", ".fwb-export-panel"),
    "Capture": ("orbit", ".fwb-capture-load"),
}


def _start(nb: NotebookPage) -> None:
    page = nb.page
    # A recovery file from an earlier (killed) kernel shows the offer first.
    fresh = page.locator(".fwb-start-fresh")
    if fresh.count():
        fresh.first.click()
    page.evaluate(
        "() => { const s = window.jupyterapp.shell; if (!s.leftCollapsed) s.collapseLeft(); }"
    )
    nb.wait_viewports(1)
    page.locator(".fwb-workbench").evaluate("e => e.scrollIntoView({block: 'start'})")


def test_each_tab_opens_without_errors(open_notebook) -> None:
    nb = open_notebook(WORKBENCH_NB, viewport_size=(1600, 1200))
    page = nb.page
    _start(nb)
    status = page.locator(".fwb-wb-status").inner_text()
    assert "vertices" in status and "undo depth 0" in status, status
    for title, (tool, selector) in _TABS.items():
        page.locator(".fwb-tabs .lm-TabBar-tab", has_text=title).click()
        page.wait_for_function(
            "(t) => document.querySelector('.fwb-viewport').getAttribute('data-tool') === t",
            arg=tool,
        )
        page.locator(selector).first.wait_for(state="visible", timeout=60_000)
        nb.wait_kernel_idle()
        page.wait_for_timeout(300)  # let the last geometry / overlay frame draw
        page.locator(".fwb-workbench").screenshot(path=str(_shot_path(nb, title)))
        st = nb.kernel_eval(_ERRORS)
        assert st["errors"] == [], f"{title}: {st['errors']}"
        assert st["tool"] == tool and st["tab"] == list(_TABS).index(title)
        assert st["regions_active"] == (title == "Regions")
    assert page.locator(".fwb-errors").inner_text().strip() == ""


def _shot_path(nb: NotebookPage, title: str) -> Path:
    nb.artifacts.mkdir(parents=True, exist_ok=True)
    return nb.artifacts / f"tab-{title.lower()}.png"
