"""Regenerate the README's workbench UI screenshots by driving the app in a real browser.

Usage::

    .venv/bin/python benchmarks/screenshot_docs_ui.py [--out notebooks/images]
                                                      [--glb /tmp/face.glb]
                                                      [--part all|main|wrinkles]

Starts one JupyterLab of its own on 127.0.0.1 (the browser tests' harness,
``tests/browser/harness.py``: temporary root/config/settings dirs) and Debian's
Chromium (``/usr/bin/chromium`` through pip Playwright), opens
``notebooks/workbench.ipynb``, runs all cells and then uses the app with the
mouse like a person: clicks on tabs and buttons, drags on sliders and on the
viewport, types the export path. Python in the kernel is only used to *read*
state (to wait for an edit to arrive) and to pick the vertex ids to aim at.
Before each picture the viewport must have drawn the edit (``data-frame``
advanced, ``data-ready``, no draft frame) and stayed still for a moment; the
picture is the whole workbench widget (top bar, viewport, timeline, tabs),
without JupyterLab around it, about 1220 px wide.

Writes into ``--out``:

    workbench_viewport_sliders.png  Shapes: jawOpen 0.6, mouthSmileLeft/Right 0.7 (slider drags)
    ui_sculpt.png                   Sculpt: Default handles, the left mouth-corner marker dragged
    ui_regions.png                  Regions: after "Find regions", colour overlay
    ui_paint.png                    Paint: mouthSmileRight then mouthSmileLeft painted on the
                                    mouth corners, mouthSmileLeft picked, overlay on (then
                                    "Bake to new shape": the smile becomes paint_1)
    ui_timeline.png                 jawOpen keyed at 0, 0.5, 1 s (ruler click, slider drag, Key),
                                    its curve view at 0.5 s, the thumbnail strip, head-pose sliders
    ui_export.png                   Export: after a brow raise with handles (an editing layer),
                                    the animation written as ``--glb``, the per-layer report
    ui_sculpt_wrinkles.png          Sculpt: "Fit wrinkles from examples", Symmetric, the brow
                                    markers dragged up: forehead furrows and the strain-coloured
                                    feature graph

The pictures use the notebook's own resolution (``WORKBENCH_RESOLUTION``, default
25k). The wrinkle picture comes from a second notebook: a copy of
``notebooks/workbench.ipynb`` pinned to ``"25k"`` (~20k vertices) whatever the
environment says. On the ~5k-vertex base head the learned furrows are about one
triangle wide and do not read in a screenshot. The first
notebook is closed (kernel shut down) before the second opens: one JupyterLab,
one browser, one kernel at a time.

The .glb is written to ``--glb`` (default ``/tmp/face.glb``: a short path that
reads well in the picture) and removed afterwards unless it existed before.
Failures leave ``test-artifacts/screenshot-docs-ui/failed-*.png`` and the
browser console. Look at the pictures after regenerating them.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import re
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from browser_session import REPO, NotebookPage, chromium_missing, lab_and_browser  # (sets sys.path)
from harness import LabServer

WORKBENCH_NB = REPO / "notebooks" / "workbench.ipynb"
ARTIFACTS = REPO / "test-artifacts" / "screenshot-docs-ui"
#: browser window (CSS px, device scale 1): tall enough for the Sculpt tab with wrinkle cards
WINDOW = {"width": 1400, "height": 1700}
#: wrinkle picture camera: mouse-wheel clicks of zoom, then a shift+drag down by this many px
WRINKLE_ZOOM_CLICKS = 2
WRINKLE_PAN_PX = 30

# Vertices to aim at: the mouth corners (the skin vertex the smile shapes move most, farthest
# out on its side) and the middle of the upper lip.
_MOUTH_IDS = """
import json, numpy as np
_skin = model.component_labels == model.component_names.index("skin")
_V = np.asarray(model.vertices)
def _top(name, k):
    return np.argsort(-np.linalg.norm(model.shape(name).delta, axis=1) * _skin)[:k]
_l, _r = _top("mouthSmileLeft", 40), _top("mouthSmileRight", 40)
_lip = _top("mouthUpperUpLeft", 60)
print(json.dumps({"left_corner": int(_l[np.argmax(_V[_l, 0])]),
                  "right_corner": int(_r[np.argmin(_V[_r, 0])]),
                  "mid": int(_lip[np.argmin(np.abs(_V[_lip, 0]))])}))
"""

#: true while a slider drag, handle drag or paint stroke is still open in the kernel
_BUSY = "bool(model.interacting or wb.viewport.dragging or wb.viewport.stroking)"


class Session:
    """One open workbench notebook and the mouse/keyboard actions on it."""

    def __init__(self, nb: NotebookPage) -> None:
        self.nb = nb
        self.page = nb.page
        self.workbench = self.page.locator(".fwb-workbench")

    # ---------------------------------------------------------------- reading state
    def py(self, expr: str) -> Any:
        return self.nb.kernel_eval(f"import json; print(json.dumps({expr}))")

    def wait_py(
        self, expr: str, pred: Callable[[Any], bool], what: str, timeout: float = 30.0
    ) -> Any:
        deadline = time.monotonic() + timeout
        value = self.py(expr)
        while not pred(value):
            if time.monotonic() > deadline:
                raise RuntimeError(f"{what}: {expr} is still {value!r}")
            time.sleep(0.15)
            value = self.py(expr)
        return value

    def wait_quiet(self, what: str) -> None:
        """The drag / stroke / slider interaction ended in the kernel (its undo step closed)."""
        self.wait_py(_BUSY, lambda v: not v, what)

    def frame(self) -> int:
        return self.nb.frame(0)

    def wait_frame_after(self, frame: int, timeout: float = 60.0) -> None:
        self.nb.wait_frame_after(0, frame, timeout=timeout)

    # ---------------------------------------------------------------- looking
    def top(self) -> None:
        self.workbench.evaluate("e => e.scrollIntoView({block: 'start'})")

    def rest_mouse(self) -> None:
        """Focus off the last control (no focus ring) and the pointer off the app (no hover)."""
        status = self.page.locator(".fwb-wb-status").bounding_box()
        if status is not None:  # a click on the status text: nothing happens there
            self.page.mouse.click(
                status["x"] + status["width"] - 4, status["y"] + status["height"] / 2
            )
        self.page.mouse.move(3, 3)

    def settle(self, quiet_ms: int = 600, timeout: float = 30.0) -> None:
        """Wait until the viewport is ready, not drafting, and drew nothing new for ``quiet_ms``."""
        self.page.wait_for_function(
            """() => { const e = document.querySelector('.fwb-viewport');
                 return e && e.getAttribute('data-ready') === '1' &&
                   e.getAttribute('data-draft') !== '1' && e.getAttribute('data-error') === ''; }""",
            timeout=timeout * 1000,
        )
        vp = self.nb.viewport(0)
        deadline = time.monotonic() + timeout
        last = None
        stable_since = time.monotonic()
        while time.monotonic() < deadline:
            now = (vp.get_attribute("data-frame"), vp.get_attribute("data-render-count"))
            if now != last:
                last, stable_since = now, time.monotonic()
            elif (time.monotonic() - stable_since) * 1000 >= quiet_ms:
                return
            self.page.wait_for_timeout(100)
        raise RuntimeError("the viewport never stopped drawing")

    def shot(self, path: Path) -> float:
        """Screenshot of the whole workbench widget into ``path``; returns seconds taken."""
        t0 = time.monotonic()
        self.top()
        self.rest_mouse()
        self.settle()
        box = self.workbench.bounding_box()
        assert box is not None, "the workbench is not on screen"
        size = self.page.viewport_size
        if box["y"] + box["height"] > size["height"] - 30:  # 30: JupyterLab's status bar
            need = int(box["y"] + box["height"] + 60)
            self.page.set_viewport_size({"width": size["width"], "height": need})
            self.top()
            self.settle()
            box = self.workbench.bounding_box()
            assert box is not None
        errors = self.py("[o.get('text', '') for o in wb.errors.outputs]")
        if errors:
            raise RuntimeError(f"the workbench shows errors: {errors}")
        clip = {
            "x": float(int(box["x"])),
            "y": float(int(box["y"])),
            "width": float(round(box["width"])),
            "height": float(round(box["height"])),
        }
        path.parent.mkdir(parents=True, exist_ok=True)
        self.page.screenshot(path=str(path), clip=clip)
        print(f"  wrote {path} ({int(clip['width'])} x {int(clip['height'])})", flush=True)
        return time.monotonic() - t0

    # ---------------------------------------------------------------- doing
    def tab(self, title: str, tool: str) -> None:
        self.page.locator(".fwb-tabs .lm-TabBar-tab", has_text=title).click()
        self.page.wait_for_function(
            "(t) => document.querySelector('.fwb-viewport').getAttribute('data-tool') === t",
            arg=tool,
        )

    def drag_slider(self, css: str, fraction: float) -> None:
        """Drag the noUiSlider inside ``css`` by its handle to ``fraction`` of its track."""
        root = self.page.locator(css)
        root.evaluate("e => e.scrollIntoView({block: 'center'})")  # (scrolls its panel only)
        hb = root.locator(".noUi-handle").bounding_box()
        tb = root.locator(".noUi-base").bounding_box()
        assert hb is not None and tb is not None, f"{css} is not visible"
        x0, y0 = hb["x"] + hb["width"] / 2, hb["y"] + hb["height"] / 2
        x1 = tb["x"] + fraction * tb["width"]
        m = self.page.mouse
        m.move(x0, y0)
        m.down()
        m.move(x1, y0, steps=12)
        m.up()

    def shape_slider(self, name: str, fraction: float) -> None:
        frame = self.frame()
        self.drag_slider(f".fwb-slider-{name}", fraction)
        self.wait_frame_after(frame)
        self.wait_quiet(f"slider {name}")

    def undo(self, times: int = 1) -> None:
        """Click the top bar's Undo ``times`` times, each time waiting for the redrawn face."""
        for _ in range(times):
            depth = len(self.py("model.history.undo_labels"))
            frame = self.frame()
            self.page.locator(".fwb-wb-undo").click()
            self.wait_py("len(model.history.undo_labels)", lambda n, d=depth: n == d - 1, "undo")
            with contextlib.suppress(Exception):  # (an undo that changes no geometry draws nothing)
                self.wait_frame_after(frame, timeout=5)

    def handles_on_screen(self) -> np.ndarray:
        pts = self.nb.viewport(0).evaluate("e => e.fwbMarkers()")
        return np.array(pts, dtype=float).reshape(-1, 3)

    def drag_handle(self, name: str, dx: float, dy: float) -> None:
        """Drag the marker of handle ``name`` by (dx, dy) page px; wait for the closed undo step."""
        names = self.py("list(model.handles.names)")
        k = names.index(name)
        self.top()
        self.page.mouse.move(3, 3)
        x, y, visible = self.handles_on_screen()[k]
        assert visible == 1, f"the {name} marker is hidden"
        depth = len(self.py("model.history.undo_labels"))
        frame = self.frame()
        m = self.page.mouse
        m.move(x, y)
        m.down()
        m.move(x + dx, y + dy, steps=15)
        m.up()
        self.wait_frame_after(frame)
        self.wait_quiet(f"drag {name}")
        self.wait_py("len(model.history.undo_labels)", lambda n: n == depth + 1, f"drag {name}")

    def default_handles(self) -> None:
        self.page.locator(".fwb-default-handles").click()
        n = self.wait_py("len(model.handles)", lambda n: n > 40, "Default handles")
        self.page.wait_for_function(
            "(n) => JSON.parse(document.querySelector('.fwb-viewport')"
            ".getAttribute('data-markers') || '[]').length === n",
            arg=n,
        )

    def stroke(self, a: np.ndarray, b: np.ndarray, steps: int = 14) -> None:
        m = self.page.mouse
        m.move(a[0], a[1])
        m.down()
        for f in np.linspace(0.0, 1.0, steps)[1:]:
            m.move(a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]))
            self.page.wait_for_timeout(30)
        m.up()

    def pick(self, expression: str) -> None:
        self.page.locator(".fwb-paint-palette .fw-thumb-button", has_text=expression).first.click()
        self.wait_py(
            "wb.viewport.tools['paint'].expression", lambda v: v == expression, f"pick {expression}"
        )

    def timeline_hooks(self) -> dict[str, Any]:
        h = self.page.locator(".fwb-timeline").evaluate("e => e.fwbHooks()")
        return {
            "ruler_y": float(h["data-ruler-y"]),
            "axis": json.loads(h["data-axis"]),
            "keys": json.loads(h["data-keys"]),
        }

    def ruler_x(self, t: float) -> tuple[float, float]:
        h = self.timeline_hooks()
        a = h["axis"]
        return a["x0"] + (t - a["t0"]) / (a["t1"] - a["t0"]) * (a["x1"] - a["x0"]), h["ruler_y"]

    def scrub(self, t: float) -> None:
        self.page.mouse.click(*self.ruler_x(t))
        self.wait_py("model.time", lambda v: abs(v - t) < 1e-9, f"scrub to {t}")


# -------------------------------------------------------------------- the pictures
def shapes(s: Session, out: Path) -> None:
    s.tab("Shapes", "orbit")
    for name, fraction in (("jawOpen", 0.6), ("mouthSmileLeft", 0.7), ("mouthSmileRight", 0.7)):
        s.shape_slider(name, fraction)
    w = s.py("{k: round(v, 2) for k, v in model.weights.items() if v}")
    assert w == {"jawOpen": 0.6, "mouthSmileLeft": 0.7, "mouthSmileRight": 0.7}, w
    # the smile sliders and the jaw group in the middle of the panel
    s.page.locator(".fwb-slider-mouthStretchLeft").evaluate(
        "e => e.scrollIntoView({block: 'center'})"
    )
    s.shot(out / "workbench_viewport_sliders.png")
    s.undo(3)  # back to the neutral face for the next tools


def sculpt(s: Session, out: Path) -> None:
    s.tab("Sculpt", "sculpt")
    s.default_handles()
    # the marker nearest to the subject's left mouth corner
    corner = s.nb.kernel_eval(_MOUTH_IDS)["left_corner"]
    name = s.nb.kernel_eval(
        "import json, numpy as np\n_V = np.asarray(model.vertices)\n"
        f"_d = np.linalg.norm(_V[model.handles.vertices] - _V[{corner}], axis=1)\n"
        "print(json.dumps(model.handles.names[int(np.argmin(_d))]))"
    )
    s.drag_handle(name, 30.0, -24.0)  # up and out: a half smile
    s.shot(out / "ui_sculpt.png")
    s.undo(2)  # the drag and the handles: no markers in the other pictures


def regions(s: Session, out: Path) -> None:
    s.tab("Regions", "orbit")
    button = s.page.locator(".fwb-find-regions")
    button.wait_for(timeout=120_000)
    renders = int(s.nb.viewport(0).get_attribute("data-render-count") or 0)
    button.click()
    s.wait_py("model.regions.state is not None", bool, "Find regions", timeout=300)
    s.page.wait_for_function(
        "(r) => Number(document.querySelector('.fwb-viewport')"
        ".getAttribute('data-render-count')) > r",
        arg=renders,
    )
    s.shot(out / "ui_regions.png")


def paint(s: Session, out: Path) -> None:
    s.tab("Paint", "paint")
    s.page.locator(".fwb-paint-palette .fw-thumb-button").first.wait_for(timeout=180_000)
    # a 2.8 cm brush at full opacity (sliders dragged): a smooth smile, no crease at its edge
    s.drag_slider(".fwb-brush-radius", 0.33)
    s.drag_slider(".fwb-brush-opacity", 1.05)
    s.wait_py("wb.paint.opacity.value", lambda v: v == 1.0, "opacity slider")
    ids = s.nb.kernel_eval(_MOUTH_IDS)
    for expression, corner in (
        ("mouthSmileRight", "right_corner"),
        ("mouthSmileLeft", "left_corner"),
    ):
        s.pick(expression)
        s.top()
        a, mid = s.nb.project([ids[corner], ids["mid"]])
        assert a[2] == 1 and mid[2] == 1, "the mouth is not in view"
        frame = s.frame()
        s.stroke(a, a + 0.7 * (mid - a))  # from the corner most of the way to the middle
        s.wait_frame_after(frame)
        s.wait_quiet(f"stroke {expression}")
    painted = s.py("{k: float(v.max()) for k, v in model.paint.items()}")
    assert set(painted) == {"mouthSmileLeft", "mouthSmileRight"}, painted
    assert s.py("wb.viewport.tools['paint'].overlay") is True
    s.shot(out / "ui_paint.png")
    # Keep the painted smile as a blendshape (weight 1), as an animator would before keying:
    # a paint layer replaces the other shapes where it is painted, so an opening jaw would
    # tear at the painted mouth corners.
    s.page.locator(".fwb-paint-bake").click()
    s.wait_py(
        '"paint_1" in model.shape_names and not model.paint', bool, "Bake to new shape"
    )


def timeline(s: Session, out: Path) -> None:
    s.tab("Shapes", "orbit")
    keyed = []
    for i, (t, fraction) in enumerate(((0.0, 0.15), (0.5, 0.75), (1.0, -0.1))):
        s.scrub(t)
        s.shape_slider("jawOpen", fraction)
        s.page.locator(".fwb-tl-key").click()
        keyed.append(
            s.wait_py(
                'model.tracks.tracks["weights/jawOpen"].times.tolist()'
                ' if "weights/jawOpen" in model.tracks.tracks else []',
                lambda v, i=i: len(v) == i + 1,
                f"key {i + 1}",
            )
        )
    assert keyed[-1] == [0.0, 0.5, 1.0], keyed
    # click the middle key: its track opens in the curve view
    x, y = next(
        (k[3], k[4]) for k in s.timeline_hooks()["keys"] if k[0] == "weights/jawOpen" and k[1] == 1
    )
    s.page.mouse.click(x, y)
    s.wait_py("wb.timeline.selected_track", lambda v: v == "weights/jawOpen", "curve view")
    frame = s.frame()
    s.scrub(0.5)  # the face at the middle key
    with contextlib.suppress(Exception):
        s.wait_frame_after(frame, timeout=5)
    s.page.locator(".fwb-slider-jawOpen").evaluate("e => e.scrollIntoView({block: 'center'})")
    s.shot(out / "ui_timeline.png")


def export(s: Session, out: Path, glb: Path) -> None:
    # An editing layer for the export's per-layer report: raise both brows with handles
    # (the end-to-end test's sculpt step).
    s.tab("Sculpt", "sculpt")
    s.default_handles()
    s.page.locator(".fwb-symmetric").click()
    s.wait_py("wb.viewport.symmetric", bool, "Symmetric")
    s.drag_handle("brows_L_2", 0.0, -20.0)
    s.tab("Export", "orbit")
    field = s.page.locator(".fwb-export-path input")
    field.click()
    field.press("Control+A")
    field.type(str(glb), delay=15)
    field.press("Tab")
    s.wait_py("wb.export.path.value", lambda v: v == str(glb), "export path")
    s.page.locator(".fwb-export-button").click()
    s.page.locator(".fwb-export-files").wait_for(timeout=300_000)
    s.page.locator(".fwb-export-layers").wait_for(timeout=10_000)
    assert "handles" in s.page.locator(".fwb-export-layers").inner_text()
    written = s.py("[str(p) for p in wb.export.last_written]")
    assert written == [str(glb)], written
    s.shot(out / "ui_export.png")


def wrinkles(s: Session, out: Path) -> None:
    # Camera first, in the Shapes tab (orbit tool): zoom in with the wheel, then shift+drag to
    # pan the face down so the forehead fills the upper half of the view.
    s.tab("Shapes", "orbit")
    s.top()
    box = s.nb.canvas_box(0)
    cx, cy = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
    s.page.mouse.move(cx, cy)
    for _ in range(WRINKLE_ZOOM_CLICKS):
        s.page.mouse.wheel(0, -120)
        s.page.wait_for_timeout(80)
    s.page.keyboard.down("Shift")
    s.page.mouse.move(box["x"] + 40, box["y"] + 40)
    s.page.mouse.down()
    s.page.mouse.move(box["x"] + 40, box["y"] + 40 + WRINKLE_PAN_PX, steps=12)
    s.page.mouse.up()
    s.page.keyboard.up("Shift")
    s.page.mouse.move(3, 3)

    s.tab("Sculpt", "sculpt")
    s.page.locator(".fwb-wrinkle-fit").click()  # the default handles come with it
    s.page.wait_for_function(
        "() => document.querySelectorAll('.fwb-wrinkle-card').length >= 6", timeout=600_000
    )
    s.wait_py("bool(model.wrinkles.fitted)", bool, "fit")
    n = s.py("len(model.handles)")
    s.page.wait_for_function(
        "(n) => JSON.parse(document.querySelector('.fwb-viewport')"
        ".getAttribute('data-markers') || '[]').length === n"
        " && Number(document.querySelector('.fwb-viewport')"
        ".getAttribute('data-feature-edges')) > 0",
        arg=n,
    )
    s.page.locator(".fwb-symmetric").click()
    s.wait_py("wb.viewport.symmetric", bool, "Symmetric")
    # raise the whole brow (middle, inner, outer marker; the mirror side follows)
    for name, dy in (("brows_L_2", -30.0), ("brows_L_1", -22.0), ("brows_L_3", -18.0)):
        s.drag_handle(name, 0.0, dy)
    detail = s.py("float(abs(model.wrinkles.details()).max())")
    assert detail > 1e-3, f"no wrinkle detail after the brow raise ({detail})"
    assert s.py("wb.viewport.feature_graph") is True
    s.shot(out / "ui_sculpt_wrinkles.png")


# -------------------------------------------------------------------- plumbing
def _open(lab: LabServer, browser: Any, name: str, source: str) -> tuple[Any, Session]:
    for f in (lab.base / "recovery").glob("*"):  # an earlier kernel's autosave: no recovery prompt
        f.unlink()
    (lab.root / name).write_text(source)
    ctx = browser.new_context(viewport=dict(WINDOW), device_scale_factor=1)
    page = ctx.new_page()
    nb = NotebookPage(page, lab, ARTIFACTS, name)
    page.goto(f"{lab.url}/lab/workspaces/docs-{Path(name).stem}/tree/{name}?reset")
    nb.wait_kernel_idle(timeout=120)
    nb.run_all(timeout=900)
    page.evaluate(
        "() => { const s = window.jupyterapp.shell; if (!s.leftCollapsed) s.collapseLeft(); }"
    )
    nb.wait_viewports(1, timeout=180)
    if page.locator(".fwb-recover").count():
        raise RuntimeError("the notebook offers recovery instead of opening the workbench")
    s = Session(nb)
    s.top()
    return ctx, s


def _close(lab: LabServer, ctx: Any, s: Session) -> None:
    kid = s.nb.kernel_id()
    if s.nb.console:
        ARTIFACTS.mkdir(parents=True, exist_ok=True)
        (ARTIFACTS / f"console-{Path(s.nb.name).stem}.log").write_text("\n".join(s.nb.console))
    with contextlib.suppress(Exception):
        ctx.close()
    if kid:
        lab.shutdown_kernels({kid})


def _notebook_at(resolution: str | None) -> str:
    """notebooks/workbench.ipynb, optionally pinned to the sample head at ``resolution``.

    The notebook reads its resolution from ``WORKBENCH_RESOLUTION`` with a default; pinning
    replaces that one line, so the picture does not depend on the caller's environment.
    """
    text = WORKBENCH_NB.read_text()
    if resolution is None:
        return text
    nb = json.loads(text)
    pattern = re.compile(r'^RESOLUTION = os\.environ\.get\("WORKBENCH_RESOLUTION", "[^"]*"\)$', re.M)
    hits = 0
    for cell in nb["cells"]:
        src = "".join(cell["source"]) if isinstance(cell["source"], list) else cell["source"]
        if cell["cell_type"] == "code" and pattern.search(src):
            cell["source"] = pattern.sub(f'RESOLUTION = "{resolution}"', src)
            hits += 1
    if hits != 1:
        raise RuntimeError(f"{WORKBENCH_NB} sets RESOLUTION from WORKBENCH_RESOLUTION in {hits} cells; expected one")
    return json.dumps(nb)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=REPO / "notebooks" / "images")
    ap.add_argument("--glb", type=Path, default=Path("/tmp/face.glb"))
    ap.add_argument(
        "--part",
        choices=("all", "main", "wrinkles"),
        default="all",
        help="main: the six pictures of the base head; wrinkles: ui_sculpt_wrinkles.png only",
    )
    args = ap.parse_args(argv)
    if chromium_missing():
        return 1

    out = args.out.resolve()
    glb = args.glb if args.glb.is_absolute() else args.glb.resolve()
    glb_existed = glb.exists()
    t_start = time.monotonic()
    timings: list[tuple[str, float]] = []

    def step(name: str, fn: Callable[[], None], s: Session) -> None:
        t0 = time.monotonic()
        print(f"{name} ...", flush=True)
        try:
            fn()
        except Exception:
            with contextlib.suppress(Exception):
                ARTIFACTS.mkdir(parents=True, exist_ok=True)
                s.page.screenshot(path=str(ARTIFACTS / f"failed-{name}.png"))
            raise
        timings.append((name, time.monotonic() - t0))

    try:
        with lab_and_browser("fwb-docs-ui-") as (lab, browser):
            if args.part in ("all", "main"):
                t0 = time.monotonic()
                ctx, s = _open(lab, browser, "workbench.ipynb", _notebook_at(None))
                timings.append(("open workbench.ipynb", time.monotonic() - t0))
                try:
                    step("shapes", lambda: shapes(s, out), s)
                    step("sculpt", lambda: sculpt(s, out), s)
                    step("regions", lambda: regions(s, out), s)
                    step("paint", lambda: paint(s, out), s)
                    step("timeline", lambda: timeline(s, out), s)
                    step("export", lambda: export(s, out, glb), s)
                finally:
                    _close(lab, ctx, s)
            if args.part in ("all", "wrinkles"):
                t0 = time.monotonic()
                ctx, s = _open(lab, browser, "workbench_25k.ipynb", _notebook_at("25k"))
                timings.append(("open workbench.ipynb at 25k", time.monotonic() - t0))
                try:
                    step("wrinkles", lambda: wrinkles(s, out), s)
                finally:
                    _close(lab, ctx, s)
    finally:
        if not glb_existed:
            glb.unlink(missing_ok=True)
    for name, secs in timings:
        print(f"  {name:32s} {secs:6.1f} s")
    print(f"done in {time.monotonic() - t_start:.0f} s; look at the pictures in {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
