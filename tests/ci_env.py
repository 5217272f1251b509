"""One rule for "a missing tool fails the run" across the test folders.

``bash .ci/workbench test`` installs every tool the tests use and sets ``CI=true``
(unless CI is already set), so there a missing browser, node tool, Blender or image
baseline is a failure; a developer running ``pytest`` by hand gets a skip instead.
"""

from __future__ import annotations

import os


def in_ci() -> bool:
    """True when the CI environment variable is set to anything but an off value."""
    return os.environ.get("CI", "").strip().lower() not in ("", "0", "false", "no", "off")
