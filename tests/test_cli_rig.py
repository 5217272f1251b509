"""``workbench rig``: transfer (and refine) the template's shapes onto a mesh from the command line.

The target is the sample head re-triangulated and warped into centimetres
(:mod:`workbench.rigging.synthetic`), written as an OBJ with one group per
part; its true shapes are known, so example poses for ``--examples`` are too.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import workbench
from workbench.cli import main
from workbench.model import FaceModel
from workbench.rigging import TransferReport
from workbench.rigging import synthetic as syn

WARP = syn.sample_head_warp()


def _write_obj(path: Path, V: np.ndarray, F: np.ndarray, labels: np.ndarray, names: list[str]) -> None:
    lines = [f"v {x:.7f} {y:.7f} {z:.7f}" for x, y, z in V]
    face_label = labels[F[:, 0]]
    for c, name in enumerate(names):
        rows = F[face_label == c]
        if len(rows):
            lines.append(f"g {name}")
            lines += [f"f {a + 1} {b + 1} {d + 1}" for a, b, d in rows]
    path.write_text("\n".join(lines) + "\n")


def _write_points(path: Path, V: np.ndarray, F: np.ndarray) -> None:
    lines = [f"v {x:.7f} {y:.7f} {z:.7f}" for x, y, z in V] + [f"f {a + 1} {b + 1} {d + 1}" for a, b, d in F]
    path.write_text("\n".join(lines) + "\n")


class Synthetic:
    def __init__(self, head: FaceModel, folder: Path) -> None:
        V2, F2, W = syn.split_remesh(head.vertices, head.faces, seed=1)
        self.labels = head.component_labels[np.asarray(W.argmax(axis=1)).ravel()]
        self.head, self.points, self.W, self.faces = head, V2, W, F2
        self.V = WARP(V2)
        self.path = folder / "actor.obj"
        _write_obj(self.path, self.V, F2, self.labels, list(head.component_names))

    def pose(self, weights: dict[str, float]) -> np.ndarray:
        d = sum(w * self.head.shapes[self.head.shape_names.index(n)].delta.astype(np.float64)
                for n, w in weights.items())
        return WARP(self.points + self.W @ d)


@pytest.fixture(scope="module")
def actor(tmp_path_factory: pytest.TempPathFactory) -> Synthetic:
    return Synthetic(workbench.load_sample("head"), tmp_path_factory.mktemp("actor"))


def test_rig_an_obj_with_landmarks_and_examples(actor: Synthetic, tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    # landmarks: template vertices and the target vertex nearest each (the remesh keeps none in place)
    tv = [int(np.argmax(actor.W[:, v].toarray())) for v in (100, 900, 2000, 3000)]
    (tmp_path / "pairs.csv").write_text("template_vertex,target_vertex\n"
                                        + "".join(f"{a},{b}\n" for a, b in zip((100, 900, 2000, 3000), tv,
                                                                              strict=True)))
    ex = tmp_path / "examples"
    ex.mkdir()
    poses = {"jaw.obj": {"jawOpen": 1.0}, "smile.obj": {"mouthSmileLeft": 1.0, "mouthSmileRight": 1.0}}
    for name, w in poses.items():
        _write_points(ex / name, actor.pose(w), actor.faces)
    (ex / "weights.json").write_text(json.dumps({k: {n: 0.8 * x for n, x in w.items()} for k, w in poses.items()}))
    out = tmp_path / "rig.fwb"
    code = main(["rig", str(actor.path), "--template", "head", "--landmarks", str(tmp_path / "pairs.csv"),
                 "--examples", str(ex), "--iterations", "2", "--out", str(out)])
    cap = capsys.readouterr()
    assert code == 0, cap.err
    text = cap.out
    assert "transfer" in text and "non-rigid fit" in text and "refine" in text  # progress lines
    assert "landmarks: 4 pairs" in text and "examples: 2 poses with rough weights" in text
    assert "worst stretch" in text and "worst shapes:" in text
    assert f"saved {out}" in text
    rig = workbench.load(out)
    assert rig.n_vertices == len(actor.V)
    assert set(actor.head.shape_names) <= set(rig.shape_names)
    report = TransferReport.from_model(rig)
    assert report.landmarks == tuple(zip((100, 900, 2000, 3000), tv, strict=True))
    # the refined jawOpen reproduces its example closely (cm; the head is ~25 cm)
    jaw = rig.shapes[rig.shape_names.index("jawOpen")].delta
    truth = actor.pose({"jawOpen": 1.0}) - actor.V
    skin = actor.labels == 0
    err = np.sqrt(((jaw[skin] - truth[skin]) ** 2).sum(1).mean()) / np.abs(truth[skin]).max()
    assert err < 0.05, err
    assert not list(tmp_path.glob("*.tmp*"))  # atomic save leaves nothing behind


def test_rig_with_wrinkles_and_a_path_template(actor: Synthetic, tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    tpl = tmp_path / "template.fwb"
    actor.head.save(tpl)
    out = tmp_path / "rig.fwb"
    assert main(["rig", str(actor.path), "--template", str(tpl), "--wrinkles", "--out", str(out)]) == 0
    assert "wrinkles: fitted 6 examples" in capsys.readouterr().out
    rig = workbench.load(out)
    assert rig.wrinkles.fitted and rig.wrinkles.fresh


@pytest.mark.parametrize(
    ("csv_text", "message"),
    [
        ("1,2\n3,4\n", "line 1: expected a header row"),
        ("template_vertex,target_vertex\n1,2\n3\n", "line 3: expected two integer vertex ids"),
        ("template_vertex,target_vertex\n1,x\n", "line 2: expected two integer vertex ids"),
        ("template_vertex,target_vertex\n99999,2\n", "line 2: template vertex 99999 out of range"),
        ("template_vertex,target_vertex\n1,999999\n", "line 2: target vertex 999999 out of range"),
        ("template_vertex,target_vertex\n", "no pairs after the header"),
    ],
)
def test_bad_landmarks_name_the_file_and_line(actor: Synthetic, tmp_path: Path, capsys, csv_text: str,
                                              message: str) -> None:
    pairs = tmp_path / "pairs.csv"
    pairs.write_text(csv_text)
    out = tmp_path / "rig.fwb"
    assert main(["rig", str(actor.path), "--landmarks", str(pairs), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"--landmarks {pairs}" in err and message in err
    assert not out.exists()


def test_input_errors_exit_2_naming_the_argument(actor: Synthetic, tmp_path: Path, capsys) -> None:
    out = str(tmp_path / "rig.fwb")
    assert main(["rig", str(tmp_path / "nobody.obj"), "--out", out]) == 2
    assert "TARGET" in (err := capsys.readouterr().err) and "nobody.obj: no such file" in err
    assert main(["rig", str(actor.path), "--template", "robot", "--out", out]) == 2
    assert "--template robot" in capsys.readouterr().err
    assert main(["rig", str(actor.path), "--landmarks", str(tmp_path / "none.csv"), "--out", out]) == 2
    assert f"--landmarks {tmp_path / 'none.csv'}: no such file" in capsys.readouterr().err
    # an example with the template's vertex count, not the target's
    ex = tmp_path / "ex"
    ex.mkdir()
    _write_points(ex / "pose.obj", actor.head.vertices, actor.head.faces)
    assert main(["rig", str(actor.path), "--examples", str(ex), "--out", out]) == 2
    err = capsys.readouterr().err
    assert f"--examples {ex / 'pose.obj'}: {actor.head.n_vertices} vertices, but the target has {len(actor.V)}" in err
    # weights.json for a file that is not there
    (ex / "pose.obj").unlink()
    _write_points(ex / "pose.obj", actor.V, actor.faces)
    (ex / "weights.json").write_text(json.dumps({"other.obj": {"jawOpen": 1.0}}))
    assert main(["rig", str(actor.path), "--examples", str(ex), "--out", out]) == 2
    assert "weights.json: needs one entry per example file" in capsys.readouterr().err
    (ex / "weights.json").write_text(json.dumps({"pose.obj": {"noSuchShape": 1.0}}))
    assert main(["rig", str(actor.path), "--examples", str(ex), "--out", out]) == 2
    assert "unknown shapes ['noSuchShape']" in capsys.readouterr().err
    assert not Path(out).exists()


def test_a_target_that_is_not_a_face_exits_2(tmp_path: Path, capsys) -> None:
    import trimesh

    s = trimesh.creation.icosphere(subdivisions=3, radius=10.0)
    path = tmp_path / "ball.obj"
    _write_points(path, np.asarray(s.vertices), np.asarray(s.faces))
    assert main(["rig", str(path), "--out", str(tmp_path / "rig.fwb")]) == 2
    assert f"TARGET {path}:" in capsys.readouterr().err


def test_a_z_up_target_rigs_with_up_and_front(actor: Synthetic, tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    # the same face lying in a Z-up file facing -y (Blender's convention): (x, y, z) -> (x, -z, y)
    zup = tmp_path / "zup.obj"
    V = np.c_[actor.V[:, 0], -actor.V[:, 2], actor.V[:, 1]]
    _write_obj(zup, V, actor.faces, actor.labels, list(actor.head.component_names))
    out = tmp_path / "rig.fwb"
    assert main(["rig", str(zup), "--units", "cm", "--up=+z", "--front=-y", "--out", str(out)]) == 0
    rig = workbench.load(out)
    assert (rig.metadata.up_axis, rig.metadata.front_axis) == ("+z", "-y")
    # jawOpen against the truth, turned the same way
    d = rig.shapes[rig.shape_names.index("jawOpen")].delta.astype(np.float64)
    t = actor.pose({"jawOpen": 1.0}) - actor.V
    t = np.c_[t[:, 0], -t[:, 2], t[:, 1]]
    skin = actor.labels == 0
    err = np.linalg.norm(d - t, axis=1)[skin]
    assert np.sqrt((err**2).mean()) < 0.05 * np.linalg.norm(t[skin], axis=1).max()
    assert main(["rig", str(zup), "--up", "+q", "--out", str(out)]) == 2
    assert "--up/--front" in capsys.readouterr().err
