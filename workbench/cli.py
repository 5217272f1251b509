"""Command line: ``workbench info PATH``, ``export``, ``rig``, ``clone``, ``app``, ``batch``.

``info`` prints what a new user wants to know before opening a face: vertex,
triangle and polygon counts, the connected components (eyes, teeth...), the
blendshapes with their ARKit-52 mapping, and units/axes. ``export`` writes the
animation of a saved ``.fwb`` file. ``rig`` gives a face mesh the template's
blendshapes (:mod:`workbench.rigging`: deformation transfer, optionally
refined from example poses) and saves the rig. ``app`` serves the workbench notebook as an
app without code cells (Voila, a separate process: the core never imports it),
on 127.0.0.1 with a token in the printed URL. ``batch`` runs a TOML job file of characters ×
takes × steps as Dask tasks (:mod:`workbench.batch`; the ``batch`` extra).
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import os
import sys
from collections.abc import Callable, Sequence
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
    p_rig = sub.add_parser(
        "rig",
        help="rig a face mesh: the template's blendshapes by deformation transfer, optionally refined from "
        "example poses (Li et al. 2010), saved as a .fwb",
    )
    p_rig.add_argument("target", help="the face to rig (.obj, .glb/.gltf, .fbx, .usd, .fwb...)")
    p_rig.add_argument("--template", default="head",
                       help="the template rig: a bundled sample name (default: head) or a path")
    p_rig.add_argument("--landmarks", default=None, metavar="PAIRS.CSV",
                       help="CSV with a header and two integer columns template_vertex,target_vertex "
                       "(three or more pairs fix the alignment)")
    p_rig.add_argument("--examples", default=None, metavar="DIR",
                       help="folder of example poses in the target's topology and units (.obj), with an optional "
                       "weights.json {file: {shape: value}} of rough weights; refines the transferred shapes")
    p_rig.add_argument("--iterations", type=int, default=10, help="refinement iterations (default 10)")
    p_rig.add_argument("--units", default=None, help="length unit of the target (default: stated or inferred)")
    p_rig.add_argument("--up", default=None, metavar="AXIS",
                       help="the target's up axis, e.g. +z (default: as the file states, else +y)")
    p_rig.add_argument("--front", default=None, metavar="AXIS",
                       help="the axis the target's face looks along, e.g. --front=-y (default: as stated, else +z)")
    p_rig.add_argument("--wrinkles", action="store_true",
                       help="also carry the template's wrinkle examples to the rig and fit its wrinkles")
    p_rig.add_argument("--out", required=True, help="the rig to write (.fwb)")
    p_clone = sub.add_parser(
        "clone",
        help="play an animated face (a point cache, an animated .glb/.fbx/.usd/.abc, a keyed .fwb) on another "
        "face of any topology and units (expression cloning, Noh & Neumann 2001)",
    )
    p_clone.add_argument("performance", help="the animation: a face file whose timeline plays it")
    p_clone.add_argument("target", help="the face to play it on (.obj, .glb/.gltf, .fbx, .usd, .fwb...)")
    p_clone.add_argument("--landmarks", default=None, metavar="PAIRS.CSV",
                         help="corresponding vertices: CSV with a header, rows performance_vertex,target_vertex")
    p_clone.add_argument("--out", required=True,
                         help="what to write: .fwb, or any export format (.abc, .pc2, .mdd, .glb, .usd...)")
    p_app = sub.add_parser("app", help="serve the workbench as an app without code cells (Voila, 127.0.0.1)")
    p_app.add_argument("--port", type=int, default=8866, help="port on 127.0.0.1 (default 8866; the next free one is used)")
    p_app.add_argument(
        "--no-token", action="store_true", help="serve without the access token (only for a machine of your own)"
    )
    p_app.add_argument("--notebook", default=None, help="notebook to serve (default: notebooks/workbench.ipynb)")
    p_batch = sub.add_parser(
        "batch",
        help="run a TOML job file (characters x takes x steps: track, transfer_rig, retime, enhance, clone, export) "
        "as Dask tasks on a local cluster or a scheduler (needs the batch extra)",
    )
    p_batch.add_argument("jobs", help="the job file (.toml); see workbench.batch.jobfile")
    p_batch.add_argument("--scheduler", default=None, metavar="ADDRESS",
                         help="a running Dask scheduler, e.g. tcp://host:8786 (default: a local cluster on 127.0.0.1)")
    p_batch.add_argument("--workers", type=int, default=None,
                         help="processes of the local cluster (default: one per CPU)")
    p_batch.add_argument("--no-dashboard", action="store_true", help="start the local cluster without its dashboard")
    args = parser.parse_args(argv)
    if args.command == "batch":
        return batch_command(args)
    if args.command == "app":
        return serve_app(args.port, token=not args.no_token, notebook=args.notebook)
    if args.command == "rig":
        return rig_command(args)
    if args.command == "clone":
        return clone_command(args)
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


class CommandError(Exception):
    """A user error in a command's inputs (printed, exit code 2)."""


def read_landmarks(path: str | Path, n_template: int, n_target: int) -> list[tuple[int, int]]:
    """``template_vertex,target_vertex`` pairs from a CSV with a header row (:func:`read_landmark_pairs`).

    Raises CommandError naming the file and line: missing file, no header, a
    row without two integers, a vertex id out of range.
    """
    from workbench.rigging.landmarks import read_landmark_pairs

    try:
        return read_landmark_pairs(path, n_template, n_target, what="--landmarks")
    except ValueError as exc:
        raise CommandError(str(exc)) from None


def read_examples(folder: str | Path, n_vertices: int) -> tuple[list[str], list[np.ndarray], list[dict[str, float]] | None]:
    """Example poses (``*.obj``, sorted by name) and their rough weights (``weights.json``) from ``folder``.

    Raises CommandError naming the file: no folder or no OBJ in it, a file that
    is not a mesh of ``n_vertices`` vertices, a weights.json that is not
    ``{file: {shape: number}}`` for exactly the example files.
    """
    import json

    from workbench.geometry.mesh_checks import MeshFormatError
    from workbench.io.obj import read_obj

    d = Path(folder)
    if not d.is_dir():
        raise CommandError(f"--examples {d}: no such folder")
    files = sorted(f for f in d.iterdir() if f.suffix.lower() == ".obj" and f.is_file())
    if not files:
        raise CommandError(f"--examples {d}: no .obj example poses in it")
    poses = []
    for f in files:
        try:
            v = np.asarray(read_obj(f).vertices, np.float64)
        except (OSError, ValueError, MeshFormatError) as exc:
            raise CommandError(f"--examples {f}: {exc}") from None
        if v.shape != (n_vertices, 3):
            raise CommandError(f"--examples {f}: {v.shape[0]} vertices, but the target has {n_vertices} "
                               "(examples must be in the target's topology)")
        poses.append(v)
    wfile = d / "weights.json"
    weights = None
    if wfile.is_file():
        try:
            raw = json.loads(wfile.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            raise CommandError(f"--examples {wfile}: not valid JSON ({exc})") from None
        if not isinstance(raw, dict):
            raise CommandError(f"--examples {wfile}: expected {{file: {{shape: value}}}}, got {type(raw).__name__}")
        names = [f.name for f in files]
        extra = sorted(set(raw) - set(names))
        missing = [n for n in names if n not in raw]
        if extra or missing:
            raise CommandError(f"--examples {wfile}: needs one entry per example file; "
                               + (f"no such example {extra}" if extra else f"missing {missing}"))
        weights = []
        for n in names:
            w = raw[n]
            if not isinstance(w, dict) or not all(isinstance(x, int | float) and not isinstance(x, bool)
                                                  for x in w.values()):
                raise CommandError(f"--examples {wfile}: {n!r}: expected {{shape: number}}, got {w!r}")
            weights.append({str(k): float(x) for k, x in w.items()})
    return [f.name for f in files], poses, weights


def rig_command(args: argparse.Namespace) -> int:
    """``workbench rig``: transfer (and refine) the template's shapes onto the target; see :mod:`workbench.rigging`."""
    from workbench.geometry.mesh_checks import MeshFormatError
    from workbench.io import load
    from workbench.rigging import RigTransfer, RigTransferError

    def say(msg: str) -> None:
        print(msg, flush=True)

    import re

    def progress(stage: str) -> Callable[[float, str], None]:
        last_kind = [""]
        last_f = [-1.0]

        def report(f: float, msg: str) -> None:
            # one line per step; repeated counters ("factored shape 7/52") at most every 10 %
            kind = re.sub(r"[\d.]+", "#", msg)
            if kind != last_kind[0] or f - last_f[0] >= 0.1 or f >= 1.0 > last_f[0]:
                last_kind[0], last_f[0] = kind, f
                say(f"{stage} {100 * f:3.0f}%  {msg}")
        return report

    try:
        if args.iterations < 1:
            raise CommandError(f"--iterations must be >= 1, got {args.iterations}")
        tpath = Path(args.target)
        if not tpath.exists():
            raise CommandError(f"TARGET {tpath}: no such file or folder")
        out = Path(args.out)
        if not out.parent.is_dir():
            raise CommandError(f"--out {out}: the folder {out.parent} does not exist")
        tpl = Path(args.template)
        if tpl.exists():
            try:
                template = load(tpl)
            except (OSError, ValueError, MeshFormatError) as exc:
                raise CommandError(f"--template {tpl}: {exc}") from None
        else:
            import workbench

            try:
                template = workbench.load_sample(args.template)
            except ValueError as exc:
                raise CommandError(f"--template {args.template}: not a file, and {exc}") from None
        try:
            target = load(tpath, units=args.units)
        except (OSError, ValueError, MeshFormatError) as exc:
            raise CommandError(f"TARGET {tpath}: {exc}") from None
        axes = {k: v for k, v in (("up_axis", args.up), ("front_axis", args.front)) if v is not None}
        if axes:
            try:
                target.set_metadata(dataclasses.replace(target.metadata, **axes), label="Axes from the command line")
            except ValueError as exc:
                raise CommandError(f"--up/--front: {exc}") from None
        say(f"template {args.template}: {template.n_vertices} vertices, {len(template.shapes)} shapes")
        say(f"target {tpath}: {target.n_vertices} vertices, units {target.metadata.units}")
        landmarks = None
        if args.landmarks is not None:
            landmarks = read_landmarks(args.landmarks, template.n_vertices, target.n_vertices)
            say(f"landmarks: {len(landmarks)} pairs")
        examples = None
        if args.examples is not None:
            names, poses, weights = read_examples(args.examples, target.n_vertices)
            if weights is not None:
                unknown = sorted({k for w in weights for k in w} - set(template.shape_names))
                if unknown:
                    raise CommandError(f"--examples {Path(args.examples) / 'weights.json'}: unknown shapes "
                                       f"{unknown[:5]}; the template has e.g. {list(template.shape_names[:5])}")
            examples = (names, poses, weights)
            say(f"examples: {len(poses)} poses" + (" with rough weights" if weights else ""))
        try:
            transfer = RigTransfer(template, target, landmarks=landmarks, progress=progress("transfer"))
            result = transfer.run()
        except RigTransferError as exc:
            raise CommandError(f"TARGET {tpath}: {exc}") from None
        rig = result.model
        if examples is not None:
            from workbench.rigging import refine_rig

            names, poses, weights = examples
            try:
                refined = refine_rig(rig, poses, weights, iterations=args.iterations, progress=progress("refine"))
            except ValueError as exc:
                raise CommandError(f"--examples {args.examples}: {exc}") from None
            rig = refined.model
            for j, n in enumerate(names):
                say(f"  example {n}: RMS error {refined.initial_errors[j]:.4g} -> {refined.errors[j, -1]:.4g} "
                    f"{rig.metadata.units}")
        if args.wrinkles:
            from workbench.rigging import transfer_details

            say("wrinkles: carrying the template's examples")
            try:
                facet = transfer_details(template, rig, transfer)
            except ValueError as exc:
                raise CommandError(f"--wrinkles: {exc}") from None
            say(f"wrinkles: fitted {len(facet.example_names)} examples")
        say(result.report.summary())
        worst = sorted(result.report.shapes, key=lambda q: q.max_stretch, reverse=True)[:5]
        if worst:
            say("  worst shapes: " + ", ".join(
                f"{q.name} (stretch {q.max_stretch:.2f}, template {q.source_max_stretch:.2f})" for q in worst))
        try:
            rig.save(out)
        except OSError as exc:
            raise CommandError(f"--out {out}: {exc}") from None
    except CommandError as exc:
        print(f"workbench rig: {exc}", file=sys.stderr)
        return 2
    say(f"saved {out}")
    return 0


def batch_command(args: argparse.Namespace) -> int:
    """``workbench batch``: check the job file (exit 2 naming line and field), run it, print the summary.

    Exit code 0 when every task is done or skipped, 1 when one failed or was blocked.
    """
    from workbench.batch import JobFileError, load_jobs

    try:
        jobs = load_jobs(args.jobs)
        if args.workers is not None and args.workers < 1:
            raise CommandError(f"--workers must be >= 1, got {args.workers}")
    except (JobFileError, CommandError) as exc:
        print(f"workbench batch: {exc}", file=sys.stderr)
        return 2
    if importlib.util.find_spec("distributed") is None:
        print("workbench batch: needs Dask: pip install 'face-workbench[batch]'", file=sys.stderr)
        return 2
    from workbench.batch import run

    report = run(jobs, scheduler=args.scheduler, workers=args.workers, dashboard=not args.no_dashboard)
    return 0 if report.ok else 1


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


def default_app_notebook() -> Path:
    """The workbench notebook ``workbench app`` serves by default.

    A checkout's ``notebooks/workbench.ipynb``; in an installed wheel, the copy the wheel
    carries (``workbench/_app/workbench.ipynb``, put there by the wheel build).
    """
    here = Path(__file__).resolve().parent
    checkout = here.parent / "notebooks" / "workbench.ipynb"
    return checkout if checkout.is_file() else here / "_app" / "workbench.ipynb"


def app_command(port: int, *, token: bool = True, notebook: str | Path | None = None) -> list[str]:
    """The Voila command line that serves ``notebook`` on 127.0.0.1:``port`` (sources hidden).

    Raises ValueError naming the notebook when it does not exist.
    """
    nb = Path(notebook) if notebook is not None else default_app_notebook()
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


def clone_command(args: argparse.Namespace) -> int:
    """``workbench clone PERFORMANCE TARGET --out OUT``: the performance's frames played on the target."""
    from workbench.animation.curves import TrackError
    from workbench.export import ExportError, export
    from workbench.io import load
    from workbench.rigging import ExpressionCloner, RigTransferError

    try:
        paths = {"PERFORMANCE": Path(args.performance), "TARGET": Path(args.target)}
        for what, path in paths.items():
            if not path.exists():
                raise CommandError(f"{what} {path}: no such file or folder")
        out = Path(args.out)
        if not out.parent.is_dir():
            raise CommandError(f"--out {out}: the folder {out.parent} does not exist")
        try:
            perf = load(paths["PERFORMANCE"])
        except (OSError, ValueError) as exc:
            raise CommandError(f"PERFORMANCE {paths['PERFORMANCE']}: {exc}") from None
        timeline = perf.tracks
        if not timeline.tracks:
            raise CommandError(f"PERFORMANCE {paths['PERFORMANCE']}: its timeline has no keys: nothing to clone")
        try:
            target = load(paths["TARGET"])
        except (OSError, ValueError) as exc:
            raise CommandError(f"TARGET {paths['TARGET']}: {exc}") from None
        landmarks = (read_landmarks(args.landmarks, perf.n_vertices, target.n_vertices)
                     if args.landmarks else None)
        times = timeline.frame_times()
        frames = np.stack([perf.evaluate_at(float(t)) for t in times])
        cloner = ExpressionCloner(perf, target, landmarks=landmarks)
        face = cloner.clone_face(frames, times, fps=timeline.fps)
        if out.suffix.lower() == ".fwb":
            face.save(out)
            written = [out]
        else:
            written = list(export(face, face.tracks, out))
    except CommandError as exc:
        print(f"workbench clone: {exc}", file=sys.stderr)
        return 2
    except (OSError, ValueError, RigTransferError, ExportError, TrackError) as exc:
        print(f"workbench clone: {exc}", file=sys.stderr)
        return 2
    for w in cloner.transfer_.warnings:
        print(f"workbench clone: warning: {w}", file=sys.stderr)
    for p in written:
        print(p)
    return 0
