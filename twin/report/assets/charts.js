// twin's report: draws each div.chart from the JSON beside it with uPlot (inlined once above).
// Kinds: "time" (series over simulated time, bands between two series, the onset marked),
// "xy" (paths seen from above) and "events" (both runs' events on one time axis).
(function () {
  "use strict";

  function onsetHook(spec) {
    return function (u) {
      if (!spec.onset) return;
      var x = u.valToPos(spec.onset.t, "x", true);
      var ctx = u.ctx, top = u.bbox.top, bottom = u.bbox.top + u.bbox.height;
      if (x < u.bbox.left || x > u.bbox.left + u.bbox.width) return;
      ctx.save();
      ctx.strokeStyle = "#9467bd";
      ctx.lineWidth = 2 * devicePixelRatio;
      ctx.setLineDash([5 * devicePixelRatio, 4 * devicePixelRatio]);
      ctx.beginPath(); ctx.moveTo(x, top); ctx.lineTo(x, bottom); ctx.stroke();
      ctx.fillStyle = "#9467bd";
      ctx.textAlign = "left";
      ctx.textBaseline = "alphabetic";
      ctx.font = (11 * devicePixelRatio) + "px sans-serif";
      ctx.fillText(spec.onset.label, x + 4 * devicePixelRatio, bottom - 6 * devicePixelRatio);
      ctx.restore();
    };
  }

  function size(el, square) {
    var w = Math.max(240, el.clientWidth || 480);
    return {width: w, height: square ? Math.min(w, 320) : 250};
  }

  function axes(spec) {
    return [{label: spec.x_label, size: 40}, {label: spec.y_label || "", size: 70}];
  }

  function timeChart(el, spec) {
    var data = [spec.x];
    var series = [{label: "t (s)"}];
    spec.series.forEach(function (s) {
      data.push(s.values);
      series.push({label: s.label, stroke: s.color, width: s.dash ? 1.2 : 1.5,
                   dash: s.dash ? [6, 4] : undefined, points: {show: false},
                   spanGaps: true, show: true});
    });
    var opts = Object.assign(size(el), {
      title: spec.title, scales: {x: {time: false}}, axes: axes(spec), series: series,
      bands: spec.bands.map(function (b) { return {series: [b[0], b[1]], fill: b[2]}; }),
      legend: {live: false}, hooks: {draw: [onsetHook(spec)]}
    });
    var u = new uPlot(opts, data, el);
    // the legend may leave out x: count its rows from the end
    var rows = u.root.querySelectorAll(".u-legend .u-series");
    var skip = rows.length - spec.series.length;
    spec.series.forEach(function (s, i) {
      if (s.legend === false && rows[i + skip]) rows[i + skip].style.display = "none";
    });
    return u;
  }

  function xyPath(u, i) {
    var xy = u.data[i], p = new Path2D();
    for (var k = 0; k < xy[0].length; k++) {
      var px = u.valToPos(xy[0][k], "x", true), py = u.valToPos(xy[1][k], "y", true);
      if (k === 0) p.moveTo(px, py); else p.lineTo(px, py);
    }
    return {stroke: p, fill: null, clip: null, band: null, gaps: null, flags: 0};
  }

  function range(values, pad) {
    var lo = Math.min.apply(null, values), hi = Math.max.apply(null, values);
    var half = Math.max((hi - lo) / 2, 1e-3) * (1 + pad), mid = (lo + hi) / 2;
    return [mid - half, mid + half];
  }

  function xyChart(el, spec) {
    var xs = [], ys = [];
    spec.series.forEach(function (s) { xs = xs.concat(s.xy[0]); ys = ys.concat(s.xy[1]); });
    // one scale for x and y: a path from above keeps its shape
    var rx = range(xs, 0.1), ry = range(ys, 0.1);
    var half = Math.max(rx[1] - rx[0], ry[1] - ry[0]) / 2;
    var cx = (rx[0] + rx[1]) / 2, cy = (ry[0] + ry[1]) / 2;
    var series = [null].concat(spec.series.map(function (s) {
      return {label: s.label, stroke: s.color, width: 1.5, dash: s.dash ? [6, 4] : undefined,
              facets: [{scale: "x", auto: false}, {scale: "y", auto: false}], paths: xyPath,
              points: {show: false}};
    }));
    var opts = Object.assign(size(el, true), {
      mode: 2, title: spec.title, axes: axes(spec), series: series, legend: {live: false},
      scales: {x: {time: false, auto: false, range: [cx - half, cx + half]},
               y: {auto: false, range: [cy - half, cy + half]}},
      hooks: {draw: [function (u) {
        var ctx = u.ctx;
        spec.marks.forEach(function (m) {
          ctx.save(); ctx.strokeStyle = m.color; ctx.lineWidth = 2 * devicePixelRatio;
          ctx.beginPath();
          ctx.arc(u.valToPos(m.x, "x", true), u.valToPos(m.y, "y", true),
                  5 * devicePixelRatio, 0, 2 * Math.PI);
          ctx.stroke(); ctx.restore();
        });
      }]}
    });
    return new uPlot(opts, [null].concat(spec.series.map(function (s) { return s.xy; })), el);
  }

  function eventsChart(el, spec) {
    var Y = {golden: 1, candidate: 0};
    function draw(u) {
      var ctx = u.ctx, r = devicePixelRatio, left = u.bbox.left, right = left + u.bbox.width;
      // labels only where they do not run into each other (zoom in to see the rest)
      var gap = 12 * r, ring = spec.marked.length > 40 ? 3 * r : 7 * r;
      ctx.save();
      ctx.textAlign = "left";
      ctx.textBaseline = "alphabetic";
      ctx.font = (10 * r) + "px sans-serif";
      ["golden", "candidate"].forEach(function (side) {
        var y = u.valToPos(Y[side], "y", true), last = -Infinity;
        spec[side].forEach(function (e) {
          var x = u.valToPos(e[0], "x", true);
          if (x < left || x > right) return;
          ctx.strokeStyle = side === "golden" ? "#1f77b4" : "#d62728";
          ctx.lineWidth = 1.5 * r;
          ctx.beginPath(); ctx.moveTo(x, y - 8 * r); ctx.lineTo(x, y + 8 * r); ctx.stroke();
          if (!e[2] && x - last >= gap) {
            last = x;
            ctx.save(); ctx.translate(x + 2 * r, y - 10 * r); ctx.rotate(-Math.PI / 4);
            ctx.fillStyle = "#333"; ctx.fillText(e[1], 0, 0); ctx.restore();
          }
        });
      });
      var lastMark = -Infinity;
      spec.marked.forEach(function (m) {
        var ends = ["golden", "candidate"].filter(function (s) { return m[s] !== null; });
        var xs = ends.map(function (s) { return u.valToPos(m[s], "x", true); });
        if (Math.max.apply(null, xs) < left || Math.min.apply(null, xs) > right) return;
        ctx.strokeStyle = m.color; ctx.lineWidth = 2 * r; ctx.beginPath();
        ends.forEach(function (s, i) {
          var y = u.valToPos(Y[s], "y", true);
          if (i === 0) ctx.moveTo(xs[i], y); else ctx.lineTo(xs[i], y);
        });
        ctx.stroke();
        var named = xs[0] - lastMark >= 4 * gap;
        if (named) lastMark = xs[0];
        ends.forEach(function (s, i) {
          var y = u.valToPos(Y[s], "y", true);
          ctx.beginPath(); ctx.arc(xs[i], y, ring, 0, 2 * Math.PI); ctx.stroke();
          if (named) { ctx.fillStyle = m.color; ctx.fillText(m.kind, xs[i] + 9 * r, y + 14 * r); }
        });
      });
      ctx.restore();
    }
    var opts = Object.assign(size(el), {
      title: spec.title, height: 260, legend: {show: false},
      scales: {x: {time: false, auto: false, range: [0, spec.end * 1.03]},
               y: {auto: false, range: [-0.6, 1.9]}},
      axes: [{label: spec.x_label, size: 40},
             {size: 80, splits: [0, 1], values: function () { return ["candidate", "golden"]; }}],
      series: [{}, {label: "", show: false}],
      hooks: {draw: [draw, onsetHook(spec)]}
    });
    return new uPlot(opts, [[0, spec.end], [null, null]], el);
  }

  var KINDS = {time: timeChart, xy: xyChart, events: eventsChart};

  function drawAll() {
    var els = document.querySelectorAll("div.chart");
    for (var i = 0; i < els.length; i++) {
      var el = els[i], spec = JSON.parse(el.querySelector("script").textContent);
      KINDS[spec.kind](el, spec);
      el.setAttribute("data-drawn", "1");
    }
  }

  if (document.readyState === "loading") document.addEventListener("DOMContentLoaded", drawAll);
  else drawAll();
})();
