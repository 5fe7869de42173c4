"""Checks valve-bridge's report pages in headless Chromium (see pages.py); exits 1 naming every
problem: a console error or uncaught exception, fewer interactive charts than expected, a chart
that drew nothing, a drag that did not narrow a chart's time range, Shift+wheel that did not
move the zoomed range later in time, a double-click that did not show all of its data, hover
values that did not show, a static chart without lines, an SVG chart's text smaller than 11 px
or overlapping other text (an axis title over its ticks), and what each page must say at first
sight: identify's best model in words and its first chart opening with the measured V_P, O_P and
the best model only (the others one click away, none drawn twice), diagnose's first chart
opening zoomed on a mismatch where the recording is long and no sentence shown with raw
Markdown backticks, the fleet's ranking rule and rows
coloured by severity, none taller than six lines.

    python3 tests/browser/check_reports.py [--screenshots DIR] --page NAME PATH MIN_CHARTS ...

NAME says which page it is (identify, diagnose, fleet, fleet-valve; any other is checked as a
page of charts only). With --screenshots, saves DIR/report-NAME.png of each HTML page as it
opens, scrolled to its first chart, values under the cursor.
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
    dlo, dhi = page.page.evaluate("i => { const x = window.vbCharts[i].data[0]; return [x[0], x[x.length - 1]]; }", i)
    if abs(rlo - dlo) > 1e-6 * max(1.0, abs(dlo)) or abs(rhi - dhi) > 1e-6 * max(1.0, abs(dhi)):
        problems.append(
            f"{where}: chart {i}: a double-click gave [{rlo}, {rhi}], not all of its data [{dlo}, {dhi}]"
        )
    values = page.hover(i)
    if len(values) < 2 or not all(v.strip() for v in values[:2]):
        problems.append(f"{where}: chart {i}: no values under the cursor ({values})")


# Every drawn SVG text: its text, font size and box.
SVG_TEXTS = """() => Array.from(document.querySelectorAll('svg text')).map(t => {
  const b = t.getBoundingClientRect();
  return [t.textContent.trim(), parseFloat(getComputedStyle(t).fontSize), b.left, b.top, b.right, b.bottom];
}).filter(t => t[0] && t[4] > t[2])"""


def check_svg_text(page, problems, where):
    """The SVG charts' text is at least 11 px and no two texts overlap."""
    texts = page.page.evaluate(SVG_TEXTS)
    small = sorted({t[0] for t in texts if t[1] < 11})
    if small:
        problems.append(f"{where}: SVG text under 11 px: {small[:5]}")
    for k, a in enumerate(texts):
        for b in texts[k + 1:]:
            if a[2] < b[4] - 1 and b[2] < a[4] - 1 and a[3] < b[5] - 1 and b[3] < a[5] - 1:
                problems.append(f"{where}: SVG texts overlap: {a[0]!r} and {b[0]!r}")


def check_first_sight(page, name, problems, where):
    """What the page must say at first sight (see the module's documentation)."""
    if name == "identify":
        line = page.page.evaluate("(document.querySelector('p.verdict') || {}).textContent || ''")
        if not line.startswith("Best model: "):
            problems.append(f"{where}: no plain best-model line at the top: {line!r}")
        shown, total, names, same = page.page.evaluate("""() => {
          const u = window.vbCharts[0], s = u.series.slice(1);
          const on = s.map((x, i) => x.show ? i + 1 : -1).filter(i => i > 0);
          const same = [];
          for (const a of on) for (const b of on)
            if (a < b && u.data[a].every((v, k) => v === u.data[b][k])) same.push([s[a - 1].label, s[b - 1].label]);
          return [on.length, s.length, s.map(x => x.label), same];
        }""")
        if shown > 3 or total <= shown:
            problems.append(f"{where}: the first chart opens with {shown} of {total} series drawn ({names})")
        if len(set(names)) != len(names) or same:
            problems.append(f"{where}: series drawn twice in the first chart: {names} {same}")
    if name in ("diagnose", "fleet-valve"):
        # Commands and config keys in the sentences are set as code, never shown with their
        # Markdown backticks.
        raw = page.page.evaluate("document.body.innerText.split('\\n').filter(l => l.includes('`'))")
        if raw:
            problems.append(f"{where}: text shown with raw backticks: {raw[0][:160]!r}")
        zoom, (lo, hi), (dlo, dhi) = page.page.evaluate("""() => {
          const el = document.querySelector('div.vb-chart'), u = window.vbCharts[0], x = u.data[0];
          return [el.dataset.zoom0 !== undefined, [u.scales.x.min, u.scales.x.max], [x[0], x[x.length - 1]]];
        }""")
        if (dhi - dlo) >= 50 and not (zoom and hi - lo < 0.8 * (dhi - dlo)):
            problems.append(f"{where}: a {dhi - dlo:.0f} s recording's first chart opens on [{lo}, {hi}], not zoomed on a mismatch")
    if name == "fleet":
        rule = page.page.evaluate("(document.querySelector('p.rule') || {}).textContent || ''")
        if "priority" not in rule or "severity" not in rule:
            problems.append(f"{where}: the ranking rule is not stated: {rule!r}")
        rows = page.page.evaluate("""() => Array.from(document.querySelectorAll('table.fleet tr')).slice(1).map(tr => {
          const td = tr.querySelector('td.what'), lh = parseFloat(getComputedStyle(td).lineHeight)
            || 1.2 * parseFloat(getComputedStyle(td).fontSize);
          return [tr.className, tr.getBoundingClientRect().height / lh];
        })""")
        for cls, lines in rows:
            if not cls.startswith("sev-"):
                problems.append(f"{where}: a row not coloured by its severity (class {cls!r})")
            if lines > 6.5:
                problems.append(f"{where}: a row {lines:.1f} lines tall")


def check_page(browser, name, path, min_charts, shots, problems):
    page = browser.open(path)
    where = f"{name} ({path})"
    n = page.charts()
    if n < min_charts:
        problems.append(f"{where}: {n} interactive charts, expected at least {min_charts}")
    if n > 0 and page.svg_paths() == 0:
        problems.append(f"{where}: the static charts (for a page without scripts) hold no lines")
    check_svg_text(page, problems, where)
    check_first_sight(page, name, problems, where)
    for i in range(n):
        check_chart(page, i, problems, where)
    if shots and path.suffix == ".html":
        # The page as it opens, scrolled to its first chart, values under the cursor.
        shown = browser.open(path)
        if n > 0:
            shown.scroll_to(0)
            shown.hover(0, 0.5)
        shown.screenshot(Path(shots) / f"report-{name}.png")
        problems.extend(f"{where} (opened again): {e}" for e in shown.errors)
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
