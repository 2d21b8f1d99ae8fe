"""The built site renders in headless Chromium: navigation, the tutorials' included code and figures,
the API reference from docstrings, and no request leaves the machine."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from tests.docs.site import built_site, open_page
from tests.studio.browser import CHROMIUM, chromium


def test_site_renders_offline() -> None:
    if not Path(CHROMIUM).exists():
        message = f"{CHROMIUM} is missing: `make test` installs Debian's chromium"
        if os.environ.get("CI"):
            pytest.fail(message)
        pytest.skip(message)
    with built_site() as url, chromium() as browser:
        outside: list[str] = []
        browser.on(
            "request", lambda r: None if r.url.startswith(url) or r.url.startswith("data:") else outside.append(r.url)
        )
        home = open_page(browser, url)
        assert "torchrl_subgoal" in home.title()
        assert "def past_halfway(td)" in home.locator("article").inner_text()  # the quick start, included
        tutorial = open_page(browser, url + "tutorials/shape_your_env/")
        text = tutorial.locator("article").inner_text()
        assert "SubgoalPotentialTransform(" in text and "unshaped" in text
        figure = tutorial.locator("img[src$='shape_your_env.png']")
        assert figure.evaluate("img => img.complete && img.naturalWidth > 0")
        api = open_page(browser, url + "api/")
        assert api.locator("[id='torchrl_subgoal.transform.SubgoalPotentialTransform']").count() == 1
        assert outside == [], f"the site fetched from outside: {outside}"
