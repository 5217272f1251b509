"""Command line: ``workbench info PATH``, ``workbench export``, ``workbench app``.

``info`` prints what a new user wants to know before opening a face: vertex,
triangle and polygon counts, the connected components (eyes, teeth...), the
blendshapes with their ARKit-52 mapping, and units/axes. ``export`` writes the
animation of a saved ``.fwb`` file. ``app`` serves the workbench notebook as an
app without code cells (Voila, a separate process: the core never imports it),
on 127.0.0.1 with a token in the printed URL.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from workbench.model import FaceModel


def format_info(model: FaceModel, path: str) -> str:
    """A human-readable summary of ``model`` (loaded from ``path``)."""
    md = model.metadata
    lines = [
        f"{path}",
        f"  name        {md.name or '-'}",
        f"  vertices    {model.n_vertices}",
        f"  triangles   {len(model.faces)}",
        f"  polygons    {len(model.polygons)} "
        f"(sizes: {', '.join(f'{int(k)}-gon x{int(c)}' for k, c in zip(*np.unique(model.polygons.sizes, return_counts=True), strict=True))})",
        f"  units       {md.units} ({md.metres_per_unit:g} m per unit), up {md.up_axis}, front {md.front_axis}",
    ]
    # how the unit was decided on import (workbench.io.units): given, stated by the format, inferred
    units_entry = next((p for p in md.provenance if p.get("operation") == "units"), None)
    if units_entry is not None:
        lines.append(f"  units from  {units_entry.get('how', '?')}: {units_entry.get('detail', '')}")
    bb = model.vertices.max(0) - model.vertices.min(0)
    size = f"  size        {bb[0]:.4g} x {bb[1]:.4g} x {bb[2]:.4g} {md.units}"
    if md.units != "m":
        m = bb * md.metres_per_unit
        size += f" ({m[0]:.3g} x {m[1]:.3g} x {m[2]:.3g} m)"
    lines.append(size)
    counts = np.bincount(model.component_labels, minlength=len(model.component_names))
    lines.append(f"  components  {len(model.component_names)}")
    for name, c in zip(model.component_names, counts, strict=True):
        lines.append(f"    {name:<20} {int(c):>8} vertices")
    arkit = model.arkit_names
    n_arkit = sum(v is not None for v in arkit.values())
    lines.append(f"  shapes      {len(model.shapes)} ({n_arkit} mapped to ARKit-52)")
    for s in model.shapes:
        moved = int(np.count_nonzero(np.abs(s.delta).max(axis=1) > 0))
        mapped = arkit[s.name]
        tag = "" if mapped is None else ("  = ARKit" if mapped == s.name else f"  -> ARKit {mapped}")
        extra = " muted" if s.mute else ""
        lines.append(
            f"    {s.name:<22} range [{s.slider_min:g}, {s.slider_max:g}]  "
            f"moves {moved} vertices{extra}{tag}"
        )
    for p in md.provenance:
        if p is units_entry:
            continue  # shown under units
        lines.append("  provenance  " + ", ".join(f"{k}={v}" for k, v in p.items()))
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="workbench", description="Facial Editing Workbench")
    sub = parser.add_subparsers(dest="command", required=True)
    p_info = sub.add_parser("info", help="summarise a face file (.fwb, .glb/.gltf, OBJ folder, .obj + targets)")
    p_info.add_argument("path")
    p_exp = sub.add_parser(
        "export",
        help="export the animation of a saved workbench file (.glb/.gltf, .usd/.usda/.usdc, .pc2, .mdd, .obj sequence, .csv; .fbx/.abc through Blender)",
    )
    p_exp.add_argument("saved_file", help="a .fwb workbench file with keys on its timeline")
    p_exp.add_argument("out", help="output path; the suffix picks the format")
    p_exp.add_argument("--fps", type=float, default=None, help="frame rate for baked/per-frame formats (default: the timeline's)")
    p_exp.add_argument("--bake", action="store_true", help="write per-frame points instead of blend shapes + weights")
    p_exp.add_argument("--format", default=None, help="override the format chosen from the suffix")
    p_exp.add_argument(
        "--style",
        choices=("plain", "livelink"),
        default=None,
        help="CSV layout: plain (time + one column per shape, the default) or livelink (Epic's Live Link "
        "Face CSV for Unreal/MetaHuman: the 52 ARKit columns + head rotation; a whole fps, 30 or 60 for Unreal)",
    )
    p_app = sub.add_parser("app", help="serve the workbench as an app without code cells (Voila, 127.0.0.1)")
    p_app.add_argument("--port", type=int, default=8866, help="port on 127.0.0.1 (default 8866; the next free one is used)")
    p_app.add_argument(
        "--no-token", action="store_true", help="serve without the access token (only for a machine of your own)"
    )
    p_app.add_argument("--notebook", default=None, help="notebook to serve (default: notebooks/workbench.ipynb)")
    args = parser.parse_args(argv)
    if args.command == "app":
        return serve_app(args.port, token=not args.no_token, notebook=args.notebook)
    if args.command == "info" and Path(args.path).suffix.lower() == ".c3d":
        return _markers_info(args.path)  # markers, not a face
    if args.command == "info":
        from workbench.io import load

        try:
            model = load(args.path)
        except (OSError, ValueError) as exc:
            print(f"workbench info: {exc}", file=sys.stderr)
            return 2
        print(format_info(model, args.path))
        return 0
    if args.command == "export":
        from workbench.animation.curves import TrackError
        from workbench.export import ExportError, export
        from workbench.io import load

        try:
            model = load(args.saved_file)
            if not model.tracks.tracks:
                print(
                    f"workbench export: {args.saved_file}: the timeline has no keys; writing the rig "
                    "with its current weights and no animation",
                    file=sys.stderr,
                )
            options = {}
            if args.style is not None:
                from workbench.export import format_for_path

                if format_for_path(args.out, args.format).name != "csv":
                    raise ExportError(f"--style {args.style} is a CSV layout; {args.out} is not a .csv")
                options["style"] = args.style
            written = export(
                model, model.tracks, args.out, fps=args.fps, bake=args.bake, format=args.format, **options
            )
            for note in getattr(written, "notes", ()):
                print(f"workbench export: note: {note}", file=sys.stderr)
        except (OSError, ValueError, ExportError, TrackError) as exc:
            print(f"workbench export: {exc}", file=sys.stderr)
            return 2
        for p in written:
            print(p)
        return 0
    return 1  # pragma: no cover - argparse rejects unknown commands


def _markers_info(path: str) -> int:
    """``workbench info`` for a C3D marker file (:func:`workbench.io.c3d.read_markers`)."""
    from workbench.io.c3d import read_markers

    try:
        m = read_markers(path)
    except (OSError, ValueError) as exc:
        print(f"workbench info: {exc}", file=sys.stderr)
        return 2
    gaps = m.gaps
    print(f"{path}\n  markers     {m.n_markers} (C3D, units {m.units}, read as metres)\n"
          f"  frames      {m.n_frames} at {m.fps:g} fps from frame {m.first_frame} ({m.n_frames / m.fps:.3g} s)\n"
          f"  gaps        {int(gaps.sum())} marker-frames missing")
    for j, name in enumerate(m.names):
        print(f"    {name:<20} missing in {int(gaps[:, j].sum())} frames")
    return 0


def app_command(port: int, *, token: bool = True, notebook: str | Path | None = None) -> list[str]:
    """The Voila command line that serves ``notebook`` on 127.0.0.1:``port`` (sources hidden).

    Raises ValueError naming the notebook when it does not exist.
    """
    nb = Path(notebook) if notebook is not None else Path(__file__).resolve().parents[1] / "notebooks" / "workbench.ipynb"
    if not nb.is_file():
        raise ValueError(f"{nb}: no such notebook (expected the workbench notebook, notebooks/workbench.ipynb)")
    cmd = [
        sys.executable, "-m", "voila", str(nb),
        "--Voila.ip=127.0.0.1", f"--port={int(port)}", "--no-browser",
        "--strip_sources=True", "--show_tracebacks=True",
    ]
    if token:
        cmd.append("--token")
    return cmd


def serve_app(port: int, *, token: bool = True, notebook: str | Path | None = None) -> int:
    """Replace this process by Voila (Ctrl-C or SIGTERM stops it and its kernel).

    ``exec`` rather than a child process: whoever stops ``workbench app`` by its
    PID stops the server itself, never leaving an orphaned Voila behind.
    Returns 2 with a message when it cannot start.
    """
    if importlib.util.find_spec("voila") is None:
        print("workbench app: Voila is not installed; run `bash .ci/workbench run` once, "
              "or pip install -e '.[ui]'", file=sys.stderr)
        return 2
    try:
        cmd = app_command(port, token=token, notebook=notebook)
    except ValueError as exc:
        print(f"workbench app: {exc}", file=sys.stderr)
        return 2
    env = dict(os.environ)
    env.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    sys.stdout.flush()
    sys.stderr.flush()
    os.execve(cmd[0], cmd, env)
    return 0  # pragma: no cover - execve does not return


if __name__ == "__main__":
    sys.exit(main())
