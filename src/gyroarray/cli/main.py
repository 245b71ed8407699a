"""The ``gyroarray`` command line.

Every subcommand takes ``--json``: then stdout carries exactly one JSON
object and nothing else. Bad input gives one line on stderr naming the
file/line/column and the problem, and exit code 2 — never a traceback.

This module builds the parser and runs a command; each command family lives in its own module
with its options, its work and its text (``add_parser(sub)`` and ``cmd_X(args) -> (dict, str)``):
:mod:`~gyroarray.cli.design` (gdop, design), :mod:`~gyroarray.cli.allan` (allan, davar),
:mod:`~gyroarray.cli.simulate` (simulate, run, sweep, report), :mod:`~gyroarray.cli.compare`
(compare, diagnose, fit, ladder) and :mod:`~gyroarray.cli.fdi` (fdi, check); what they share is
in :mod:`~gyroarray.cli.common`.
"""

from __future__ import annotations

import os
import signal
import sys

#: What an interrupt (Ctrl-C, SIGINT) prints, whenever it comes; the exit code is 130.
INTERRUPTED = "gyroarray: interrupted"
EXIT_INTERRUPTED = 130

_sigint = {"program": False,   # this process is the command (console script, python -m)
           "raised": False,    # main's handler raised a KeyboardInterrupt
           "said": False}      # INTERRUPTED is on stderr


def _exit_interrupted(signum=None, frame=None) -> None:
    """SIGINT where nothing is left to clean up (the command line still loading, a second
    interrupt while the first one's clean-ups run, the interpreter exiting): :data:`INTERRUPTED`
    unless it is said, and exit 130 now."""
    if not _sigint["said"]:
        _sigint["said"] = True
        try:
            os.write(2, (INTERRUPTED + "\n").encode())
        except OSError:                 # stderr closed: the exit code says it
            pass
    os._exit(EXIT_INTERRUPTED)


def _raise_interrupt(signum, frame) -> None:
    """SIGINT while :func:`main` runs: a KeyboardInterrupt, so that the command's clean-ups run
    (no temporary file left, workers stopped); in the command's own process a second interrupt
    while they run exits at once."""
    _sigint["raised"] = True
    if _sigint["program"]:
        signal.signal(signal.SIGINT, _exit_interrupted)
    raise KeyboardInterrupt


def _loaded_by_the_program() -> bool:
    """Whether this import is the command's own start: this module runs as ``__main__``, or the
    first frame above the import machinery is the ``__main__`` module's (the console script,
    ``python -m gyroarray.cli``), not a test's, a library's or a spawned worker's
    (``__mp_main__``)."""
    if __name__ == "__main__":
        return True
    frame = sys._getframe(1).f_back             # the frame that imports this module, or importlib's
    while frame is not None and frame.f_code.co_filename.startswith("<frozen importlib"):
        frame = frame.f_back
    return frame is not None and frame.f_globals.get("__name__") == "__main__"


# The first thing, before the imports below (tens of ms): in the command's own process an
# interrupt while the command line loads is the one line and exit 130, not a traceback, until
# main() takes over. A handler someone else set, or SIGINT ignored (`nohup`, `cmd &`), is kept.
try:
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler and _loaded_by_the_program():
        _sigint["program"] = True
        signal.signal(signal.SIGINT, _exit_interrupted)
except ValueError:                              # imported outside the main thread: not ours to set
    pass

import argparse  # noqa: E402 - the imports after the start-up SIGINT handler
import json  # noqa: E402
import re  # noqa: E402
import warnings  # noqa: E402

from gyroarray import __version__  # noqa: E402
from gyroarray.cli import allan, compare, convert, design, fdi, fuse, simulate  # noqa: E402
from gyroarray.cli import export as export_cmd, plan as plan_cmd  # noqa: E402
from gyroarray.cli import parity as parity_cmd  # noqa: E402
from gyroarray.cli import import_ as import_cmd  # noqa: E402
from gyroarray.cli.common import EXIT_FAIL, EXIT_OK, EXIT_USAGE, json_safe  # noqa: E402
from gyroarray.core.errors import InputError, one_line  # noqa: E402


class _Parser(argparse.ArgumentParser):
    """argparse that reports a usage error as one line and exit code 2."""

    plugin_help = False          # True: --help lists the installed plugins

    def error(self, message: str):  # noqa: D401 - argparse API
        raise InputError(f"{message} (see '{self.prog} --help')")

    def format_help(self) -> str:
        text = super().format_help()
        return text + _plugins_help() if getattr(self, "plugin_help", False) else text


def _plugins_help() -> str:
    """What installed third-party code scenario, model and sweep files may load by name."""
    # deferred: importlib.metadata's scan of the installed packages, for --help only
    from gyroarray.core.plugins import EFFECTS_GROUP as EFFECTS, ESTIMATORS_GROUP as ESTIMATORS, installed

    def listed(pairs):
        return "\n".join(f"  {name} = {value}" for name, value in pairs) or "  (none installed)"
    return (f"\ninstalled effect plugins (entry-point group {EFFECTS!r}; imported when the effect "
            f"registry loads, named by scenario and model files):\n{listed(installed(EFFECTS))}\n"
            f"installed estimator plugins (group {ESTIMATORS!r}; imported when --estimators or a "
            f"sweep file names one):\n{listed(installed(ESTIMATORS))}\n"
            "--plugin PATH.py runs that file. --scheduler tcp://... exchanges pickled tasks: use only "
            "a scheduler you trust (README: 'What gyroarray trusts').\n")


def build_parser() -> argparse.ArgumentParser:
    """The ``gyroarray`` argument parser: one subparser per subcommand, each with ``--max-memory``."""
    parser = _Parser(prog="gyroarray", description=__doc__.splitlines()[0])
    parser.plugin_help = True
    parser.add_argument("--version", action="version", version=f"gyroarray {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    design.add_parser(sub)
    allan.add_parser(sub)
    simulate.add_parser(sub)
    compare.add_parser(sub)
    fdi.add_parser(sub)
    fuse.add_parser(sub)
    convert.add_parser(sub)
    export_cmd.add_parser(sub)
    plan_cmd.add_parser(sub)
    parity_cmd.add_parser(sub)
    import_cmd.add_parser(sub)
    for p in sub.choices.values():
        p.add_argument("--max-memory", type=_size, metavar="SIZE",
                       help="memory gyroarray may plan to use, e.g. 8G (default: half the "
                            "machine's; or $GYROARRAY_MAX_MEMORY); larger runs are refused up front")
    return parser


def _size(text: str) -> int:
    """``--max-memory SIZE`` in bytes, refused in one line."""
    from gyroarray.core.limits import parse_size  # deferred: not needed to build the parser
    try:
        return parse_size(text)
    except InputError as err:
        raise argparse.ArgumentTypeError(err.message) from None


#: The argument naming a command's one input file, first found (a refusal that names neither a
#: file nor an argument is about it).
_INPUT_ARGS = ("measurement", "scenario", "sweep")


def _located_input_error(err: InputError, args, argv=()) -> InputError:
    """``err`` located for the user when it names neither a file nor an argument.

    With the command's input file (``MEAS.csv``, ``SCENARIO.toml``, ``SWEEP.toml``) as its
    file: a refusal deep in an analysis then still says which file it is about. A command
    without one (``design``, ``gdop``) gets the option the user gave whose name the message
    uses (``rho = 1 makes ...`` comes from ``--rho``; ``unknown shipped motion profile`` from
    ``--motion``).
    """
    if err.file is not None or args is None or "--" in err.message or err.message.startswith("gyroarray "):
        return err
    for name in _INPUT_ARGS:
        value = getattr(args, name, None)
        if isinstance(value, (str, os.PathLike)):
            return err.with_file(value)
    words = set(re.findall(r"[a-z_]+", err.message.lower()))
    for item in argv or ():
        opt = str(item).split("=", 1)[0]
        dest = opt[2:].replace("-", "_")
        if (opt.startswith("--") and len(dest) >= 3          # not --n: "for N = 4" is no reference
                and any(w == dest or w.startswith(dest + "_") for w in words)):
            return InputError(f"{opt}: {err.message}", line=err.line, column=err.column)
    return err


def main(argv: list[str] | None = None) -> int:
    """Run the CLI; returns the exit code (0 ok, 1 failure, 2 bad input, 130 interrupted).

    An interrupt (SIGINT, Ctrl-C) at any moment, the imports of the commands, the parser and the
    output included, prints :data:`INTERRUPTED` and returns 130, never a traceback; the handler
    the caller had is back on return (the command's own process keeps one that exits 130 at
    once, for the interpreter's exit).
    """
    _sigint["said"] = _sigint["raised"] = False
    previous = signal.getsignal(signal.SIGINT)
    ours = previous is signal.default_int_handler or previous is _exit_interrupted
    try:
        if ours:
            try:
                signal.signal(signal.SIGINT, _raise_interrupt)
            except ValueError:          # not the main thread: signals are not ours to set
                ours = False
        return _main(argv)
    except KeyboardInterrupt:           # outside the command's own try: imports, parser, output
        return _interrupted()
    except Exception:
        if _sigint["raised"]:           # an interrupt that became another error
            return _interrupted()
        raise
    finally:
        if ours:                        # first, before anything can raise
            signal.signal(signal.SIGINT, previous)


def _interrupted() -> int:
    """Print :data:`INTERRUPTED` once (a further interrupt ignored meanwhile); 130."""
    if signal.getsignal(signal.SIGINT) in (_raise_interrupt, _exit_interrupted):
        try:
            signal.signal(signal.SIGINT, signal.SIG_IGN)
        except ValueError:              # not the main thread
            pass
    if not _sigint["said"]:
        print(INTERRUPTED, file=sys.stderr)
        _sigint["said"] = True
    return EXIT_INTERRUPTED


def _main(argv: list[str] | None) -> int:
    """:func:`main` without its SIGINT handling."""
    # deferred: core.outputs (tempfile, shutil) and core.limits: `import gyroarray.cli.main` stays light
    from gyroarray.core.limits import memory_budget
    from gyroarray.core.outputs import private_matplotlib_dir
    private_matplotlib_dir()            # matplotlib's font cache not in the user's home
    from gyroarray.core.outputs import Terminated, handle_termination  # deferred, as above
    if argv is None:    # the CLI's own process: SIGTERM/SIGHUP raise Terminated, clean-ups run
        handle_termination()
    parser = build_parser()
    try:
        with warnings.catch_warnings():
            if not os.environ.get("GYROARRAY_DEBUG"):   # stderr carries one line at most
                warnings.simplefilter("ignore")
            args = parser.parse_args(argv)
            if sys.stdout is None:          # started with stdout closed (`>&-`): refuse before work
                print("gyroarray: cannot write the output to standard output: it is closed; "
                      "redirect it to a file or to /dev/null", file=sys.stderr)
                return EXIT_USAGE
            if getattr(args, "plugin", None):
                from gyroarray.chain.plugins import load_plugins  # deferred: loads numba, the registries
                load_plugins(args.plugin)
            with memory_budget(getattr(args, "max_memory", None)):
                result, text, *code = args.func(args)
    except InputError as err:
        print(f"gyroarray: {_located_input_error(err, locals().get('args'), argv if argv is not None else sys.argv[1:])}", file=sys.stderr)
        return EXIT_USAGE
    except Terminated as stop:     # SIGTERM/SIGHUP: no temporary file left, none half-named
        print(f"gyroarray: {stop}", file=sys.stderr)
        return stop.exit_code
    except KeyboardInterrupt:
        return _interrupted()
    except Exception as err:  # an internal bug, not bad input: keep stderr to one line
        if _sigint["raised"]:   # an interrupt that became another error (a C extension's import)
            return _interrupted()
        if os.environ.get("GYROARRAY_DEBUG"):
            raise
        print(f"gyroarray: internal error: {type(err).__name__}: {one_line(err)} "
              "(set GYROARRAY_DEBUG=1 for the traceback)", file=sys.stderr)
        return EXIT_FAIL
    try:
        if getattr(args, "json", False):
            json.dump(json_safe(result), sys.stdout, allow_nan=False)
            sys.stdout.write("\n")
        else:
            print(text)
        sys.stdout.flush()
    except BrokenPipeError:  # e.g. piped into `head`: not an error of ours
        _stdout_to_devnull()
    except OSError as err:   # a full disk (`> /dev/full`), a read-only descriptor: the user's setup
        _stdout_to_devnull()
        print(f"gyroarray: cannot write the output to standard output: "
              f"{err.strerror or err}; free some space or redirect it elsewhere", file=sys.stderr)
        return EXIT_USAGE
    return code[0] if code else EXIT_OK


def _stdout_to_devnull() -> None:
    """Point file descriptor 1 at /dev/null after a failed write to stdout, so that the
    interpreter's own flush at exit finds a sink and prints no "Exception ignored" traceback."""
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, ValueError, OSError):       # not a real file (a test's StringIO)
        return
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, fd)
    finally:
        os.close(null)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
