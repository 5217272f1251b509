"""The webcam as a widget: the front end ``widgets/static/camera.js`` (built from ``widgets/js/src/camera.js``).

While :attr:`CameraWidget.active` is True the page holds the camera and sends JPEG
frames, one in flight: :attr:`on_frame` gets each as an ``(h, w, 3)`` uint8 RGB
array with the page's timestamp, on the kernel's main thread (comm messages arrive
there), and the widget acks it afterwards (with the milliseconds it took, for the
page's latency report), so a slow kernel drops frames instead of queueing them.
:attr:`state` follows the camera (``"off"``, ``"on"``, ``"error"``) and
:attr:`error` says why it failed (no camera, no permission, unplugged).
"""

from __future__ import annotations

import io
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import anywidget
import numpy as np
import traitlets as t
from numpy.typing import NDArray

from widgets.viewport.common import read_bundle

#: the bundle anywidget loads (built by widgets/js/build.mjs)
CAMERA_BUNDLE = Path(__file__).resolve().parent.parent / "static" / "camera.js"

FrameCallback = Callable[[NDArray[np.uint8], float], None]


def load_camera_bundle(path: Path = CAMERA_BUNDLE) -> str:
    """The camera front end's ESM text (raises FileNotFoundError naming the build command)."""
    return read_bundle(path, f"the camera's JavaScript bundle {path} is missing: it is built from "
                             "widgets/js/src (esbuild). Run `npm --prefix widgets/js ci && "
                             "npm --prefix widgets/js run build`.")


def decode_jpeg(data: bytes) -> NDArray[np.uint8]:
    """(h, w, 3) uint8 RGB of a JPEG (PIL)."""
    from PIL import Image

    with Image.open(io.BytesIO(data)) as im:
        return np.asarray(im.convert("RGB"), np.uint8)


class CameraWidget(anywidget.AnyWidget):
    """The page's webcam (see the module docstring)."""

    _esm = t.Unicode("").tag(sync=True)
    #: the page holds the camera while True
    active = t.Bool(False).tag(sync=True)
    #: the face model it drives (``widgets.viewport.common.scene_key``): while frames flow, the
    #: page counts that model as playing (its viewports draw at draft resolution on software WebGL)
    _scene = t.Unicode("").tag(sync=True)

    def __init__(self, on_frame: FrameCallback | None = None, **kwargs: Any) -> None:
        super().__init__(_esm=load_camera_bundle(), **kwargs)
        self.on_frame = on_frame
        self.on_state: Callable[[str, str], None] | None = None
        self.state = "off"
        self.error = ""
        self.frames_received = 0
        self.on_msg(self._on_frontend_msg)

    def _on_frontend_msg(self, _w: Any, content: Any, buffers: list[Any]) -> None:
        kind = content.get("type") if isinstance(content, dict) else None
        if kind == "frame":
            t0 = time.perf_counter()
            try:
                if buffers and self.on_frame is not None:
                    self.frames_received += 1
                    self.on_frame(decode_jpeg(bytes(buffers[0])), float(content.get("t", 0.0)))
            finally:
                # the next frame may come; the page's latency report splits its round trip with this
                self.send({"type": "ack", "kernel_ms": round(1e3 * (time.perf_counter() - t0), 2)})
        elif kind == "camera":
            self.state = str(content.get("state", "off"))
            self.error = str(content.get("message", "")) if self.state == "error" else ""
            if self.on_state is not None:
                self.on_state(self.state, self.error)
