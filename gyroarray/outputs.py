"""Writing what the user asked for without touching what the user gave.

Every file the CLI writes goes through this module:

* :func:`check_output` refuses, before any work is done, an output path
  that resolves (after symlinks) to one of the command's inputs — a
  measurement and its sidecar, a model, a scenario and the profile files it
  names — whatever ``--force`` says; an existing file unless ``--force``; an
  existing directory; a suffix the writer cannot produce; a folder that
  cannot be created or written. Each refusal is one
  :class:`~gyroarray.errors.InputError` naming the option and the path.
* :func:`write_bytes` / :func:`write_text` / :func:`save_figure` write
  atomically: a temporary file in the target folder, ``fsync``, then

  - without ``force``: ``os.link`` to the final name, which fails if the name
    exists (create-new semantics: a file that appeared since the check is
    not overwritten);
  - with ``force``: ``os.replace``, which replaces the directory entry: an
    existing symlink at the final name is replaced by the new file, its
    target is never written through.

  A reader never sees a half-written file, and a crash leaves at most a
  hidden ``.*.tmp`` file behind.
"""

from __future__ import annotations

import io
import os
import tempfile
from pathlib import Path
from typing import Iterable

from gyroarray.errors import InputError

__all__ = ["PLOT_SUFFIXES", "measurement_files", "check_output", "check_output_dir", "write_bytes",
           "write_text", "save_figure", "same_path"]

#: Suffixes matplotlib writes without extra software.
PLOT_SUFFIXES = (".png", ".svg", ".pdf")


def _one_of(suffixes) -> str:
    """``.png, .svg or .pdf``."""
    s = list(suffixes)
    return s[0] if len(s) == 1 else ", ".join(s[:-1]) + " or " + s[-1]


def _resolved(p: Path) -> Path:
    try:
        return Path(os.path.realpath(p))
    except (OSError, ValueError):
        return Path(os.path.abspath(p))


def same_path(a, b) -> bool:
    """True when ``a`` and ``b`` name the same file (after symlinks; by inode if both exist)."""
    a, b = Path(a), Path(b)
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
    except OSError:
        pass
    return _resolved(a) == _resolved(b)


def measurement_files(path) -> list[Path]:
    """The files a measurement argument stands for: its CSV (plain or .gz) and its sidecar.

    ``run42``, ``run42.csv``, ``run42.csv.gz`` and ``run42.toml`` all stand for
    the same three candidate files, whichever of them exist.
    """
    p = Path(path)
    name = p.name
    for suffix in (".csv.gz", ".csv", ".toml"):
        if name.lower().endswith(suffix):
            name = name[: -len(suffix)]
            break
    stem = p.with_name(name)
    return [stem.with_name(name + s) for s in (".csv", ".csv.gz", ".toml")] + [p]


def _refuse_inputs(path: Path, inputs: Iterable, what: str) -> None:
    for given in inputs:
        if given is None:
            continue
        if same_path(path, given):
            raise InputError(f"{what} {path} is an input of this command ({given}); choose another "
                             "path (gyroarray never modifies what you gave it)", file=str(path))


def _check_folder(folder: Path, what: str, path: Path) -> None:
    if folder.exists() and not folder.is_dir():
        raise InputError(f"{what}: {folder} is not a folder", file=str(path))
    if not folder.exists():
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise InputError(f"{what}: cannot create the folder {folder}: {err.strerror or err}",
                             file=str(path)) from None
    if not os.access(folder, os.W_OK | os.X_OK):
        raise InputError(f"{what}: the folder {folder} is not writable", file=str(path))


def check_output(path, *, inputs: Iterable = (), force: bool = False, what: str = "--out",
                 suffixes: tuple[str, ...] | None = None) -> Path:
    """Check an output file path before any work is done; returns it as a Path.

    Parameters
    ----------
    path : path-like
        The output file the user named.
    inputs : iterable of path-like
        Every file the command reads (use :func:`measurement_files` for a
        measurement). The output may never be one of them, with or without
        ``force``.
    force : bool
        Allow replacing an existing file (the ``--force`` option).
    what : str
        The option's name, for the message.
    suffixes : tuple of str, optional
        Allowed (lower-case) suffixes, e.g. :data:`PLOT_SUFFIXES`.

    Raises
    ------
    InputError
        For every refusal listed in the module docstring.
    """
    p = Path(path)
    if str(p) in ("", "."):
        raise InputError(f"{what}: an output file name is needed", file=str(p))
    if p.is_dir():
        raise InputError(f"{what}: {p} is a folder; give a file name", file=str(p))
    if suffixes is not None:
        low = p.name.lower()
        if not any(low.endswith(s) for s in suffixes):
            raise InputError(f"{what}: cannot write {p.name!r}: the file name must end in "
                             f"{_one_of(suffixes)}", file=str(p))
    _refuse_inputs(p, inputs, what)
    if (p.exists() or p.is_symlink()) and not force:
        raise InputError(f"{what}: {p} exists; give another name, or --force to replace it",
                         file=str(p))
    _check_folder(p.parent if str(p.parent) else Path("."), what, p)
    return p


def check_output_dir(path, *, what: str = "--out") -> Path:
    """Check (and create) an output folder; returns it as a Path."""
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise InputError(f"{what} must be a folder; {p} is a file", file=str(p))
    _check_folder(p, what, p)
    return p


def write_bytes(path, data: bytes, *, force: bool = False) -> Path:
    """Write ``data`` to ``path`` atomically (module docstring); returns the path."""
    p = Path(path)
    folder = p.parent if str(p.parent) else Path(".")
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=folder)
    except OSError as err:
        raise InputError(f"cannot write in {folder}: {err.strerror or err}", file=str(p)) from None
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        if force:
            os.replace(tmp, p)
        else:
            try:
                os.link(tmp, p)
            except FileExistsError:
                raise InputError(f"{p} exists (it appeared while gyroarray worked); nothing was "
                                 "written over it; give another name, or --force", file=str(p)) from None
            except OSError:
                # a file system without hard links: check and replace
                if p.exists() or p.is_symlink():
                    raise InputError(f"{p} exists; give another name, or --force", file=str(p)) from None
                os.replace(tmp, p)
    except OSError as err:
        raise InputError(f"cannot write: {err.strerror or err}", file=str(p)) from None
    finally:
        try:
            os.unlink(tmp)
        except OSError:
            pass
    return p


def write_text(path, text: str, *, force: bool = False) -> Path:
    """UTF-8 text through :func:`write_bytes`."""
    return write_bytes(path, text.encode("utf-8"), force=force)


def save_figure(fig, path, *, force: bool = False, dpi: int = 120) -> Path:
    """A matplotlib figure to ``path`` (format from its suffix) through :func:`write_bytes`."""
    p = Path(path)
    fmt = p.suffix.lower().lstrip(".")
    if "." + fmt not in PLOT_SUFFIXES:
        raise InputError(f"cannot write a plot as {p.name!r}: the file name must end in "
                         f"{_one_of(PLOT_SUFFIXES)}", file=str(p))
    buf = io.BytesIO()
    fig.savefig(buf, format=fmt, dpi=dpi)
    return write_bytes(p, buf.getvalue(), force=force)
