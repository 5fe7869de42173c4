"""Checks the live page of a running valve-bridge daemon (GET / on its [metrics] address) in
headless Chromium (see pages.py); exits 1 naming every problem: a console error or uncaught
exception, fewer valves than expected, with --within a valve without a health window or the page
without a diagnosis that many seconds after --started, a trace chart that drew nothing, a trace
chart that looked the same in two screenshots taken seconds apart or whose time range did not
move, time labels of a chart that overlap, the alarm of the drifting valve not shown within the
wait, or shown without its figure, its limit, since when and what explains it, or with numbers
that are not its figure's row's (a row that must be marked past its limit), an alarm badge or
caption that disagrees with the figures, an alarm shown for the healthy valve, a snake_case name
or `%²` in the page's text, and with --diagnosis, no diagnosis of the drifting valve listed with
a report that opens without errors, an alarm not explained by its diagnosis, the effects its
diagnoses name not charted (one chart of sizes over time per unit, each with ink on it), or the
healthy valve not diagnosed within the wait or its diagnosis finding anything.

    python3 tests/browser/check_live.py URL --valves N --alarm NAME [--healthy NAME]
        [--diagnosis] [--wait S] [--started UNIX_S --within S] [--screenshots DIR]

With --screenshots, saves DIR/live-page.png: the whole page once the alarm (and the diagnosis)
are shown, and every valve's diagnosis when it comes within the wait.
"""

import argparse
import re
import sys
import time
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


def check_first_minute(page, valves, started, within, problems):
    """Every valve shows a health window, and the page a diagnosis, `within` s of `started`."""
    left = started + within - time.time()
    ok = left > 0 and wait(page, "n => document.querySelectorAll('table.health-figures').length >= n "
                           "&& document.querySelectorAll('table.diagnosis-history tr').length >= 2",
                           valves, left)
    if not ok:
        problems.append(f"no health window of each valve and no diagnosis {within} s after the daemon started")
    else:
        print(f"health windows and a diagnosis {time.time() - started:.0f} s after the start")


# Each health alarm of a section against the figures beside it: [figure, alarm text, the row's
# class, its `now` and `limit` cells]; the badge's and the caption's state.
ALARMS = """s => ({
  alarms: Array.from(s.querySelectorAll('ul.alarms li.health')).map(li => {
    const tr = s.querySelector(`tr[data-figure="${li.dataset.figure}"]`);
    const cells = tr ? Array.from(tr.cells).map(c => c.textContent) : [];
    return [li.dataset.figure, li.textContent, tr ? tr.className : null, cells[1], cells[3]];
  }),
  past: s.querySelectorAll('table.health-figures tr.past').length,
  badge: !s.querySelector('.in-alarm').hidden,
  items: s.querySelectorAll('ul.alarms li').length,
  caption: (s.querySelector('table.health-figures caption') || {}).textContent || '',
})"""


def check_agreement(page, name, problems, explained):
    """Each health alarm of `name` states its figure, its limit, since when and (when
    `explained`) the diagnosis that explains it, with the numbers of its figure's row, which is
    marked past its limit; the badge and the caption agree with the figures."""
    a = page.page.evaluate(f"(() => {{ const s = {section(name)}; return ({ALARMS})(s); }})()")
    for figure, text, cls, now, limit in a["alarms"]:
        if cls != "past":
            problems.append(f"{name}: the alarm on {figure} but its row is not marked past its limit: {text}")
        for needed in ("limit of", "since", "baseline"):
            if needed not in text:
                problems.append(f"{name}: the alarm does not say its {needed.split()[0]}: {text}")
        # A figure not measured in this window is quoted as last measured, against that limit.
        measured = bool(now and re.search(r"\d", now))
        numbers = [c for c in (now, limit) if measured and c and re.search(r"\d", c)]
        for cell in numbers:
            value = re.search(r"-?\d+\.\d+", cell).group(0)
            if value not in text:
                problems.append(f"{name}: the alarm's text does not quote its row's {value}: {text}")
        if explained and "explains it:" not in text:
            problems.append(f"{name}: the alarm is not explained by a diagnosis: {text}")
    if a["badge"] != (a["items"] > 0):
        problems.append(f"{name}: the badge says {'in alarm' if a['badge'] else 'no alarm'} with {a['items']} alarms listed")
    if ("in alarm" in a["caption"]) != (a["past"] > 0):
        problems.append(f"{name}: the caption {a['caption']!r} with {a['past']} figures past their limits")
    if a["past"] != len(a["alarms"]):
        problems.append(f"{name}: {a['past']} figures marked past their limits, {len(a['alarms'])} health alarms")
    return a


def check_alarm(page, name, healthy, seconds, problems, explained):
    """The drifting valve `name` shows its health alarm in agreement with its figures (and,
    when `explained`, the diagnosis that explains it); the `healthy` one shows none."""
    text = "explains it:" if explained else "health alarm"
    shown = wait(page, f"() => {{ const s = {section(name)}; return s && "
                 f"s.querySelector('ul.alarms').textContent.includes('{text}'); }}",
                 None, seconds)
    if not shown:
        problems.append(f"{name}: no health alarm ({text}) shown within {seconds} s")
    a = check_agreement(page, name, problems, explained)
    if not a["alarms"]:
        problems.append(f"{name}: no health alarm listed")
    if healthy:
        quiet = check_agreement(page, healthy, problems, explained)
        if quiet["items"]:
            problems.append(f"{healthy}: an alarm is shown for the healthy valve: {quiet['alarms']}")
    for figure, text, *_ in a["alarms"]:
        print(f"{name}: {text}")


def check_labels(page, problems):
    """No two time labels of a chart overlap: each label's width in the axis's font, at its
    tick's position."""
    overlaps = page.page.evaluate("""() => window.vbCharts.map((u, i) => {
      const a = u.axes[0], vals = a._values || [], splits = a._splits || [];
      const ctx = document.createElement('canvas').getContext('2d');
      ctx.font = Array.isArray(a.font) ? a.font[0] : a.font;
      const boxes = splits.map((v, k) => {
        const x = u.valToPos(v, 'x'), w = ctx.measureText(String(vals[k])).width;
        return [x - w / 2, x + w / 2, vals[k]];
      }).filter(b => b[2] != null && b[2] !== '');
      const bad = [];
      for (let k = 1; k < boxes.length; k++)
        if (boxes[k][0] < boxes[k - 1][1] + 2) bad.push(boxes[k - 1][2] + ' / ' + boxes[k][2]);
      return [i, bad];
    }).filter(r => r[1].length)""")
    for i, bad in overlaps:
        problems.append(f"chart {i}: time labels overlap: {bad}")


def check_words(page, problems):
    """The page speaks in plain words: no snake_case name, no squared percent."""
    text = page.page.evaluate("document.getElementById('valves').innerText")
    for word in sorted(set(re.findall(r"\b[a-z]+_[a-z_]+\b", text))):
        problems.append(f"the page shows the name {word!r}")
    if "%²" in text:
        problems.append("the page shows a figure in %²")


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


def check_quiet(page, name, seconds, problems):
    """The healthy valve `name` is diagnosed within `seconds` (the history the page draws from,
    /api/diagnoses/NAME), and its diagnoses find nothing: it is its health baseline model."""
    history = f"""async () => (await (await fetch('/api/diagnoses/{name}', {{ cache: 'no-store' }})).json())
      .map(r => [r.error || null, r.effects.filter(e => e.finding).map(e => e.effect), r.verdict])"""
    end = time.time() + seconds
    records = page.page.evaluate(history)
    while not records and time.time() < end:
        page.page.wait_for_timeout(1000)
        records = page.page.evaluate(history)
    if not records:
        problems.append(f"{name}: no diagnosis within {seconds} s")
    for error, found, verdict in records:
        if error or found:
            problems.append(f"{name}: the healthy valve's diagnosis found {found or error}: {verdict}")
    print(f"{name}: {len(records)} diagnoses, finding {[r[1] for r in records]}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("url")
    ap.add_argument("--valves", type=int, default=1)
    ap.add_argument("--alarm", required=True, help="the valve whose drift raises an alarm")
    ap.add_argument("--healthy", help="a valve that must show no alarm")
    ap.add_argument("--diagnosis", action="store_true", help="the alarm is diagnosed")
    ap.add_argument("--wait", type=float, default=90, help="s to wait for the alarm")
    ap.add_argument("--started", type=float, help="Unix time the daemon started")
    ap.add_argument("--within", type=float, help="s after --started for health and a diagnosis")
    ap.add_argument("--screenshots", help="directory to save live-page.png into")
    args = ap.parse_args()
    problems = []
    with Browser() as browser:
        page = browser.visit(args.url)
        if args.within:
            check_first_minute(page, args.valves, args.started or time.time(), args.within, problems)
        check_updates(page, args.valves, problems)
        check_alarm(page, args.alarm, args.healthy, args.wait, problems, args.diagnosis)
        if args.diagnosis:
            check_diagnosis(browser, page, args.url, args.alarm, args.wait, problems)
            check_sizes(page, args.alarm, problems)
            if args.healthy:
                check_quiet(page, args.healthy, args.wait, problems)
        check_labels(page, problems)
        check_words(page, problems)
        if args.screenshots:
            # Every valve with a diagnosis on the picture, when they come within the wait.
            wait(page, "n => document.querySelectorAll('table.diagnosis-history').length >= n",
                 args.valves, args.wait)
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
