"""The ``workbench`` command line: info and export."""

from __future__ import annotations

import csv
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import workbench
from workbench.cli import main
from workbench.export import export

REPO = Path(__file__).resolve().parent.parent


def test_info_on_the_sample_head(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["info", str(REPO / "sample_models" / "head")]) == 0
    out = capsys.readouterr().out
    assert "vertices    5084" in out
    assert "4-gon x4948" in out
    assert "units       dm (0.1 m per unit), up +y, front +z" in out
    assert "shapes      52 (52 mapped to ARKit-52)" in out
    for comp in ("skin", "eye_left", "teeth_lower", "tongue"):
        assert comp in out


def test_info_on_a_gltf_with_morph_targets(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    model = workbench.load_sample("head")
    for name in list(model.shape_names)[6:]:
        model.remove_shape(name)
    model.rename_shape("browDownLeft", "BrowDown_L")  # a non-canonical spelling
    glb = tmp_path / "face.glb"
    model.timeline.key_weights(0.0, ["cheekPuff"])
    export(model, model.tracks, glb)
    assert main(["info", str(glb)]) == 0
    out = capsys.readouterr().out
    assert "shapes      6 (6 mapped to ARKit-52)" in out
    assert "BrowDown_L" in out and "-> ARKit browDownLeft" in out
    assert "units       m (1 m per unit)" in out


def _accessor_floats(gltf, index: int) -> np.ndarray:
    """The float32 values of a glTF accessor, read through pygltflib (not our importer)."""
    acc = gltf.accessors[index]
    view = gltf.bufferViews[acc.bufferView]
    start = (view.byteOffset or 0) + (acc.byteOffset or 0)
    width = {"SCALAR": 1, "VEC3": 3, "VEC4": 4}[acc.type]
    return np.frombuffer(gltf.binary_blob(), "<f4", acc.count * width, start)


def _weight_sampler(path: Path):
    from pygltflib import GLTF2

    gltf = GLTF2().load(str(path))
    (anim,) = gltf.animations
    (channel,) = [c for c in anim.channels if c.target.path == "weights"]
    return gltf, anim.samplers[channel.sampler]


@pytest.fixture(scope="module")
def saved_animation(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, int]:
    """Two keys, at 0 s and 1.5 s; returns the saved file and its shape count."""
    model = workbench.load_sample("head")
    model.key_expression(0.0, "jawOpen")
    model.key_expression(1.5, "mouthSmileLeft")
    saved = tmp_path_factory.mktemp("cli") / "anim.fwb"
    model.save(saved)
    return saved, len(model.shapes)


def _export(saved: Path, out: Path, *extra: str) -> None:
    r = subprocess.run(
        [sys.executable, "-m", "workbench.cli", "export", str(saved), str(out), *extra],
        capture_output=True, text=True, check=False,
    )
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == str(out) and out.is_file()


def test_export_command_writes_the_keys_of_a_glb(saved_animation, tmp_path: Path) -> None:
    saved, k = saved_animation
    out = tmp_path / "anim.glb"
    _export(saved, out, "--fps", "24")
    assert out.read_bytes()[:4] == b"glTF"
    gltf, sampler = _weight_sampler(out)
    # not baked: the two keys themselves (Bézier -> CUBICSPLINE: in-tangent, value, out-tangent)
    assert sampler.interpolation == "CUBICSPLINE"
    np.testing.assert_allclose(_accessor_floats(gltf, sampler.input), [0.0, 1.5])
    assert gltf.accessors[sampler.output].count == 3 * 2 * k


@pytest.mark.parametrize(("fps", "frames"), [(24, 37), (10, 16)])  # 1.5 s * fps + 1
def test_export_bake_writes_one_sample_per_frame(saved_animation, tmp_path: Path, fps: int, frames: int) -> None:
    saved, k = saved_animation
    out = tmp_path / "baked.glb"
    _export(saved, out, "--fps", str(fps), "--bake")
    gltf, sampler = _weight_sampler(out)
    assert sampler.interpolation == "LINEAR"
    times = _accessor_floats(gltf, sampler.input)
    np.testing.assert_allclose(times, np.arange(frames) / fps, atol=1e-6)
    assert gltf.accessors[sampler.output].count == frames * k
    # the CSV is per frame as well, one row per frame at the same times
    csv_out = tmp_path / "anim.csv"
    _export(saved, csv_out, "--fps", str(fps))
    with open(csv_out, newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    assert len(rows[0]) == 1 + k and len(rows) == 1 + frames
    np.testing.assert_allclose([float(r[0]) for r in rows[1:]], np.arange(frames) / fps, atol=1e-9)
    jaw = rows[0].index("jawOpen")
    assert float(rows[1][jaw]) == pytest.approx(1.0) and float(rows[-1][jaw]) == pytest.approx(0.0)


def test_cli_errors_name_the_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "broken.obj"
    bad.write_text("v 0 0 0\nv 1 0 0\nf 1 2 9\n")
    assert main(["info", str(bad)]) == 2
    assert "broken.obj" in capsys.readouterr().err



def test_export_of_a_rig_without_keys_writes_the_rig_and_says_so(tmp_path, capsys):
    import pygltflib

    model = workbench.load_sample("head")
    model.set_weights({"jawOpen": 0.25, "mouthSmileLeft": 0.5})
    saved = tmp_path / "nokeys.fwb"
    model.save(saved)
    out = tmp_path / "x.glb"
    assert main(["export", str(saved), str(out)]) == 0
    err = capsys.readouterr().err
    assert "no keys" in err and "no animation" in err
    gltf = pygltflib.GLTF2().load(str(out))
    assert not gltf.animations
    mesh = gltf.meshes[0]
    names = mesh.extras["targetNames"]
    weights = dict(zip(names, mesh.weights, strict=True))
    assert weights["jawOpen"] == 0.25 and weights["mouthSmileLeft"] == 0.5 and len(names) >= 52


def test_app_command_binds_localhost_with_a_token(tmp_path):
    from workbench.cli import app_command

    cmd = app_command(9001)
    assert cmd[1:3] == ["-m", "voila"] and cmd[3].endswith("notebooks/workbench.ipynb")
    assert "--Voila.ip=127.0.0.1" in cmd and "--port=9001" in cmd and "--token" in cmd
    assert "--token" not in app_command(9001, token=False)
    with pytest.raises(ValueError, match=r"missing\.ipynb: no such notebook"):
        app_command(9001, notebook=tmp_path / "missing.ipynb")


def test_app_reports_a_missing_notebook(tmp_path, capsys):
    import importlib.util

    if importlib.util.find_spec("voila") is None:
        assert main(["app", "--notebook", str(tmp_path / "x.ipynb")]) == 2
        assert "Voila is not installed" in capsys.readouterr().err
    else:
        assert main(["app", "--notebook", str(tmp_path / "x.ipynb")]) == 2
        assert "x.ipynb: no such notebook" in capsys.readouterr().err


def test_fbx_export_without_blender_says_what_is_missing(tmp_path, capsys, monkeypatch) -> None:
    monkeypatch.setenv("WORKBENCH_BPY_PYTHON", str(tmp_path / "no-such-python"))
    model = workbench.load_sample("head")
    model.key_expression(0.0, "jawOpen")
    saved = tmp_path / "anim.fwb"
    model.save(saved)
    for suffix in (".fbx", ".abc"):
        out = tmp_path / f"anim{suffix}"
        assert main(["export", str(saved), str(out)]) == 2
        err = capsys.readouterr().err
        assert f"anim{suffix}" in err and "no Python with bpy" in err and "WORKBENCH_BPY_PYTHON" in err
        assert not out.exists() and list(tmp_path.glob(".anim*")) == []  # nothing half-written
