"""Writing what the user asked for without touching what the user gave.

Every file the CLI writes goes through this module:

* :func:`check_output` refuses, before any work is done, an output path
  that resolves (after symlinks) to one of the command's inputs — a
  measurement and its sidecar, a model, a scenario and the profile files it
  names — whatever ``--force`` says; an existing file unless ``--force``; an
  existing directory; a suffix the writer cannot produce; a folder that
  cannot be created or written. Each refusal is one
  :class:`~gyroarray.core.errors.InputError` naming the option and the path.
* :func:`write_bytes` / :func:`write_text` / :func:`save_figure` write
  atomically: a temporary file in the target folder, ``fsync``, then

  - without ``force``: ``os.link`` to the final name, which fails if the name
    exists (create-new semantics: a file that appeared since the check is
    not overwritten);
  - with ``force``: ``os.replace``, which replaces the directory entry: an
    existing symlink at the final name is replaced by the new file, its
    target is never written through.

  A reader never sees a half-written file under its final name. The temporary
  is named for its output, its machine and its process
  (``.NAME.gyroarray-tmp-<host>-<pid>-<random>.tmp``, :data:`TEMP_MARK`): a
  SIGTERM or SIGHUP is an exception in the CLI (:func:`handle_termination`,
  :class:`Terminated`), so the clean-ups on the way out remove it (SIGINT is
  ``KeyboardInterrupt``); after a SIGKILL, which runs no clean-up, the next
  write into the folder removes it (:func:`remove_stale_temps`: only this
  machine's temporaries of processes that are gone). A new file gets ``0o666`` less the umask
  (:func:`file_mode`), as ``open`` would give it. A full disk or a read-only
  folder is one :class:`~gyroarray.core.errors.InputError`, and nothing is left.
* :func:`write_many` writes several files (a report, its Markdown twin and
  figures) all or nothing; a file too long to hold in memory (a streamed fused
  record) is written piece by piece into :func:`open_staged`'s temporary file
  and given its name with the others.
* :func:`check_own_file` / :func:`append_line` guard the files gyroarray keeps
  and appends to in an output folder (a sweep's ``sweep.json`` and
  ``rows.sha256``): never a symbolic link (gyroarray makes none), never a
  FIFO, device or folder, never another user's file, never an input of the
  command; an append that fails is cut back, no partial line is kept.
* :func:`markdown_figures` checks a Markdown twin's figure folder before the work.
* :func:`private_matplotlib_dir` keeps matplotlib's caches out of the user's home.
* :func:`make_temp_dir` makes a scratch folder (a streamed ADEV's phase files) named the same
  way; what this process still holds at exit is removed (:func:`remove_own_temps`).
"""

from __future__ import annotations

import atexit
import errno
import io
import os
import re
import shutil
import signal
import stat
import sys
import tempfile
import threading
import zlib
from pathlib import Path
from typing import Iterable

from gyroarray.core.errors import InputError
from gyroarray.core.limits import file_kind

__all__ = ["PLOT_SUFFIXES", "measurement_files", "check_output", "check_output_dir", "write_bytes",
           "write_many", "write_text", "save_figure", "same_path", "file_mode", "check_own_file",
           "append_line", "markdown_figures", "private_matplotlib_dir", "Staged", "open_staged",
           "TEMP_MARK", "temp_prefix", "pid_gone", "stale_temp", "remove_stale_temps", "make_temp_dir",
           "remove_own_temps", "Terminated", "handle_termination"]

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
    """The files a measurement argument stands for: its CSV (plain or .gz) or Parquet, and its
    sidecar.

    ``run42``, ``run42.csv``, ``run42.csv.gz``, ``run42.parquet`` and ``run42.toml`` all stand
    for the same four candidate files, whichever of them exist.
    """
    p = Path(path)
    name = p.name
    for suffix in (".csv.gz", ".csv", ".parquet", ".toml"):
        if name.lower().endswith(suffix):
            name = name[: -len(suffix)]
            break
    stem = p.with_name(name)
    return [stem.with_name(name + s) for s in (".csv", ".csv.gz", ".parquet", ".toml")] + [p]


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
        above = folder.parent
        while not above.exists() and above != above.parent:
            above = above.parent
        if above.is_dir() and not os.access(above, os.W_OK | os.X_OK):   # refuse, create nothing
            raise InputError(f"{what}: cannot create the folder {folder}: {above} is not writable",
                             file=str(path))
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
    try:
        os.lstat(p)
    except (FileNotFoundError, NotADirectoryError):    # a file in the way: _check_folder says so
        pass
    except OSError as err:          # a name too long, a loop of links
        raise InputError(f"{what}: cannot use this path: {err.strerror or err}", file=str(p)) from None
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
    _refuse_special(p, what)
    return p


def _refuse_special(p: Path, what: str) -> None:
    """Refuse to replace anything but a regular file or a symlink's own entry.

    ``--force`` replaces a file gyroarray (or the user) wrote. A device, FIFO
    or socket at the name is never one: as root, replacing ``/dev/null``
    would take it from the whole machine.
    """
    try:
        mode = os.lstat(p).st_mode
    except FileNotFoundError:
        return
    except OSError as err:
        raise _refusal(err, p) from None
    if not (stat.S_ISREG(mode) or stat.S_ISLNK(mode)):
        raise InputError(f"{what}: {p} is {file_kind(mode)}, not a file gyroarray may replace (--force "
                         "replaces regular files only); give a file name", file=str(p))


def check_output_dir(path, *, what: str = "--out") -> Path:
    """Check (and create) an output folder; returns it as a Path."""
    p = Path(path)
    try:
        os.stat(p)
    except FileNotFoundError:
        pass
    except OSError as err:          # a name too long, a loop of links, a file used as a folder
        raise InputError(f"{what}: cannot use this folder: {err.strerror or err}", file=str(p)) from None
    if p.exists() and not p.is_dir():
        raise InputError(f"{what} must be a folder; {p} is a file", file=str(p))
    _check_folder(p, what, p)
    return p


def _read_umask() -> int:
    """The process's umask, read without changing it where the system says it (Linux
    ``/proc/self/status``); elsewhere the one read at import (set and restored at once)."""
    try:
        with open("/proc/self/status", encoding="ascii", errors="replace") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    return _UMASK_AT_IMPORT


_UMASK_AT_IMPORT = os.umask(0o022)
os.umask(_UMASK_AT_IMPORT)


def file_mode() -> int:
    """The permissions of a new output file: ``0o666`` less the umask (what ``open`` gives)."""
    return 0o666 & ~_read_umask()


def _write_all(fd: int, data: bytes) -> None:
    """Every byte of ``data`` to ``fd`` (``os.write`` may write less than asked)."""
    view = memoryview(data)
    while view:
        n = os.write(fd, view)
        view = view[n:]


def _refusal(err: OSError, p: Path, doing: str = "cannot write") -> InputError:
    why = err.strerror or str(err)
    if err.errno in (errno.ENOSPC, getattr(errno, "EDQUOT", errno.ENOSPC)):
        why += " (free some space, or write elsewhere)"
    elif err.errno in (errno.EROFS, errno.EACCES, errno.EPERM):
        why += " (choose a folder you can write to)"
    return InputError(f"{doing}: {why}; nothing was written there", file=str(p))


def _unlink(path) -> None:
    _LIVE.discard(str(path))
    try:
        os.unlink(path)
    except OSError:
        pass


# -- temporary files and folders: named for their process, removed on a signal or by the next run --

#: The mark in the name of every temporary file and folder gyroarray makes:
#: ``<name>.gyroarray-tmp-<host>-<pid>-<random>`` (a file beside an output is hidden and ends in
#: ``.tmp``: ``.run42.csv.gz.gyroarray-tmp-1a2b3c4d-4711-k2j3h4g5.tmp``). The host (a hash of its
#: name) and the pid say whose it is, so a later run can tell one left by a process that is gone
#: (a SIGKILL, a power cut: no clean-up of its own ran) from one a live process is writing.
TEMP_MARK = ".gyroarray-tmp-"
_TEMP_RE = re.compile(re.escape(TEMP_MARK) + r"([0-9a-f]{8})-([0-9]+)-[A-Za-z0-9_]+(?:\.tmp)?")
#: Temporary files and folders this process made and has not yet named or removed.
_LIVE: set[str] = set()
#: Folders this process has already cleared of stale temporaries (once per folder).
_SWEPT: set[str] = set()


def _host_tag() -> str:
    """This machine's name, hashed to 8 hex digits."""
    try:
        host = os.uname().nodename
    except AttributeError:                          # not POSIX
        host = os.environ.get("COMPUTERNAME", "")
    return f"{zlib.crc32(host.encode('utf-8', 'replace')):08x}"


def temp_prefix(name: str) -> str:
    """The ``mkstemp``/``mkdtemp`` prefix of a temporary named for ``name`` and this process."""
    return f"{name}{TEMP_MARK}{_host_tag()}-{os.getpid()}-"


def pid_gone(pid: int) -> bool:
    """True when no process ``pid`` runs on this machine (a zombie counts as gone)."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    except OSError:                # another user's live process (EPERM)
        return False
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state in ("Z", "X")


def stale_temp(name: str) -> bool:
    """Whether ``name`` is a gyroarray temporary of this machine whose process is gone."""
    m = _TEMP_RE.search(name)
    return (m is not None and m.end() == len(name) and m.group(1) == _host_tag()
            and int(m.group(2)) != os.getpid() and pid_gone(int(m.group(2))))


def remove_stale_temps(folder, *, once: bool = False) -> list[str]:
    """Remove the temporary files and folders gyroarray left in ``folder`` (not below it) whose
    process is gone; returns their names.

    Only entries marked :data:`TEMP_MARK` with this machine's host and the pid of a process that
    no longer runs, owned by this user, are removed: a temporary of a live process (another
    gyroarray writing beside this one, a Dask worker on another machine sharing the folder) is
    left alone. ``once``: only the first call for a folder in this process looks (a folder is
    cleared when its first output is written, not at every file).
    """
    key = os.path.abspath(folder)
    if once and key in _SWEPT:
        return []
    _SWEPT.add(key)
    removed: list = []
    try:
        with os.scandir(folder) as it:
            entries = [e for e in it if TEMP_MARK in e.name]
    except OSError:
        return removed
    uid = os.geteuid() if hasattr(os, "geteuid") else None
    for e in entries:
        if not stale_temp(e.name):
            continue
        try:
            st = os.lstat(e.path)
            if uid is not None and st.st_uid != uid:
                continue
            if stat.S_ISDIR(st.st_mode):
                shutil.rmtree(e.path, ignore_errors=True)
            elif stat.S_ISREG(st.st_mode):
                os.unlink(e.path)
            else:
                continue
            removed.append(e.name)
        except OSError:
            pass
    return removed


def make_temp_dir(what: str, dir=None) -> str:
    """A new private temporary folder (``mkdtemp``) named ``gyroarray-<what>`` and this process
    (:data:`TEMP_MARK`), in ``dir`` or the system's temporary folder; stale ones of processes
    that are gone are removed there first. The caller removes it (``shutil.rmtree`` in a
    ``finally``; a SIGTERM is an exception in the CLI, :func:`handle_termination`), else
    :func:`remove_own_temps` does at exit."""
    folder = tempfile.gettempdir() if dir is None else os.fspath(dir)
    remove_stale_temps(folder, once=True)
    path = tempfile.mkdtemp(prefix=temp_prefix(f"gyroarray-{what}"), dir=folder)
    for gone in [q for q in list(_LIVE) if not os.path.lexists(q)]:   # removed by their callers
        _LIVE.discard(gone)
    _LIVE.add(path)
    return path


def remove_own_temps() -> None:
    """Remove every temporary file and folder this process made and still holds (at exit, after
    a SIGTERM: whatever a clean-up on the way out did not reach)."""
    for path in list(_LIVE):
        _LIVE.discard(path)
        try:
            if os.path.isdir(path) and not os.path.islink(path):
                shutil.rmtree(path, ignore_errors=True)
            else:
                os.unlink(path)
        except OSError:
            pass


atexit.register(remove_own_temps)


def _new_temp(p: Path) -> tuple[int, str]:
    """A new hidden temporary file beside ``p`` (``mkstemp``: created, never through a link),
    named for ``p`` and this process (:data:`TEMP_MARK`): its descriptor and path. The folder's
    stale temporaries (of processes that are gone) are removed the first time."""
    folder = p.parent if str(p.parent) else Path(".")
    remove_stale_temps(folder, once=True)
    try:
        fd, tmp = tempfile.mkstemp(prefix=temp_prefix(f".{p.name[:64]}"), suffix=".tmp", dir=folder)
    except OSError as err:
        raise _refusal(err, p, f"cannot write in {folder}") from None
    _LIVE.add(tmp)
    return fd, tmp


class Terminated(BaseException):
    """A SIGTERM or SIGHUP turned into an exception in the main thread
    (:func:`handle_termination`), so that every ``finally`` and ``except BaseException``
    clean-up runs (temporary files and folders removed, workers stopped) before the CLI exits
    with ``128 + signal``. Not an ``Exception``: nothing that handles errors swallows it."""

    def __init__(self, signum: int):
        self.signum = int(signum)
        self.exit_code = 128 + self.signum
        try:
            name = signal.Signals(self.signum).name
        except ValueError:
            name = f"signal {self.signum}"
        super().__init__(f"terminated by {name}")


def handle_termination() -> None:
    """In the main thread: SIGTERM and SIGHUP raise :class:`Terminated` (a second one ends the
    process at once, as the signal would). A signal the process was started ignoring (``nohup``)
    stays ignored; one with a handler of someone else's is left alone. SIGINT is Python's
    ``KeyboardInterrupt`` already."""
    if threading.current_thread() is not threading.main_thread():
        return

    def raise_terminated(signum, frame):
        signal.signal(signum, signal.SIG_DFL)          # a second one: the default, at once
        raise Terminated(signum)

    for name in ("SIGTERM", "SIGHUP"):
        signum = getattr(signal, name, None)
        if signum is not None and signal.getsignal(signum) == signal.SIG_DFL:
            signal.signal(signum, raise_terminated)


def _stage(p: Path, data: bytes) -> str:
    """``data`` in a hidden temporary file beside ``p``, synced, with :func:`file_mode`;
    returns its path. Nothing is left behind on failure."""
    fd, tmp = _new_temp(p)
    try:
        try:
            os.fchmod(fd, file_mode())
            _write_all(fd, data)
            os.fsync(fd)
        finally:
            os.close(fd)
    except OSError as err:
        _unlink(tmp)
        raise _refusal(err, p) from None
    except BaseException:
        _unlink(tmp)
        raise
    return tmp


class Staged:
    """A file written in full beside its final name and not yet given it (:func:`open_staged`);
    :func:`write_many` commits it with the other files, or :meth:`discard` removes it."""

    def __init__(self, tmp: str, final: Path):
        self.tmp, self.final = tmp, final

    def discard(self) -> None:
        _unlink(self.tmp)


def open_staged(path):
    """A hidden temporary file beside ``path`` (created new: never a name that exists, never
    through a symbolic link), open for binary writing, and its :class:`Staged` handle.

    The caller writes, closes the file object, then passes the handle to
    :func:`write_many` in place of the bytes (it is synced and given its name
    there) or calls :meth:`Staged.discard`.

    Raises
    ------
    InputError
        The folder cannot be written.
    """
    p = Path(path)
    fd, tmp = _new_temp(p)
    try:
        os.fchmod(fd, file_mode())
        return os.fdopen(fd, "wb"), Staged(tmp, p)
    except BaseException:
        os.close(fd)
        _unlink(tmp)
        raise


def _commit(tmp: str, p: Path, force: bool) -> None:
    """Give the staged ``tmp`` its final name ``p`` (module docstring)."""
    try:
        if force:
            _refuse_special(p, "output")      # a device appeared since the check
            os.replace(tmp, p)
            return
        try:
            os.link(tmp, p)
        except FileExistsError:
            raise InputError(f"{p} exists (it was not there when gyroarray checked its outputs); "
                             "nothing was written over it; give another name, or --force",
                             file=str(p)) from None
        except OSError as err:
            if err.errno not in (errno.EPERM, errno.EOPNOTSUPP, errno.EXDEV, errno.EMLINK):
                raise
            # a file system without hard links: check and replace
            if p.exists() or p.is_symlink():
                raise InputError(f"{p} exists; give another name, or --force", file=str(p)) from None
            os.replace(tmp, p)
    except OSError as err:
        raise _refusal(err, p) from None


def write_bytes(path, data: bytes, *, force: bool = False) -> Path:
    """Write ``data`` to ``path`` atomically (module docstring); returns the path.

    The file gets the mode ``0o666`` less the umask (:func:`file_mode`), as a
    file ``open`` creates would. A full disk, a read-only folder or any other
    failure ends in one :class:`InputError` naming the path and leaves nothing
    behind (no partial file, no temporary file).
    """
    return write_many([(path, data)], force=force)[0]


def write_many(items, *, force: bool = False) -> list[Path]:
    """Write several files all or nothing: ``items`` is ``[(path, bytes or Staged), ...]``.

    Every file is first written in full to a temporary file beside its final
    name (so a full disk or a read-only folder is met before any final name
    appears); then each gets its name as :func:`write_bytes` does. When one
    fails, the files this call already created are removed again (a file
    replaced with ``force`` stays replaced), so a refusal leaves no half
    report behind.
    """
    items = list(items)
    staged: list[tuple[str, Path]] = []
    done: list[tuple[Path, tuple]] = []
    try:
        for path, data in items:
            p = Path(path)
            if isinstance(data, Staged):          # written already: synced here
                try:
                    fd = os.open(data.tmp, os.O_RDONLY)
                    try:
                        os.fsync(fd)
                    finally:
                        os.close(fd)
                except OSError as err:
                    raise _refusal(err, p) from None
                staged.append((data.tmp, p))
            else:
                staged.append((_stage(p, bytes(data)), p))
        for tmp, p in staged:
            st = os.stat(tmp)
            new = not (p.exists() or p.is_symlink())
            _commit(tmp, p, force)
            if new:
                done.append((p, (st.st_dev, st.st_ino)))
    except BaseException:
        for p, ident in done:                     # only what this call created
            try:
                st = os.lstat(p)
                if (st.st_dev, st.st_ino) == ident:
                    os.unlink(p)
            except OSError:
                pass
        raise
    finally:
        for tmp, _ in staged:
            _unlink(tmp)
        for _, data in items:                     # a handle the loop did not reach
            if isinstance(data, Staged):
                data.discard()
    return [p for _, p in staged]


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


def check_own_file(path, *, inputs: Iterable = (), what: str = "bookkeeping file") -> Path:
    """Check, before any work, a file gyroarray keeps in an output folder and will replace or
    append to (a sweep's ``sweep.json`` and ``rows.sha256``).

    It may be absent; if present it must be a regular file (not a symbolic
    link: gyroarray makes none, so one there is someone else's, and writing
    through it would modify the file it points to), owned by the user who
    runs gyroarray, and not one of the command's ``inputs``.

    Raises
    ------
    InputError
        Naming the path, what is wrong and the way out.
    """
    p = Path(path)
    _refuse_inputs(p, inputs, what)
    try:
        st = os.lstat(p)
    except FileNotFoundError:
        return p
    except OSError as err:
        raise InputError(f"cannot check the {what}: {err.strerror or err}", file=str(p)) from None
    if stat.S_ISLNK(st.st_mode):
        raise InputError(f"the {what} is a symbolic link, which gyroarray did not make; it will "
                         "not write through it: remove the link, or use a new --out folder",
                         file=str(p))
    if not stat.S_ISREG(st.st_mode):
        kind = file_kind(st.st_mode)
        raise InputError(f"the {what} is {kind}; gyroarray keeps a file there: move it away, or "
                         "use a new --out folder", file=str(p))
    if hasattr(os, "geteuid") and st.st_uid != os.geteuid():
        raise InputError(f"the {what} belongs to another user (uid {st.st_uid}); gyroarray only "
                         "writes to its own files: use a new --out folder", file=str(p))
    return p


def append_line(path, text: str, *, inputs: Iterable = (), what: str = "bookkeeping file") -> Path:
    """Append one line to a file gyroarray keeps (e.g. a sweep's ``rows.sha256``), safely.

    The file is opened with ``O_NOFOLLOW | O_APPEND | O_CREAT`` (a new file
    gets :func:`file_mode`) and checked on the open descriptor: a regular
    file of this user, never a symbolic link, a FIFO or a device, never one of
    the command's ``inputs``. A previous line torn by a crash is ended first,
    so the new line stays whole. If the write fails (a full disk), the file is
    cut back to its length before, so no partial line is kept.

    Parameters
    ----------
    path : path-like
        The file.
    text : str
        The line (a newline is added if missing).
    inputs : iterable of path-like
        Files the command reads: never appended to.
    what : str
        What the file is, for the messages.

    Raises
    ------
    InputError
        One line naming the path, for each refusal and each failure to write.
    """
    p = Path(path)
    _refuse_inputs(p, inputs, what)
    line = (text if text.endswith("\n") else text + "\n").encode("utf-8")
    flags = (os.O_RDWR | os.O_APPEND | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0)
             | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    try:
        fd = os.open(p, flags, file_mode())
    except OSError as err:
        if err.errno == errno.ELOOP or p.is_symlink():
            check_own_file(p, what=what)            # says: a symbolic link
        if err.errno in (errno.EISDIR, errno.ENXIO):
            check_own_file(p, what=what)            # says: a folder / not a regular file
        raise _refusal(err, p, f"cannot append to the {what}") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode) or (hasattr(os, "geteuid") and st.st_uid != os.geteuid()):
            check_own_file(p, what=what)
            raise InputError(f"the {what} is not a regular file of yours", file=str(p))
        size = st.st_size
        if size and os.pread(fd, 1, size - 1) != b"\n":
            line = b"\n" + line                      # end a line torn by a crash
        try:
            _write_all(fd, line)
            os.fsync(fd)
        except OSError as err:
            try:
                os.ftruncate(fd, size)               # no partial line kept
            except OSError:
                pass
            raise _refusal(err, p, f"cannot append to the {what}") from None
    finally:
        os.close(fd)
    return p


def markdown_figures(md_path, names: Iterable[str] = (), *, inputs: Iterable = (),
                     force: bool = False) -> Path:
    """Check, before any work, the folder of a Markdown twin's figures (``<stem>_figures/``).

    The folder may be absent (it is created) or a folder this user can write
    in. Without ``force`` it must not hold any PNG already (a previous
    report's figures would be mixed with, or replaced by, this one's): the
    way out is another ``--md`` name or ``--force``. No figure may be one of
    the command's ``inputs``, whatever ``force`` says. ``names`` are the
    figure names the report may write (without ``.png``), checked too.

    Returns
    -------
    Path
        The figures' folder.
    """
    md = Path(md_path)
    folder = md.with_name(md.stem + "_figures")
    what = "--md"
    if folder.is_symlink() or (folder.exists() and not folder.is_dir()):
        raise InputError(f"{what}: the Markdown figures go to {folder}, which is "
                         + ("a symbolic link" if folder.is_symlink() else "not a folder")
                         + "; move it away, or give another --md name", file=str(md))
    for given in inputs:
        if given is not None and same_path(_resolved(Path(given)).parent, folder) \
                and Path(given).name.lower().endswith(".png"):
            raise InputError(f"{what}: the Markdown figures go to {folder}, which holds an input "
                             f"of this command ({given}); give another --md name", file=str(md))
    for name in names:
        _refuse_inputs(folder / f"{name}.png", inputs, what)
    if folder.is_dir():
        if not force:
            try:
                clash = sorted(q.name for q in folder.iterdir() if q.name.lower().endswith(".png"))
            except OSError as err:
                raise InputError(f"{what}: cannot read the figures' folder {folder}: "
                                 f"{err.strerror or err}", file=str(md)) from None
            if clash:
                raise InputError(f"{what}: the Markdown figures go to {folder}, which already holds "
                                 f"{len(clash)} figure(s) ({clash[0]}...); give another --md name, "
                                 "or --force to replace them", file=str(md))
        if not os.access(folder, os.W_OK | os.X_OK):
            raise InputError(f"{what}: the figures' folder {folder} is not writable", file=str(md))
    else:
        _check_folder(folder.parent if str(folder.parent) else Path("."), what, md)
    return folder


def private_matplotlib_dir() -> str | None:
    """Keep matplotlib out of the user's home: point ``MPLCONFIGDIR`` at a private folder.

    Without it matplotlib writes its font cache to ``~/.cache/matplotlib``
    (and creates ``~/.config/matplotlib``). Called by the CLI before anything
    imports matplotlib. A ``MPLCONFIGDIR`` the user set is left alone (also
    when matplotlib is already imported: then it is too late to change).
    The folder is ``gyroarray-mpl-<uid>`` in the system's temporary folder,
    created with mode 0700 and used only if it is a real folder of this user
    that nobody else can write (else a fresh private folder is made), so the
    font cache is built once per boot (measured: 0.3-0.8 s more than a warm
    cache) and then reused.

    Returns
    -------
    str or None
        The folder set, or None when nothing was changed.
    """
    if os.environ.get("MPLCONFIGDIR") or "matplotlib" in sys.modules:
        return None
    uid = os.geteuid() if hasattr(os, "geteuid") else 0
    made = os.path.join(tempfile.gettempdir(), f"gyroarray-mpl-{uid}")
    folder: str | None = made
    try:
        os.mkdir(made, 0o700)
    except FileExistsError:
        pass
    except OSError:
        folder = None
    if folder is not None:
        try:
            st = os.lstat(folder)
            if not (stat.S_ISDIR(st.st_mode) and st.st_uid == uid and not st.st_mode & 0o077):
                folder = None
        except OSError:
            folder = None
    if folder is None:
        try:
            folder = tempfile.mkdtemp(prefix="gyroarray-mpl-")
        except OSError:
            return None
    os.environ["MPLCONFIGDIR"] = folder
    return folder
