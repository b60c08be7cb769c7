// The thermographer's workbench on the session page: tools drawn on the picture with live
// readouts (box, spot, line; ΔT between the first two), the detector's target boxes, an
// isotherm overlay, a histogram, a region's time series under the scrubber, play at the
// recorded rate, and frame stepping with the arrow keys. Every number comes from the API.
"use strict";
const workbench = (() => {
  const state = { tools: [], frame: 0, meta: null, drag: null, playing: false, timer: null, busy: false };
  const $ = (id) => document.getElementById(id);
  let ctx = null;  // {base, session, showFrame}

  function toText(t) {
    const r = (v) => Math.round(v);
    if (t.kind === "spot") return `spot:${r(t.x0)},${r(t.y0)}`;
    return `${t.kind}:${r(t.x0)},${r(t.y0)},${r(t.x1)},${r(t.y1)}`;
  }
  function toPixel(e) {
    const c = $("overlay"), b = c.getBoundingClientRect();
    return [Math.min(ctx.session.width - 1, Math.max(0, (e.clientX - b.left) / b.width * ctx.session.width)),
            Math.min(ctx.session.height - 1, Math.max(0, (e.clientY - b.top) / b.height * ctx.session.height))];
  }
  function fit() {  // the overlay is drawn at screen resolution, in the frame's pixel coordinates
    const c = $("overlay"), r = c.getBoundingClientRect(), dpr = window.devicePixelRatio || 1;
    c.width = Math.max(1, Math.round(r.width * dpr)); c.height = Math.max(1, Math.round(r.height * dpr));
    draw(state.last);
  }
  function draw(readouts) {
    const c = $("overlay"), g = c.getContext("2d"), W = ctx.session.width, H = ctx.session.height;
    state.last = readouts;
    g.setTransform(1, 0, 0, 1, 0, 0);
    g.clearRect(0, 0, c.width, c.height);
    g.setTransform(c.width / W, 0, 0, c.height / H, 0, 0);
    g.imageSmoothingEnabled = false;  // the isotherm's pixels are the frame's pixels
    if (state.iso) g.drawImage(state.iso, 0, 0, W, H);
    const k = W / Math.max(1, c.getBoundingClientRect().width);  // frame pixels per screen pixel
    g.lineWidth = 1.5 * k;
    g.font = `${12 * k}px system-ui`;
    if ($("boxes").checked && state.meta)
      for (const t of state.meta.targets || []) {
        const [x0, y0, x1, y1] = t.bbox;
        g.strokeStyle = "#ff0"; g.strokeRect(x0 - 0.5, y0 - 0.5, x1 - x0 + 1, y1 - y0 + 1);
        g.fillStyle = "#ff0"; g.fillText(`${t.target_id} ${(+t.max_temp_c).toFixed(1)}`, x0, Math.max(12 * k, y0 - 2 * k));
      }
    const all = state.drag ? [...state.tools, state.drag] : state.tools;
    all.forEach((t, i) => {
      g.strokeStyle = g.fillStyle = "#0ff";
      if (t.kind === "box") g.strokeRect(Math.min(t.x0, t.x1), Math.min(t.y0, t.y1), Math.abs(t.x1 - t.x0), Math.abs(t.y1 - t.y0));
      if (t.kind === "line") { g.beginPath(); g.moveTo(t.x0, t.y0); g.lineTo(t.x1, t.y1); g.stroke(); }
      if (t.kind === "spot") { const a = 8 * k; g.beginPath(); g.moveTo(t.x0 - a, t.y0); g.lineTo(t.x0 + a, t.y0);
                               g.moveTo(t.x0, t.y0 - a); g.lineTo(t.x0, t.y0 + a); g.stroke(); }
      const m = readouts && readouts[i];
      if (m && m.max_c !== null) g.fillText(`#${i + 1} ${m.max_c.toFixed(1)}°`, Math.min(t.x0, t.x1 ?? t.x0) + 2 * k,
                                            Math.max(t.y0, t.y1 ?? t.y0) + 14 * k);
    });
  }
  async function readout() {
    const table = $("readouts");
    if (!state.tools.length) { table.innerHTML = ""; draw(); return; }
    const q = state.tools.map(t => "tool=" + encodeURIComponent(toText(t))).join("&");
    try {
      const r = await (await api(`${ctx.base}/frames/${state.frame}/measure?${q}`)).json();
      const rows = r.measurements.map((m, i) => `<tr><td>#${i + 1}</td><td>${esc(m.tool)}</td><td>${m.min_c ?? "-"}</td>` +
        `<td><b>${m.max_c ?? "-"}</b></td><td>${m.mean_c ?? "-"}</td><td>${m.std_c ?? "-"}</td>` +
        `<td>${m.max_xy ? m.max_xy.join(",") : "-"}</td></tr>`);
      const dt = r.delta_t_c ? `<tr><td colspan=7>ΔT #1 − #2: max ${r.delta_t_c.max} °C, mean ${r.delta_t_c.mean} °C</td></tr>` : "";
      table.innerHTML = "<tr><th></th><th>tool</th><th>min</th><th>max</th><th>mean</th><th>std</th><th>max at</th></tr>" +
        rows.join("") + dt + `<tr><td colspan=7 class=muted>°C, model version ${r.model_version ?? 0}</td></tr>`;
      draw(r.measurements);
    } catch (e) { table.innerHTML = `<tr><td>${esc(e.message)}</td></tr>`; draw(); }
  }
  async function isotherm() {
    state.iso = null;
    if ($("iso").checked) {
      const r = await api(`${ctx.base}/frames/${state.frame}/isotherm?above=${+$("isoT").value}&format=png`);
      const mask = await createImageBitmap(await r.blob());
      const c = document.createElement("canvas"); c.width = mask.width; c.height = mask.height;
      const g = c.getContext("2d"); g.drawImage(mask, 0, 0);
      const px = g.getImageData(0, 0, c.width, c.height);
      for (let i = 0; i < px.data.length; i += 4) {  // white = above: cyan, half transparent; the rest clear
        const on = px.data[i] > 127; px.data[i] = 0; px.data[i + 1] = 255; px.data[i + 2] = 255; px.data[i + 3] = on ? 140 : 0;
      }
      g.putImageData(px, 0, 0); state.iso = c;
      const n = await (await api(`${ctx.base}/frames/${state.frame}/isotherm?above=${+$("isoT").value}`)).json();
      $("isoinfo").textContent = `${n.pixels} px above ${n.above_c} °C (${(n.fraction * 100).toFixed(2)} %)`;
    } else $("isoinfo").textContent = "";
  }
  async function histogram() {
    const c = $("hist"), g = c.getContext("2d");
    const box = state.tools.find(t => t.kind === "box");
    const h = await (await api(`${ctx.base}/frames/${state.frame}/histogram?bins=64` +
                                (box ? "&tool=" + encodeURIComponent(toText(box)) : ""))).json();
    g.clearRect(0, 0, c.width, c.height);
    const top = Math.max(1, ...h.counts), w = c.width / Math.max(1, h.counts.length);
    g.fillStyle = "#f93";
    h.counts.forEach((n, i) => { const bh = (c.height - 14) * Math.sqrt(n / top); g.fillRect(i * w, c.height - 14 - bh, Math.max(1, w - 1), bh); });
    g.fillStyle = "#aaa"; g.font = "10px system-ui";
    if (h.edges_c.length) { g.fillText(`${h.edges_c[0].toFixed(1)} °C`, 0, c.height - 2);
      const t = `${h.edges_c[h.edges_c.length - 1].toFixed(1)} °C`; g.fillText(t, c.width - g.measureText(t).width, c.height - 2); }
    $("histinfo").textContent = `${h.pixels} px` + (box ? ` in #${state.tools.indexOf(box) + 1}` : " (whole frame)") + ", √ scale";
  }
  async function series() {
    const box = state.tools.find(t => t.kind === "box" || t.kind === "spot");
    if (!box) { $("seriesinfo").textContent = "draw a box (or a spot) first"; return; }
    const step = Math.max(1, Math.ceil(ctx.session.frames / 400));
    $("seriesinfo").textContent = "computing...";
    const r = await (await api(`${ctx.base}/series?tool=${encodeURIComponent(toText(box))}&stat=max&step=${step}`)).json();
    state.series = r.points;
    drawSeries();
    const vals = r.points.map(p => p.celsius).filter(v => v !== null);
    $("seriesinfo").textContent = `max of #${state.tools.indexOf(box) + 1} over ${r.points.length} frames (every ${step}): ` +
      `${Math.min(...vals).toFixed(2)} .. ${Math.max(...vals).toFixed(2)} °C; click to jump`;
  }
  function drawSeries() {
    const c = $("series"), g = c.getContext("2d");
    g.clearRect(0, 0, c.width, c.height);
    const pts = state.series || [];
    if (!pts.length) return;
    const vals = pts.map(p => p.celsius ?? NaN), lo = Math.min(...vals.filter(isFinite)), hi = Math.max(...vals.filter(isFinite));
    const X = (f) => f / Math.max(1, ctx.session.frames - 1) * c.width, Y = (v) => 6 + (c.height - 12) * (1 - (v - lo) / ((hi - lo) || 1));
    g.strokeStyle = "#0ff"; g.beginPath();
    pts.forEach((p, i) => { if (p.celsius === null) return; i ? g.lineTo(X(p.frame), Y(p.celsius)) : g.moveTo(X(p.frame), Y(p.celsius)); });
    g.stroke();
    g.fillStyle = "#fff"; g.fillRect(X(state.frame) - 1, 0, 2, c.height);
  }
  function step(d) { ctx.showFrame(Math.min(ctx.session.frames - 1, Math.max(0, state.frame + d))); }
  function play() {
    state.playing = !state.playing;
    $("play").textContent = state.playing ? "pause" : "play";
    clearInterval(state.timer);
    if (!state.playing) return;
    const span = Math.max(1, ctx.session.end_ns - ctx.session.start_ns) / 1e9;
    const fps = Math.max(1, (ctx.session.frames - 1) / span);  // the recorded rate
    const t0 = performance.now(), f0 = state.frame;
    state.timer = setInterval(async () => {
      if (state.busy) return;  // a frame still loading: skip to where the clock is, never fall behind it
      const f = f0 + Math.floor((performance.now() - t0) / 1000 * fps);
      if (f >= ctx.session.frames) { play(); return; }
      if (f !== state.frame) { state.busy = true; try { await ctx.showFrame(f); } finally { state.busy = false; } }
    }, 1000 / Math.min(fps, 60));
  }
  function init(c) {
    ctx = c;
    const ov = $("overlay");
    $("img").addEventListener("load", fit);
    window.addEventListener("resize", fit);
    ov.onmousedown = (e) => {
      const kind = $("tool").value; if (!kind) return;
      const [x, y] = toPixel(e);
      state.drag = { kind, x0: x, y0: y, x1: x, y1: y };
      if (kind === "spot") { state.tools.push(state.drag); state.drag = null; refresh(); }
    };
    ov.onmousemove = (e) => {
      if (state.drag) { [state.drag.x1, state.drag.y1] = toPixel(e); draw(); }
      ctx.hover(e);
    };
    ov.onmouseup = () => {
      if (!state.drag) return;
      const t = state.drag; state.drag = null;
      if (Math.abs(t.x1 - t.x0) + Math.abs(t.y1 - t.y0) >= 2) state.tools.push(t);
      refresh();
    };
    $("clear").onclick = () => { state.tools = []; state.series = null; drawSeries(); refresh(); };
    $("boxes").onchange = () => draw();
    $("iso").onchange = $("isoT").onchange = () => refresh();
    $("play").onclick = play;
    $("seriesbtn").onclick = () => series().catch(e => { $("seriesinfo").textContent = e.message; });
    $("series").onclick = (e) => {
      const r = e.target.getBoundingClientRect();
      ctx.showFrame(Math.round((e.clientX - r.left) / r.width * (ctx.session.frames - 1)));
    };
    document.addEventListener("keydown", (e) => {
      if (e.target.tagName === "INPUT" && e.target.type !== "range") return;
      if (e.key === "ArrowRight") { step(e.shiftKey ? 10 : 1); e.preventDefault(); }
      if (e.key === "ArrowLeft") { step(e.shiftKey ? -10 : -1); e.preventDefault(); }
      if (e.key === " ") { play(); e.preventDefault(); }
    });
  }
  async function refresh() {
    await Promise.all([readout(), isotherm().then(() => draw()), histogram()]).catch(e => console.warn(e));
    await readout();
    drawSeries();
  }
  async function onFrame(n, meta) { state.frame = n; state.meta = meta; if (ctx) await refresh(); }
  function addTool(text) {  // "box:x0,y0,x1,y1" etc.: for scripts and tests, as drawing one does
    const [kind, rest] = text.split(":"), v = rest.split(",").map(Number);
    state.tools.push(kind === "spot" ? { kind, x0: v[0], y0: v[1] } : { kind, x0: v[0], y0: v[1], x1: v[2], y1: v[3] });
    return refresh();
  }
  return { init, onFrame, addTool, series, state, play };
})();
