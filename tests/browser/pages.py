"""Opens valve-bridge's HTML pages in headless Chromium and checks what a reader would see.

A small driver over Playwright for Python, pointed at the system's Chromium (Debian's
`chromium`, or the program named by VB_CHROMIUM) with `executable_path`: Playwright's own browser
download is never used. A page is a local file (the reports) or a URL (the daemon's live page).
Each opened page collects its console errors and uncaught exceptions; the helpers say whether a
chart drew (ink on its canvas, or paths in an SVG), zoom a uPlot chart by dragging across it and
read its time range, and take screenshots (of the page, or of one chart).

Used by check_reports.py (run by tests/pages/browser_reports.rs) and check_live.py (run by
tests/pages/live_page.rs); not here: which pages to check.
"""

import os
from pathlib import Path

from playwright.sync_api import sync_playwright

CHROMIUM = os.environ.get("VB_CHROMIUM", "/usr/bin/chromium")
VIEWPORT = {"width": 1100, "height": 900}


class Browser:
    """Headless Chromium for the time of a `with` block."""

    def __enter__(self):
        self._pw = sync_playwright().start()
        # --no-sandbox: CI runs as root, where Chromium refuses its sandbox.
        self._browser = self._pw.chromium.launch(
            executable_path=CHROMIUM, headless=True, args=["--no-sandbox"]
        )
        return self

    def __exit__(self, *exc):
        self._browser.close()
        self._pw.stop()

    def open(self, path):
        """The page of the local file `path`, loaded."""
        return self.visit(Path(path).resolve().as_uri())

    def visit(self, url):
        """The page at `url`, loaded."""
        return Page(self._browser.new_page(viewport=VIEWPORT), url)


class Page:
    """One loaded page and the errors it logged."""

    def __init__(self, page, url):
        self.page = page
        self.url = url
        self.errors = []
        page.on(
            "console",
            lambda m: self.errors.append(f"console {m.type}: {m.text}")
            if m.type == "error"
            else None,
        )
        page.on("pageerror", lambda e: self.errors.append(f"uncaught: {e}"))
        page.goto(url)
        page.wait_for_load_state("load")

    def charts(self):
        """Number of uPlot charts the page drew (window.vbCharts)."""
        return self.page.evaluate("(window.vbCharts || []).length")

    def ink(self, i):
        """Share of the pixels of chart `i`'s canvas that are neither blank nor white."""
        return self.page.evaluate(
            """i => {
              const c = window.vbCharts[i].root.querySelector('canvas');
              const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
              let n = 0;
              for (let k = 0; k < d.length; k += 4) {
                if (d[k + 3] > 0 && (d[k] < 245 || d[k + 1] < 245 || d[k + 2] < 245)) n++;
              }
              return n / (c.width * c.height);
            }""",
            i,
        )

    def svg_paths(self):
        """Number of drawn lines and shapes in the page's SVG charts (shown or not)."""
        return self.page.evaluate(
            """() => {
              let n = document.querySelectorAll('svg path, svg polyline, svg circle').length;
              for (const ns of document.querySelectorAll('noscript'))
                n += (ns.textContent.match(/<(path|polyline|circle)\\b/g) || []).length;
              return n;
            }"""
        )

    def x_range(self, i):
        """The [min, max] shown on chart `i`'s time axis."""
        return self.page.evaluate(
            "i => [window.vbCharts[i].scales.x.min, window.vbCharts[i].scales.x.max]", i
        )

    def _over(self, i):
        over = self.page.locator(".vb-chart .u-over").nth(i)
        over.scroll_into_view_if_needed()
        return over, over.bounding_box()

    def drag_zoom(self, i, start=0.3, end=0.6):
        """Drags across chart `i` from `start` to `end` of its width; its range after."""
        _, box = self._over(i)
        y = box["y"] + box["height"] / 2
        mouse = self.page.mouse
        mouse.move(box["x"] + box["width"] * start, y)
        mouse.down()
        mouse.move(box["x"] + box["width"] * (start + end) / 2, y, steps=5)
        mouse.move(box["x"] + box["width"] * end, y, steps=5)
        mouse.up()
        return self.x_range(i)

    def pan(self, i, notches=2):
        """Turns the wheel over chart `i` with Shift held (later in time); its range after."""
        _, box = self._over(i)
        self.page.mouse.move(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
        self.page.keyboard.down("Shift")
        for _ in range(notches):
            self.page.mouse.wheel(0, 100)
        self.page.keyboard.up("Shift")
        self.page.wait_for_timeout(100)
        return self.x_range(i)

    def reset(self, i):
        """Double-clicks chart `i`; its range after."""
        over, _ = self._over(i)
        over.dblclick()
        return self.x_range(i)

    def hover(self, i, at=0.5):
        """Moves the cursor over chart `i` at `at` of its width; the legend's values then."""
        _, box = self._over(i)
        self.page.mouse.move(box["x"] + box["width"] * at, box["y"] + box["height"] / 2)
        return self.page.evaluate(
            """i => Array.from(window.vbCharts[i].root.querySelectorAll('.u-legend .u-value'))
                 .map(e => e.textContent)""",
            i,
        )

    def scroll_to(self, i):
        """Scrolls chart `i` (with the heading or text before it) to the top of the viewport."""
        self.page.locator(".vb-chart").nth(i).evaluate(
            """e => {
              let top = e.previousElementSibling;
              while (top && (top.tagName === 'SCRIPT' || top.classList.contains('vb-note')))
                top = top.previousElementSibling;
              (top || e).scrollIntoView();
            }"""
        )

    def screenshot(self, path, full_page=False):
        """Saves what the viewport shows (or the whole page) as PNG at `path`."""
        self.page.screenshot(path=str(path), full_page=full_page)

    def chart_png(self, i):
        """A screenshot of chart `i` (its canvas, axes and legend), as PNG bytes."""
        box = self.page.evaluate(
            """i => {
              const r = window.vbCharts[i].root;
              r.scrollIntoView();
              const b = r.getBoundingClientRect();
              return {x: b.x, y: b.y, width: b.width, height: b.height};
            }""",
            i,
        )
        return self.page.screenshot(clip=box)
