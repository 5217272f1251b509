"""What the saving and the loading side share: the format's name, version and suffix, checksums, the families' parts."""

from __future__ import annotations

import hashlib

from workbench.core import families

FORMAT_NAME = "face-workbench"
SCHEMA_VERSION = 2
SUFFIX = ".fwb"
_MAX_MANIFEST_BYTES = 64 * 2**20


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _parts() -> list[families.FilePart]:
    """The file parts of the registered method families, in family order."""
    return [f.file_part for f in families.families() if f.file_part is not None]
