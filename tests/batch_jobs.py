"""Projects the batch tests and the benchmark run: rigs, weight-CSV takes and job files on disk."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from workbench import load_sample
from workbench.animation.tracks import Timeline
from workbench.export import export
from workbench.model import FaceModel

#: shapes the generated takes key (ARKit names of the sample head)
TAKE_SHAPES = ("jawOpen", "eyeBlinkLeft", "eyeBlinkRight", "mouthSmileLeft", "mouthSmileRight", "browInnerUp")


def take_timeline(seed: int, seconds: float = 1.0, fps: float = 30.0) -> Timeline:
    """A few linear keys on :data:`TAKE_SHAPES`, different per ``seed``."""
    rng = np.random.default_rng(seed)
    tl = Timeline(fps=fps, start=0.0, end=seconds)
    for name in TAKE_SHAPES:
        for t in np.linspace(0.0, seconds, 5):
            tl = tl.add_key(f"weights/{name}", float(t), float(rng.uniform(0, 1)), interpolation="linear")
    return tl


def write_take(model: FaceModel, path: Path, seed: int, seconds: float = 1.0) -> Path:
    """A plain weight CSV (what ``workbench export`` writes; re-importable) of :func:`take_timeline`."""
    export(model, take_timeline(seed, seconds), path)
    return path


def small_head() -> FaceModel:
    """The base sample head (~5k vertices, 52 shapes)."""
    return load_sample("head")


def make_project(root: Path, *, characters: int = 2, takes: int = 3, formats: tuple[str, ...] = ("glb", "usdc"),
                 extra_steps: str = "", resolution: str = "base", seconds: float = 1.0) -> Path:
    """Write rigs, takes and ``jobs.toml`` under ``root``; returns the job file.

    The characters are the sample head (at ``resolution``) under different names (distinct files:
    distinct content addresses).
    """
    root.mkdir(parents=True, exist_ok=True)
    head = load_sample("head", resolution=resolution)
    lines = ['output = "out"', ""]
    for c in range(characters):
        rig = root / f"char{c}.fwb"
        m = load_sample("head", resolution=resolution)
        m.set_metadata(dataclasses.replace(m.metadata, name=f"char{c}"), label="name")  # distinct files
        m.save(rig)
        lines += ["[[characters]]", f'name = "char{c}"', f'rig = "{rig.name}"', ""]
    for t in range(takes):
        write_take(head, root / f"take{t}.csv", seed=t, seconds=seconds)
        lines += ["[[takes]]", f'name = "take{t}"', f'path = "take{t}.csv"', ""]
    lines += ["[[steps]]", 'kind = "export"', "formats = [" + ", ".join(f'"{f}"' for f in formats) + "]", ""]
    if extra_steps:
        lines.append(extra_steps)
    job = root / "jobs.toml"
    job.write_text("\n".join(lines))
    return job


def write_marker_take(model: FaceModel, path: Path, map_path: Path, seed: int, frames: int = 30,
                      fps: float = 30.0) -> Path:
    """A marker CSV in mm (the flat layout) and its ``marker -> vertex`` JSON, as in notebooks/capture.ipynb."""
    import json

    from workbench.capture import synthetic_performance
    from workbench.capture.inputs import metres_per_unit

    mm = 1000 * metres_per_unit(model.metadata.units)
    take = synthetic_performance(model, frames, fps=fps, seed=seed, markers=60, noise=0.2 / mm)
    names = [f"M{j + 1:02d}" for j in range(take.markers.shape[1])]
    with open(path, "w") as f:
        f.write(f"# units: mm\n# fps: {fps:g}\n")
        f.write(",".join(["frame", "time"] + [f"{m}_{a}" for m in names for a in "xyz"]) + "\n")
        for i, row in enumerate(take.markers.reshape(frames, -1) * mm):
            cells = ["" if np.isnan(v) else f"{v:.3f}" for v in row]
            f.write(f"{i + 1},{i / fps:.4f}," + ",".join(cells) + "\n")
    map_path.write_text(json.dumps({m: int(v) for m, v in zip(names, take.marker_ids, strict=True)}))
    return path
