"""Helpers of the studio's browser tests and screenshots: a live server and Debian's headless Chromium.

The browser is the system's ``/usr/bin/chromium`` (Debian's ``chromium``
package, which ``make test`` installs) driven by Playwright through its
executable path: nothing downloads a browser build.
"""

from __future__ import annotations

import os
import secrets
import tempfile
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from torchrl_subgoal.studio.server import create_app, serve

CHROMIUM = os.environ.get("STUDIO_CHROMIUM", "/usr/bin/chromium")
#: A name of another site that the browser resolves to this machine, as after a DNS-rebinding attack
#: (``.example`` is reserved: no real site is hidden).
REBOUND_HOST = "evil.example"
#: Flags for a closed network and a root user (see the machine notes): no sandbox, no background traffic;
#: and :data:`REBOUND_HOST` resolving to the loopback address.
CHROMIUM_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    f"--host-resolver-rules=MAP {REBOUND_HOST} 127.0.0.1",
]
#: Generous: CI machines can be busy. Waits poll for a state; nothing sleeps for a fixed time.
TIMEOUT_MS = 120_000


@contextmanager
def live_studio(folder: Path, *, token: bool = True, **kwargs: Any) -> Iterator[tuple[str, Any]]:
    """Serve a studio saving into ``folder`` on a free loopback port with a token, as the command line
    does (``token=False``: without); yields ``(url, app)``, the url with its ``?token=`` (add parameters
    with ``&``)."""
    secret = secrets.token_urlsafe(24) if token else None
    app = create_app(folder, **({"token": secret} if secret else {}), **kwargs)
    server = serve(app, "127.0.0.1", 0)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.port}/" + (f"?token={secret}" if secret else ""), app
    finally:
        server.shutdown()
        server.server_close()
        app.extensions["studio"].jobs.shutdown()
        thread.join(30)


@contextmanager
def chromium() -> Iterator[Any]:
    """A headless Chromium (Playwright ``Browser``) with a fresh profile."""
    from playwright.sync_api import sync_playwright

    with tempfile.TemporaryDirectory(prefix="studio-chromium-") as profile, sync_playwright() as p:
        context = p.chromium.launch_persistent_context(
            profile,
            executable_path=CHROMIUM,
            headless=True,
            args=CHROMIUM_ARGS,
            viewport={"width": 1100, "height": 1000},
        )
        try:
            yield context
        finally:
            context.close()


def click_map(page: Any, x: float, y: float) -> None:
    """Click a PinBall map at table coordinates ``(x, y)`` (y pointing down, as drawn)."""
    box = page.locator("#map-view").bounding_box()
    page.mouse.click(box["x"] + x * box["width"], box["y"] + y * box["height"])


def click_cell(page: Any, row: int, col: int, button: str = "left") -> None:
    """Click a four-rooms cell (walls included: the server judges them)."""
    box = page.locator(f'rect[data-row="{row}"][data-col="{col}"]').bounding_box()
    page.mouse.click(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2, button=button)


def open_page(context: Any, url: str) -> Any:
    """A new page at ``url``, once the studio has loaded its domains and map."""
    page = context.new_page()
    page.set_default_timeout(TIMEOUT_MS)
    page.goto(url)
    page.wait_for_selector("body[data-ready=true]")
    return page
