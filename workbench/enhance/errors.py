"""The error every enhancement input check raises (its message names the argument)."""

from __future__ import annotations

__all__ = ["DatabaseError"]


class DatabaseError(ValueError):
    """Bad input to the performance database or to enhancement (the message names the argument)."""
