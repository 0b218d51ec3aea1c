"""A real small filesystem for tests of full and read-only disks: a tmpfs of a given size, mounted.

Mounting needs root (CI runs as root); elsewhere the tests that use it skip and say why.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path

import pytest

from controller.benchmarks.disk_full import MountError, fill, mounted_tmpfs

__all__ = ["fill", "small_filesystem"]


@contextlib.contextmanager
def small_filesystem(where: Path, size_kb: int, read_only: bool = False) -> Iterator[Path]:
    """A tmpfs of `size_kb` kB mounted at `where` (created), unmounted afterwards."""
    try:
        with mounted_tmpfs(where, size_kb, read_only) as mounted:
            yield mounted
    except MountError as exc:
        pytest.skip(f"{exc.strerror} (needs root)")
