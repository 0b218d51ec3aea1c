"""Writing what a run records without losing it or faking it: atomic files and claimed folders.

- `write_atomic(path, data)` / `write_json_atomic(path, obj)`: through `path.tmp` and a rename, so a
  reader sees the old whole file or the new whole file, never half of one. A failed write (a full
  disk, a read-only or removed folder) removes the temporary file and raises: nothing half-written
  is left looking whole.
- `write_new(path, data)`: the same for a file that must be new (a recording): never over another.
- `claim_dir(path, what)`: make `path` this run's own output folder, atomically. A new folder, or
  an existing empty one, is claimed by creating the marker `.claim` in it exclusively (O_EXCL), so of
  two runs started at once on one folder exactly one gets it; the other is told who holds it.
  `release_claim(path)` removes the marker once the run has written its first file there.
  A folder that cannot be written (read-only, no space) is refused here, before anything starts.
- `still_there(file, path)`: whether an open file is still the one at `path`: a recording whose folder
  was removed under it writes on into a file nobody can find, without an error; this tells it.
- `set_aside(path)`: an unfinished run's folder renamed out of the way (`<name>.unfinished`,
  `<name>.unfinished-2`, ...), kept, so a resumed job can start its folder afresh.
- `claimed_dir(path, what)`: the same claim for a block of work: a failure that leaves the folder
  holding nothing gives it back as it was (an empty folder that existed stays; one made here goes),
  so a command that fails leaves no empty folder behind; on success the claim is released.
"""

from __future__ import annotations

import contextlib
import json
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

CLAIM_MARKER = ".claim"


class OutputDirError(FileExistsError):
    """An output folder that cannot be this run's: it holds something, another run holds it, or it
    cannot be written. The message names the folder and what to do."""


def write_atomic(path: str | Path, data: bytes | str) -> None:
    """Write `data` to `path` through a temporary file and a rename; on failure nothing is left behind."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    payload = data.encode("utf-8") if isinstance(data, str) else data
    try:
        with tmp.open("wb") as file:
            file.write(payload)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def write_new(path: str | Path, data: bytes) -> None:
    """`write_atomic` that never replaces a file: `FileExistsError` if `path` appeared meanwhile (the file
    is linked into place, which fails where a rename would overwrite)."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    try:
        with tmp.open("xb") as file:
            file.write(data)
        os.link(tmp, path)
    finally:
        with contextlib.suppress(OSError):
            tmp.unlink()


def write_json_atomic(path: str | Path, data: Any, indent: int | None = 2) -> None:
    """`data` as JSON (a trailing newline) written with `write_atomic`."""
    write_atomic(path, json.dumps(data, indent=indent) + "\n")


def claim_dir(path: str | Path, what: str = "output folder") -> Path:
    """`path` as this run's own folder: created if new, refused if it holds anything or cannot be written.

    Raises `OutputDirError` with one line that says why and what to do.
    """
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.mkdir(exist_ok=True)
    except FileExistsError:
        raise OutputDirError(f"{what} {path} exists and is not a folder") from None
    except OSError as exc:
        raise OutputDirError(f"cannot create the {what} {path}: {exc.strerror or exc}") from None
    marker = path / CLAIM_MARKER
    try:
        fd = os.open(marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
    except FileExistsError:
        holder = _read_holder(marker)
        raise OutputDirError(
            f"{what} {path} is being written by another run{holder}; give another folder "
            f"(or remove {marker} if that run is gone)"
        ) from None
    except OSError as exc:
        raise OutputDirError(f"cannot write in the {what} {path}: {exc.strerror or exc}") from None
    try:
        os.write(fd, f"{os.getpid()}\n".encode())
    except OSError as exc:
        os.close(fd)
        with contextlib.suppress(OSError):
            marker.unlink()
        raise OutputDirError(f"cannot write in the {what} {path}: {exc.strerror or exc}") from None
    os.close(fd)
    held = sorted(p.name for p in path.iterdir() if p.name != CLAIM_MARKER)
    if held:
        marker.unlink()
        shown = ", ".join(held[:4]) + (", ..." if len(held) > 4 else "")
        raise OutputDirError(
            f"{what} {path} already holds {shown}: nothing recorded is ever written over; "
            "give a new or empty folder"
        )
    return path


@contextlib.contextmanager
def claimed_dir(path: str | Path, what: str = "output folder") -> Iterator[Path]:
    """`claim_dir` for the block; on a failure inside it, a folder that still holds nothing but the
    claim is given back as it was: the folders the claim made are removed, an empty one that existed
    stays. On success the claim is released."""
    path = Path(path)
    made = [folder for folder in (path, *path.parents) if not folder.exists()]  # innermost first
    claimed = claim_dir(path, what)
    try:
        yield claimed
    except BaseException:
        release_claim(claimed)
        for folder in made:
            try:
                folder.rmdir()  # only ever an empty one
            except OSError:
                break
        raise
    release_claim(claimed)


def still_there(file: Any, path: str | Path) -> bool:
    """Whether the open `file` is still the file at `path` (False once it, or its folder, was removed or
    replaced: writes would go on into an unlinked file, lost, and say nothing)."""
    try:
        mine, there = os.fstat(file.fileno()), os.stat(path)
    except (OSError, ValueError):
        return False
    return (mine.st_dev, mine.st_ino) == (there.st_dev, there.st_ino)


def set_aside(path: str | Path) -> Path | None:
    """Rename `path` (if it exists) to the first free `<name>.unfinished[-N]` beside it; the new path."""
    path = Path(path)
    if not path.exists():
        return None
    candidate, n = path.with_name(f"{path.name}.unfinished"), 1
    while candidate.exists():
        n += 1
        candidate = path.with_name(f"{path.name}.unfinished-{n}")
    os.replace(path, candidate)
    return candidate


def claim_fresh_dir(base: str | Path, what: str = "output folder") -> Path:
    """A default output folder claimed for this run: `base`, else `base-2`, `base-3`, ...: the first that
    nobody holds. Runs started at once (the same default name, the same second) each get their own."""
    base = Path(base)
    for n in range(1, 1000):
        candidate = base if n == 1 else base.with_name(f"{base.name}-{n}")
        if candidate.exists():
            continue
        try:
            return claim_dir(candidate, what)
        except OutputDirError:  # another run claimed it first: the next name
            continue
    raise OutputDirError(f"no free {what} name beside {base} (999 taken)")


def release_claim(path: str | Path) -> None:
    """Remove the claim marker (once the run's first file is in the folder); idempotent."""
    with contextlib.suppress(FileNotFoundError):
        (Path(path) / CLAIM_MARKER).unlink()


def _read_holder(marker: Path) -> str:
    try:
        pid = int(marker.read_text().strip())
    except (OSError, ValueError):
        return ""
    return f" (pid {pid})"
