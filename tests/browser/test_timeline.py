"""The keyframe timeline in a real JupyterLab + Chromium, driven with the mouse.

A small notebook shows ``widgets.Viewport`` above ``TimelineWidget`` on the
sample head with three keyed expressions (jawOpen at 0 s, a saved "smile" at
1 s, browInnerUp at 2 s). The tests scrub the playhead, drag a key diamond,
play/pause, drag an expression's thumbnail from the timeline's chip gallery
onto the ruler (HTML5 drag and drop; the pictures are an ``ExpressionGallery``'s
PNGs), drag a Bézier tangent handle and delete a key with the keyboard,
checking the Python model (read back from the kernel) and the pixels. The timeline's test
hooks (``data-playhead-x``, ``data-keys``, ``data-axis``, ``data-tangents``)
give the screen positions to aim at. Screenshots: ``test-artifacts/<test>/``.
"""

from __future__ import annotations

import json
import time
from typing import Any

import numpy as np
from harness import NotebookPage, clip_around, pixel_change

CELLS = [
    """
import ipywidgets as W
import widgets
import workbench
from widgets.timeline import TimelineWidget

model = workbench.load_sample("head")
model.set_weights({"mouthSmileLeft": 1.0, "mouthSmileRight": 1.0})
model.expressions.save("smile")
model.reset_weights()
model.key_expression(0.0, "jawOpen")
model.key_expression(1.0, "smile")
model.key_expression(2.0, "browInnerUp")
model.set_time(0.0)
vp = widgets.Viewport(model, height=330)
gal = widgets.ExpressionGallery(model, size=(64, 64), expressions=True)  # not shown: the chips use it
tl = TimelineWidget(model, gallery=gal)
W.VBox([vp, tl])
""",
]

_PROBE_MOUTH = """
import json, numpy as np
_d = np.linalg.norm(model.shape("jawOpen").delta, axis=1)
_skin = model.component_labels == model.component_names.index("skin")
_ids = np.argsort(-(_d * _skin))[:80]
vp.probe_ids = _ids
print(json.dumps([int(i) for i in _ids]))
"""


def _py(nb: NotebookPage, expr: str) -> Any:
    return nb.kernel_eval(f"import json; print(json.dumps({expr}))")


def _open(open_notebook) -> tuple[NotebookPage, Any, list[int]]:
    nb = open_notebook(CELLS)
    nb.page.evaluate(
        "() => { const s = window.jupyterapp.shell; if (!s.leftCollapsed) s.collapseLeft(); }"
    )
    nb.wait_viewports(1)
    ids = nb.kernel_eval(_PROBE_MOUTH)
    root = nb.page.locator(".fwb-timeline")
    root.wait_for()
    nb.page.wait_for_function(
        "() => { const e = document.querySelector('.fwb-timeline');"
        " return e && JSON.parse(e.getAttribute('data-keys') || '[]').length >= 12; }"
    )
    nb.viewport(0).evaluate("e => e.scrollIntoView({block: 'start'})")
    _wait_layout_settled(nb)  # the sidebar collapsed: the timeline grew
    return nb, root, ids


def _frames(nb: NotebookPage, n: int = 2) -> None:
    """Wait ``n`` animation frames: what the page was asked to draw is drawn."""
    nb.page.evaluate(
        "n => new Promise(done => { const f = k => k ? requestAnimationFrame(() => f(k - 1)) : done();"
        " f(n); })",
        n,
    )


def _wait_layout_settled(nb: NotebookPage, frames: int = 10) -> None:
    """Wait until the timeline's box kept its size and place for ``frames`` animation frames."""
    nb.page.wait_for_function(
        """(n) => { const e = document.querySelector('.fwb-timeline');
             const r = e.getBoundingClientRect();
             const key = [r.left, r.top, r.width, r.height].join();
             const s = (window.__fwbLayout = window.__fwbLayout || { key: '', same: 0 });
             s.same = key === s.key ? s.same + 1 : 0;
             s.key = key;
             return s.same >= n; }""",
        arg=frames,
        polling="raf",
    )
    _frames(nb)  # the resize observer's redraw


def _wait_hooks(
    nb: NotebookPage, root: Any, pred, what: str, timeout: float = 15.0
) -> dict[str, Any]:
    """Poll the timeline's hooks until ``pred(hooks)``, then let it draw; return the hooks."""
    deadline = time.monotonic() + timeout
    h = _hooks(root)
    while not pred(h):
        if time.monotonic() > deadline:
            raise AssertionError(f"the timeline never showed {what}; hooks {h}")
        _frames(nb, 1)
        h = _hooks(root)
    _frames(nb)
    return h


def _wait_viewport_current(nb: NotebookPage) -> None:
    """Wait until the viewport drew the geometry of the model's current version."""
    version = _py(nb, "vp._version")
    nb.page.wait_for_function(
        "v => Number(document.querySelector('.fwb-viewport').getAttribute('data-version')) >= v",
        arg=version,
    )
    _frames(nb)


def _hooks(root: Any) -> dict[str, Any]:
    h = root.evaluate("e => e.fwbHooks()")
    return {
        "time": float(h["data-time"]),
        "playhead_x": float(h["data-playhead-x"]),
        "ruler_y": float(h["data-ruler-y"]),
        "axis": json.loads(h["data-axis"]),
        "keys": json.loads(h["data-keys"]),
        "tangents": json.loads(h["data-tangents"]),
        "selected": json.loads(h["data-selected"]),
    }


def _x_of(h: dict[str, Any], t: float) -> float:
    a = h["axis"]
    return a["x0"] + (t - a["t0"]) / (a["t1"] - a["t0"]) * (a["x1"] - a["x0"])


def _key(h: dict[str, Any], track: str, index: int) -> tuple[float, float]:
    for name, i, _t, x, y in h["keys"]:
        if name == track and i == index:
            return x, y
    raise AssertionError(f"no key {track}[{index}] in {h['keys']}")


def _wait_py(nb: NotebookPage, expr: str, pred, timeout: float = 15.0) -> Any:
    deadline = time.monotonic() + timeout
    value = None
    while time.monotonic() < deadline:
        value = _py(nb, expr)
        if pred(value):
            return value
        time.sleep(0.15)
    raise AssertionError(
        f"{expr} never satisfied the condition; last value {value!r} "
        f"(timeline status {_py(nb, 'tl.status')!r}, error {_py(nb, 'tl._error')!r})"
    )


def _drag(nb: NotebookPage, x0: float, y0: float, x1: float, y1: float, steps: int = 12) -> None:
    m = nb.page.mouse
    m.move(x0, y0)
    m.down()
    m.move(x1, y1, steps=steps)
    m.up()


def test_scrub_drag_key_and_play(open_notebook):
    nb, root, ids = _open(open_notebook)
    clip = clip_around(nb.project(ids), pad=40)
    nb.screenshot("page-start")
    before = nb.screenshot("mouth-t0", clip=clip)
    assert _py(nb, "model.time") == 0.0
    assert _py(nb, 'model.weights["jawOpen"]') == 1.0

    # --- scrub: grab the playhead in the ruler and drag it to t = 1 s (the smile)
    h = _hooks(root)
    assert abs(h["playhead_x"] - _x_of(h, 0.0)) < 1.0
    frame0 = nb.frame(0)
    _drag(nb, h["playhead_x"], h["ruler_y"], _x_of(h, 1.0), h["ruler_y"], steps=15)
    t = _wait_py(nb, "model.time", lambda v: abs(v - 1.0) < 1e-9)
    assert t == 1.0
    assert int(root.get_attribute("data-scrub-sent")) >= 2  # intermediate positions were sent
    nb.wait_frame_after(0, frame0)
    w = _py(nb, "dict(model.weights)")
    assert w["jawOpen"] == 0.0 and w["mouthSmileLeft"] == 1.0
    _wait_viewport_current(nb)
    after = nb.screenshot("mouth-t1", clip=clip)
    nb.screenshot("page-scrubbed")
    changed = pixel_change(before, after)
    assert changed > 0.03, f"only {changed:.1%} of the mouth region changed"
    h = _wait_hooks(nb, root, lambda h: h["time"] == 1.0, "the playhead at 1 s")
    assert abs(h["playhead_x"] - _x_of(h, 1.0)) < 1.0

    # --- drag the browInnerUp key at 2 s to 1.5 s: one undo step
    undo0 = _py(nb, "model.history.undo_labels")
    x, y = _key(h, "weights/browInnerUp", 2)
    _drag(nb, x, y, _x_of(h, 1.5), y)
    times = _wait_py(
        nb,
        'model.tracks.tracks["weights/browInnerUp"].times.tolist()',
        lambda v: v != [0.0, 1.0, 2.0],
    )
    assert times == [0.0, 1.0, 1.5]
    undo1 = _py(nb, "model.history.undo_labels")
    assert undo1 == [*undo0, "Move key of weights/browInnerUp"]
    _wait_hooks(
        nb,
        root,
        lambda h: (
            abs(_key(h, "weights/browInnerUp", 2)[0] - _x_of(h, 1.5)) < 1.0
            and h["selected"] == [["weights/browInnerUp", 2]]
        ),
        "the moved key at 1.5 s, selected",
    )
    nb.screenshot("key-dragged")
    nb.kernel_eval("model.undo()")
    assert _py(nb, 'model.tracks.tracks["weights/browInnerUp"].times.tolist()') == [0.0, 1.0, 2.0]
    assert _py(nb, "model.history.undo_labels") == undo0

    # --- Play (looping), let several frames go by, Pause
    root.locator(".fwb-tl-loop").check()
    _wait_py(nb, "tl.loop", bool)
    frame1 = nb.frame(0)
    renders1 = int(nb.viewport(0).get_attribute("data-render-count"))
    t_start = _py(nb, "model.time")
    root.locator(".fwb-tl-play").click()
    _wait_py(nb, "tl.playing", bool, timeout=10)
    # the playhead follows playback in the front end: it shows three different times
    shown = nb.page.wait_for_function(
        """() => { const e = document.querySelector('.fwb-timeline');
             const s = (window.__fwbShown = window.__fwbShown || new Set());
             s.add(e.getAttribute('data-time'));
             return s.size >= 3 ? Array.from(s) : false; }""",
        polling="raf",
    ).json_value()
    nb.screenshot("playing", full_detail=False)  # a playing clip drafts
    # the viewport draws the played frames (drafts while playing: data-render-count counts them,
    # data-frame only full-detail ones): wait for five (a busy machine draws fewer per second than
    # the playhead moves), then pause
    nb.page.wait_for_function(
        "(prev) => Number(document.querySelector('.fwb-viewport').getAttribute('data-render-count')) >= prev + 5",
        arg=renders1, timeout=60_000,
    )
    root.locator(".fwb-tl-pause").click()
    _wait_py(nb, "tl.playing", lambda v: not v, timeout=10)
    stats = _py(nb, "tl.playback_stats")
    renders = int(nb.viewport(0).get_attribute("data-render-count")) - renders1
    assert stats["frames"] >= 5, stats
    assert renders >= 5, f"the viewport drew only {renders} new frames while playing"
    nb.wait_frame_after(0, frame1)  # and the full-detail face once paused
    assert _py(nb, "model.time") != t_start
    assert len(shown) >= 3, f"the playhead showed only the times {shown}"
    nb.page.wait_for_function(
        """() => { const e = document.querySelector('.fwb-timeline');
             return e.getAttribute('data-playing') === '0'
               && e.querySelector('.fwb-tl-status').textContent.includes('played'); }"""
    )
    nb.screenshot("paused")


def _box_pixels(nb: NotebookPage, name: str, box: dict[str, float]) -> np.ndarray:
    return nb.screenshot(name, clip={k: box[k] for k in ("x", "y", "width", "height")})


def test_drop_chip_tangent_and_delete(open_notebook):
    nb, root, _ids = _open(open_notebook)

    # --- the chips are a gallery: one thumbnail (the gallery's PNG) per expression
    n_chips = _py(nb, "len(tl.expressions)")
    assert n_chips == 53  # "smile" + 52 blendshapes
    strip = root.locator(".fwb-tl-chips")
    nb.page.wait_for_function(
        "n => document.querySelector('.fwb-tl-chips').getAttribute('data-thumbs') === String(n)",
        arg=n_chips,
    )
    assert root.locator(".fwb-tl-chip img").count() == n_chips
    img = root.locator('.fwb-tl-chip[data-name="smile"] img')
    nb.page.wait_for_function("e => e.complete && e.naturalWidth === 64", arg=img.element_handle())
    assert img.get_attribute("src").startswith("blob:")  # binary PNG, no data: URL
    sbox = strip.bounding_box()
    assert sbox["height"] < 100  # one compact row ...
    assert strip.evaluate("e => e.scrollWidth > e.clientWidth")  # ... that scrolls sideways
    ibox = img.bounding_box()
    assert 40 <= ibox["width"] <= 64 and 40 <= ibox["height"] <= 64
    pic = _box_pixels(nb, "smile-thumbnail", ibox).astype(float)
    assert pic.std() > 20, "the smile thumbnail is blank"
    assert len(np.unique(pic.reshape(-1, 3) // 16, axis=0)) > 20
    nb.screenshot("chip-gallery")

    # --- the mouse drags the smile thumbnail onto the ruler at 0.5 s: keyed there
    undo0 = _py(nb, "model.history.undo_labels")
    h = _hooks(root)
    _drag(
        nb,
        ibox["x"] + ibox["width"] / 2,
        ibox["y"] + ibox["height"] / 2,
        _x_of(h, 0.5),
        h["ruler_y"],
        steps=15,
    )
    _wait_py(nb, "len(model.history.undo_labels)", lambda n: n == len(undo0) + 1)
    assert _py(nb, "model.history.undo_labels")[-1] == "Key smile at 0.5s"
    w = _py(nb, "model.tracks.evaluate(0.5).weights")
    assert w == {"browInnerUp": 0.0, "jawOpen": 0.0, "mouthSmileLeft": 1.0, "mouthSmileRight": 1.0}
    assert _py(nb, "model.time") == 0.0  # the drop keyed; it did not scrub
    # ... and on screen: a key diamond at 0.5 s on every track
    nb.page.wait_for_function(
        "() => JSON.parse(document.querySelector('.fwb-timeline').getAttribute('data-keys'))"
        ".length >= 16"
    )
    h = _wait_hooks(
        nb,
        root,
        lambda h: abs(_key(h, "weights/mouthSmileLeft", 1)[0] - _x_of(h, 0.5)) < 1.0,
        "the dropped key at 0.5 s",
    )
    x, y = _key(h, "weights/mouthSmileLeft", 1)
    diamond = _box_pixels(nb, "dropped-key", {"x": x - 7, "y": y - 7, "width": 14, "height": 14})
    r, g, b = (diamond[..., i].astype(int) for i in range(3))
    key_orange = (r > 190) & (g > 130) & (g < 190) & (b < 90)  # COLORS.key #e0a526
    assert key_orange.sum() >= 10, "no key diamond drawn at 0.5 s"
    nb.screenshot("chip-dropped")

    # --- click a key: it is selected and its track shown in the curve view
    h = _hooks(root)
    x, y = _key(h, "weights/jawOpen", 2)  # jawOpen keys: 0, 0.5, 1, 2 s
    nb.page.mouse.click(x, y)
    _wait_py(nb, "tl.selected_keys", lambda v: v == [["weights/jawOpen", 2]])
    assert _py(nb, "tl.selected_track") == "weights/jawOpen"

    # --- drag the out-tangent handle of jawOpen's first key (1 at 0 s) downwards
    h = _wait_hooks(
        nb,
        root,
        lambda h: any(tn == "weights/jawOpen" for tn, *_rest in h["tangents"]),
        "the curve view of jawOpen",
    )
    handles = {(tn, i, side): (hx, hy) for tn, i, side, hx, hy in h["tangents"]}
    hx, hy = handles[("weights/jawOpen", 0, "out")]
    nb.screenshot("curve-before")
    _drag(nb, hx, hy, hx, hy + 40)
    key0 = _wait_py(
        nb,
        '[model.tracks.tracks["weights/jawOpen"].keys[0].tangent_mode,'
        ' float(model.tracks.tracks["weights/jawOpen"].keys[0].out_tangent)]',
        lambda v: v[0] == "user",
    )
    assert key0[1] < 0  # dragged down: the curve leaves the key falling

    def dragged_handle_y(h: dict[str, Any]) -> float:
        return next(
            y
            for tn, i, side, _x, y in h["tangents"]
            if (tn, i, side) == ("weights/jawOpen", 0, "out")
        )

    _wait_hooks(nb, root, lambda h: dragged_handle_y(h) > hy + 20, "the new tangent")
    nb.screenshot("curve-after")

    # --- Delete key: selected key 2 of jawOpen (t = 1 s) goes, one undo step
    undo1 = _py(nb, "model.history.undo_labels")
    x, y = _key(_hooks(root), "weights/jawOpen", 2)
    nb.page.mouse.click(x, y)
    _wait_py(nb, "tl.selected_keys", lambda v: v == [["weights/jawOpen", 2]])
    nb.page.keyboard.press("Delete")
    times = _wait_py(
        nb,
        'model.tracks.tracks["weights/jawOpen"].times.tolist()',
        lambda v: len(v) == 3,
    )
    assert times == [0.0, 0.5, 2.0]
    assert _py(nb, "model.history.undo_labels") == [*undo1, "Delete key 2 of weights/jawOpen"]
    # the notebook itself was untouched by the key press (JupyterLab shortcuts did not fire)
    assert len(nb.state()["counts"]) == 1

    # --- double-click on the smile row at 1.5 s adds a key with the current weight
    h = _hooks(root)
    _x, y = _key(h, "weights/mouthSmileLeft", 0)
    nb.page.mouse.dblclick(_x_of(h, 1.5), y)
    times = _wait_py(
        nb,
        'model.tracks.tracks["weights/mouthSmileLeft"].times.tolist()',
        lambda v: 1.5 in v,
    )
    assert times == [0.0, 0.5, 1.0, 1.5, 2.0]
    _wait_hooks(
        nb,
        root,
        lambda h: any(k[0] == "weights/mouthSmileLeft" and k[2] == 1.5 for k in h["keys"]),
        "the key added at 1.5 s",
    )
    nb.screenshot("final")
    assert root.get_attribute("data-error") == ""
