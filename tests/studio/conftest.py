"""Fixtures of the studio tests: an app on a temporary save folder, a live server, headless Chromium."""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from flask import Flask
from flask.testing import FlaskClient

from tests.studio.browser import CHROMIUM, chromium, live_studio
from torchrl_subgoal.studio.server import create_app


@pytest.fixture
def app(tmp_path: Path) -> Flask:
    return create_app(tmp_path / "files")


@pytest.fixture
def client(app: Flask) -> Iterator[FlaskClient]:
    yield app.test_client()
    app.extensions["studio"].jobs.shutdown()


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    """Debian's Chromium; missing, the browser tests fail under CI (``make test`` installs it) and skip elsewhere."""
    if not Path(CHROMIUM).exists():
        message = f"{CHROMIUM} is missing: `make test` installs Debian's chromium (apt-get install chromium)"
        if os.environ.get("CI"):
            pytest.fail(message)
        pytest.skip(message)
    with chromium() as context:
        yield context


@pytest.fixture
def studio(tmp_path: Path) -> Iterator[tuple[str, Flask, Path]]:
    """A live studio: ``(url, app, save folder)``."""
    folder = tmp_path / "files"
    with live_studio(folder) as (url, app):
        yield url, app, folder
