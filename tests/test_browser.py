"""Headless-Chromium check used by the report tests: it must see loaded figures and catch errors.

Synthetic pages only (independent of the report's content).  Tests (b)-(f)
are the "can it fail?" half: each page is broken in one way and the check
must say so.
"""

from __future__ import annotations

import base64
import io
import struct
import zlib
from pathlib import Path

import pytest

from gyroarray.reports.browser import BrowserCheck, find_chromium, render_check

pytestmark = pytest.mark.skipif(
    find_chromium() is None, reason="chromium not installed: apt-get install chromium"
)


def png_bytes(width: int, height: int, rgb: tuple[int, int, int] = (200, 30, 30)) -> bytes:
    """A valid truecolour PNG written by hand (signature, IHDR, IDAT, IEND)."""

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    row = b"\x00" + bytes(rgb) * width  # filter type 0 per scanline
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", ihdr)
        + chunk(b"IDAT", zlib.compress(row * height))
        + chunk(b"IEND", b"")
    )


def matplotlib_png() -> bytes:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(2, 1.5), dpi=50)
    ax.plot([0, 1, 2], [0, 1, 0])
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    plt.close(fig)
    return buf.getvalue()


def data_uri(png: bytes) -> str:
    return "data:image/png;base64," + base64.b64encode(png).decode("ascii")


SVG = '<svg xmlns="http://www.w3.org/2000/svg" width="40" height="20"><rect width="40" height="20" fill="teal"/></svg>'


def page(tmp_path: Path, body: str, title: str = "synthetic report") -> Path:
    path = tmp_path / "report.html"
    path.write_text(
        f'<!doctype html>\n<html><head><meta charset="utf-8"><title>{title}</title></head>\n'
        f"<body>\n{body}\n</body></html>\n",
        encoding="utf-8",
    )
    return path


def check(path: Path, **kw: float) -> BrowserCheck:
    result = render_check(path, **kw)
    print(result.summary())  # shown by pytest on failure; timing for the CI budget
    return result


def test_png_data_uris_and_inline_svg_all_load(tmp_path):
    body = "\n".join(
        [
            "<h1>Figures</h1>",
            f'<img alt="hand-made" src="{data_uri(png_bytes(7, 5))}">',
            f'<img alt="matplotlib" src="{data_uri(matplotlib_png())}">',
            SVG,
        ]
    )
    result = check(page(tmp_path, body, title="all good"))
    assert result.ok, result.summary()
    assert result.title == "all good"
    assert (result.images_total, result.images_loaded) == (2, 2)
    assert (result.svg_total, result.svg_rendered) == (1, 1)
    assert result.console_errors == [] and result.network_requests == []


def test_lazy_offscreen_image_is_still_checked(tmp_path):
    # A long report may mark figures loading="lazy"; below the fold they would never load.
    body = f'<div style="height: 20000px"></div><img loading="lazy" src="{data_uri(png_bytes(3, 3))}">'
    result = check(page(tmp_path, body))
    assert result.ok, result.summary()
    assert result.images_loaded == result.images_total == 1


def test_broken_data_uri_image_is_not_loaded(tmp_path):
    body = f'<img src="{data_uri(png_bytes(4, 4))}">\n<img src="data:image/png;base64,AAAA">\n{SVG}'
    result = check(page(tmp_path, body))
    assert not result.ok
    assert result.images_total == 2
    assert result.images_loaded == 1 < result.images_total
    assert result.images_failed == ["data:image/png;base64,AAAA"]


def test_missing_image_file_is_not_loaded_and_logged(tmp_path):
    result = check(page(tmp_path, '<img src="figures/missing.png">'))
    assert not result.ok
    assert (result.images_total, result.images_loaded) == (1, 0)
    assert any("ERR_FILE_NOT_FOUND" in e and "missing.png" in e for e in result.console_errors), result.console_errors


def test_console_error_is_captured(tmp_path):
    result = check(page(tmp_path, '<p>text</p><script>console.error("boom", 42)</script>'))
    assert not result.ok
    assert any("boom" in e for e in result.console_errors), result.console_errors
    assert result.images_total == 0  # a page without figures is otherwise fine


def test_console_assert_is_captured(tmp_path):
    result = check(page(tmp_path, '<script>console.assert(1 === 2, "figures mismatch")</script>'))
    assert any("figures mismatch" in e for e in result.console_errors), result.console_errors


def test_uncaught_exceptions_are_captured(tmp_path):
    body = (
        '<script>throw new TypeError("kaputt-sync")</script>\n'
        '<script>setTimeout(() => { throw new Error("kaputt-timer"); }, 0)</script>\n'
        '<script>Promise.reject(new Error("kaputt-promise"))</script>'
    )
    result = check(page(tmp_path, body))
    assert not result.ok
    for word in ("kaputt-sync", "kaputt-timer", "kaputt-promise"):
        assert any(word in e for e in result.console_errors), (word, result.console_errors)


def test_network_request_is_recorded_and_blocked(tmp_path):
    # Self-contained means no network: the request is reported (and not sent).
    result = check(page(tmp_path, '<img src="https://example.invalid/figure.png">'))
    assert not result.ok
    assert result.network_requests == ["https://example.invalid/figure.png"]
    assert result.images_loaded == 0


def test_page_that_never_loads_times_out_cleanly(tmp_path):
    path = page(tmp_path, "<script>while (true) {}</script>")
    with pytest.raises(RuntimeError, match="timed out"):
        render_check(path, timeout_s=4)


def test_missing_file_raises(tmp_path):
    with pytest.raises(FileNotFoundError):
        render_check(tmp_path / "nope.html")
