"""Checks valve-bridge's report pages in headless Chromium (see pages.py); exits 1 naming every
problem: a console error or uncaught exception, fewer interactive charts than expected, a chart
that drew nothing, a drag that did not narrow a chart's time range, Shift+wheel that did not
move the zoomed range later in time, a double-click that did not restore it, hover values that
did not show, a static chart without lines.

    python3 tests/browser/check_reports.py [--screenshots DIR] --page NAME PATH MIN_CHARTS ...

With --screenshots, saves DIR/report-NAME.png of each page (zoomed into its first chart, values
under the cursor).
"""

import argparse
import sys
from pathlib import Path

from pages import Browser


def check_chart(page, i, problems, where):
    """Checks chart `i` of `page`: drawn, zooms on a drag, pans on Shift+wheel, resets on a
    double-click, shows values under the cursor."""
    ink = page.ink(i)
    if ink < 0.002:
        problems.append(f"{where}: chart {i} drew nothing ({ink:.4f} of its canvas inked)")
    lo, hi = page.x_range(i)
    zlo, zhi = page.drag_zoom(i)
    if not (lo < zlo < zhi < hi) or (zhi - zlo) > 0.6 * (hi - lo):
        problems.append(
            f"{where}: chart {i}: dragging across it left its range at [{zlo}, {zhi}] (was [{lo}, {hi}])"
        )
    plo, phi = page.pan(i)
    moved, kept = plo - zlo, (phi - plo) - (zhi - zlo)
    if not (moved > 0 and abs(kept) <= 1e-6 * max(1.0, zhi - zlo)):
        problems.append(
            f"{where}: chart {i}: Shift+wheel left the zoomed range at [{plo}, {phi}] (was [{zlo}, {zhi}])"
        )
    rlo, rhi = page.reset(i)
    if abs(rlo - lo) > 1e-6 * max(1.0, abs(lo)) or abs(rhi - hi) > 1e-6 * max(1.0, abs(hi)):
        problems.append(
            f"{where}: chart {i}: a double-click gave [{rlo}, {rhi}], not the whole [{lo}, {hi}]"
        )
    values = page.hover(i)
    if len(values) < 2 or not all(v.strip() for v in values[:2]):
        problems.append(f"{where}: chart {i}: no values under the cursor ({values})")


def check_page(browser, name, path, min_charts, shots, problems):
    page = browser.open(path)
    where = f"{name} ({path})"
    n = page.charts()
    if n < min_charts:
        problems.append(f"{where}: {n} interactive charts, expected at least {min_charts}")
    if n > 0 and page.svg_paths() == 0:
        problems.append(f"{where}: the static charts (for a page without scripts) hold no lines")
    for i in range(n):
        check_chart(page, i, problems, where)
    if shots:
        if n > 0:
            page.scroll_to(0)
            page.drag_zoom(0, 0.45, 0.55)
            page.hover(0, 0.5)
        page.screenshot(Path(shots) / f"report-{name}.png")
    problems.extend(f"{where}: {e}" for e in page.errors)
    print(f"{name}: {n} charts checked, {len(page.errors)} console errors")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--screenshots", help="directory to save report-NAME.png into")
    ap.add_argument("--page", nargs=3, action="append", required=True,
                    metavar=("NAME", "PATH", "MIN_CHARTS"))
    args = ap.parse_args()
    problems = []
    if args.screenshots:
        Path(args.screenshots).mkdir(parents=True, exist_ok=True)
    with Browser() as browser:
        for name, path, min_charts in args.page:
            check_page(browser, name, Path(path), int(min_charts), args.screenshots, problems)
    for p in problems:
        print(f"FAIL {p}", file=sys.stderr)
    sys.exit(1 if problems else 0)


if __name__ == "__main__":
    main()
