// The live page of valve-bridge's daemon (crates/daemon/src/serve/page/): every second it asks /api/live for
// what is new (each valve's trace after the last point it has, its status, its last health
// window, its count of diagnoses) and draws, per valve, O_P and V_P over the last minutes with
// uPlot, the health figures against their limits and the alarms (each health alarm with its
// figure, its limit, since when and the diagnosis that explains it; diagnosis alarms; a log the
// disk refuses); when a valve has a new diagnosis it reads /api/diagnoses/NAME and draws the
// effect sizes over time (a chart per unit, each size with its 90 % interval) and the table of
// diagnoses in the vocabulary's words, each linked to its report.
// Times are the browser's clock: loop time plus the wall-clock time of loop time 0.
// window.vbCharts holds every chart (each valve's trace first, in the order of the valves);
// window.vbLive counts the answers drawn (updates) and the polls that failed (failures).
(function () {
  "use strict";
  var POLL_MS = 1000;
  var COLORS = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2",
    "#17becf", "#7f7f7f", "#bcbd22"];
  var BAD = { timeout: 1, error: 1, disconnected: 1 };
  var live = { started: null, traceS: 300, valves: [], since: null };
  window.vbCharts = [];
  window.vbLive = { updates: 0, failures: 0 };

  function el(tag, cls, text) {
    var e = document.createElement(tag);
    if (cls) { e.className = cls; }
    if (text != null) { e.textContent = text; }
    return e;
  }
  function row(cells, cls) {
    var tr = el("tr", cls);
    cells.forEach(function (c) {
      var td = c instanceof Node ? c : el("td", null, c);
      tr.appendChild(td);
    });
    return tr;
  }
  function num(v, digits) { return v == null ? "–" : v.toFixed(digits); }
  function pad2(n) { return (n < 10 ? "0" : "") + n; }
  // Wall-clock time of a Unix time, 24-hour HH:MM:SS (the same width in every locale).
  function clock(unix) {
    var d = new Date(unix * 1000);
    return pad2(d.getHours()) + ":" + pad2(d.getMinutes()) + ":" + pad2(d.getSeconds());
  }
  // Loop time as the browser's clock with the loop time beside it.
  function when(t) { return clock(live.started + t) + " (loop " + Math.round(t) + " s)"; }
  // How long until loop time t, from the valve's last row.
  function until(v, t) {
    var s = v.lastT == null ? t : t - v.lastT;
    return s <= 0 ? "any moment now" : "in about " + (s < 90 ? Math.ceil(s) + " s" : Math.ceil(s / 60) + " min");
  }
  // A time axis whose labels keep apart: HH:MM:SS every 90 px at least.
  function timeAxis() {
    return { space: 90, values: function (u, ticks) { return ticks.map(clock); } };
  }
  function words(name) { return name.replace(/_/g, " "); }
  // A size's name without its unit: friction_band_pct is the friction band.
  function sizeName(name) { return words(name.replace(/_(pct_per_s|pct|s)$/, "")); }
  // An effect's plain name with its size's name: "lost motion (backlash): friction band".
  function effectLabel(e) { return (e.name || words(e.effect)) + ": " + sizeName(e.size.name); }
  function width(div) { return Math.max(320, div.clientWidth); }
  function charts() {
    var all = live.valves.map(function (v) { return v.chart; });
    live.valves.forEach(function (v) { all = all.concat(v.sizeCharts); });
    window.vbCharts = all;
  }

  // A valve's section, made the first time the valve is seen.
  function section(name) {
    var sec = el("section", "valve");
    sec.id = "valve-" + name;
    var h2 = el("h2", null, name + " ");
    var v = {
      name: name, section: sec, status: el("span", "badge status"),
      alarmBadge: el("span", "badge bad in-alarm", "in alarm"), alarms: el("ul", "alarms"),
      trace: el("div", "vb-chart trace"), health: el("div", "health"), diag: el("div", "diagnoses"),
      sizes: el("div", "sizes"), data: [[], [], []], lastT: null, count: undefined, history: [],
      healthAlarms: [], healthT: null, firstDiagnosis: null, sizeCharts: []
    };
    v.alarmBadge.hidden = true;
    h2.appendChild(v.status);
    h2.appendChild(v.alarmBadge);
    [h2, v.alarms, v.trace, v.health, el("h3", null, "Diagnoses"), v.sizes, v.diag]
      .forEach(function (e) { sec.appendChild(e); });
    document.getElementById("valves").appendChild(sec);
    v.chart = new uPlot({
      title: "O_P and V_P, the last " + Math.round(live.traceS / 60) + " minutes",
      width: width(v.trace), height: 260,
      scales: { x: { time: true }, y: { range: function (u, lo, hi) {
        return [Math.min(0, lo == null ? 0 : lo), Math.max(100, hi == null ? 100 : hi)];
      } } },
      series: [{}, { label: "O_P (%)", stroke: COLORS[0], width: 1.5 },
        { label: "V_P (%)", stroke: COLORS[1], width: 1.5 }],
      axes: [timeAxis(), { label: "%" }]
    }, v.data, v.trace);
    live.valves.push(v);
    charts();
    return v;
  }

  function valve(name) {
    for (var i = 0; i < live.valves.length; i++) {
      if (live.valves[i].name === name) { return live.valves[i]; }
    }
    return section(name);
  }

  // Appends the points after the last one shown and keeps the last minutes.
  function addTrace(v, tr) {
    var d = v.data;
    var last = d[0].length ? d[0][d[0].length - 1] : -Infinity;
    for (var k = 0; k < tr.t.length; k++) {
      var x = live.started + tr.t[k];
      if (x <= last) { continue; }
      d[0].push(x);
      d[1].push(tr.op[k]);
      d[2].push(tr.vp[k]);
      v.lastT = tr.t[k];
    }
    if (!d[0].length) { return; }
    var from = d[0][d[0].length - 1] - live.traceS, cut = 0;
    while (cut < d[0].length && d[0][cut] < from) { cut++; }
    if (cut) { d.forEach(function (c) { c.splice(0, cut); }); }
    v.chart.setData(d);
  }

  function showStatus(v, j) {
    var s = j.status || "no data yet";
    v.status.textContent = s + (j.t_s == null ? "" : " at loop time " + j.t_s.toFixed(1) + " s");
    v.status.className = "badge status" + (BAD[s] ? " bad" : s === "ok" ? "" : " warn");
  }

  function showHealth(v, h) {
    var box = v.health;
    box.textContent = "";
    v.healthAlarms = h && h.t_s != null ? h.alarms : [];
    v.healthT = h ? h.t_s : null;
    if (h == null) {
      box.appendChild(el("p", "note", "No health check: the config has no [health]."));
      return;
    }
    if (h.t_s == null) {
      box.appendChild(el("p", "note", "Health: the first window ends at loop time " +
        Math.round(h.first_t_s) + " s (" + until(v, h.first_t_s) + ")."));
      return;
    }
    var held = {};
    h.alarms.forEach(function (a) { held[a.name] = a; });
    var t = el("table", "health-figures");
    t.appendChild(el("caption", null, "Health over the window ending at " + when(h.t_s) +
      (h.alarms.length ? ": in alarm" : ": within its limits")));
    var head = row([], null);
    ["figure", "now", "baseline", "limit"].forEach(function (c) { head.appendChild(el("th", null, c)); });
    t.appendChild(head);
    h.figures.forEach(function (f) {
      var d = f.unit === "s" ? 3 : 2;
      var limit = f.limit == null ? "–" : (f.highest ? "at most " : "at least ") + num(f.limit, d);
      var now = f.now == null ? "not measured (too few steps)" : num(f.now, d);
      var tr = row([f.name + " (" + f.unit + ")", el("td", "num", now),
        el("td", "num", num(f.base, d)), el("td", "num", limit)], held[f.name] ? "past" : null);
      tr.dataset.figure = f.name;
      t.appendChild(tr);
    });
    box.appendChild(t);
    if (h.note) { box.appendChild(el("p", "note", h.note)); }
  }

  // The diagnosis that explains an alarm raised at loop time `since`: the last one since then
  // that names something worth maintenance, else the last one since then.
  function explaining(v, since) {
    var last = null, named = null;
    v.history.forEach(function (r) {
      if (r.error || r.t_s < since) { return; }
      last = r;
      if ((r.advice || []).length) { named = r; }
    });
    return named || last;
  }

  // A health alarm in words: its figure, its limit, since when, and what explains it.
  function healthAlarm(v, a) {
    var d = a.unit === "s" ? 3 : 2;
    var text = "health alarm: " + a.name + " " + num(a.now, d) + " " + a.unit + ", " +
      (a.highest ? "above" : "below") + " its limit of " + num(a.limit, d) + " " + a.unit +
      " (baseline " + num(a.base, d) + " " + a.unit + "), since " + when(a.since_t_s);
    if (v.healthT != null && a.measured_t_s < v.healthT) {
      text += "; not measured since " + when(a.measured_t_s) + " (too few steps)";
    }
    if (v.count === null) { return text + "."; }
    var r = explaining(v, a.since_t_s);
    if (!r) { return text + "; its diagnosis is on its way."; }
    var found = (r.advice || []).map(function (x) { return x.name + " " + x.does; });
    return text + "; the diagnosis at " + when(r.t_s) + (found.length ?
      " explains it: " + found.join("; ") + "." : " names nothing worth maintenance.");
  }

  function showAlarms(v) {
    var items = [];
    if (v.logAlarm != null) { items.push(el("li", "log", "log alarm: " + v.logAlarm)); }
    (v.healthAlarms || []).forEach(function (a) {
      var li = el("li", "health", healthAlarm(v, a));
      li.dataset.figure = a.name;
      items.push(li);
    });
    var last = v.history.length ? v.history[v.history.length - 1] : null;
    (last && last.alarms || []).forEach(function (a) {
      items.push(el("li", "diagnosis", "diagnosis alarm: " + a));
    });
    v.alarms.textContent = "";
    items.forEach(function (li) { v.alarms.appendChild(li); });
    v.alarmBadge.hidden = items.length === 0;
  }

  function loadDiagnoses(v) {
    fetch("/api/diagnoses/" + encodeURIComponent(v.name), { cache: "no-store" })
      .then(function (r) {
        if (!r.ok) { throw new Error("HTTP " + r.status); }
        return r.json();
      })
      .then(function (list) { v.history = list; drawDiagnoses(v); showAlarms(v); })
      .catch(function () { v.count = undefined; });  // asked again with the next answer
  }

  // The time scale of diagnoses at times `xs`: a single one is shown a minute either side (left
  // to itself, the chart would stretch one instant over years).
  function xScale(xs) {
    return xs.length === 1 ? { time: true, auto: false, range: [xs[0] - 60, xs[0] + 60] }
      : { time: true };
  }

  // One chart per unit: each effect's size over time, its 90 % interval as a band.
  function sizeCharts(v) {
    v.sizeCharts.forEach(function (c) { c.destroy(); });
    v.sizeCharts = [];
    v.sizes.textContent = "";
    var done = v.history.filter(function (r) { return !r.error; });
    var units = {};
    done.forEach(function (r) {
      r.effects.forEach(function (e) {
        var u = units[e.size.unit] = units[e.size.unit] || {};
        u[effectLabel(e)] = true;
      });
    });
    Object.keys(units).forEach(function (unit) {
      var keys = Object.keys(units[unit]);
      var data = [done.map(function (r) { return live.started + r.t_s; })];
      var series = [{}], bands = [];
      keys.forEach(function (key, i) {
        var pick = function (f) {
          return done.map(function (r) {
            var e = r.effects.find(function (e) { return effectLabel(e) === key; });
            return e ? f(e.size) : null;
          });
        };
        var color = COLORS[i % COLORS.length];
        data.push(pick(function (s) { return s.value; }), pick(function (s) { return s.low; }),
          pick(function (s) { return s.high; }));
        series.push({ label: key, stroke: color, width: 1.5, points: { show: true, size: 7 } },
          { label: "low", stroke: color, width: 0.5, dash: [4, 4], points: { show: false } },
          { label: "high", stroke: color, width: 0.5, dash: [4, 4], points: { show: false } });
        bands.push({ series: [3 * i + 3, 3 * i + 2], fill: color + "22" });
      });
      var div = el("div", "vb-chart sizes-" + unit.replace(/[^a-z]/gi, ""));
      v.sizes.appendChild(div);
      v.sizeCharts.push(new uPlot({
        title: "Effect sizes (" + unit + "), 90 % intervals", width: Math.min(width(v.sizes), 620),
        height: 220, bands: bands, series: series,
        scales: { x: xScale(data[0]) },
        axes: [timeAxis(), { label: unit }]
      }, data, div));
    });
    charts();
  }

  // What a diagnosis found, in the vocabulary's words: a line per finding, coloured by severity.
  function found(r) {
    var td = el("td", "verdict");
    if (r.error) { td.textContent = "failed: " + r.error; return td; }
    td.appendChild(el("div", "note", r.compared ? "What differs from the reference model:"
      : r.reference ? "The reference: the valve as first diagnosed over a whole window (later diagnoses say what changed since):"
        : "Diagnosed afresh, before the reference (the first whole window):"));
    if (!(r.advice || []).length) { td.appendChild(el("div", null, r.verdict)); }
    (r.advice || []).forEach(function (a) {
      var line = el("div", "sev-" + a.severity);
      line.appendChild(el("b", null, a.severity + " · " + a.name));
      line.appendChild(document.createTextNode(" " + a.does + ". To do: " + a.action + "."));
      td.appendChild(line);
    });
    return td;
  }

  function drawDiagnoses(v) {
    sizeCharts(v);
    var box = v.diag;
    box.textContent = "";
    if (!v.history.length) {
      box.appendChild(el("p", "note", "No diagnosis yet: the first is of the window ending at loop time " +
        Math.round(v.firstDiagnosis) + " s (" + until(v, v.firstDiagnosis) + "), then a while to diagnose it."));
      return;
    }
    var t = el("table", "diagnosis-history");
    var head = row([], null);
    ["time", "trigger", "what it found", "sizes (90 % interval)", "alarms", ""]
      .forEach(function (c) { head.appendChild(el("th", null, c)); });
    t.appendChild(head);
    v.history.slice(-50).reverse().forEach(function (r) {
      var effects = el("td");
      (r.effects || []).forEach(function (e) {
        var s = e.size, line = el(e.finding ? "b" : "span", null, effectLabel(e) + " " +
          s.value.toPrecision(3) + " " + s.unit + " (" + s.low.toPrecision(3) + "–" +
          s.high.toPrecision(3) + ")" + (e.finding ? "" : ", too small to act on"));
        effects.appendChild(line);
        effects.appendChild(el("br"));
      });
      var link = el("td");
      if (r.report) {
        var a = el("a", null, "report");
        a.href = "/reports/" + r.report;
        link.appendChild(a);
      }
      var trigger = r.trigger === "every_s" ? "scheduled" : r.trigger;
      t.appendChild(row([when(r.t_s), trigger, found(r), effects, (r.alarms || []).join("; "),
        link], null));
    });
    box.appendChild(t);
  }

  function update(j) {
    if (live.started != null && j.started_unix_s != null &&
        Math.abs(j.started_unix_s - live.started) > 1) {
      location.reload();  // another run of the daemon: start over
      return;
    }
    live.started = j.started_unix_s;
    live.traceS = j.trace_s;
    j.valves.forEach(function (vj) {
      var v = valve(vj.name);
      if (live.started != null) { addTrace(v, vj.trace); }
      showStatus(v, vj);
      v.logAlarm = vj.log_alarm;
      showHealth(v, vj.health);
      v.firstDiagnosis = vj.first_diagnosis_t_s;
      if (vj.diagnoses !== v.count) {
        v.count = vj.diagnoses;
        if (vj.diagnoses == null) {
          v.diag.textContent = "";
          v.diag.appendChild(el("p", "note", "No live diagnosis: the config has no [diagnosis]."));
        } else {
          loadDiagnoses(v);
        }
      } else if (vj.diagnoses === 0) {
        drawDiagnoses(v);
      }
      showAlarms(v);
    });
    // The points after the earliest last point of a valve (a logger may lag the others).
    var lasts = live.valves.map(function (v) { return v.lastT; });
    live.since = lasts.some(function (t) { return t == null; }) ? null : Math.min.apply(null, lasts);
    window.vbLive.updates++;
  }

  function connected(ok, why) {
    var c = document.getElementById("conn");
    c.textContent = ok ? "updated " + new Date().toLocaleTimeString()
      : "the daemon does not answer (" + why + "); trying again every second";
    c.className = ok ? "" : "down";
  }

  function poll() {
    var url = "/api/live" + (live.since == null ? "" : "?since=" + live.since);
    fetch(url, { cache: "no-store" })
      .then(function (r) {
        if (!r.ok) { throw new Error("HTTP " + r.status); }
        return r.json();
      })
      .then(function (j) { update(j); connected(true); })
      .catch(function (e) { window.vbLive.failures++; connected(false, e.message); })
      .then(function () { setTimeout(poll, POLL_MS); });
  }

  window.addEventListener("resize", function () {
    live.valves.forEach(function (v) {
      v.chart.setSize({ width: width(v.trace), height: 260 });
    });
  });
  poll();
})();
