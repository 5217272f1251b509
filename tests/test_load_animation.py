"""workbench.load puts a file's own weights animation on the timeline (glTF, USD)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import workbench
from workbench.animation.importers import AnimationImportError
from workbench.animation.tracks import Timeline
from workbench.export import export
from workbench.io.animation import animation_of, read_file_animation


@pytest.fixture(scope="module")
def head():
    return workbench.load_sample("head")


def _timeline() -> Timeline:
    tl = Timeline(fps=30.0)
    tl = tl.add_key("weights/jawOpen", 0.0, 0.0, interpolation="linear")
    tl = tl.add_key("weights/jawOpen", 0.5, 0.8, interpolation="linear")
    tl = tl.add_key("weights/jawOpen", 1.0, 0.1, interpolation="linear")
    tl = tl.add_key("weights/mouthSmileLeft", 0.0, 0.2, interpolation="step")
    tl = tl.add_key("weights/mouthSmileLeft", 0.5, 0.9, interpolation="step")  # float32-exact time
    return tl.fit_range()


@pytest.mark.parametrize("suffix", [".glb", ".usda"])
def test_load_puts_the_files_animation_on_the_timeline(head, tmp_path: Path, suffix: str) -> None:
    tl = _timeline()
    path = tmp_path / f"anim{suffix}"
    export(head, tl, path)
    model = workbench.load(path)
    assert not model.can_undo  # the loaded animation is the starting point, not an edit
    t = tl.frame_times()
    got = model.tracks.weight_matrix(model.shape_names, t)
    want = tl.weight_matrix(model.shape_names, t)
    np.testing.assert_allclose(got, want, atol=1e-6)
    # and the model plays it: evaluate_at equals the source model at the same time
    for when in (0.25, 0.7):
        head.set_weights({n: 0.0 for n in head.shape_names})
        ref = head.evaluate_at(when, tl)
        np.testing.assert_allclose(model.evaluate_at(when) * _scale(model, head), ref, atol=2e-5)


def _scale(model, head) -> float:
    return model.metadata.metres_per_unit / head.metadata.metres_per_unit


def test_a_file_without_animation_loads_with_an_empty_timeline(head, tmp_path: Path) -> None:
    path = tmp_path / "still.glb"
    export(head, Timeline(), path)
    assert animation_of(path, head.shape_names) is None
    model = workbench.load(path)
    assert not model.tracks.tracks


def test_a_broken_animation_refuses_the_whole_file(head, tmp_path: Path) -> None:
    path = tmp_path / "anim.glb"
    export(head, _timeline(), path)
    data = bytearray(path.read_bytes())
    # the keyframe times are the first floats of the binary chunk's animation input:
    # make them non-increasing by writing the json's declared min/max elsewhere is fiddly,
    # so corrupt through the reader's own contract instead: an unknown channel target node
    import json
    import struct

    jlen = struct.unpack_from("<I", data, 12)[0]
    doc = json.loads(bytes(data[20 : 20 + jlen]))
    doc["animations"][0]["channels"][0]["target"]["node"] = 99
    raw = json.dumps(doc).encode()
    raw += b" " * (-len(raw) % 4)
    out = data[:12] + struct.pack("<I", len(raw)) + data[16:20] + raw + data[20 + jlen :]
    struct.pack_into("<I", out, 8, len(out))
    path.write_bytes(bytes(out))
    with pytest.raises(Exception, match=r"anim\.glb") as info:
        workbench.load(path)
    assert "node" in str(info.value)


def test_read_file_animation_dispatches_csv(head, tmp_path: Path) -> None:
    tl = _timeline()
    path = tmp_path / "w.csv"
    export(head, tl, path)
    back = read_file_animation(path, head.shape_names, fps=30.0)
    t = tl.frame_times()
    names = head.shape_names
    np.testing.assert_allclose(back.weight_matrix(names, t), tl.weight_matrix(names, t), atol=1e-8)
    with pytest.raises(AnimationImportError, match="no animations"):
        read_file_animation(_still(head, tmp_path), head.shape_names)


def _still(head, tmp_path: Path) -> Path:
    path = tmp_path / "still.glb"
    export(head, Timeline(), path)
    return path
