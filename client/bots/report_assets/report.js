// terrane-bots' HTML report: draws the charts of the runs in the page's
// JSON block (<script type="application/json" id="report-data">, written by
// client/bots/report_html.cpp) with uPlot, embedded in the same page.
//
// The data: {"runs": [{"name": "...", "report": <the JSON report>}, ...]},
// one run for a report, two for `terrane-bots compare`. Every chart puts
// the runs side by side (the second run's lines dashed).
//
// When it is done the script writes to <pre id="report-status"> either
// "ok charts=N" or what went wrong: "errors: ..." (script errors, uncaught
// or reported with console.error) and "empty: ..." (charts that were drawn
// but got no point). The browser test (tests/client/bots/report_page_test.py)
// reads that line. A chart whose source the run does not have (no edits, no
// --server-metrics) is not drawn, and a note says why.
"use strict";

(function () {
  const errors = [];
  const note = (what) => errors.push(String(what).slice(0, 300));
  window.addEventListener("error", (e) => note(e.message || e.error || "error"));
  window.addEventListener("unhandledrejection", (e) => note("unhandled rejection: " + e.reason));
  const consoleError = console.error.bind(console);
  console.error = (...args) => {
    note(args.join(" "));
    consoleError(...args);
  };

  const palette = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf",
                   "#7f7f7f", "#bcbd22"];
  const finite = (v) => typeof v === "number" && isFinite(v);
  const orNull = (v) => (finite(v) ? v : null);

  // Numbers for axes and legends: at most 3 significant digits past the
  // point, no float noise ("6.2048" -> "6.2").
  function fmt(v) {
    if (v == null || !isFinite(v)) return "-";
    const a = Math.abs(v);
    if (a >= 100 || a === 0) return (Math.round(v * 10) / 10).toLocaleString("en-US", {maximumFractionDigits: 1});
    if (a >= 1) return String(Math.round(v * 100) / 100);
    return String(Number(v.toPrecision(3)));
  }

  // A histogram as the JSON report writes it (client/bots/histogram.h):
  // [[lowest_us, count], ...] with 64 buckets per power of two above 128 us.
  function buckets(lat) {
    if (!lat || !lat.histogram || !Array.isArray(lat.histogram.buckets)) return [];
    return lat.histogram.buckets.filter((b) => Array.isArray(b) && finite(b[0]) && finite(b[1]) && b[1] > 0);
  }
  function bucketWidthUs(lowest) {
    return lowest < 128 ? 1 : Math.pow(2, Math.floor(Math.log2(lowest)) - 6);
  }
  // Share of samples (%) in bins of a quarter power of two, by the bin's
  // lower edge in ms: the buckets are too fine to read one by one.
  function histogramPoints(lat) {
    const bins = new Map();
    let total = 0;
    for (const [lowest, count] of buckets(lat)) {
      const mid = Math.max(lowest + bucketWidthUs(lowest) / 2, 1) / 1000;
      const k = Math.floor(Math.log2(mid) * 4);
      bins.set(k, (bins.get(k) || 0) + count);
      total += count;
    }
    return [...bins.entries()].sort((a, b) => a[0] - b[0]).map(([k, n]) => [Math.pow(2, k / 4), (100 * n) / total]);
  }
  // The fraction of samples at or below each bucket's upper edge, in ms.
  function cdfPoints(lat) {
    const b = buckets(lat);
    const total = b.reduce((s, x) => s + x[1], 0);
    let seen = 0;
    return b.map(([lowest, count]) => {
      seen += count;
      return [Math.max(lowest + bucketWidthUs(lowest), 1) / 1000, seen / total];
    });
  }
  // The value in ms below which a fraction p of the samples lie, for p from
  // 0 to 1: the inverse of the CDF, so ms is the y axis (and a threshold a
  // horizontal line).
  function quantilePoints(lat) {
    const b = buckets(lat);
    const total = b.reduce((s, x) => s + x[1], 0);
    let seen = 0;
    const out = [];
    for (const [lowest, count] of b) {
      seen += count;
      out.push([(100 * seen) / total, (lowest + bucketWidthUs(lowest) / 2) / 1000]);
    }
    return out;
  }

  // Series given as [[x, y], ...] each, on the union of their x values
  // (null where a series has no point there).
  function unionXY(pointLists) {
    const xs = [...new Set(pointLists.flatMap((l) => l.map((p) => p[0])))].sort((a, b) => a - b);
    const index = new Map(xs.map((x, i) => [x, i]));
    return [xs, ...pointLists.map((l) => {
      const ys = new Array(xs.length).fill(null);
      for (const [x, y] of l) ys[index.get(x)] = y;
      return ys;
    })];
  }

  const charts = [];
  const skipped = [];
  const grid = document.getElementById("charts");

  // One chart. spec: {id, title, unit, xUnit, logX, series: [{label, values,
  // colour, dash, scale, points}], x, thresholds: [{label, value}],
  // y2: {unit} for series on scale "y2", span: connect over nulls}.
  function chart(spec) {
    const box = document.createElement("div");
    box.className = "chart";
    box.id = "chart-" + spec.id;
    grid.appendChild(box);
    let points = 0;
    for (const s of spec.series) points += s.values.filter((v) => v != null && isFinite(v)).length;
    const series = [{label: spec.xUnit || "s", value: (u, v) => fmt(v)}];
    const data = [spec.x];
    for (const s of spec.series) {
      series.push({label: s.label, stroke: s.colour, width: 1.5, dash: s.dash, scale: s.scale || "y",
                   spanGaps: !!spec.span, paths: s.paths, points: {show: s.points !== undefined ? s.points : false},
                   value: (u, v) => fmt(v)});
      data.push(s.values);
    }
    for (const t of spec.thresholds || []) {
      series.push({label: t.label, stroke: "#000", width: 1, dash: [6, 4], scale: "y", points: {show: false},
                   value: (u, v) => fmt(v)});
      data.push(spec.x.map(() => t.value));
    }
    // A log axis leaves most of its ticks unlabelled (null); its unit is
    // in the axis label, not on each tick (they stand close together).
    const xAxisValues = (u, vals) => vals.map((v) => (v == null ? "" : fmt(v) + (spec.xUnit && !spec.logX ? " " + spec.xUnit : "")));
    const axes = [{values: xAxisValues, label: spec.xLabel || "second of the run (from the first connection)"},
                  {label: spec.unit, values: (u, vals) => vals.map((v) => (v == null ? "" : fmt(v))), size: 60}];
    const scales = {x: {time: false}, y: {range: (u, lo, hi) => [Math.min(0, lo), hi > 0 ? hi * 1.05 : 1]}};
    if (spec.logX) scales.x = {time: false, distr: 3};
    if (spec.yRange) scales.y = {range: () => spec.yRange};
    if (spec.y2) {
      scales.y2 = {range: (u, lo, hi) => [0, hi > 0 ? hi * 1.05 : 1]};
      axes.push({scale: "y2", side: 1, label: spec.y2.unit, values: (u, vals) => vals.map((v) => (v == null ? "" : fmt(v))), size: 50,
                 grid: {show: false}});
    }
    const width = Math.max(360, Math.min(560, (grid.clientWidth || 1120) / 2 - 16));
    new uPlot({title: spec.title, width, height: 260, series, scales, axes, legend: {show: true, live: false}}, data, box);
    charts.push({id: spec.id, title: spec.title, points});
  }

  function skip(title, why) {
    const p = document.createElement("p");
    p.className = "skipped";
    p.textContent = title + ": " + why;
    grid.appendChild(p);
    skipped.push(title);
  }

  function draw(runs) {
    const many = runs.length > 1;
    const name = (run, label) => (many ? run.tag + " " : "") + label;
    const dash = (i) => (i === 0 ? undefined : [8, 4]);
    runs.forEach((run, i) => (run.tag = String.fromCharCode(65 + i)));
    const seconds = Math.max(...runs.map((r) => (Array.isArray(r.report.timeline) ? r.report.timeline.length : 0)));
    const x = Array.from({length: seconds}, (_, i) => i + 1);
    // A per-second series of one run on x: null where the run has no such second.
    const perSecond = (run, f) => x.map((_, i) => {
      const p = (run.report.timeline || [])[i];
      return p ? orNull(f(p)) : null;
    });
    // The thresholds of the first run whose metric starts with one of prefixes.
    const thresholdsFor = (prefixes) => {
      const out = [];
      for (const t of runs[0].report.thresholds || [])
        if (prefixes.some((p) => String(t.metric).startsWith(p)) && finite(t.limit))
          out.push({label: "threshold " + t.expression, value: t.limit});
      return out;
    };
    const latencyOf = (p, key, q) => (p[key] && p[key].count > 0 ? p[key][q] : null);
    const quantiles = [["p50", "#2ca02c"], ["p95", "#ff7f0e"], ["p99", "#d62728"], ["max", "#7f7f7f"]];
    const anyEdits = runs.some((r) => (r.report.edits_sent || 0) > 0);

    for (const [key, id, title, prefix] of [["ack_ms", "ack", "Edit ack per second, by send time (ms)", "ack_"],
                                            ["fanout_ms", "fanout", "Edit fan-out per second, by send time (ms)",
                                             "fanout_"]]) {
      if (!anyEdits) {
        skip(title, "no edits in this run (an editing --behavior draws it)");
        continue;
      }
      const series = [];
      runs.forEach((run, r) => quantiles.forEach(([q, colour]) =>
        series.push({label: name(run, q), colour, dash: dash(r), values: perSecond(run, (p) => latencyOf(p, key, q))})));
      chart({id, title, unit: "ms", x, xUnit: "s", series, thresholds: thresholdsFor([prefix])});
    }

    if (anyEdits) {
      const dists = [["edit_fanout_ms", "fan-out"], ["edit_ack_ms", "ack"], ["round_trip_ms", "round trip"]];
      const lists = [], meta = [];
      runs.forEach((run, r) => dists.forEach(([key, label], d) => {
        lists.push(histogramPoints(run.report[key]));
        meta.push({label: name(run, label), colour: palette[d], dash: dash(r)});
      }));
      const [hx, ...hy] = unionXY(lists);
      chart({id: "histogram", title: "Latency distribution (share of samples per quarter power of two)", unit: "%",
             x: hx, xUnit: "ms", xLabel: "ms (log scale)", logX: true, span: true,
             series: meta.map((m, k) => ({...m, values: hy[k], paths: uPlot.paths.stepped({align: 1})}))});
      const cdfLists = [];
      runs.forEach((run) => dists.forEach(([key]) => cdfLists.push(cdfPoints(run.report[key]))));
      const [cx, ...cy] = unionXY(cdfLists);
      chart({id: "cdf", title: "Latency CDF (fraction of samples at or below)", unit: "fraction", x: cx, xUnit: "ms",
             xLabel: "ms (log scale)", logX: true, span: true, yRange: [0, 1],
             series: meta.map((m, k) => ({...m, values: cy[k]}))});
    } else {
      skip("Latency distribution and CDF", "no edits in this run");
    }

    {
      const series = [];
      runs.forEach((run, r) => {
        series.push({label: name(run, "bots connected"), colour: palette[0], dash: dash(r),
                     values: perSecond(run, (p) => p.bots)});
        series.push({label: name(run, "joins / s"), colour: palette[1], dash: dash(r), scale: "y2",
                     values: perSecond(run, (p) => (finite(p.joins) ? p.joins : null)), points: true});
      });
      chart({id: "bots", title: "Bots connected; joins completed per second", unit: "bots", x, xUnit: "s", series,
             y2: {unit: "joins / s"}});
    }

    {
      const lists = [], meta = [];
      runs.forEach((run, r) => [["join_coarse_ms", "coarse view"], ["join_full_ms", "full resolution"]].forEach(
        ([key, label], d) => {
          lists.push(quantilePoints(run.report[key]));
          meta.push({label: name(run, label), colour: palette[d], dash: dash(r)});
        }));
      const [qx, ...qy] = unionXY(lists);
      chart({id: "joins", title: "Join time by percentile of the bots (ms)", unit: "ms", x: qx, xUnit: "%",
             xLabel: "percentile of the bots' joins", span: true, thresholds: thresholdsFor(["join_"]),
             series: meta.map((m, k) => ({...m, values: qy[k], points: true}))});
    }

    {
      const types = [...new Set(runs.flatMap((run) => (run.report.timeline || []).flatMap(
        (p) => Object.keys(p.bytes_in_by_type || {}))))].sort();
      if (types.length === 0) {
        chart({id: "bandwidth", title: "Bandwidth, all bots (MB/s)", unit: "MB/s", x, xUnit: "s",
               series: runs.flatMap((run, r) => [
                 {label: name(run, "in"), colour: palette[0], dash: dash(r), values: perSecond(run, (p) => p.mb_per_s_in)},
                 {label: name(run, "out"), colour: palette[1], dash: dash(r), values: perSecond(run, (p) => p.mb_per_s_out)}])});
      } else {
        const series = [];
        runs.forEach((run, r) => types.forEach((type, t) => series.push({
          label: name(run, type), colour: palette[t % palette.length], dash: dash(r),
          values: perSecond(run, (p) => (p.bots > 0 ? ((p.bytes_in_by_type || {})[type] || 0) / p.bots / 1000 : null))})));
        chart({id: "bytes-by-type", title: "Bytes in per bot per second by message type (kB)", unit: "kB", x, xUnit: "s",
               series});
      }
    }

    const anyServer = runs.some((run) => (run.report.timeline || []).some((p) => p.server));
    if (!anyServer) {
      skip("The server's CPU, memory, ticks and send queues", "no --server-metrics in this run");
    } else {
      const server = (run, f) => perSecond(run, (p) => (p.server ? f(p.server) : null));
      const serverChart = (id, title, unit, lines) => chart({id, title, unit, x, xUnit: "s",
        series: runs.flatMap((run, r) => lines.map(([label, f], k) =>
          ({label: name(run, label), colour: palette[k], dash: dash(r), values: server(run, f)})))});
      serverChart("server-cpu", "Server CPU (% of one core)", "%", [["CPU", (s) => 100 * s.cpu_share]]);
      serverChart("server-rss", "Server resident memory (MiB)", "MiB",
                  [["RSS", (s) => (finite(s.rss_bytes) ? s.rss_bytes / 1048576 : null)]]);
      serverChart("server-tick", "Server tick (ms, bucket bounds)", "ms",
                  [["tick p99", (s) => s.tick_p99_ms_bound], ["tick max", (s) => s.tick_ms_max_bound]]);
      serverChart("server-queue", "Server send queues, all sessions (kB)", "kB",
                  [["queued", (s) => (finite(s.send_queue_bytes) ? s.send_queue_bytes / 1000 : null)]]);
    }
  }

  function finish() {
    const status = document.getElementById("report-status");
    const empty = charts.filter((c) => c.points === 0).map((c) => c.id);
    const lines = [];
    if (errors.length) lines.push("errors: " + errors.join(" | "));
    if (empty.length) lines.push("empty: " + empty.join(" "));
    if (!lines.length) lines.push("ok charts=" + charts.length + (skipped.length ? " skipped=" + skipped.length : ""));
    status.textContent = lines.join("\n");
    status.className = errors.length || empty.length ? "bad" : "good";
  }

  window.addEventListener("load", () => {
    try {
      if (typeof uPlot === "undefined") throw new Error("the chart library did not load");
      const data = JSON.parse(document.getElementById("report-data").textContent);
      if (!data || !Array.isArray(data.runs) || data.runs.length === 0) throw new Error("no runs in the report data");
      draw(data.runs);
    } catch (e) {
      note(e && e.stack ? e.stack : e);
    }
    finish();
  });
})();
