"""The GPU path's kernel side (``widgets/viewport/gpu.py``): what the page is told to evaluate.

The browser's half is tested in Chromium (tests/browser/test_gpu_viewport.py);
here, without a browser: the sparse deltas rebuild the dense ones, and the rules
by which the page turns slider values into played weights (``gpu_local.js``)
give :meth:`StateView.weight_vector` for muted and corrective shapes.
"""

from __future__ import annotations

import numpy as np
import pytest

import workbench

pytestmark = pytest.mark.ui


def _play(rules: dict, names: list[str], raw: dict[str, float]) -> np.ndarray:
    """What gpu_local.js plays for raw slider values (the same arithmetic, in numpy)."""
    mute = set(rules["mute"])
    P = np.array([0.0 if i in mute else raw.get(nm, 0.0) for i, nm in enumerate(names)])
    for s, drivers, lo, hi in rules["products"]:
        w = 1.0
        for d in drivers:
            w *= 0.0 if d in mute else P[d]
        P[s] = min(max(w, lo), hi)
    return P


def test_morph_csr_rebuilds_the_dense_deltas() -> None:
    from widgets.viewport.gpu import morph_csr

    rng = np.random.default_rng(3)
    D = rng.normal(size=(4, 30, 3)).astype(np.float32)
    D[:, rng.random(30) < 0.5] = 0  # vertices no shape moves
    D[2, :10] = 0
    index, entries = morph_csr(D)
    dense = np.zeros_like(D)
    for v, (off, cnt) in enumerate(index):
        for dx, dy, dz, s in entries[off : off + cnt]:
            dense[int(s), v] = (dx, dy, dz)
    np.testing.assert_array_equal(dense, D)
    assert entries.shape[0] == int((D != 0).any(axis=2).sum())


def test_local_weight_rules_play_what_the_kernel_plays() -> None:
    from widgets.viewport.gpu import local_weight_rules

    m = workbench.load_sample("head")
    m.shape_tools.add_corrective("fix", ["jawOpen", "mouthSmileLeft"])
    m.set_shape_mute("eyeBlinkLeft", True)
    view = m.view()
    rules = local_weight_rules(view)
    names = list(view.shape_names)
    assert rules["mute"] == [names.index("eyeBlinkLeft")]
    fix = names.index("fix")
    assert [r[0] for r in rules["products"]] == [fix]
    assert sorted(rules["products"][0][1]) == sorted([names.index("jawOpen"), names.index("mouthSmileLeft")])
    for raw in ({"jawOpen": 0.7, "mouthSmileLeft": 0.5, "eyeBlinkLeft": 0.9},
                {"jawOpen": 1.0, "mouthSmileLeft": 1.0, "fix": 0.2}):
        for nm, w in raw.items():
            m.set_weight(nm, w)
        np.testing.assert_allclose(_play(rules, names, dict(m.weights)), m.view().weight_vector(),
                                   atol=1e-6)
    m.set_shape_mute("mouthSmileLeft", True)  # a muted driver plays its product 0
    rules = local_weight_rules(m.view())
    P = _play(rules, names, dict(m.weights))
    assert P[fix] == 0.0
    np.testing.assert_allclose(P, m.view().weight_vector(), atol=1e-6)


def test_follow_sliders_sends_the_sliders_model_ids() -> None:
    import ipywidgets as W

    from widgets import Viewport

    m = workbench.load_sample("head")
    vp = Viewport(m, height=200)
    try:
        s = W.FloatSlider()
        vp.follow_sliders({"jawOpen": s})
        assert vp.weight_sliders == {"jawOpen": s}
        # plain model ids: the page looks the sliders up itself, never waits for them
        assert vp.get_state()["_weight_slider_ids"] == {"jawOpen": s.model_id}
        assert vp.fast_interaction == "auto"
        with pytest.raises(Exception, match="fast_interaction"):
            vp.fast_interaction = "sometimes"
    finally:
        vp.close()


def test_the_workbench_links_its_shape_sliders_and_relinks_new_ones() -> None:
    import widgets

    m = workbench.load_sample("head")
    wb = widgets.Workbench(m)
    try:
        assert set(wb.viewport.weight_sliders) == set(m.shape_names)
        assert wb.viewport.weight_sliders["jawOpen"] is wb.panel.sliders["jawOpen"]
        m.shape_tools.add_corrective("fix", ["jawOpen", "mouthSmileLeft"])
        assert "fix" in wb.viewport.weight_sliders
        assert wb.viewport.weight_sliders["fix"] is wb.panel.sliders["fix"]
    finally:
        wb.close()


def _record_states(vp) -> list[set[str]]:
    """The trait names of every state message the widget sends from now on."""
    sent: list[set[str]] = []
    send_state = vp.send_state

    def record(key=None):
        sent.append({key} if isinstance(key, str) else set(vp.keys if key is None else key))
        return send_state(key)

    vp.send_state = record
    return sent


@pytest.mark.parametrize("gpu", [False, True])
def test_a_full_update_sends_what_python_kept_silently(gpu: bool) -> None:
    """Patches keep ``_positions`` (streaming) or ``_gpu_params`` (GPU) current in Python
    only; a full update of the same value must still reach the page, which would
    otherwise read its own stale copy of the trait (a picture from before the patches)."""
    from widgets import Viewport

    m = workbench.load_sample("head")
    vp = Viewport(m, height=200, gpu=gpu)
    try:
        if gpu:
            vp._on_frontend_msg(vp, {"type": "gpu_ready"}, [])
            assert vp._gpu_mode == "gpu"
        messages: list[dict] = []
        vp.send = lambda content, buffers=None: messages.append(content)  # patches / parameters
        m.set_weight("eyeBlinkLeft", 0.6)  # a small change: a message, the trait kept silently
        assert [c["type"] for c in messages] == ["gpu_params" if gpu else "patch"]
        silent = "_gpu_params" if gpu else "_positions"
        sent = _record_states(vp)
        vp._on_frontend_msg(vp, {"type": "request_full", "have": 0}, [])  # the page lost track
        assert any(silent in keys and "_version" in keys for keys in sent), sent
        if gpu:
            assert any("_gpu_residual" in keys for keys in sent), sent
    finally:
        vp.close()


def test_assign_synced_sends_an_equal_value_and_keeps_it_on_error() -> None:
    import ipywidgets as W
    import traitlets

    from widgets.viewport.common import assign_synced, store_silently

    class Probe(W.DOMWidget):
        data = traitlets.Bytes(b"").tag(sync=True)
        count = traitlets.Int(0).tag(sync=True)

    w = Probe()
    sent = _record_states(w)
    store_silently(w, data=b"abc")
    assert sent == [] and w.data == b"abc"
    with w.hold_sync():
        w.data = b"abc"  # plain assignment of an equal value: nothing to send
    assert all("data" not in keys for keys in sent)
    sent.clear()
    with w.hold_sync():
        assign_synced(w, data=b"abc", count=1)
    assert sent == [{"data", "count"}] and w.data == b"abc" and w.count == 1
    with pytest.raises(traitlets.TraitError):
        assign_synced(w, count="not a number")
    assert w.count == 1
    w.close()


def test_a_resync_with_the_rig_sends_the_rig_again() -> None:
    """``request_full`` with ``rig``: the page missed the switch to GPU mode (it has no rig),
    so the full update carries the rig and the mode again, equal values or not."""
    from widgets import Viewport

    m = workbench.load_sample("head")
    vp = Viewport(m, height=200, gpu=True)
    try:
        vp._on_frontend_msg(vp, {"type": "gpu_ready"}, [])
        rig = {"_gpu_neutral", "_gpu_morph_index", "_gpu_morph_entries", "_gpu_gain", "_gpu_meta"}
        sent = _record_states(vp)
        vp._on_frontend_msg(vp, {"type": "request_full", "have": 0}, [])
        assert not rig & set().union(*sent), sent  # a plain resync: parameters, not the rig
        sent.clear()
        vp._on_frontend_msg(vp, {"type": "request_full", "have": 0, "rig": True}, [])
        keys = set().union(*sent)
        assert rig <= keys and {"_gpu_mode", "_gpu_params", "_gpu_residual", "_version"} <= keys, keys
        assert vp._gpu_mode == "gpu"
    finally:
        vp.close()
