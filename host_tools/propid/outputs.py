"""Writing output files: one rule for every command, checked before the work.

The rule (README.md, "Output files"): an output's missing directories are
created, as `mkdir -p` would, when the output is written. Before any work a command
checks each output path and refuses it with a one-line error only when it cannot be
written: a part of the path exists and is not a directory, a file output is an existing
directory (a directory output an existing file), the nearest existing directory is
not writable, or the output is one of the command's input files. The directories are created at the write, not at the check, so a command
that stops on a bad input leaves nothing behind.

Files are written to a temporary name beside the target and renamed over it only when
complete: an error or Ctrl-C half-way never leaves a truncated file, and an existing
file is kept unless the new one is ready.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path
from typing import IO, Iterator

from propid.errors import UserError


def _label(path: Path, option: str) -> str:
    return f"{option} {path}" if option else str(path)


def _existing_ancestor(path: Path, label: str) -> Path:
    """The nearest part of `path` (itself included) that exists; UserError when it is not a
    directory, or is one we may not create entries in."""
    for candidate in (path, *path.parents):
        if candidate.exists() or candidate.is_symlink():
            break
    if not candidate.is_dir():
        raise UserError(f"cannot write {label}: {candidate} is not a directory")
    if not os.access(candidate, os.W_OK | os.X_OK):
        raise UserError(f"cannot write {label}: permission denied in {candidate}")
    return candidate


def check_writable(path: str | os.PathLike, option: str = "") -> Path:
    """A file output: UserError now if it could not be written later (missing directories
    are fine: they are created at the write)."""
    path = Path(path)
    label = _label(path, option)
    if path.is_dir():
        raise UserError(f"cannot write {label}: it is a directory")
    if path.exists() and not os.access(path, os.W_OK):
        raise UserError(f"cannot write {label}: permission denied")
    _existing_ancestor(path.parent, label)
    return path


def _figure_format(path: Path) -> str:
    """matplotlib's format for a figure file: its extension (PNG when it has none)."""
    from matplotlib.backend_bases import FigureCanvasBase

    kind = path.suffix.lower().lstrip(".") or "png"
    if kind not in FigureCanvasBase.get_supported_filetypes():
        raise UserError(f"cannot write {path}: no figure format '.{kind}' (name it *.png)")
    return kind


def check_figure(path: str | os.PathLike, option: str = "") -> Path:
    """A figure output: check_writable, and a file extension matplotlib can write."""
    path = check_writable(path, option)
    _figure_format(path)
    return path


def check_directory(path: str | os.PathLike, option: str = "") -> Path:
    """A directory output (the command writes files into it): UserError now if it could not
    be created or written later."""
    path = Path(path)
    label = _label(path, option)
    if (path.exists() or path.is_symlink()) and not path.is_dir():
        raise UserError(f"cannot write {label}: it is a file, not a directory")
    _existing_ancestor(path, label)
    return path


def check_not_inputs(outputs, inputs) -> None:
    """UserError now if an output (option, path) would overwrite one of the command's input
    files (a log, a vehicle file, a table): an output is never written over what was read."""
    read: dict[Path, Path] = {}
    for path in inputs:
        if path is not None:
            read.setdefault(Path(path).resolve(), Path(path))
    for option, path in outputs:
        if path is None or str(path) == "-":
            continue
        source = read.get(Path(path).resolve())
        if source is not None:
            raise UserError(f"cannot write {_label(Path(path), option)}: must not overwrite the input file {source}")


def make_directory(path: str | os.PathLike) -> Path:
    """Create a directory and its missing parents (`mkdir -p`); a one-line UserError if not."""
    path = Path(path)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"cannot create directory {path}: {exc.strerror or exc}") from None
    return path


def make_parents(path: str | os.PathLike) -> Path:
    """Create the missing directories a file output is to be written in; returns the path."""
    path = Path(path)
    make_directory(path.parent)
    return path


@contextlib.contextmanager
def replacing(path: str | os.PathLike, mode: str = "w", **open_kwargs) -> Iterator[IO]:
    """Open a temporary file beside `path` (its directories created); on success rename it
    to `path`, on any error remove it and leave `path` as it was."""
    path = make_parents(path)
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


def save_figure(fig, path: str | os.PathLike, **savefig_kwargs) -> None:
    """Write a matplotlib figure by replacing the file only when complete; the format is
    the file's extension (PNG when it has none)."""
    path = Path(path)
    kind = _figure_format(path)
    try:
        with replacing(path, "wb") as handle:
            fig.savefig(handle, format=kind, **savefig_kwargs)
    except OSError as exc:
        raise UserError(f"cannot write {path}: {exc.strerror or exc}") from None
