"""The Live tab: webcam capture (:class:`LivePanel`, :class:`~widgets.live.camera.CameraWidget`)."""

from widgets.live.camera import CameraWidget
from widgets.live.panel import LivePanel

__all__ = ["CameraWidget", "LivePanel"]
