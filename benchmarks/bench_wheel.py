"""Benchmark: the wheel's size, its install time with and without extras, and import time.

Run: .venv/bin/python benchmarks/bench_wheel.py [--extras "" ui "ui,fast"] [--repeats 5] [--no-cache]

Builds the sdist and the wheel of this checkout (``python -m build --no-isolation``: the
wheel is made from the sdist, as ``python -m build`` does), then for each ``--extras``
entry creates a fresh venv in a temporary folder outside the repository and times
``pip install <wheel>[extras]`` in it (dependencies from the package index; pip's cache is
used unless ``--no-cache``, so the default measures a warm machine: unpacking and linking,
not downloading). In each venv, from a directory outside the repository with ``python -I``
(no source tree on ``sys.path``), it times ``import workbench`` (best of ``--repeats``
fresh interpreters, the bare interpreter's start subtracted), ``load_sample("head")``, the
first-use build of the 25k head from the wheel's own data, and, where the ``ui`` extra is
installed, ``import widgets`` and reading the viewport bundle. The checkout's own venv
(``sys.executable``) is measured the same way for comparison. Prints two tables.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

PROBE = """
import json, sys, time
t0 = time.perf_counter()
import workbench
t_import = time.perf_counter() - t0
out = {"import": t_import, "file": workbench.__file__, "version": workbench.__version__}
if "--full" in sys.argv:
    from workbench.samples import load_sample
    t0 = time.perf_counter(); load_sample("head"); out["load_base"] = time.perf_counter() - t0
    t0 = time.perf_counter(); load_sample("head", "25k"); out["build_25k"] = time.perf_counter() - t0
    try:
        t0 = time.perf_counter()
        import widgets
        from widgets.viewport.common import load_bundle
        out["bundle_bytes"] = len(load_bundle())
        out["import_widgets"] = time.perf_counter() - t0
    except ImportError as e:
        out["widgets"] = f"not importable: {e.name}"
print(json.dumps(out))
"""


def _mb(n: float) -> str:
    return f"{n / 1e6:.2f}"


def _du(path: Path) -> int:
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file() and not p.is_symlink())


def build(out: Path) -> tuple[Path, Path, float]:
    """Build sdist + wheel into ``out``; (wheel, sdist, seconds)."""
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "build", "--no-isolation", "--outdir", str(out), str(ROOT)],
                   check=True, capture_output=True)
    dt = time.perf_counter() - t0
    (whl,) = out.glob("*.whl")
    (sdist,) = out.glob("*.tar.gz")
    return whl, sdist, dt


def wheel_contents(whl: Path) -> dict[str, int]:
    """Compressed bytes in the wheel by part."""
    parts = {"front-end bundle (widgets/static)": 0, "sample head (workbench/_sample_models)": 0,
             "Python code and the rest": 0}
    with zipfile.ZipFile(whl) as zf:
        for i in zf.infolist():
            if i.filename.startswith("widgets/static/"):
                parts["front-end bundle (widgets/static)"] += i.compress_size
            elif i.filename.startswith("workbench/_sample_models/"):
                parts["sample head (workbench/_sample_models)"] += i.compress_size
            else:
                parts["Python code and the rest"] += i.compress_size
    return parts


def probe(python: Path, cwd: Path, env: dict[str, str], repeats: int) -> dict:
    """Import time (best of ``repeats``, interpreter start subtracted) and the full probe once."""
    def wall(args: list[str]) -> float:
        t0 = time.perf_counter()
        subprocess.run([str(python), "-I", *args], cwd=cwd, env=env, check=True, capture_output=True)
        return time.perf_counter() - t0

    bare = min(wall(["-c", "pass"]) for _ in range(repeats))
    imp = min(wall(["-c", "import workbench"]) for _ in range(repeats))
    proc = subprocess.run([str(python), "-I", "-c", PROBE, "--full"], cwd=cwd, env=env,
                          check=True, capture_output=True, text=True)
    got = json.loads(proc.stdout.strip().splitlines()[-1])
    got["import_wall"] = imp - bare
    return got


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--extras", nargs="*", default=["", "ui"],
                    help='extras to install, one venv each ("" = none; "ui,fast" = both)')
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--no-cache", action="store_true", help="pip --no-cache-dir (download everything)")
    ap.add_argument("--keep", action="store_true", help="keep the temporary venvs")
    args = ap.parse_args()

    tmp = Path(tempfile.mkdtemp(prefix="bench_wheel_"))
    assert ROOT not in tmp.parents
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    env["WORKBENCH_CACHE_DIR"] = str(tmp / "sample-cache")
    try:
        whl, sdist, t_build = build(tmp / "dist")
        print(f"\nface-workbench wheel (python -m build --no-isolation: {t_build:.1f} s for sdist + wheel)\n")
        print("| file | MB |")
        print("|---|---|")
        print(f"| {whl.name} | {_mb(whl.stat().st_size)} |")
        for part, n in wheel_contents(whl).items():
            print(f"| &nbsp; {part} (compressed) | {_mb(n)} |")
        print(f"| {sdist.name} | {_mb(sdist.stat().st_size)} |")

        rows = []
        for extras in args.extras:
            venv = tmp / f"venv-{extras.replace(',', '-') or 'core'}"
            subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
            py = venv / "bin" / "python"
            spec = f"{whl}[{extras}]" if extras else str(whl)
            cmd = [str(py), "-m", "pip", "install", "-q", "--disable-pip-version-check", spec]
            if args.no_cache:
                cmd.insert(4, "--no-cache-dir")
            t0 = time.perf_counter()
            subprocess.run(cmd, check=True, cwd=tmp, env=env, capture_output=True)
            t_install = time.perf_counter() - t0
            shutil.rmtree(tmp / "sample-cache", ignore_errors=True)
            got = probe(py, tmp, env, args.repeats)
            assert got["file"].startswith(str(venv)), got["file"]
            rows.append((extras or "(none)", t_install, _du(venv), got))
        # the checkout's own venv (editable install, every extra), for comparison
        shutil.rmtree(tmp / "sample-cache", ignore_errors=True)
        rows.append(("checkout .venv (editable)", float("nan"), 0,
                     probe(Path(sys.executable), ROOT, env, args.repeats)))

        cache = "cold (--no-cache-dir)" if args.no_cache else "warm pip cache"
        print(f"\ninstall into a fresh venv outside the repository ({cache}); then, from /tmp with "
              f"python -I: import workbench (best of {args.repeats}, interpreter start subtracted), "
              "load_sample('head'), the first-use 25k build, import widgets + read the bundle\n")
        print("| extras | pip install (s) | venv size (MB) | import workbench (s) | load_sample base (s) "
              "| first 25k build (s) | import widgets (s) |")
        print("|---|---|---|---|---|---|---|")
        for name, t_inst, size, g in rows:
            inst = "—" if t_inst != t_inst else f"{t_inst:.1f}"
            sz = "—" if not size else f"{size / 1e6:.0f}"
            w = f"{g['import_widgets']:.2f}" if "import_widgets" in g else g.get("widgets", "—")
            print(f"| {name} | {inst} | {sz} | {g['import_wall']:.2f} | {g['load_base']:.2f} "
                  f"| {g['build_25k']:.2f} | {w} |")
    finally:
        if args.keep:
            print(f"\nkept {tmp}")
        else:
            shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
