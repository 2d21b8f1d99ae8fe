"""The studio's safeguards in a real headless Chromium: the page with its token, saving over a file
asks first, and a page of another site (or a DNS-rebinding one) cannot drive the studio.

Every wait polls for a state of the page (with a generous timeout); nothing sleeps for a fixed time.
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from flask import Flask
from playwright.sync_api import expect

from tests.studio.browser import REBOUND_HOST, TIMEOUT_MS, click_cell, live_studio, open_page
from torchrl_subgoal import load_patterns
from torchrl_subgoal.subgoals import Cell

Studio = tuple[str, Flask, Path]
EVIL = REBOUND_HOST  # another site's name, which the test browser resolves to this machine


def test_the_page_works_with_its_token_and_not_without(browser: Any, studio: Studio) -> None:
    url, _, folder = studio
    assert "?token=" in url
    bare = browser.new_page()
    response = bare.goto(url.split("?")[0])
    assert response is not None and response.status == 403
    expect(bare.locator("body")).to_contain_text("token is missing or wrong", timeout=TIMEOUT_MS)
    bare.close()
    page = open_page(browser, url)
    click_cell(page, 3, 6)
    expect(page.locator("#message")).to_have_class("ok", timeout=TIMEOUT_MS)
    page.fill("#file-name", "mine")
    page.click("#save")
    expect(page.locator("#message")).to_contain_text("Saved", timeout=TIMEOUT_MS)
    assert "token=" in page.url and "file=mine.yaml" in page.url  # a reload keeps both
    expect(page.locator("#download")).to_have_attribute(
        "href", re.compile(r"^/files/mine\.yaml\?token="), timeout=TIMEOUT_MS
    )
    href = page.locator("#download").get_attribute("href")
    body = page.evaluate("async (href) => { const r = await fetch(href); return [r.status, await r.text()]; }", href)
    assert body == [200, (folder / "mine.yaml").read_text()]


def test_saving_over_another_file_asks_first(browser: Any, studio: Studio) -> None:
    url, _, folder = studio
    page = open_page(browser, url)
    dialogs: list[str] = []
    answer = {"accept": False}

    def on_dialog(dialog: Any) -> None:
        dialogs.append(dialog.message)
        dialog.accept() if answer["accept"] else dialog.dismiss()

    page.on("dialog", on_dialog)
    click_cell(page, 3, 6)
    expect(page.locator("#message")).to_have_class("ok", timeout=TIMEOUT_MS)
    page.fill("#file-name", "plan")
    page.click("#save")
    expect(page.locator("#message")).to_contain_text("Saved", timeout=TIMEOUT_MS)
    first = (folder / "plan.yaml").read_bytes()
    # the file this page saved: saved again without a question
    click_cell(page, 7, 9)
    expect(page.locator("#message")).to_contain_text("valid: ready to save", timeout=TIMEOUT_MS)  # not "Saved"
    page.click("#save")
    expect(page.locator("#message")).to_contain_text("Saved", timeout=TIMEOUT_MS)
    assert dialogs == [] and load_patterns(folder / "plan.yaml")["pattern_1"].predicates == (Cell(3, 6), Cell(7, 9))
    second = (folder / "plan.yaml").read_bytes()
    assert second != first
    # a new drawing under that name: the page asks; "Cancel" saves nothing
    page.click("#new")
    click_cell(page, 10, 6)
    expect(page.locator("#message")).to_contain_text("valid: ready to save", timeout=TIMEOUT_MS)
    page.fill("#file-name", "plan")
    page.click("#save")
    expect(page.locator("#message")).to_contain_text("Not saved: plan.yaml exists", timeout=TIMEOUT_MS)
    assert dialogs == ["plan.yaml exists in the save folder. Replace it?"]
    assert (folder / "plan.yaml").read_bytes() == second
    # "OK" replaces it
    answer["accept"] = True
    page.click("#save")
    expect(page.locator("#message")).to_contain_text("Saved", timeout=TIMEOUT_MS)
    assert len(dialogs) == 2
    assert load_patterns(folder / "plan.yaml")["pattern_1"].predicates == (Cell(10, 6),)


DRAWING = {"domain": "four_rooms", "patterns": [{"name": "p", "subgoals": [{"cell": [3, 6]}], "order": None}]}


@contextmanager
def open_studio(browser: Any, tmp_path: Path) -> Iterator[tuple[Any, str, Flask, Path, int]]:
    """A studio without a token (only the Host and Origin checks stand in the way) holding ``kept.yaml``, and
    a page of ``evil.example`` (which the test browser resolves to this machine): ``(page, url, app, folder,
    port)``."""
    folder = tmp_path / "files"
    with live_studio(folder, token=False) as (url, app):
        (folder / "kept.yaml").write_text("patterns: {p: {subgoals: [{cell: [7, 9]}]}}\n")
        port = urlsplit(url).port
        assert port is not None
        page = browser.new_page()
        page.set_default_timeout(TIMEOUT_MS)
        page.goto(f"http://{EVIL}:{port}/")  # a page of evil.example, served by the studio's machine
        assert page.evaluate("location.origin") == f"http://{EVIL}:{port}"
        yield page, url, app, folder, port


def test_a_rebinding_page_can_neither_list_read_nor_overwrite_files(browser: Any, tmp_path: Path) -> None:
    with open_studio(browser, tmp_path) as (page, url, _, folder, _):
        kept = (folder / "kept.yaml").read_bytes()
        # to the browser these are same-origin requests: readable, with any content type
        rebound = page.evaluate(
            """async (body) => {
            const list = await fetch("/api/files");
            const read = await fetch("/api/files/kept.yaml");
            const put = await fetch("/api/files/kept.yaml?overwrite=1",
                {method: "PUT", headers: {"Content-Type": "application/json"}, body});
            return [list.status, await list.text(), read.status, put.status];
        }""",
            json.dumps(DRAWING),
        )
        assert rebound[0] == 403 and "kept.yaml" not in rebound[1], rebound
        assert rebound[2:] == [403, 403], rebound
        assert (folder / "kept.yaml").read_bytes() == kept
        # the studio's own page, opened under its own name, still works
        own = open_page(browser, url)
        click_cell(own, 3, 6)
        expect(own.locator("#message")).to_have_class("ok", timeout=TIMEOUT_MS)
        own.fill("#file-name", "mine")
        own.click("#save")
        expect(own.locator("#message")).to_contain_text("Saved", timeout=TIMEOUT_MS)
        assert load_patterns(folder / "mine.yaml")["pattern_1"].predicates == (Cell(3, 6),)


def test_another_sites_simple_post_and_form_start_nothing(browser: Any, tmp_path: Path) -> None:
    with open_studio(browser, tmp_path) as (page, _, app, folder, port):
        # a "simple" cross-site POST (text/plain: no preflight) to start a learning; the request reaches
        # the studio, and its answer, opaque to the page anyway, is blocked by the browser as
        # Cross-Origin-Resource-Policy asks, hence the catch
        page.evaluate(
            """async ([target, body]) => {
            try {
                await fetch(target, {method: "POST", mode: "no-cors", headers: {"Content-Type": "text/plain"}, body});
            } catch (e) {}
        }""",
            [f"http://127.0.0.1:{port}/api/try", json.dumps(DRAWING)],
        )
        # and a form posted to it (a navigation, no script at all): a text/plain form sends
        # "NAME=VALUE", here a drawing of another pattern whose description takes the "="
        name = '{"domain": "four_rooms", "patterns": [{"name": "q", "subgoals": [{"cell": [7, 9]}]}], "description": "'
        page.set_content(f"""<form method="post" action="http://127.0.0.1:{port}/api/try" enctype="text/plain">
            <input name='{name}' value='"}}'></form>""")
        with page.expect_navigation():
            page.evaluate("document.forms[0].submit()")
        expect(page.locator("body")).to_contain_text("from another site", timeout=TIMEOUT_MS)
        assert app.extensions["studio"].jobs._jobs == {}  # no learning was started
        assert sorted(p.name for p in folder.iterdir()) == ["kept.yaml"]
