"""Writing output files safely: check before the work, replace only when complete.

A command checks every output path before it starts (so a typo costs nothing), then
writes each file to a temporary name beside it and renames it over the target only
when it is complete: an error or Ctrl-C half-way never leaves a truncated file, and an
existing file is kept unless the new one is ready.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path
from typing import IO, Iterator

from propid.errors import UserError


def check_writable(path: str | os.PathLike, option: str = "") -> Path:
    """UserError now if `path` could not be written later."""
    path = Path(path)
    label = f"{option} {path}" if option else str(path)
    if path.is_dir():
        raise UserError(f"cannot write {label}: it is a directory")
    parent = path.parent
    if not parent.is_dir():
        raise UserError(f"cannot write {label}: no directory {parent}")
    if not os.access(parent, os.W_OK) or (path.exists() and not os.access(path, os.W_OK)):
        raise UserError(f"cannot write {label}: permission denied")
    return path


@contextlib.contextmanager
def replacing(path: str | os.PathLike, mode: str = "w", **open_kwargs) -> Iterator[IO]:
    """Open a temporary file beside `path`; on success rename it to `path`, on any error
    remove it and leave `path` as it was."""
    path = Path(path)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent)
    try:
        with os.fdopen(fd, mode, **open_kwargs) as handle:
            yield handle
        if path.exists():
            os.chmod(tmp_name, path.stat().st_mode & 0o777)
        else:
            umask = os.umask(0)
            os.umask(umask)
            os.chmod(tmp_name, 0o666 & ~umask)
        os.replace(tmp_name, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp_name)
        raise


def write_text(path: str | os.PathLike, text: str) -> None:
    """Write a text file (UTF-8) by replacing it only when complete."""
    try:
        with replacing(path, "w", encoding="utf-8", newline="\n") as handle:
            handle.write(text)
    except OSError as exc:
        raise UserError(f"cannot write {path}: {exc.strerror or exc}") from None
