"""Driving the page as a person does: through labels, buttons and mouse positions on the photo."""

from __future__ import annotations

import operator
import re
import time
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

import cv2
import numpy as np
from playwright.sync_api import Page, expect
from service.conftest import API_KEYS

from prismsynth import Scene

KEY = API_KEYS["acme"]
# The Scale setting's choice for a scan in pixels (the page chooses no scale by itself).
NO_SCALE = "None: the dimensions in pixels, not millimetres"
T = TypeVar("T")


def save_photo(scene: Scene, path: Path) -> Path:
    ok = cv2.imwrite(str(path), cv2.cvtColor(scene.image, cv2.COLOR_RGB2BGR))
    assert ok
    return path


class PageDriver:
    def __init__(self, page: Page) -> None:
        self.page = page

    def log_in(self, key: str = KEY) -> None:
        self.page.get_by_label("API key").fill(key)
        self.page.get_by_role("button", name="Log in").click()
        expect(self.page.locator("#main")).to_be_visible()

    def add_photos(self, *paths: Path) -> None:
        self.page.get_by_label("Add photos").set_input_files([str(p) for p in paths])
        for path in paths:
            expect(self.page.locator("#photo-list")).to_contain_text(f"{path.name} (")
        expect(self.page.locator("#photo-list li", has_text="uploaded")).to_have_count(len(paths))

    def two_photos(self, front: Scene, side: Scene, folder: Path) -> None:
        """Log in, switch to two-photo mode and add the front and side photos as such."""
        self.log_in()
        self.page.get_by_label("Two photos").check()
        self.add_photos(save_photo(front, folder / "front.png"), save_photo(side, folder / "side.png"))
        self.page.get_by_label("Front photo", exact=True).select_option(label="front.png")
        self.page.get_by_label("Side photo", exact=True).select_option(label="side.png")

    def view(self) -> tuple[float, float, float]:
        """(scale, ox, oy) of the photo canvas: screen = (image + 0.5) * scale + offset."""
        scale, ox, oy = self.page.locator("#marker").get_attribute("data-view").split(",")
        return float(scale), float(ox), float(oy)

    def screen(self, xy: tuple[float, float]) -> tuple[float, float]:
        """Where image point `xy` is in the window, with the photo canvas scrolled to the top."""
        canvas = self.page.locator("#marker")
        box = canvas.bounding_box()
        if abs(box["y"]) > 0.5:  # other controls used since may have scrolled the page
            canvas.evaluate("c => c.scrollIntoView({block: 'start'})")
            box = canvas.bounding_box()
        scale, ox, oy = self.view()
        return box["x"] + (xy[0] + 0.5) * scale + ox, box["y"] + (xy[1] + 0.5) * scale + oy

    def click_photo(self, xy: tuple[float, float]) -> None:
        self.page.mouse.click(*self.screen(xy))

    def hover_readout(self, xy: tuple[float, float]) -> tuple[float, float]:
        self.page.mouse.move(*self.screen(xy))
        text = self.page.locator("#pointer-xy").text_content()
        x, y = re.fullmatch(r"x (-?[\d.]+), y (-?[\d.]+)", text).groups()
        return float(x), float(y)

    def canvas_colour_near(self, xy: tuple[float, float], want: tuple[int, int, int]) -> float:
        """How far (RGB distance) the photo canvas's pixel nearest to `want` within 3 screen px
        of image point `xy` is from it."""
        scale, ox, oy = self.view()
        sx, sy = (xy[0] + 0.5) * scale + ox, (xy[1] + 0.5) * scale + oy
        pixels = self.page.evaluate("""([x, y]) => {
            const c = document.getElementById("marker");
            const r = window.devicePixelRatio || 1;
            const d = c.getContext("2d").getImageData(Math.round(x * r) - 3, Math.round(y * r) - 3, 7, 7);
            return Array.from(d.data);
        }""", [sx, sy])
        rgb = np.array(pixels, float).reshape(-1, 4)[:, :3]
        return float(np.min(np.linalg.norm(rgb - np.array(want, float), axis=1)))

    def loupe_pixels(self) -> np.ndarray:
        """The magnifier's canvas as drawn: (H, W, 3) uint8 RGB."""
        width, height, data = self.page.evaluate("""() => {
            const c = document.getElementById("loupe");
            const pixels = c.getContext("2d").getImageData(0, 0, c.width, c.height).data;
            return [c.width, c.height, Array.from(pixels)];
        }""")
        return np.array(data, np.uint8).reshape(height, width, 4)[..., :3]

    def zoom_at(self, xy: tuple[float, float], clicks: int) -> None:
        for _ in range(clicks):
            before = self.view()[0]
            self.page.mouse.move(*self.screen(xy))
            self.page.mouse.wheel(0, -400)
            self.page.wait_for_function(
                f"document.getElementById('marker').dataset.view.split(',')[0] > {before}")

    def drag(self, start: tuple[float, float], end: tuple[float, float]) -> None:
        self.page.mouse.move(*self.screen(start))
        self.page.mouse.down()
        self.page.mouse.move(*self.screen(end), steps=10)
        self.page.mouse.up()

    def mark(self, name: str) -> tuple[float, float] | None:
        """The point as the page holds it (its row in the table of points), or None."""
        x = self.page.get_by_label(f"{name.upper()} x (pixels)").input_value()
        y = self.page.get_by_label(f"{name.upper()} y (pixels)").input_value()
        return (float(x), float(y)) if x and y else None

    def submit_and_wait(self, timeout_ms: float = 120_000) -> str:
        """Submit, and the new job's final state as the page shows it. The last job's state stays
        on the page until the new job's is shown: waited for first, or a "Done" left from the last
        job passed the wait and the new job was read "Queued" (a second submit in one test failed
        so, 1 run in 2 alone, while the worker had finished that job in under a second)."""
        state = self.page.locator("#job-state")
        before = state.text_content() or ""
        self.page.get_by_role("button", name="Submit job").click()
        expect(state).not_to_have_text(before, timeout=timeout_ms)
        expect(state).to_contain_text(re.compile(r"Done|Failed|Cancelled"), timeout=timeout_ms)
        return state.text_content()

    def dimensions(self) -> dict[str, float]:
        out = {}
        for field in ("width", "height", "depth"):
            text = self.page.locator(f"#dimensions dd[data-field={field}]").text_content()
            out[field] = float(text.split()[0])
        return out

    def viewer_pixels(self) -> np.ndarray:
        """The 3D view as the screen shows it: (H, W, 3) uint8 RGB."""
        expect(self.page.locator("#viewer-status")).to_contain_text("Showing", timeout=30_000)
        png = self.page.locator("#viewer canvas").screenshot()
        return cv2.cvtColor(cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)

    def settled(self, read: Callable[[], T], *, same: Callable[[T, T], bool] = operator.eq,
                unlike: T | None = None, timeout_s: float = 30) -> T:
        """What `read` gives once two reads in a row agree, and (given `unlike`, the view before a
        change) differ from it: the layout settled, or a change drawn by the 3D view, which
        renders on its own frames. Waited for, not a fixed pause (a loaded machine draws later);
        after `timeout_s` the last read, for the caller's assertion to fail on."""
        deadline = time.monotonic() + timeout_s
        last = read()
        while True:
            self.page.wait_for_timeout(150)
            now = read()
            if same(now, last) and (unlike is None or not same(now, unlike)):
                return now
            if time.monotonic() > deadline:
                return now
            last = now

    def settled_view(self, unlike: np.ndarray | None = None, timeout_s: float = 30) -> np.ndarray:
        """The 3D view once it stays the same (and, given `unlike`, is no longer that view)."""
        return self.settled(self.viewer_pixels, same=np.array_equal, unlike=unlike, timeout_s=timeout_s)
