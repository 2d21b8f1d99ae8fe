"""Build the documentation site and serve it on a loopback port, for the browser test and the screenshots.

.venv/bin/python -m tests.docs.site docs/images     # screenshots of the home page and a tutorial
"""

from __future__ import annotations

import functools
import http.server
import os
import subprocess
import sys
import tempfile
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from tests.studio.browser import TIMEOUT_MS, chromium

ROOT = Path(__file__).resolve().parents[2]


def build(site_dir: Path) -> None:
    """``mkdocs build --strict`` into ``site_dir``; raises with mkdocs' output if it fails."""
    done = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(site_dir)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        env={**os.environ, "NO_MKDOCS_2_WARNING": "1"},
    )
    if done.returncode != 0:
        raise RuntimeError(f"mkdocs build --strict failed:\n{done.stderr[-4000:]}")


class _Quiet(http.server.SimpleHTTPRequestHandler):
    def log_message(self, format: str, *args: object) -> None:
        pass


@contextmanager
def serve(site_dir: Path) -> Iterator[str]:
    """Serve ``site_dir`` on a free loopback port; yields the base URL."""
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(_Quiet, directory=str(site_dir)))
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}/"
    finally:
        server.shutdown()
        server.server_close()
        thread.join(30)


@contextmanager
def built_site() -> Iterator[str]:
    """A freshly built site, served; yields its URL."""
    with tempfile.TemporaryDirectory(prefix="site-") as tmp:
        build(Path(tmp))
        with serve(Path(tmp)) as url:
            yield url


def open_page(browser: object, url: str) -> object:
    """A page at ``url`` once its fonts and images have loaded."""
    page = browser.new_page()  # type: ignore[attr-defined]
    page.set_default_timeout(TIMEOUT_MS)
    page.goto(url, wait_until="load")
    return page


def main(out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    with built_site() as url, chromium() as browser:
        page = open_page(browser, url)
        page.set_viewport_size({"width": 1280, "height": 1000})
        page.screenshot(path=out / "site_home.png")
        page = open_page(browser, url + "tutorials/shape_your_env/")
        page.set_viewport_size({"width": 1280, "height": 1000})
        page.locator("img[src$='shape_your_env.png']").scroll_into_view_if_needed()
        page.screenshot(path=out / "site_tutorial.png")
    print(f"wrote {out / 'site_home.png'} and {out / 'site_tutorial.png'}")


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "docs/images"))
