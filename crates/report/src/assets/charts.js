// Draws the interactive charts of a valve-bridge report (crates/report/src/chart.rs) with uPlot: each
// <div class="vb-chart" data-set=ID> reads the series of <script id="vb-data-ID"> (over its
// data-x0..data-x1 stretch of time when given). Drag across a chart to zoom into that time,
// turn the wheel with Shift held to pan along it, double-click to go back; the legend shows the
// values under the cursor. A chart with data-shown draws only those series at first (a click on
// a legend entry shows another); one with data-zoom0..data-zoom1 opens zoomed on that time (a
// double-click shows all of it). The drawn charts are window.vbCharts, in page order.
(function () {
  "use strict";
  var sets = {};
  function dataset(id) {
    if (!sets[id]) {
      sets[id] = JSON.parse(document.getElementById("vb-data-" + id).textContent);
    }
    return sets[id];
  }
  // First index whose x is at least v (x ascending).
  function lowerBound(x, v) {
    var lo = 0, hi = x.length;
    while (lo < hi) {
      var mid = (lo + hi) >> 1;
      if (x[mid] < v) { lo = mid + 1; } else { hi = mid; }
    }
    return lo;
  }
  function number(v) {
    if (v == null) { return "–"; }
    return Math.abs(v) >= 1000 ? v.toFixed(1) : v.toFixed(3);
  }
  function draw(el) {
    var d = dataset(el.dataset.set);
    var a = 0, b = d.x.length;
    if (el.dataset.x0 !== undefined) {
      a = lowerBound(d.x, Number(el.dataset.x0));
      b = Math.max(a + 1, lowerBound(d.x, Number(el.dataset.x1) + 1e-9));
    }
    var data = [d.x.slice(a, b)].concat(d.y.map(function (c) { return c.slice(a, b); }));
    var series = [{ label: el.dataset.x, value: function (u, v) { return v == null ? "–" : v.toFixed(2); } }];
    var shown = el.dataset.shown === undefined ? null : el.dataset.shown.split(",").map(Number);
    d.names.forEach(function (name, i) {
      series.push({ label: name, stroke: d.colors[i], width: 1, show: !shown || shown.indexOf(i) >= 0,
        value: function (u, v) { return number(v); } });
    });
    var chart = new uPlot({
      title: el.dataset.title,
      width: Math.max(320, el.clientWidth),
      height: 320,
      scales: { x: { time: false } },
      cursor: { drag: { x: true, y: false, setScale: true } },
      axes: [{ label: el.dataset.x }, { label: el.dataset.y }],
      series: series
    }, data, el);
    if (el.dataset.zoom0 !== undefined) {
      chart.setScale("x", { min: Number(el.dataset.zoom0), max: Number(el.dataset.zoom1) });
    }
    // Shift+wheel pans by a tenth of the shown time, within the data (a plain wheel still
    // scrolls the page: uPlot has no pan of its own).
    chart.over.addEventListener("wheel", function (e) {
      if (!e.shiftKey) { return; }
      e.preventDefault();
      var x = chart.scales.x, xs = chart.data[0];
      var first = xs[0], last = xs[xs.length - 1], span = x.max - x.min;
      var step = 0.1 * span * Math.sign(e.deltaY || e.deltaX);
      var lo = Math.min(Math.max(x.min + step, first), last - span);
      chart.setScale("x", { min: lo, max: lo + span });
    }, { passive: false });
    var hint = document.createElement("div");
    hint.className = "vb-hint";
    hint.textContent = "Drag across the chart to zoom into that time, Shift+wheel to pan, double-click to see all of it again.";
    el.appendChild(hint);
    return chart;
  }
  window.vbCharts = Array.prototype.map.call(document.querySelectorAll("div.vb-chart"), draw);
  window.addEventListener("resize", function () {
    window.vbCharts.forEach(function (u) {
      u.setSize({ width: Math.max(320, u.root.parentNode.clientWidth), height: 320 });
    });
  });
})();
