"""Screenshots of the studio for ``docs/studio.md``, taken in headless Chromium like the browser tests.

.venv/bin/python -m tests.studio.screenshots docs/images                  # all
.venv/bin/python -m tests.studio.screenshots docs/images pick_and_place   # only the form
"""

from __future__ import annotations

import shutil
import sys
import tempfile
from pathlib import Path
from typing import Any

from playwright.sync_api import expect

from tests.studio.browser import TIMEOUT_MS, chromium, click_cell, click_map, live_studio, open_page
from torchrl_subgoal.envs import fetch


def pick_and_place(browser: Any, url: str, folder: Path, out: Path) -> None:
    """The form: the participants' file opened, a second pattern being written."""
    shutil.copy(fetch.PARTICIPANTS_FILE, folder / "pick_and_place_participants.yaml")
    page = open_page(browser, f"{url}&file=pick_and_place_participants.yaml")
    expect(page.locator("#box-form .box-card")).to_have_count(2, timeout=TIMEOUT_MS)
    page.click("#add-pattern")
    page.fill("#pattern-name", "grasp_then_lift")
    page.press("#pattern-name", "Enter")
    page.check('#box-form .components input[value="finger_joints"]')
    page.click("#add-box")
    page.uncheck('#box-form .components input[value="object_relative_position"]')
    page.uncheck('#box-form .components input[value="finger_joints"]')
    page.check('#box-form .components input[value="object_position"]')
    page.click("#add-box")
    for j, value in enumerate(("0", "0", "0", "0.02", "0.02")):
        page.fill(
            f'[aria-label="{"object_relative_position" if j < 3 else "finger_joints"}[{j % 3}] of subgoal 1"]', value
        )
    for j, value in enumerate(("1.3", "0.75", "0.6")):
        page.fill(f'[aria-label="object_position[{j}] of subgoal 2"]', value)
    page.fill('[aria-label="margin of subgoal 2"]', "0.03, 0.03, 0.05")
    page.press('[aria-label="margin of subgoal 2"]', "Tab")
    expect(page.locator("#message")).to_have_class("ok", timeout=TIMEOUT_MS)
    page.screenshot(path=out / "studio_pick_and_place.png", full_page=True)


def main(out: Path, only: str = "") -> None:
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as folder, live_studio(Path(folder)) as (url, _), chromium() as browser:
        pick_and_place(browser, url, Path(folder), out)
        if only == "pick_and_place":
            return
        page = open_page(browser, url)
        # four-rooms: two patterns, the second being edited
        for cell in ((6, 2), (10, 6)):
            click_cell(page, *cell)
        page.fill("#pattern-name", "west_door")
        page.press("#pattern-name", "Enter")
        page.click("#add-pattern")
        page.fill("#pattern-name", "hallways")
        page.press("#pattern-name", "Enter")
        for cell in ((3, 6), (7, 9)):
            click_cell(page, *cell)
        expect(page.locator("#message")).to_have_class("ok", timeout=TIMEOUT_MS)
        page.fill("#file-name", "my_subgoals")
        page.click("#save")
        expect(page.locator("#message")).to_contain_text("Saved", timeout=TIMEOUT_MS)
        page.screenshot(path=out / "studio_four_rooms.png", full_page=True)

        # Try it with the hallways pattern
        page.fill("#episodes", "300")
        page.fill("#learners", "20")
        page.click("#try")
        expect(page.locator("#try-status")).to_have_attribute("data-state", "done", timeout=TIMEOUT_MS)
        page.screenshot(path=out / "studio_try_it.png", full_page=True)

        # an invalid placement: the loader's message on the page
        click_cell(page, 0, 4)
        expect(page.locator("#message")).to_have_class("error", timeout=TIMEOUT_MS)
        page.locator("#message").screenshot(path=out / "studio_error.png")

        # PinBall: participant 1's circles and a partially ordered pattern
        page.select_option("#domain", "pinball")
        page.wait_for_selector("#map-view polygon.obstacle")
        for x, y in ((0.5877, 0.6486), (0.6442, 0.3202)):
            click_map(page, x, y)
        page.fill("#pattern-name", "participant_1")
        page.press("#pattern-name", "Enter")
        page.click("#add-pattern")
        for x, y in ((0.28, 0.26), (0.34, 0.75), (0.69, 0.31)):
            click_map(page, x, y)
        page.check("#partial")
        page.locator("#edges li").nth(0).locator("button").click()  # 1 -> 2 goes: both are first
        page.select_option("#edge-from", "0")
        page.select_option("#edge-to", "2")
        page.click("#add-edge")
        expect(page.locator("#message")).to_have_class("ok", timeout=TIMEOUT_MS)
        page.screenshot(path=out / "studio_pinball.png", full_page=True)


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "docs/images"), sys.argv[2] if len(sys.argv) > 2 else "")
