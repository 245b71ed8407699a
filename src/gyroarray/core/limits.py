"""Sizes and shapes checked before anything is allocated or read.

Every input of gyroarray comes through here before it costs memory or
blocks:

* :func:`open_regular` opens a path the user named only if it is a regular
  file (a FIFO, a device or a folder is refused without ever blocking: the
  file is opened non-blocking and checked with ``fstat`` on the open
  descriptor, so nothing can be swapped in between);
* :func:`read_regular` reads it whole, refusing a file larger than a cap;
* :func:`gunzip_bounded` decompresses gzip (every member) in pieces and stops
  at a cap, so a gzip bomb ends with a message instead of the machine's
  memory; :func:`decompress_bounded` does the same for bz2, zstd and lz4
  (ROS bag chunks), into memory or a file, and :func:`check_disk_space`
  refuses writing more than a folder's free space;
* :func:`check_memory` compares an estimate of what a step will allocate
  with the memory budget (:func:`max_memory`) and refuses with the size
  needed and the way out, before the step runs.

The budget is half the machine's memory (or of the container's limit when
that is lower); the CLI's ``--max-memory SIZE`` or the environment variable
``GYROARRAY_MAX_MEMORY`` set another one.
"""

from __future__ import annotations

import bz2
import contextlib
import functools
import errno
import json
import math
import os
import re
import shutil
import stat
import zlib
from pathlib import Path

from gyroarray.core.errors import InputError

__all__ = ["MAX_RATE_DEG_S", "file_kind", "MEMORY_FRACTION", "max_memory", "set_max_memory", "memory_budget",
           "parse_size", "format_size", "check_memory", "open_regular", "read_regular",
           "gunzip_bounded", "read_json", "MAX_JSON_DEPTH", "MAX_JSON_BYTES", "STREAM_BUDGET_BYTES",
           "STREAM_WORK_BYTES", "stream_work_bytes", "decompress_bounded", "check_disk_space"]

#: Largest angular rate a gyro (or a rate table) can physically see [deg/s];
#: beyond it a value is a unit or logging error, not a measurement.
MAX_RATE_DEG_S = 1e5
#: Share of the machine's memory gyroarray may plan to use by default [-].
MEMORY_FRACTION = 0.5
#: Environment variable that overrides the default budget (a size, e.g. ``8G``).
ENV_MAX_MEMORY = "GYROARRAY_MAX_MEMORY"
#: A record whose reading into memory is estimated to need more than this [bytes] (or more than
#: the memory budget, :func:`max_memory`) is streamed by ``gyroarray allan``: read in chunks
#: twice, never whole (``allan --stream`` streams any record). 2 GiB: 1e7 samples x 4 gyros of
#: Parquet (about 2e8 bytes whole) stay in memory, 1e8 samples are streamed.
STREAM_BUDGET_BYTES = 2 * 2**30
#: Working memory [bytes] a streamed analysis plans for (chunks of samples, windows of the
#: phase), beyond the interpreter and its libraries; at most a quarter of the memory budget
#: (:func:`stream_work_bytes`). Independent of the record's length.
STREAM_WORK_BYTES = 256 * 2**20

_override: int | None = None
_UNITS = {"": 1, "b": 1, "k": 2**10, "kb": 10**3, "kib": 2**10, "m": 2**20, "mb": 10**6,
          "mib": 2**20, "g": 2**30, "gb": 10**9, "gib": 2**30, "t": 2**40, "tb": 10**12,
          "tib": 2**40}
_SIZE_RE = re.compile(r"\s*([0-9]+(?:\.[0-9]*)?(?:[eE][+-]?[0-9]+)?)\s*([A-Za-z]*)\s*")


def parse_size(text: str, what: str = "--max-memory") -> int:
    """Bytes in a size such as ``8G``, ``512MiB``, ``1.5e9`` (binary K/M/G/T)."""
    m = _SIZE_RE.fullmatch(str(text))
    unit = m.group(2).lower() if m else ""
    if not m or unit not in _UNITS:
        raise InputError(f"{what} must be a size such as 8G, 512M or 2000000000, got {text!r}")
    value = float(m.group(1)) * _UNITS[unit]
    if not (math.isfinite(value) and 1 <= value < 2**62):
        raise InputError(f"{what} must be between 1 byte and 4 EiB, got {text!r}")
    return int(value)


def format_size(nbytes: float) -> str:
    """``34.9 GiB`` style."""
    for unit, size in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if nbytes >= size:
            return f"{nbytes / size:.3g} {unit}"
    return f"{int(nbytes)} bytes"


@functools.lru_cache(maxsize=1)
def _machine_memory() -> int:
    try:
        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        total = 8 * 2**30
    for cgroup in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        try:
            text = Path(cgroup).read_text().strip()
        except OSError:
            continue
        if text.isdigit() and 0 < int(text) < total:
            total = int(text)
    return int(total)


def max_memory() -> int:
    """The memory budget [bytes]: ``--max-memory``, else ``$GYROARRAY_MAX_MEMORY``,
    else :data:`MEMORY_FRACTION` of the machine's (or container's) memory."""
    if _override is not None:
        return _override
    env = os.environ.get(ENV_MAX_MEMORY)
    if env:
        return parse_size(env, ENV_MAX_MEMORY)
    return int(MEMORY_FRACTION * _machine_memory())


def stream_work_bytes() -> int:
    """Working memory [bytes] of a streamed analysis: :data:`STREAM_WORK_BYTES`, at most a
    quarter of :func:`max_memory` (and at least 64 KiB)."""
    return max(1 << 16, min(STREAM_WORK_BYTES, max_memory() // 4))


def set_max_memory(nbytes: int | None) -> None:
    """Set (or with None clear) the budget for this process."""
    global _override
    _override = None if nbytes is None else int(nbytes)


@contextlib.contextmanager
def memory_budget(nbytes: int | None):
    """Run a block with another budget (None: leave it as it is)."""
    before = _override
    if nbytes is not None:
        set_max_memory(nbytes)
    try:
        yield
    finally:
        set_max_memory(before)


def check_memory(nbytes: float, what: str, way_out: str, *, file: str | None = None,
                 line: int | None = None, column: str | None = None) -> None:
    """Refuse a step that would allocate more than the budget.

    Parameters
    ----------
    nbytes : float
        Estimated peak allocation of the step [bytes].
    what : str
        What needs it, e.g. ``"1000 h at 100 Hz x 6 gyros"``.
    way_out : str
        How to get under the budget, e.g. ``"lower sample_rate_hz"``.
    """
    limit = max_memory()
    if nbytes > limit:
        raise InputError(f"{what} needs about {format_size(nbytes)} of memory, more than the "
                         f"limit of {format_size(limit)}; {way_out}, or raise the limit with "
                         "--max-memory SIZE", file=file, line=line, column=column)


_KINDS = ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
          (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
          (stat.S_ISSOCK, "a socket"))


def file_kind(mode: int) -> str:
    """What a non-regular file is, in words (``a FIFO (named pipe)``), from its ``st_mode``."""
    return next((word for test, word in _KINDS if test(mode)), "not a regular file")


def open_regular(path, what: str = "file"):
    """Open ``path`` for binary reading if it is a regular file; never blocks.

    Returns a file object. A folder, FIFO, device or socket is refused with
    an :class:`InputError` naming the path and what it is.
    """
    name = str(path)
    try:
        fd = os.open(name, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError:
        raise InputError(f"{what} not found", file=name) from None
    except IsADirectoryError:
        raise InputError(f"{what} expected, but this is a folder", file=name) from None
    except OSError as err:
        if err.errno == errno.ENXIO:     # a socket, or a FIFO opened in another mode
            raise InputError(f"{what} expected, but this is not a regular file", file=name) from None
        raise InputError(f"cannot read {what}: {err.strerror or err}", file=name) from None
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            raise InputError(f"{what} expected, but this is {file_kind(mode)}", file=name)
        if hasattr(os, "set_blocking"):
            os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def read_regular(path, what: str = "file", max_bytes: int | None = None) -> bytes:
    """The bytes of a regular file (:func:`open_regular`), at most ``max_bytes``.

    ``max_bytes`` defaults to a quarter of the memory budget.
    """
    cap = max_memory() // 4 if max_bytes is None else int(max_bytes)
    name = str(path)
    with open_regular(path, what) as fh:
        size = os.fstat(fh.fileno()).st_size
        if size > cap:
            raise InputError(f"{what} is {format_size(size)}, more than the {format_size(cap)} "
                             "gyroarray reads (raise --max-memory for a larger file)", file=name)
        try:
            data = fh.read(size + 1) if size else _read_capped(fh, cap)
        except OSError as err:
            raise InputError(f"cannot read {what}: {err.strerror or err}", file=name) from None
    if len(data) > cap:
        raise InputError(f"{what} grew beyond {format_size(cap)} while being read", file=name)
    return data


#: Deepest nesting of arrays/objects gyroarray reads in a JSON file [-] (its own files nest < 10).
MAX_JSON_DEPTH = 64
#: Largest JSON file gyroarray reads [bytes] (also at most a sixteenth of the memory budget:
#: parsed JSON takes about ten times its text).
MAX_JSON_BYTES = 256 * 2**20


def _json_depth_over(obj, cap: int) -> str | None:
    """The path (``scenarios[3].params``) where ``obj`` nests deeper than ``cap``, or None
    (iterative: no recursion)."""
    stack = [(obj, 1, "")]
    while stack:
        node, depth, path = stack.pop()
        if not isinstance(node, (dict, list)):
            continue
        if depth > cap:
            return path or "(top)"
        items = node.items() if isinstance(node, dict) else enumerate(node)
        for k, v in items:
            if isinstance(v, (dict, list)):
                stack.append((v, depth + 1, f"{path}[{k}]" if isinstance(k, int)
                              else f"{path}.{k}".lstrip(".")))
    return None


def read_json(path, what: str = "JSON file", *, max_bytes: int | None = None,
              max_depth: int = MAX_JSON_DEPTH, expect: type | None = dict):
    """Parse a JSON file the user gave, bounded in size, depth and time; never blocks.

    The file is read with :func:`read_regular` (a FIFO, device, socket or
    folder is refused at once, ``/dev/zero`` included), at most ``max_bytes``
    (default: :data:`MAX_JSON_BYTES`, or a sixteenth of the memory budget when
    that is less). Non-finite numbers (``NaN``, ``Infinity``) are refused.

    Parameters
    ----------
    path : path-like
        The file.
    what : str
        What the file is, for the messages (e.g. ``"design result"``).
    max_bytes : int, optional
        Largest file read [bytes].
    max_depth : int
        Deepest nesting of arrays and objects [-].
    expect : type or None
        The type the top level must have (``dict``: a JSON object); None: any.

    Returns
    -------
    object
        The parsed document.

    Raises
    ------
    InputError
        Naming the file (and the line and column of a syntax error): not a
        regular file, too large, not UTF-8, not JSON, nested deeper than
        ``max_depth``, or not of the ``expect`` type at its top.
    """
    name = str(path)
    cap = min(MAX_JSON_BYTES, max(max_memory() // 16, 1 << 20)) if max_bytes is None else int(max_bytes)
    data = read_regular(path, what, max_bytes=cap)
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        raise InputError(f"{what} is not UTF-8 text (byte {err.start}): not a JSON file",
                         file=name) from None

    def no_constant(word):
        raise ValueError(f"{word} is not a finite number")

    too_deep = (f"{what} nests arrays/objects more than {max_depth} deep (gyroarray reads JSON at "
                f"most {max_depth} levels deep): not a file gyroarray wrote")
    try:
        obj = json.loads(text, parse_constant=no_constant)
    except RecursionError:
        raise InputError(too_deep, file=name) from None
    except json.JSONDecodeError as err:
        raise InputError(f"{what} is not valid JSON: {err.msg}", file=name, line=err.lineno,
                         column=err.colno) from None
    except ValueError as err:
        raise InputError(f"{what} is not valid JSON: {err}", file=name) from None
    if _json_depth_over(obj, max_depth) is not None:
        raise InputError(too_deep, file=name)
    if expect is not None and not isinstance(obj, expect):
        kinds: dict[type, str] = {dict: "an object", list: "an array", str: "a string",
                                  bool: "true/false", type(None): "null"}
        kind = kinds.get(type(obj), "a number")
        wants: dict[type, str] = {dict: "object ({...})", list: "array ([...])"}
        want = wants.get(expect, expect.__name__)
        raise InputError(f"{what} must be a JSON {want} at its top, but it is {kind}: not the "
                         "file gyroarray wrote (was it edited or replaced?)", file=name)
    return obj


_GZIP_PIECE = 1 << 20


def _read_capped(fh, cap: int) -> bytes:
    """Read a file whose size is not known (st_size 0) in pieces, at most ``cap + 1`` bytes."""
    out = bytearray()
    while len(out) <= cap:
        piece = fh.read(min(_GZIP_PIECE, cap + 1 - len(out)))
        if not piece:
            break
        out += piece
    return bytes(out)


def gunzip_bounded(data: bytes, max_bytes: int, name: str, cost=None, max_cost: float = math.inf
                   ) -> bytes:
    """Decompress every gzip member of ``data``, refusing more than ``max_bytes`` of output.

    ``cost(piece)``, when given, estimates the memory [bytes] a decompressed
    piece will take once parsed; decompression also stops when the summed
    cost passes ``max_cost`` (said with :func:`check_memory`'s message).

    Raises
    ------
    InputError
        Invalid gzip data, or output beyond ``max_bytes`` (said with both
        sizes; the decompression stops there).
    """
    out = bytearray()
    pos, spent = 0, 0.0
    while pos < len(data):
        d = zlib.decompressobj(wbits=31)
        chunk = data[pos:]
        try:
            while True:
                piece = d.decompress(chunk, _GZIP_PIECE)
                out += piece
                if cost is not None:
                    spent += cost(piece)
                    if spent > max_cost:
                        check_memory(spent, f"reading what {format_size(len(data))} of gzip "
                                     f"expand to (at least {format_size(len(out))} so far)",
                                     "split the record", file=name)
                if len(out) > max_bytes:
                    raise InputError(
                        f"decompresses to more than {format_size(max_bytes)} (from "
                        f"{format_size(len(data))} compressed); stopped there: gyroarray refuses "
                        "a file this large (raise --max-memory if it is a real record)", file=name)
                chunk = d.unconsumed_tail
                if d.eof or (not chunk and not piece):
                    break
        except zlib.error as err:
            raise InputError(f"not a valid gzip file (the name ends in .gz): {err}", file=name) from None
        if not d.eof:
            raise InputError("not a valid gzip file (the name ends in .gz): the compressed data "
                             "ends early (truncated file?)", file=name)
        rest = d.unused_data
        pos = len(data) - len(rest)
        if rest and not rest.startswith(b"\x1f\x8b"):
            if rest.strip(b"\x00"):
                raise InputError("not a valid gzip file (the name ends in .gz): trailing garbage "
                                 "after the last member", file=name)
            break
    return bytes(out)


# -- bounded decompression of bz2 / zstd / lz4 and the free space of a folder (ROS bags) -----
def _decompressor(fmt: str):
    """A new streaming decompressor of ``fmt`` (``bz2``, ``zstd``, ``lz4``) with
    ``decompress(data, max_length)``, ``eof``, ``unused_data`` and ``needs_input``."""
    if fmt == "bz2":
        return bz2.BZ2Decompressor()
    if fmt == "zstd":
        try:
            from compression import zstd  # type: ignore[import-not-found]
        except ImportError:  # Python < 3.14: the backport rosbags depends on
            from backports import zstd  # type: ignore[import-not-found,no-redef,unused-ignore]
        return zstd.ZstdDecompressor()
    if fmt == "lz4":
        import lz4.frame  # type: ignore[import-untyped]
        return lz4.frame.LZ4FrameDecompressor()
    raise ValueError(f"unknown compression {fmt!r}")


def decompress_bounded(data, fmt: str, max_bytes: int, name: str | None, what: str = "the data",
                       sink=None) -> bytes:
    """Decompress ``data`` (every concatenated stream/frame of ``fmt``: ``bz2``, ``zstd`` or
    ``lz4``) in pieces of at most 1 MiB, refusing more than ``max_bytes`` of output.

    With ``sink`` (a callable taking each piece) the pieces go there and b"" is returned
    (nothing is held in memory: decompression to a file).

    Raises
    ------
    InputError
        Naming ``name``: output beyond ``max_bytes`` (the decompression stops there, said
        with both sizes), or data that is not valid ``fmt`` (truncated, corrupt).
    """
    out = bytearray()
    total = 0
    rest = data if isinstance(data, bytes) else bytes(data)
    try:
        while rest:
            d = _decompressor(fmt)
            chunk = rest
            while not d.eof:
                piece = d.decompress(chunk, _GZIP_PIECE)
                chunk = b""
                total += len(piece)
                if total > max_bytes:
                    raise InputError(
                        f"{what} decompresses to more than {format_size(max_bytes)} (from "
                        f"{format_size(len(data))} of {fmt}); stopped there: more than gyroarray "
                        "decompresses (raise --max-memory if it is a real record)", file=name)
                if sink is not None:
                    sink(piece)
                else:
                    out += piece
                if not piece and d.needs_input:
                    break
            if not d.eof:
                raise InputError(f"{what}: the {fmt} data ends early (truncated or corrupt)",
                                 file=name)
            rest = d.unused_data
    except InputError:
        raise
    except Exception as err:  # bz2/zstd/lz4 errors (OSError, ZstdError, RuntimeError): corrupt
        raise InputError(f"{what} is not valid {fmt} data ({type(err).__name__}: "
                         f"{' '.join(str(err).split())[:120]})", file=name) from None
    return bytes(out)


def check_disk_space(folder, nbytes: float, what: str, *, file: str | None = None,
                     margin: int = 64 << 20) -> None:
    """Refuse writing ``nbytes`` into ``folder`` when its file system has less free (plus a
    ``margin``), saying how much is needed and how much is free."""
    try:
        free = shutil.disk_usage(folder).free
    except OSError as err:
        raise InputError(f"cannot see the free space of {folder}: {err.strerror or err}",
                         file=file) from None
    if nbytes + margin > free:
        raise InputError(f"{what} needs {format_size(nbytes)} of disk in {folder}, but only "
                         f"{format_size(free)} is free; free some space or point $TMPDIR at a "
                         "larger disk", file=file)


# -- lines of text read with a bounded length (CSV headers, streamed CSV rows) ---------------
#: Longest line of text gyroarray reads from a file the user gave [bytes]: a measurement row is
#: under 1 KiB and a CSV header of the most columns a measurement may have well under 100 KiB;
#: a longer run without a newline is not a CSV of samples (a sparse file, a binary file).
MAX_LINE_BYTES = 1 << 20


def read_line_bounded(fh, max_bytes: int = MAX_LINE_BYTES) -> tuple[bytes, bool]:
    """The next line of the binary stream ``fh`` (its ``\\n`` kept; ``b""`` at the end of the
    stream), and False when it runs past ``max_bytes`` without a newline (then the bytes are
    its first ``max_bytes + 1``, the rest unread).

    At most ``max_bytes + 1`` bytes are read (``readline(size)``), never the whole line: a file
    whose first line never ends (a sparse file of zeros, a gzip of one) costs ``max_bytes`` of
    memory, not its size.
    """
    raw = fh.readline(int(max_bytes) + 1)
    return raw, not (len(raw) > max_bytes and not raw.endswith(b"\n"))
