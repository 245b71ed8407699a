"""Open an HTML file in headless Chromium and report whether it rendered cleanly.

Used by the tests of ``gyroarray report``: the report must be one
self-contained HTML file that a real browser shows with every figure loaded,
no console error and no network access.

How it works
------------
Chromium is started headless with a throw-away profile and
``--remote-debugging-pipe``.  With that flag the browser speaks the Chrome
DevTools Protocol (CDP) over two inherited file descriptors instead of a
websocket: it *reads* commands from fd 3 and *writes* replies and events to
fd 4.  Every message is one UTF-8 JSON object terminated by a NUL byte::

    -> {"id": 1, "method": "Target.createTarget", "params": {...}}\\0
    <- {"id": 1, "result": {"targetId": "..."}}\\0
    <- {"method": "Target.targetCreated", "params": {...}}\\0

Commands carry an ``id`` that the reply echoes; events have a ``method`` and
no ``id``.  The pipe talks to the *browser* target, so we create a page
(``Target.createTarget``), attach to it in "flat" mode
(``Target.attachToTarget`` with ``flatten: true``) and address the page's
commands by adding the returned ``sessionId`` to each message.

In the page session we enable ``Runtime`` (console API calls and uncaught
exceptions), ``Log`` (browser-side errors such as "Failed to load resource"),
``Network`` (to see, and block, any request that leaves the file) and
``Page`` (for the load event), navigate to the ``file://`` URL, wait for
``Page.loadEventFired`` and finally ``Runtime.evaluate`` a small script that
waits for pending images and returns their state.

The pipe ends must sit at exactly fds 3 and 4 in the child.  The browser is
spawned with :func:`os.posix_spawn`, whose ``dup2`` file actions place them
there without a ``preexec_fn`` (which is unsafe in threaded processes such as
a pytest run that has used Dask); ``setsid`` puts the browser and all its
helper processes in one process group, which is killed on the way out.  No
Python dependency beyond the standard library is needed.
"""

from __future__ import annotations

import fcntl
import json
import os
import select
import shutil
import signal
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["BrowserCheck", "find_chromium", "render_check"]

#: Executable names tried, in order, on PATH.
CHROMIUM_NAMES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
#: Environment variable naming the browser executable (a path or a name on PATH).
CHROMIUM_ENV = "GYROARRAY_CHROMIUM"

CHROMIUM_FLAGS = (
    "--headless=new",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-dev-shm-usage",  # small /dev/shm in containers crashes renderers
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--disable-extensions",
    "--disable-default-apps",
    "--no-first-run",
    "--no-default-browser-check",
    "--mute-audio",
    "--remote-debugging-pipe",
)

#: Schemes a self-contained report may load; anything else is recorded and blocked.
LOCAL_SCHEMES = ("data:", "file:", "about:", "blob:", "chrome-error:", "devtools:")
#: Blocked by ``Network.setBlockedURLs``: nothing may leave the machine.
BLOCKED_URL_PATTERNS = ("http://*", "https://*", "ws://*", "wss://*", "ftp://*")

# Runs in the page after the load event.  Lazy images are made eager and every
# image that is not complete yet is awaited (load or error), then one animation
# frame plus a short timeout lets late console errors (timers) arrive.
_STATUS_JS = r"""
(async () => {
  if (document.readyState !== "complete") {
    await new Promise((done) => window.addEventListener("load", done, {once: true}));
  }
  const imgs = Array.from(document.images);
  for (const img of imgs) { if (img.loading === "lazy") img.loading = "eager"; }
  await Promise.all(imgs.map((img) => img.complete ? null : new Promise((done) => {
    img.addEventListener("load", done, {once: true});
    img.addEventListener("error", done, {once: true});
  })));
  await new Promise((done) => requestAnimationFrame(() => setTimeout(done, %(settle_ms)d)));
  const shortSrc = (s) => s.length > 120 ? s.slice(0, 117) + "..." : s;
  const svgs = Array.from(document.querySelectorAll("svg")).filter(
    (s) => !(s.parentElement && s.parentElement.closest("svg")));
  const svgRendered = (s) => { const r = s.getBoundingClientRect(); return r.width > 0 && r.height > 0; };
  return {
    title: document.title,
    href: location.href,
    images_total: imgs.length,
    images_loaded: imgs.filter((i) => i.complete && i.naturalWidth > 0).length,
    images_failed: imgs.filter((i) => !(i.complete && i.naturalWidth > 0))
                       .map((i) => shortSrc(i.currentSrc || i.src || i.outerHTML)),
    svg_total: svgs.length,
    svg_rendered: svgs.filter(svgRendered).length,
  };
})()
"""


@dataclass
class BrowserCheck:
    """What headless Chromium saw when it opened one HTML file."""

    url: str
    title: str
    images_total: int
    images_loaded: int
    svg_total: int
    svg_rendered: int
    images_failed: list[str] = field(default_factory=list)
    console_errors: list[str] = field(default_factory=list)
    network_requests: list[str] = field(default_factory=list)
    seconds: float = 0.0

    @property
    def ok(self) -> bool:
        """Every image decoded, every inline SVG laid out, no error, no network."""
        return not self.problems()

    def problems(self) -> list[str]:
        """Human-readable list of everything that is wrong (empty when ``ok``)."""
        out: list[str] = []
        if self.images_loaded != self.images_total:
            out.append(
                f"{self.images_total - self.images_loaded} of {self.images_total} images not loaded: "
                + ", ".join(self.images_failed)
            )
        if self.svg_rendered != self.svg_total:
            out.append(f"{self.svg_total - self.svg_rendered} of {self.svg_total} inline SVGs have no size")
        out.extend(f"console error: {msg}" for msg in self.console_errors)
        out.extend(f"network request: {url}" for url in self.network_requests)
        return out

    def summary(self) -> str:
        """One line for assertion messages and logs."""
        head = (
            f"{self.url}: {self.images_loaded}/{self.images_total} images, "
            f"{self.svg_rendered}/{self.svg_total} svg, {len(self.console_errors)} console errors, "
            f"{len(self.network_requests)} network requests, {self.seconds:.2f} s"
        )
        problems = self.problems()
        return head if not problems else head + "\n  " + "\n  ".join(problems)


def find_chromium() -> str | None:
    """Path of a Chromium/Chrome executable, or None when there is none.

    ``$GYROARRAY_CHROMIUM`` wins when set (a path or a name on PATH); an empty
    value is ignored.  Otherwise ``chromium``, ``chromium-browser`` and
    ``google-chrome`` are looked up on PATH.
    """
    override = os.environ.get(CHROMIUM_ENV, "").strip()
    if override:
        found = shutil.which(override)
        return str(Path(found).resolve()) if found else None
    for name in CHROMIUM_NAMES:
        found = shutil.which(name)
        if found:
            return found
    return None


class _CDPPipe:
    """Chrome DevTools Protocol over the two ``--remote-debugging-pipe`` fds."""

    def __init__(self, to_browser: int, from_browser: int, deadline: float, what: str) -> None:
        self._out = to_browser
        self._in = from_browser
        self._buf = b""
        self._next_id = 0
        self.deadline = deadline
        self.what = what
        self.events: list[dict[str, Any]] = []

    def _read_message(self) -> dict[str, Any]:
        while b"\0" not in self._buf:
            left = self.deadline - time.monotonic()
            if left <= 0:
                raise TimeoutError
            ready, _, _ = select.select([self._in], [], [], left)
            if not ready:
                raise TimeoutError
            chunk = os.read(self._in, 1 << 16)
            if not chunk:
                raise EOFError("the browser closed the DevTools pipe (it exited)")
            self._buf += chunk
        raw, self._buf = self._buf.split(b"\0", 1)
        msg: dict[str, Any] = json.loads(raw)
        return msg

    def send(self, method: str, params: dict[str, Any] | None = None, session: str | None = None) -> dict[str, Any]:
        """Send one command and return its ``result``; events seen meanwhile are queued."""
        self._next_id += 1
        msg: dict[str, Any] = {"id": self._next_id, "method": method, "params": params or {}}
        if session is not None:
            msg["sessionId"] = session
        data = json.dumps(msg).encode() + b"\0"
        while data:
            data = data[os.write(self._out, data):]
        while True:
            reply = self._read_message()
            if reply.get("id") == self._next_id:
                if "error" in reply:
                    raise RuntimeError(f"{self.what}: CDP {method} failed: {reply['error']}")
                result: dict[str, Any] = reply.get("result", {})
                return result
            if "method" in reply:
                self.events.append(reply)

    def wait_for(self, method: str, session: str | None = None) -> dict[str, Any]:
        """Block until the event ``method`` arrives (checking the queue first)."""
        for ev in self.events:
            if ev["method"] == method and (session is None or ev.get("sessionId") == session):
                return ev
        while True:
            ev = self._read_message()
            if "method" in ev:
                self.events.append(ev)
                if ev["method"] == method and (session is None or ev.get("sessionId") == session):
                    return ev


def _remote_object_text(obj: dict[str, Any]) -> str:
    if "value" in obj:
        v = obj["value"]
        return v if isinstance(v, str) else json.dumps(v)
    return str(obj.get("description") or obj.get("unserializableValue") or obj.get("type", "?"))


def _collect(events: list[dict[str, Any]], session: str) -> tuple[list[str], list[str]]:
    """Console errors and non-local network requests from the page session's events."""
    errors: list[str] = []
    requests: list[str] = []
    for ev in events:
        if ev.get("sessionId") != session:
            continue
        method, p = ev["method"], ev.get("params", {})
        if method == "Runtime.consoleAPICalled" and p.get("type") in ("error", "assert"):
            text = " ".join(_remote_object_text(a) for a in p.get("args", []))
            errors.append(f"console.{p['type']}: {text}".rstrip())
        elif method == "Runtime.exceptionThrown":
            d = p.get("exceptionDetails", {})
            exc = d.get("exception") or {}
            text = exc.get("description") or d.get("text", "exception")
            where = f" ({d['url']}:{d.get('lineNumber', 0) + 1})" if d.get("url") and d["url"] not in text else ""
            errors.append(f"uncaught: {text}{where}")
        elif method == "Log.entryAdded":
            e = p.get("entry", {})
            if e.get("level") == "error":
                where = f" ({e['url']})" if e.get("url") else ""
                errors.append(f"{e.get('source', 'browser')}: {e.get('text', '')}{where}")
        elif method == "Network.requestWillBeSent":
            url = p.get("request", {}).get("url", "")
            if url and not url.startswith(LOCAL_SCHEMES):
                requests.append(url)
    return errors, requests


def _log_tail(path: Path, n: int = 15) -> str:
    try:
        lines = path.read_text(errors="replace").splitlines()
    except OSError:
        return ""
    return "\n".join(lines[-n:])


def _spawn_browser(exe: str, workdir: Path, log_path: Path, fds: list[int]) -> tuple[int, int, int]:
    """Start Chromium with the DevTools pipe on fds 3/4: (pid, our command fd, our event fd).

    The pipe ends we keep are appended to ``fds`` (the caller closes them)."""
    cmd_r, cmd_w = os.pipe()  # we write commands, the browser reads them on fd 3
    fds += [cmd_r, cmd_w]
    ev_r, ev_w = os.pipe()  # the browser writes on fd 4, we read
    fds += [ev_r, ev_w]
    # The child-side ends go >= 10 so that the dup2 actions below cannot
    # overwrite one with the other (os.pipe may well return fds 3 and 4).
    for old in (cmd_r, ev_w):
        new = fcntl.fcntl(old, fcntl.F_DUPFD_CLOEXEC, 10)
        fds[fds.index(old)] = new
        os.close(old)
    cmd_r, cmd_w, ev_r, ev_w = fds
    argv = [exe, *CHROMIUM_FLAGS, f"--user-data-dir={workdir / 'profile'}", "about:blank"]
    env = dict(os.environ)
    env.setdefault("HOME", str(workdir))  # the Debian wrapper looks under $HOME
    pid = os.posix_spawn(
        exe,
        argv,
        env,
        file_actions=[
            (os.POSIX_SPAWN_OPEN, 0, os.devnull, os.O_RDONLY, 0),
            (os.POSIX_SPAWN_OPEN, 1, str(log_path), os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600),
            (os.POSIX_SPAWN_DUP2, 1, 2),
            (os.POSIX_SPAWN_DUP2, cmd_r, 3),
            (os.POSIX_SPAWN_DUP2, ev_w, 4),
        ],
        setsid=True,
        setsigdef=(signal.SIGPIPE, signal.SIGXFSZ),  # Python ignores SIGPIPE; don't pass that on
    )
    # The child holds its own copies; close ours so EOF means "browser gone".
    for fd in (cmd_r, ev_w):
        fds.remove(fd)
        os.close(fd)
    return pid, cmd_w, ev_r


def _load_and_check(cdp: "_CDPPipe", path: Path, url: str, settle_ms: int, timeout_s: float,
                    log_path: Path) -> tuple[dict[str, Any], str]:
    """Open ``url`` in a new target over ``cdp`` and run the image/SVG status script:
    (its result, the CDP session id)."""
    stage = "starting the browser"
    try:
        target = cdp.send("Target.createTarget", {"url": "about:blank"})["targetId"]
        session = cdp.send("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
        stage = "enabling CDP domains"
        for domain in ("Runtime", "Log", "Network", "Page"):
            cdp.send(f"{domain}.enable", session=session)
        try:  # experimental CDP method; requests are recorded even if it goes away
            cdp.send("Network.setBlockedURLs", {"urls": list(BLOCKED_URL_PATTERNS)}, session=session)
        except RuntimeError:
            pass
        stage = f"loading {url}"
        cdp.events.clear()
        nav = cdp.send("Page.navigate", {"url": url}, session=session)
        if nav.get("errorText"):
            raise RuntimeError(f"{path}: navigation failed: {nav['errorText']}")
        cdp.wait_for("Page.loadEventFired", session=session)
        stage = "checking images"
        res = cdp.send(
            "Runtime.evaluate",
            {"expression": _STATUS_JS % {"settle_ms": settle_ms}, "awaitPromise": True, "returnByValue": True},
            session=session,
        )
    except TimeoutError:
        raise RuntimeError(
            f"{path}: headless Chromium timed out after {timeout_s:g} s while {stage}\n{_log_tail(log_path)}"
        ) from None
    except EOFError as exc:
        raise RuntimeError(f"{path}: {exc} while {stage}\n{_log_tail(log_path)}") from None
    if "exceptionDetails" in res:
        raise RuntimeError(f"{path}: image check script failed: {res['exceptionDetails']}")
    return res["result"]["value"], session


def render_check(html_path: str | os.PathLike[str], *, timeout_s: float = 60, settle_ms: int = 100) -> BrowserCheck:
    """Open ``html_path`` in headless Chromium and report images, console errors, requests.

    Raises FileNotFoundError when the file is missing, RuntimeError when no
    browser is installed, it dies, or the page does not finish within
    ``timeout_s`` seconds.  The browser (its whole process group) is killed and
    its temporary profile removed in every case.
    """
    path = Path(html_path).resolve()
    if not path.is_file():
        raise FileNotFoundError(path)
    exe = find_chromium()
    if exe is None:
        raise RuntimeError(f"no Chromium found (apt-get install chromium, or set ${CHROMIUM_ENV})")
    url = path.as_uri()
    t0 = time.monotonic()
    workdir = Path(tempfile.mkdtemp(prefix="gyroarray-chromium-"))
    log_path = workdir / "chromium.log"
    pid: int | None = None
    fds: list[int] = []  # our open pipe ends, closed in `finally`
    try:
        pid, cmd_w, ev_r = _spawn_browser(exe, workdir, log_path, fds)
        cdp = _CDPPipe(cmd_w, ev_r, t0 + timeout_s, what=str(path))
        status, session = _load_and_check(cdp, path, url, settle_ms, timeout_s, log_path)
        errors, requests = _collect(cdp.events, session)
        seconds = time.monotonic() - t0
        _close_browser(cdp, pid)
        return BrowserCheck(
            url=url,
            title=str(status.get("title", "")),
            images_total=int(status["images_total"]),
            images_loaded=int(status["images_loaded"]),
            images_failed=[str(s) for s in status.get("images_failed", [])],
            svg_total=int(status["svg_total"]),
            svg_rendered=int(status["svg_rendered"]),
            console_errors=errors,
            network_requests=requests,
            seconds=seconds,
        )
    finally:
        for fd in fds:
            try:
                os.close(fd)
            except OSError:
                pass
        if pid is not None:
            _kill_group(pid)
        shutil.rmtree(workdir, ignore_errors=True)


def _close_browser(cdp: _CDPPipe, pid: int, grace_s: float = 5.0) -> None:
    """Ask the browser to quit (it then reaps its own helpers) and wait up to ``grace_s``."""
    try:
        cdp.deadline = min(cdp.deadline, time.monotonic() + grace_s)
        cdp.send("Browser.close")
    except (TimeoutError, EOFError, RuntimeError, OSError):
        return  # the process group is killed by the caller anyway
    end = time.monotonic() + grace_s
    while time.monotonic() < end:
        try:
            done, _ = os.waitpid(pid, os.WNOHANG)
        except ChildProcessError:
            return
        if done:
            return
        time.sleep(0.02)


def _kill_group(pid: int) -> None:
    """SIGKILL the browser's process group (it is the session leader) and reap it."""
    try:
        os.killpg(pid, signal.SIGKILL)  # also any helper left behind by a reaped browser
    except (ProcessLookupError, PermissionError):
        pass
    try:
        os.waitpid(pid, 0)
    except ChildProcessError:
        pass  # already reaped by _close_browser
