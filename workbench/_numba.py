"""numba when it is installed (the ``fast`` extra), else stand-ins that run the same Python.

``njit`` without numba returns the function unchanged, ``prange`` is ``range``
and ``numba`` is None; :data:`NUMBA` says which. The hot loops of the wrinkle
kernels, the capture solver and the self-intersection test are written once
and tested both ways.
"""

from __future__ import annotations

from typing import Any

__all__ = ["NUMBA", "njit", "numba", "prange"]

try:
    import numba
    from numba import njit, prange

    NUMBA = True
except ImportError:  # pragma: no cover - numba is optional
    numba = None  # type: ignore[assignment]
    NUMBA = False

    def njit(*args: Any, **kwargs: Any) -> Any:  # type: ignore[no-redef]
        def wrap(f: Any) -> Any:
            return f

        return wrap if not (len(args) == 1 and callable(args[0])) else args[0]

    prange = range  # type: ignore[misc]
