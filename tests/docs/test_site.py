"""The built site renders in headless Chromium: navigation, the tutorials' included code and figures,
the API reference from docstrings (its cross-references links, not literal Sphinx roles), and no
request leaves the machine."""

from __future__ import annotations

import os
import re
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.docs.site import build, open_page, serve
from tests.studio.browser import CHROMIUM, chromium

#: what a docstring's cross-reference looks like when it did not become a link
ROLE = re.compile(r":(?:class|func|meth|mod|data|attr|exc|obj):`?")


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """The site, built once (``mkdocs build --strict``) for this module's tests."""
    out = tmp_path_factory.mktemp("site")
    build(out)
    yield out


def test_the_api_reference_renders_its_cross_references(site: Path) -> None:
    """No page shows a Sphinx role as text; the docstrings' references are links; the reference documents
    the public API by its public names (``torchrl_subgoal.X``), ``experiment_logger`` among them."""
    found = [
        f"{page.relative_to(site)}: {text[max(0, m.start() - 60) : m.end() + 40]!r}"
        for page in site.rglob("*.html")
        for text in [page.read_text(encoding="utf-8")]
        for m in ROLE.finditer(text)
    ]
    assert not found, "literal roles on the site:\n" + "\n".join(found[:20])
    api = (site / "api" / "index.html").read_text(encoding="utf-8")
    for anchor in ("torchrl_subgoal.SubgoalPotentialTransform", "torchrl_subgoal.training.experiment_logger"):
        assert f'id="{anchor}"' in api, anchor
    assert 'id="torchrl_subgoal.transform.setup' not in api  # an internal module
    links = re.findall(r'<a class="autorefs autorefs-internal"[^>]*href="#([\w.]+)"', api)
    assert len(links) > 100 and "torchrl_subgoal.SubgoalSeries" in links
    css = (site / "stylesheets" / "extra.css").read_text()
    assert "white-space: pre-wrap" in css  # code blocks wrap


def test_site_renders_offline(site: Path) -> None:
    if not Path(CHROMIUM).exists():
        message = f"{CHROMIUM} is missing: `make test` installs Debian's chromium"
        if os.environ.get("CI"):
            pytest.fail(message)
        pytest.skip(message)
    with serve(site) as url, chromium() as browser:
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
        assert api.locator("[id='torchrl_subgoal.SubgoalPotentialTransform']").count() == 1
        wrap = api.locator("pre > code").first.evaluate("code => getComputedStyle(code).whiteSpace")
        assert wrap == "pre-wrap"  # long lines wrap instead of scrolling sideways
        assert outside == [], f"the site fetched from outside: {outside}"
