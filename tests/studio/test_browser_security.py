"""The studio's safeguards in a real headless Chromium: the page with its token, saving over a file
asks first, and a page of another site (or a DNS-rebinding one) cannot drive the studio.

Every wait polls for a state of the page (with a generous timeout); nothing sleeps for a fixed time.
"""

from __future__ import annotations

import json
import re
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
    expect(bare.locator("body")).to_contain_text("token is missing or wrong")
    bare.close()
    page = open_page(browser, url)
    click_cell(page, 3, 6)
    expect(page.locator("#message")).to_have_class("ok", timeout=TIMEOUT_MS)
    page.fill("#file-name", "mine")
    page.click("#save")
    expect(page.locator("#message")).to_contain_text("Saved", timeout=TIMEOUT_MS)
    assert "token=" in page.url and "file=mine.yaml" in page.url  # a reload keeps both
    expect(page.locator("#download")).to_have_attribute("href", re.compile(r"^/files/mine\.yaml\?token="))
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
    page.click("#save")
    expect(page.locator("#message")).to_contain_text("Saved", timeout=TIMEOUT_MS)
    assert dialogs == [] and load_patterns(folder / "plan.yaml")["pattern_1"].predicates == (Cell(3, 6), Cell(7, 9))
    second = (folder / "plan.yaml").read_bytes()
    assert second != first
    # a new drawing under that name: the page asks; "Cancel" saves nothing
    page.click("#new")
    click_cell(page, 10, 6)
    expect(page.locator("#message")).to_have_class("ok", timeout=TIMEOUT_MS)
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


def test_another_site_and_a_rebinding_page_cannot_drive_the_studio(browser: Any, tmp_path: Path) -> None:
    """Without a token, only the Host and Origin checks stand between another site and the studio."""
    folder = tmp_path / "files"
    with live_studio(folder, token=False) as (url, app):
        (folder / "kept.yaml").write_text("patterns: {p: {subgoals: [{cell: [7, 9]}]}}\n")
        kept = (folder / "kept.yaml").read_bytes()
        port = urlsplit(url).port
        page = browser.new_page()
        page.set_default_timeout(TIMEOUT_MS)
        page.goto(f"http://{EVIL}:{port}/")  # a page of evil.example, served by the studio's machine
        assert page.evaluate("location.origin") == f"http://{EVIL}:{port}"
        # DNS rebinding: to the browser these are same-origin requests, readable and with any content type
        rebound = page.evaluate("""async (body) => {
            const list = await fetch("/api/files");
            const read = await fetch("/api/files/kept.yaml");
            const put = await fetch("/api/files/kept.yaml?overwrite=1",
                {method: "PUT", headers: {"Content-Type": "application/json"}, body});
            return [list.status, await list.text(), read.status, put.status];
        }""", json.dumps(DRAWING))
        assert rebound[0] == 403 and "kept.yaml" not in rebound[1], rebound
        assert rebound[2:] == [403, 403], rebound
        # another site: a "simple" cross-site POST (text/plain, no preflight) to start a learning
        # (the request reaches the studio; its answer, opaque to the page anyway, is blocked by the
        # browser as Cross-Origin-Resource-Policy asks, hence the catch)
        page.evaluate("""async ([target, body]) => {
            try {
                await fetch(target, {method: "POST", mode: "no-cors", headers: {"Content-Type": "text/plain"}, body});
            } catch (e) {}
        }""", [f"http://127.0.0.1:{port}/api/try", json.dumps(DRAWING)])
        # and a form posted to it (a navigation, no fetch at all)
        page.set_content(f"""<form method="post" action="http://127.0.0.1:{port}/api/validate" enctype="text/plain">
            <input name='{{"domain": "four_rooms", "patterns": [], "x": "' value='"}}'></form>""")
        with page.expect_navigation():
            page.evaluate("document.forms[0].submit()")
        assert "from another site" in page.content() or "JSON" in page.content()
        assert app.extensions["studio"].jobs._jobs == {}  # no learning was started
        assert (folder / "kept.yaml").read_bytes() == kept and sorted(p.name for p in folder.iterdir()) == ["kept.yaml"]
        # the studio's own page, opened under its own name, still works
        own = open_page(browser, url)
        click_cell(own, 3, 6)
        expect(own.locator("#message")).to_have_class("ok", timeout=TIMEOUT_MS)
        own.fill("#file-name", "mine")
        own.click("#save")
        expect(own.locator("#message")).to_contain_text("Saved", timeout=TIMEOUT_MS)
        assert load_patterns(folder / "mine.yaml")["pattern_1"].predicates == (Cell(3, 6),)
