"""The fitted wrinkles are part of the ``.fwb`` file (the ``wrinkles`` family's file part)."""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np
import pytest

import workbench
from workbench.fileformat import WorkbenchFileError
from workbench.methods.wrinkles.family import fit_sample_wrinkles


@pytest.fixture(scope="module")
def fitted() -> workbench.FaceModel:
    m = workbench.load_sample("head")
    fit_sample_wrinkles(m)
    m.wrinkles.edit_example("brow_raise", scale=1.5)
    m.wrinkles.set_strength(0.8)
    m.move_handle(m.handles.names.index("brows_L_2"), [0.0, 0.05, 0.0])
    return m


def test_wrinkles_survive_save_and_load(fitted: workbench.FaceModel, tmp_path: Path) -> None:
    path = tmp_path / "wrinkled.fwb"
    fitted.save(path)
    back = workbench.load(path)
    assert back.wrinkles.fitted and back.wrinkles.strength == 0.8
    assert back.wrinkles.example_names == fitted.wrinkles.example_names
    np.testing.assert_array_equal(back.wrinkles.pose_space.train_values, fitted.wrinkles.pose_space.train_values)
    d = fitted.wrinkles.details()
    assert d is not None and np.abs(d).max() > 1e-4  # the brow drag really wrinkles
    np.testing.assert_allclose(back.wrinkles.details(), d, rtol=0, atol=1e-6)
    np.testing.assert_allclose(back.evaluate(), fitted.evaluate(), rtol=0, atol=1e-6)


def test_a_model_without_wrinkles_writes_null(tmp_path: Path) -> None:
    m = workbench.load_sample("head")
    m.save(tmp_path / "plain.fwb")
    with zipfile.ZipFile(tmp_path / "plain.fwb") as zf:
        assert json.loads(zf.read("manifest.json"))["wrinkles"] is None
    assert not workbench.load(tmp_path / "plain.fwb").wrinkles.fitted


def _rewrite(src: Path, dst: Path, edit) -> None:
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item)
            if item.filename == "manifest.json":
                manifest = json.loads(data)
                edit(manifest)
                data = json.dumps(manifest).encode()
            zout.writestr(item, data)


@pytest.mark.parametrize(
    ("edit", "field"),
    [
        (lambda m: m["wrinkles"].update(mode="cubic"), "wrinkles.mode"),
        (lambda m: m["wrinkles"].update(basis=[99]), "wrinkles.basis[0]"),
        (lambda m: m["wrinkles"]["examples"][0].update(name=""), "wrinkles.examples[0].name"),
        (lambda m: m["wrinkles"].pop("strength"), "wrinkles.strength"),
        (lambda m: m["arrays"].pop("wrinkles_train_values"), "arrays.wrinkles_train_values"),
    ],
)
def test_bad_wrinkle_fields_are_named(fitted: workbench.FaceModel, tmp_path: Path, edit, field: str) -> None:
    good = tmp_path / "good.fwb"
    fitted.save(good)
    bad = tmp_path / "bad.fwb"
    _rewrite(good, bad, edit)
    with pytest.raises(WorkbenchFileError, match=field.replace("[", r"\[").replace("]", r"\]")):
        workbench.load(bad)
