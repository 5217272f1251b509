"""One BLAS thread for small dense work (threadpoolctl, a core dependency).

Small matrices (capture's 150×150 blocks, the enhancement matching's D×D
systems) gain nothing from threads, and on a busy 2-core machine a threaded
BLAS makes each call wait for cores (measured ~40× slower per block in
capture). The public methods that do such work hold BLAS to one thread once,
around all of it.

A threaded BLAS also keeps its worker threads spinning for a while after each
call before they sleep: a loop of small calls a few dozen times a second (a
live camera: the solve, the face's update) keeps a worker busy-waiting on a
core the whole time — measured in the Live tab, 67 % of one of the machine's
two cores, taken from the browser that draws the face. Such loops hold one
BLAS thread around each step.
"""

from __future__ import annotations

import contextlib
from typing import Any

__all__ = ["one_blas_thread"]

_LIMITER: Any = None


def one_blas_thread() -> Any:
    """A context holding BLAS to one thread (threadpoolctl when installed, else nothing)."""
    global _LIMITER
    if _LIMITER is None:
        try:
            from threadpoolctl import ThreadpoolController

            _LIMITER = ThreadpoolController()
        except ImportError:  # pragma: no cover - threadpoolctl is a core dependency
            _LIMITER = False
    if _LIMITER is False:
        return contextlib.nullcontext()
    return _LIMITER.limit(limits=1, user_api="blas")
