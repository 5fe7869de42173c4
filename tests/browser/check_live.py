"""Checks the live page of a running valve-bridge daemon (GET / on its [metrics] address) in
headless Chromium (see pages.py); exits 1 naming every problem: a console error or uncaught
exception, fewer valves than expected, a trace chart that drew nothing, a trace chart that looked
the same in two screenshots taken seconds apart or whose time range did not move, the alarm of
the drifting valve not shown within the wait (or without its figure marked past its limit), an
alarm shown for the healthy valve, and with --diagnosis, no diagnosis of the drifting valve
listed with a report that opens without errors, or the effects its diagnoses name not charted
(one chart of sizes over time per unit, each with ink on it).

    python3 tests/browser/check_live.py URL --valves N --alarm NAME [--healthy NAME]
        [--diagnosis] [--wait S] [--screenshots DIR]

With --screenshots, saves DIR/live-page.png: the whole page once the alarm (and the diagnosis)
are shown.
"""

import argparse
import sys
from pathlib import Path
from urllib.parse import urljoin

from playwright.sync_api import TimeoutError as Timeout

from pages import Browser


def section(name):
    return f"document.getElementById('valve-{name}')"


def wait(page, script, arg, seconds):
    """True once `script(arg)` is true, false if it is not within `seconds`."""
    try:
        page.page.wait_for_function(script, arg=arg, timeout=seconds * 1000)
        return True
    except Timeout:
        return False


def check_updates(page, valves, problems):
    """The page shows the valves and their traces, and the first trace moves on in time."""
    if not wait(page, "n => window.vbLive && window.vbLive.updates >= 2 && "
                "window.vbCharts.length >= n && window.vbCharts[0].data[0].length > 10",
                valves, 20):
        problems.append("the page did not draw the traces within 20 s")
        return
    shown = page.page.evaluate("document.querySelectorAll('section.valve').length")
    if shown < valves:
        problems.append(f"{shown} valves shown, expected {valves}")
    first, (lo0, hi0) = page.chart_png(0), page.x_range(0)
    page.page.wait_for_timeout(3000)
    second, (lo1, hi1) = page.chart_png(0), page.x_range(0)
    if first == second:
        problems.append("the trace chart looked the same in two screenshots 3 s apart")
    if not hi1 >= hi0 + 2:
        problems.append(f"the trace's time range did not move on: [{lo0}, {hi0}] then [{lo1}, {hi1}]")
    for i in range(valves):
        ink = page.ink(i)
        if ink < 0.002:
            problems.append(f"trace chart {i} drew nothing ({ink:.4f} of its canvas inked)")


def check_alarm(page, name, healthy, seconds, problems):
    """The drifting valve `name` shows its health alarm and the figure past its limit; the
    `healthy` one shows none."""
    shown = wait(page, f"() => {{ const s = {section(name)}; return s && "
                 "s.querySelector('ul.alarms').textContent.includes('health alarm'); }",
                 None, seconds)
    if not shown:
        problems.append(f"{name}: no health alarm shown within {seconds} s")
        return
    alarms = page.page.evaluate(f"{section(name)}.querySelector('ul.alarms').textContent")
    past = page.page.evaluate(f"{section(name)}.querySelectorAll('tr.past').length")
    if past < 1 and "delay" not in alarms:
        problems.append(f"{name}: the alarm names no delay and no figure is marked past its limit: {alarms}")
    if healthy:
        quiet = page.page.evaluate(f"{section(healthy)}.querySelector('ul.alarms').textContent")
        if quiet:
            problems.append(f"{healthy}: an alarm is shown for the healthy valve: {quiet}")
    print(f"{name}: {alarms}")


def check_diagnosis(browser, page, url, name, seconds, problems):
    """The drifting valve's diagnosis is listed with a link to its report, which opens."""
    link = f"{section(name)}.querySelector('table.diagnosis-history a')"
    if not wait(page, f"() => {{ const s = {section(name)}; return s && {link}; }}", None, seconds):
        problems.append(f"{name}: no diagnosis with a report listed within {seconds} s")
        return
    href = page.page.evaluate(f"{link}.getAttribute('href')")
    report = browser.visit(urljoin(url, href))
    title = report.page.title()
    if "live diagnosis" not in title:
        problems.append(f"{name}: the report at {href} has the title {title!r}")
    problems.extend(f"report {href}: {e}" for e in report.errors)
    print(f"{name}: diagnosis report {href} ({title})")


def check_sizes(page, name, problems):
    """The effects the diagnoses of `name` name (the history the page draws from,
    /api/diagnoses/NAME) are charted over time: one chart per unit of their sizes, each drawn.
    The page reads the history every few seconds, so a diagnosis newer than its last read is
    waited for (up to 10 s)."""
    units_and_charts = f"""async () => {{
      const history = await (await fetch('/api/diagnoses/{name}', {{ cache: 'no-store' }})).json();
      const u = new Set();
      history.filter(r => !r.error).forEach(r => r.effects.forEach(e => u.add(e.size.unit)));
      const box = {section(name)}.querySelector('div.sizes');
      const charts = window.vbCharts.map((c, i) => box.contains(c.root) ? i : -1)
        .filter(i => i >= 0);
      return [Array.from(u).sort(), charts];
    }}"""
    for _ in range(10):
        units, charts = page.page.evaluate(units_and_charts)
        if len(charts) == len(units):
            break
        page.page.wait_for_timeout(1000)
    if not units:
        problems.append(f"{name}: its diagnoses name no effect to chart")
    if len(charts) != len(units):
        problems.append(f"{name}: {len(charts)} charts of effect sizes for the units {units}")
    for i in charts:
        ink = page.ink(i)
        if ink < 0.001:
            problems.append(f"{name}: the effect-size chart {i} drew nothing ({ink:.4f} inked)")
    print(f"{name}: effect sizes charted in {units}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("url")
    ap.add_argument("--valves", type=int, default=1)
    ap.add_argument("--alarm", required=True, help="the valve whose drift raises an alarm")
    ap.add_argument("--healthy", help="a valve that must show no alarm")
    ap.add_argument("--diagnosis", action="store_true", help="the alarm is diagnosed")
    ap.add_argument("--wait", type=float, default=90, help="s to wait for the alarm")
    ap.add_argument("--screenshots", help="directory to save live-page.png into")
    args = ap.parse_args()
    problems = []
    with Browser() as browser:
        page = browser.visit(args.url)
        check_updates(page, args.valves, problems)
        check_alarm(page, args.alarm, args.healthy, args.wait, problems)
        if args.diagnosis:
            check_diagnosis(browser, page, args.url, args.alarm, args.wait, problems)
            check_sizes(page, args.alarm, problems)
        if args.screenshots:
            Path(args.screenshots).mkdir(parents=True, exist_ok=True)
            page.page.evaluate("window.scrollTo(0, 0)")
            page.screenshot(Path(args.screenshots) / "live-page.png", full_page=True)
        problems.extend(f"live page: {e}" for e in page.errors)
        print(f"live page: {page.page.evaluate('window.vbLive.updates')} updates, "
              f"{len(page.errors)} console errors")
    for p in problems:
        print(f"FAIL {p}", file=sys.stderr)
    sys.exit(1 if problems else 0)


if __name__ == "__main__":
    main()
