"""Regenerate the README pictures in notebooks/images/ and print render timings.

Usage::

    .venv/bin/python benchmarks/render_docs_images.py [--out notebooks/images]
                                                      [--resolutions base,25k,100k]

Writes
    head_front.png, head_three_quarter.png   the sample head, neutral
    head_jawOpen_displacement.png            jawOpen displacement as a heat map
    expressions_grid.png                     contact sheet of all blendshapes (8 columns)
    head_base.png, head_25k.png, ...         eye/nose close-ups with mesh edges per resolution

Renders are offscreen (EGL/llvmpipe) and deterministic, so re-running without
changes to the model or renderer gives identical files. Look at the pictures
after regenerating them.
"""

from __future__ import annotations

import argparse
import io
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402
from PIL import Image, ImageDraw, ImageFont  # noqa: E402

from widgets.render import expression_thumbnails, render_png, screen_positions  # noqa: E402
from workbench import FaceModel, load_sample  # noqa: E402


def contact_sheet(
    thumbs: dict[str, bytes], columns: int = 8, label_height: int = 18
) -> Image.Image:
    """Paste thumbnails in a grid with each name centred under its picture."""
    images = {n: Image.open(io.BytesIO(b)).convert("RGB") for n, b in thumbs.items()}
    w, h = next(iter(images.values())).size
    rows = -(-len(images) // columns)
    pad = 4
    cell_w, cell_h = w + pad, h + label_height + pad
    sheet = Image.new("RGB", (columns * cell_w + pad, rows * cell_h + pad), "white")
    draw = ImageDraw.Draw(sheet)
    font = ImageFont.load_default(size=11)
    for i, (name, im) in enumerate(images.items()):
        x = pad + (i % columns) * cell_w
        y = pad + (i // columns) * cell_h
        sheet.paste(im, (x, y))
        text_w = draw.textlength(name, font=font)
        draw.text((x + (w - text_w) / 2, y + h + 2), name, fill=(40, 40, 40), font=font)
    return sheet


def close_up_with_edges(model: FaceModel, big: int = 1200, crop: int = 480) -> bytes:
    """Triangle edges around the subject's left eye and nose, cropped from a big render.

    A whole-face picture at 100k vertices is all edges; a crop at full
    resolution keeps the triangle density readable at every level.
    """
    png = render_png(model, size=(big, big), camera="face", show_edges=True)
    eye = model.component_vertices("eye_left")
    target = np.asarray(model.vertices)[eye].mean(axis=0)
    col, row = screen_positions(model, [target], size=(big, big), camera="face")[0]
    # centre between the eye and the face midline so the nose is in the picture
    cx = int((col + big / 2) / 2)
    left = min(max(cx - crop // 2, 0), big - crop)
    top = min(max(int(row) - crop // 3, 0), big - crop)
    im = Image.open(io.BytesIO(png)).crop((left, top, left + crop, top + crop))
    buf = io.BytesIO()
    im.save(buf, format="PNG")
    return buf.getvalue()


def timed(fn, *args, **kwargs):
    t = time.perf_counter()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - t


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=ROOT / "notebooks" / "images")
    ap.add_argument("--resolutions", default="base,25k,100k")
    args = ap.parse_args(argv)
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    rows: list[tuple[str, str, float]] = []

    head: FaceModel = load_sample("head")
    n = head.n_vertices
    # warm-up (EGL context, shader compilation) so the table shows steady costs
    render_png(head, size=(64, 64))

    png, t = timed(render_png, head, size=(480, 560), camera="front")
    (out / "head_front.png").write_bytes(png)
    rows.append(("render_png front 480x560", f"{n}", t))
    png, t = timed(render_png, head, size=(480, 560), camera="three_quarter")
    (out / "head_three_quarter.png").write_bytes(png)
    rows.append(("render_png three_quarter 480x560", f"{n}", t))
    _, t = timed(render_png, head, size=(480, 480), antialias=False)
    rows.append(("render_png 480x480, no antialias", f"{n}", t))

    if "jawOpen" in head.shape_names:
        disp = np.linalg.norm(head.shape("jawOpen").effective_delta(), axis=1)
        png, t = timed(
            render_png,
            head,
            {"jawOpen": 1.0},
            size=(480, 480),
            camera="three_quarter",
            scalars=disp,
            cmap="YlOrRd",
        )
        (out / "head_jawOpen_displacement.png").write_bytes(png)
        rows.append(("render_png scalars 480x480", f"{n}", t))

    timings: dict[str, float] = {}
    thumbs = expression_thumbnails(head, size=(128, 128), progress=False, timings=timings)
    rows.append((f"expression_thumbnails x{len(thumbs)} 128x128 (total)", f"{n}", timings["total"]))
    rows.append(("  per thumbnail", f"{n}", timings["per_thumbnail"]))
    if thumbs:
        contact_sheet(thumbs).save(out / "expressions_grid.png")

    for res in [r for r in args.resolutions.split(",") if r]:
        try:
            model, t_load = timed(load_sample, "head", resolution=res)
        except Exception as exc:  # a resolution may not be buildable yet
            print(f"skip {res}: {type(exc).__name__}: {exc}")
            continue
        png, t = timed(close_up_with_edges, model)
        (out / f"head_{res}.png").write_bytes(png)
        rows.append((f"load_sample {res}", f"{model.n_vertices}", t_load))
        rows.append((f"close-up with edges (1200x1200 render) {res}", f"{model.n_vertices}", t))
        pts = np.asarray(model.vertices)
        _, t = timed(render_png, model, size=(480, 480), points=pts, antialias=False)
        rows.append((f"render_png 480x480 no AA {res}", f"{model.n_vertices}", t))

    print(f"\nwrote pictures to {out}")
    print(f"{'what':<52} {'vertices':>9} {'seconds':>9}")
    for what, verts, secs in rows:
        print(f"{what:<52} {verts:>9} {secs:>9.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
