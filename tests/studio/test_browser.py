"""The studio in a real headless Chromium: place, drag, save, reload, invalid placements, Try it, recipes.

Every wait polls for a state of the page (with a generous timeout); nothing
sleeps for a fixed time.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from flask import Flask
from playwright.sync_api import expect

from tests.recipes.test_recipes import recipe
from tests.studio.browser import TIMEOUT_MS, click_cell, click_map, open_page
from torchrl_subgoal import load_patterns
from torchrl_subgoal.envs import fetch
from torchrl_subgoal.subgoals import Box, Cell, Circle

Studio = tuple[str, Flask, Path]


def subgoal_rows(page: Any) -> list[str]:
    return [t.strip() for t in page.locator("#subgoals li .where").all_text_contents()]


def save_as(page: Any, name: str) -> None:
    page.fill("#file-name", name)
    page.click("#save")
    expect(page.locator("#message")).to_contain_text("Saved", timeout=TIMEOUT_MS)


def save_and_reload(page: Any, name: str, command: str) -> None:
    """Save as ``name``, check the recipe ``command`` shown, reload the page (it reopens the file)."""
    save_as(page, name)
    expect(page.locator("#recipe")).to_contain_text(command)
    page.reload()
    page.wait_for_selector("body[data-ready=true]")


def test_place_two_subgoals_save_reload_and_train_with_the_recipe(
    browser: Any, studio: Studio, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    url, _, folder = studio
    page = open_page(browser, url)
    click_cell(page, 3, 6)
    click_cell(page, 7, 9)
    expect(page.locator("#message")).to_have_class("ok", timeout=TIMEOUT_MS)
    save_and_reload(
        page, "hallways", f"torchrl-subgoal reproduce four-rooms --subgoals {folder.resolve()}/hallways.yaml"
    )
    expect(page.locator("#subgoals li")).to_have_count(2, timeout=TIMEOUT_MS)
    assert subgoal_rows(page) == ["(3, 6)", "(7, 9)"]
    assert page.locator("#map-view g.subgoal").count() == 2
    assert page.input_value("#file-name") == "hallways.yaml"

    saved = folder / "hallways.yaml"
    assert load_patterns(saved, domain="four_rooms")["pattern_1"].predicates == (Cell(3, 6), Cell(7, 9))
    results = tmp_path / "results"
    args = [
        "--subgoals",
        str(saved),
        "--methods",
        "HRS,SARSA",
        "--episodes",
        "5",
        "--learnings",
        "1",
        "--workers",
        "0",
        "--results",
        str(results),
    ]
    assert recipe("four_rooms").main(args) == 0
    capsys.readouterr()
    config = json.loads((results / "config.json").read_text())
    assert config["config"]["patterns"]["pattern_1"] == {"subgoals": [{"cell": [3, 6]}, {"cell": [7, 9]}]}
    summary = json.loads((results / "summary.json").read_text())
    assert summary["methods"]["HRS"]["learners"] == 1


def test_edit_drag_reorder_remove_partial_order_and_patterns(browser: Any, studio: Studio) -> None:
    url, _, folder = studio
    page = open_page(browser, url)
    for cell in ((3, 6), (6, 2), (10, 6)):
        click_cell(page, *cell)
    expect(page.locator("#subgoals li")).to_have_count(3)
    # drag the first subgoal one cell to the right
    start = page.locator('#map-view g.subgoal[data-index="0"]').bounding_box()
    target = page.locator('rect[data-row="3"][data-col="7"]').bounding_box()
    page.mouse.move(start["x"] + start["width"] / 2, start["y"] + start["height"] / 2)
    page.mouse.down()
    page.mouse.move(target["x"] + target["width"] / 2, target["y"] + target["height"] / 2, steps=5)
    page.mouse.up()
    assert subgoal_rows(page) == ["(3, 7)", "(6, 2)", "(10, 6)"]
    page.locator("#subgoals li").nth(0).locator("button", has_text="↓").click()  # reorder
    assert subgoal_rows(page) == ["(6, 2)", "(3, 7)", "(10, 6)"]
    click_cell(page, 3, 7, button="right")  # remove
    assert subgoal_rows(page) == ["(6, 2)", "(10, 6)"]
    page.locator("#subgoals li").nth(0).locator("input.sg-name").fill("west")
    page.locator("#subgoals li").nth(0).locator("input.sg-name").press("Enter")
    page.fill("#pattern-name", "mine")
    page.press("#pattern-name", "Enter")
    # a second pattern with a partial order: two sources before a door
    page.click("#add-pattern")
    expect(page.locator("#pattern-name")).to_have_value("pattern_1")  # the first free name
    for cell in ((6, 2), (3, 6), (10, 6)):
        click_cell(page, *cell)
    page.check("#partial")
    page.locator("#edges li").nth(1).locator("button").click()  # drop the arrow 2 -> 3
    page.select_option("#edge-from", "0")
    page.select_option("#edge-to", "2")
    page.click("#add-edge")
    expect(page.locator("#edges li")).to_have_count(2)
    assert page.locator("#map-view line.arrow").count() == 2
    expect(page.locator("#message")).to_have_class("ok", timeout=TIMEOUT_MS)
    save_as(page, "two.yaml")
    patterns = load_patterns(folder / "two.yaml", domain="four_rooms")
    assert patterns["mine"].predicates == (Cell(6, 2), Cell(10, 6)) and patterns["mine"].names == ("west", "sg2")
    assert patterns["pattern_1"].order == ((0, 1), (0, 2)) and not patterns["pattern_1"].is_chain
    # a cycle is refused, and said on the page
    page.select_option("#edge-from", "2")
    page.select_option("#edge-to", "0")
    page.click("#add-edge")
    expect(page.locator("#message")).to_have_class("error", timeout=TIMEOUT_MS)
    expect(page.locator("#message")).to_contain_text("pattern 'pattern_1': order: the order has a cycle")


def test_an_invalid_placement_shows_the_error_and_is_not_saved(browser: Any, studio: Studio) -> None:
    url, _, folder = studio
    page = open_page(browser, url)
    click_cell(page, 3, 6)
    click_cell(page, 0, 4)  # the outer wall
    message = page.locator("#message")
    expect(message).to_have_class("error", timeout=TIMEOUT_MS)
    expect(message).to_contain_text("pattern 'pattern_1': subgoals[1].cell: (0, 4) is a wall")
    assert page.locator("#map-view g.subgoal.invalid").count() == 1
    page.fill("#file-name", "walls")
    page.click("#save")
    expect(message).to_contain_text("walls.yaml: pattern 'pattern_1': subgoals[1].cell: (0, 4) is a wall")
    assert not (folder / "walls.yaml").exists()
    page.locator("#map-view g.subgoal.invalid").click(button="right")
    expect(message).to_have_class("ok", timeout=TIMEOUT_MS)


def test_try_it_shows_both_curves_and_the_potential(browser: Any, studio: Studio) -> None:
    url, _, _ = studio
    page = open_page(browser, url)
    click_cell(page, 3, 6)
    click_cell(page, 7, 9)
    page.fill("#episodes", "20")
    page.fill("#learners", "3")
    page.click("#try")
    expect(page.locator("#try-status")).to_have_attribute("data-state", "done", timeout=TIMEOUT_MS)
    for series in ("shaped", "baseline"):
        points = page.locator(f'#curves polyline[data-series="{series}"]').get_attribute("points")
        assert points is not None and len(points.split()) == 20
    expect(page.locator("#values tbody tr")).to_have_count(3)
    expect(page.locator("#result-title")).to_contain_text("3 learners \u00d7 20 episodes")
    assert page.locator("#map-view text.value").count() == 2  # V next to each subgoal
    page.fill("#episodes", "0")
    page.click("#try")
    expect(page.locator("#message")).to_contain_text("episodes: must be from 1 to 2000, got 0")


def test_pinball_circles_on_the_hard_map_and_the_recipe(
    browser: Any, studio: Studio, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    url, _, folder = studio
    page = open_page(browser, url)
    page.select_option("#domain", "pinball")
    expect(page.locator("#map-label")).to_be_visible()
    page.select_option("#map", "hard")
    page.wait_for_selector("#map-view polygon.obstacle")
    page.fill("#radius", "0.05")
    click_map(page, 0.5, 0.5)  # inside an obstacle of the hard map
    expect(page.locator("#message")).to_contain_text("lies inside obstacle", timeout=TIMEOUT_MS)
    page.locator("#map-view g.subgoal").click(button="right")
    click_map(page, 0.25, 0.15)
    click_map(page, 0.45, 0.3)
    expect(page.locator("#message")).to_have_class("ok", timeout=TIMEOUT_MS)
    save_as(page, "hard_circles")
    expect(page.locator("#recipe")).to_contain_text("--map hard")
    series = load_patterns(folder / "hard_circles.yaml", domain="pinball")["pattern_1"]
    assert [type(p) for p in series.predicates] == [Circle, Circle]
    assert all(p.radius == 0.05 for p in series.predicates if isinstance(p, Circle))
    (x0, y0), (x1, y1) = (p.centre for p in series.predicates if isinstance(p, Circle))
    assert abs(x0 - 0.25) < 0.01 and abs(y0 - 0.15) < 0.01 and abs(x1 - 0.45) < 0.01 and abs(y1 - 0.3) < 0.01
    args = [
        "--subgoals",
        str(folder / "hard_circles.yaml"),
        "--map",
        "hard",
        "--methods",
        "HRS",
        "--episodes",
        "10",
        "--learnings",
        "1",
        "--max-steps",
        "100",
        "--workers",
        "0",
        "--results",
        str(tmp_path / "results"),
    ]
    assert recipe("pinball").main(args) == 0
    capsys.readouterr()


def test_pick_and_place_form_two_boxes_save_reload(browser: Any, studio: Studio) -> None:
    """The form needs no MuJoCo (it is built from ``fetch.COMPONENTS``), so this runs without the fetch extra."""
    url, _, folder = studio
    page = open_page(browser, url)
    page.select_option("#domain", "pick_and_place")
    expect(page.locator("#box-form")).to_be_visible()
    expect(page.locator("#map-view")).to_be_hidden()
    expect(page.locator("#try")).to_be_hidden()
    expect(page.locator("#try-note")).to_contain_text("too slow for a click")
    page.click("#add-box")  # the default component: object_relative_position, centre 0, margin 0.01
    page.check('#box-form .components input[value="finger_joints"]')
    page.click("#add-box")
    expect(page.locator("#box-form .box-card")).to_have_count(2)
    page.fill('[aria-label="finger_joints[0] of subgoal 2"]', "0.02")
    page.fill('[aria-label="finger_joints[1] of subgoal 2"]', "0.02")
    page.locator('[aria-label="finger_joints[1] of subgoal 2"]').press("Tab")
    page.fill("#pattern-name", "grasp")
    page.locator("#pattern-name").press("Tab")
    expect(page.locator("#message")).to_have_class("ok", timeout=TIMEOUT_MS)
    page.fill('[aria-label="margin of subgoal 1"]', "-0.01")  # an invalid margin: the loader's message
    page.locator('[aria-label="margin of subgoal 1"]').press("Tab")
    expect(page.locator("#message")).to_contain_text("subgoals[0].box.margin: must be non-negative", timeout=TIMEOUT_MS)
    page.fill('[aria-label="margin of subgoal 1"]', "0.01")
    page.locator('[aria-label="margin of subgoal 1"]').press("Tab")
    expect(page.locator("#message")).to_have_class("ok", timeout=TIMEOUT_MS)
    save_and_reload(page, "grasp", f"torchrl-subgoal reproduce pick-and-place --subgoals {folder.resolve()}/grasp.yaml")
    expect(page.locator("#box-form .box-card")).to_have_count(2, timeout=TIMEOUT_MS)
    assert page.input_value("#domain") == "pick_and_place"
    assert page.input_value("#pattern-name") == "grasp"
    assert subgoal_rows(page) == [
        "object_relative_position = [0, 0, 0] ± 0.01",
        "object_relative_position + finger_joints = [0, 0, 0, 0.02, 0.02] ± 0.01",
    ]
    assert page.input_value('[aria-label="finger_joints[1] of subgoal 2"]') == "0.02"

    patterns = fetch.human_patterns(str(folder / "grasp.yaml"))  # what the recipe reads
    assert patterns["grasp"].predicates == load_patterns(fetch.PARTICIPANTS_FILE)["participants"].predicates
    assert len(fetch.random_patterns(patterns["grasp"], 2, seed=0)) == 2  # and its RRS patterns from it


def test_point_maze_circles_in_maze_coordinates_y_up(browser: Any, studio: Studio) -> None:
    """The UMaze table is [-2.5, 2.5]² with y up: a click lands where the maze has that point."""
    url, _, folder = studio
    page = open_page(browser, url)
    page.select_option("#domain", "point_maze_umaze")
    expect(page.locator("#map-label")).to_be_hidden()
    expect(page.locator("#try")).to_be_hidden()
    expect(page.locator("#try-note")).to_contain_text("--domain point_maze_umaze --subgoals FILE")
    expect(page.locator("#map-view polygon.obstacle")).to_have_count(18)
    assert page.input_value("#pattern-name") == "bottom_to_top"  # named after the first route
    assert page.input_value("#radius") == "0.65"

    def click_maze(x: float, y: float) -> None:
        click_map(page, (x + 2.5) / 5, (2.5 - y) / 5)

    click_maze(0.0, 0.0)  # wall cell (2, 2), the middle of the U
    expect(page.locator("#message")).to_contain_text("lies in a wall cell (2, 2)", timeout=TIMEOUT_MS)
    assert page.locator("#map-view g.subgoal.invalid").count() == 1
    page.locator("#map-view g.subgoal").click(button="right")
    click_maze(1.0, -1.0)  # the lower right-hand corner, cell (3, 3)
    click_maze(1.0, 1.0)  # the upper one, cell (1, 3)
    expect(page.locator("#message")).to_have_class("ok", timeout=TIMEOUT_MS)
    assert page.locator("#map-view g.subgoal.invalid").count() == 0
    save_as(page, "corners")
    expect(page.locator("#recipe")).to_contain_text(
        "torchrl-subgoal train --algo ppo --domain point_maze_umaze --subgoals"
    )
    series = load_patterns(folder / "corners.yaml", domain="point_maze_umaze")["bottom_to_top"]
    circles = [p for p in series.predicates if isinstance(p, Circle)]
    assert [p.radius for p in circles] == [0.65, 0.65]
    for circle, (x, y) in zip(circles, [(1.0, -1.0), (1.0, 1.0)], strict=True):
        assert abs(circle.centre[0] - x) < 0.02 and abs(circle.centre[1] - y) < 0.02, circle.centre


def test_mountain_car_form_after_pick_and_place(browser: Any, studio: Studio) -> None:
    """The form's ticks are each domain's: MountainCar's new box covers position, not pick-and-place's component."""
    url, _, folder = studio
    page = open_page(browser, url)
    page.select_option("#domain", "pick_and_place")
    expect(page.locator("#box-form")).to_be_visible()
    page.select_option("#domain", "mountain_car")
    expect(page.locator('#box-form .components input[value="velocity"]')).to_be_visible()
    expect(page.locator("#box-form .components")).to_contain_text("in [-1.2, 0.6]")
    page.click("#add-box")
    page.fill('[aria-label="position[0] of subgoal 1"]', "-1")
    page.locator('[aria-label="position[0] of subgoal 1"]').press("Tab")
    expect(page.locator("#message")).to_have_class("ok", timeout=TIMEOUT_MS)
    save_as(page, "car")
    expect(page.locator("#recipe")).to_contain_text("torchrl-subgoal train --algo dqn --domain mountain_car --subgoals")
    series = load_patterns(folder / "car.yaml", domain="mountain_car")["pattern_1"]
    assert series.predicates == (Box((-1.0,), (0.05,), (0,)),)
