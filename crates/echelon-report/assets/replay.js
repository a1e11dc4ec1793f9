// echelon replay: draws the run embedded in #echelon-data on a canvas.
// Batched paths (one per colour), typed arrays, trails thinned to <= TRAIL_POINTS.
"use strict";
(function () {
  const TRAIL_SECONDS = 12;
  const TRAIL_POINTS = 120;
  const ROBOT_PX = 9;
  const state = { framesDrawn: 0, drawMs: 0, time: 0, playing: false, errors: [] };
  window.echelonReplay = state;
  window.addEventListener("error", (e) => state.errors.push(String(e.message)));

  const data = JSON.parse(document.getElementById("echelon-data").textContent);
  const f32 = (b64) => {
    const bin = atob(b64);
    const bytes = new Uint8Array(bin.length);
    for (let i = 0; i < bin.length; i++) bytes[i] = bin.charCodeAt(i);
    const out = new Float32Array(bytes.length / 4);
    const view = new DataView(bytes.buffer);
    for (let i = 0; i < out.length; i++) out[i] = view.getFloat32(4 * i, true);
    return out;
  };
  const times = Float64Array.from(data.times);
  const poses = f32(data.poses);               // [instant][agent][x, y, θ]
  const ref = data.reference ? f32(data.reference) : null; // [instant][x, y]
  const n = data.agents.length;
  const frames = times.length;
  const t0 = times[0], t1 = times[frames - 1];
  state.time = t0;

  const canvas = document.getElementById("view");
  const ctx = canvas.getContext("2d");
  const ui = {
    play: document.getElementById("play"), speed: document.getElementById("speed"),
    time: document.getElementById("time"), clock: document.getElementById("clock"),
    fit: document.getElementById("fit"), trails: document.getElementById("trails"),
    links: document.getElementById("links"), frames: document.getElementById("frames"),
  };

  // Agents grouped by colour: one path per group per layer.
  const groups = new Map();
  data.agents.forEach((a, i) => {
    if (!groups.has(a.color)) groups.set(a.color, []);
    groups.get(a.color).push(i);
  });

  // View: world (m, y up) -> CSS pixels: px = ox + s x, py = oy - s y.
  const view = { s: 1, ox: 0, oy: 0 };
  let cssW = 0, cssH = 0, dpr = 1, dirty = true;

  function bounds() {
    let x0 = Infinity, x1 = -Infinity, y0 = Infinity, y1 = -Infinity;
    const add = (x, y) => { if (x < x0) x0 = x; if (x > x1) x1 = x; if (y < y0) y0 = y; if (y > y1) y1 = y; };
    for (let k = 0; k < poses.length; k += 3) add(poses[k], poses[k + 1]);
    if (ref) for (let k = 0; k < ref.length; k += 2) add(ref[k], ref[k + 1]);
    return [x0, x1, y0, y1];
  }
  const world = bounds();
  function fit() {
    const [x0, x1, y0, y1] = world;
    const w = Math.max(x1 - x0, 1e-3), h = Math.max(y1 - y0, 1e-3);
    view.s = 0.92 * Math.min(cssW / w, cssH / h);
    view.ox = cssW / 2 - view.s * (x0 + x1) / 2;
    view.oy = cssH / 2 + view.s * (y0 + y1) / 2;
    dirty = true;
  }
  function resize() {
    dpr = window.devicePixelRatio || 1;
    const r = canvas.getBoundingClientRect();
    const first = cssW === 0;
    cssW = Math.max(1, r.width); cssH = Math.max(1, r.height);
    canvas.width = Math.round(cssW * dpr); canvas.height = Math.round(cssH * dpr);
    if (first) fit();
    dirty = true;
  }

  // Instant index k and fraction u with times[k] <= t < times[k+1].
  function locate(t) {
    let lo = 0, hi = frames - 1;
    if (t <= times[0]) return [0, 0];
    if (t >= times[hi]) return [hi, 0];
    while (hi - lo > 1) { const m = (lo + hi) >> 1; if (times[m] <= t) lo = m; else hi = m; }
    return [lo, (t - times[lo]) / (times[lo + 1] - times[lo])];
  }
  const pos = new Float64Array(3 * n);
  const refPos = new Float64Array(2);
  function interpolate(t) {
    const [k, u] = locate(t);
    const k2 = Math.min(k + 1, frames - 1);
    const a = 3 * n * k, b = 3 * n * k2;
    for (let i = 0; i < 3 * n; i += 3) {
      pos[i] = poses[a + i] + u * (poses[b + i] - poses[a + i]);
      pos[i + 1] = poses[a + i + 1] + u * (poses[b + i + 1] - poses[a + i + 1]);
      let d = poses[b + i + 2] - poses[a + i + 2];
      if (d > Math.PI) d -= 2 * Math.PI; else if (d < -Math.PI) d += 2 * Math.PI;
      pos[i + 2] = poses[a + i + 2] + u * d;
    }
    if (ref) {
      refPos[0] = ref[2 * k] + u * (ref[2 * k2] - ref[2 * k]);
      refPos[1] = ref[2 * k + 1] + u * (ref[2 * k2 + 1] - ref[2 * k + 1]);
    }
    return k;
  }

  const css = (name) => getComputedStyle(document.documentElement).getPropertyValue(name).trim() || "#888";
  const X = (x) => view.ox + view.s * x;
  const Y = (y) => view.oy - view.s * y;

  function draw() {
    const started = performance.now();
    const k = interpolate(state.time);
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    ctx.clearRect(0, 0, cssW, cssH);
    ctx.lineJoin = "round"; ctx.lineCap = "round";
    const muted = css("--muted"), ink = css("--ink");
    // Reference path (thinned to about one point per 2 px of canvas width).
    if (ref) {
      ctx.beginPath();
      const step = Math.max(1, Math.floor(frames / (cssW / 2)));
      for (let j = 0; j < frames; j += step) {
        const x = X(ref[2 * j]), y = Y(ref[2 * j + 1]);
        if (j === 0) ctx.moveTo(x, y); else ctx.lineTo(x, y);
      }
      ctx.lineTo(X(ref[2 * (frames - 1)]), Y(ref[2 * (frames - 1) + 1]));
      ctx.setLineDash([7, 5]); ctx.strokeStyle = muted; ctx.lineWidth = 1.5; ctx.stroke();
      ctx.setLineDash([]);
    }
    // Trails: the last TRAIL_SECONDS, at most TRAIL_POINTS points per agent.
    if (ui.trails.checked) {
      const [kStart] = locate(state.time - TRAIL_SECONDS);
      const step = Math.max(1, Math.ceil((k - kStart) / TRAIL_POINTS));
      ctx.lineWidth = 2; ctx.globalAlpha = 0.75;
      for (const [color, members] of groups) {
        ctx.beginPath();
        for (const i of members) {
          ctx.moveTo(X(poses[3 * n * kStart + 3 * i]), Y(poses[3 * n * kStart + 3 * i + 1]));
          for (let j = kStart + step; j <= k; j += step) {
            ctx.lineTo(X(poses[3 * n * j + 3 * i]), Y(poses[3 * n * j + 3 * i + 1]));
          }
          ctx.lineTo(X(pos[3 * i]), Y(pos[3 * i + 1]));
        }
        ctx.strokeStyle = color; ctx.stroke();
      }
      ctx.globalAlpha = 1;
    }
    // Leader links.
    if (ui.links.checked) {
      ctx.beginPath();
      data.agents.forEach((a, i) => {
        if (a.leader === null) return;
        let lx, ly;
        if (a.leader < 0) { if (!ref) return; lx = refPos[0]; ly = refPos[1]; }
        else { lx = pos[3 * a.leader]; ly = pos[3 * a.leader + 1]; }
        ctx.moveTo(X(pos[3 * i]), Y(pos[3 * i + 1])); ctx.lineTo(X(lx), Y(ly));
      });
      ctx.setLineDash([2, 4]); ctx.strokeStyle = muted; ctx.lineWidth = 1.2; ctx.stroke();
      ctx.setLineDash([]);
    }
    if (ref) {
      ctx.beginPath(); ctx.arc(X(refPos[0]), Y(refPos[1]), 4, 0, 2 * Math.PI);
      ctx.fillStyle = muted; ctx.fill();
    }
    // Robots: oriented triangles, one filled path per colour.
    for (const [color, members] of groups) {
      ctx.beginPath();
      for (const i of members) {
        const x = X(pos[3 * i]), y = Y(pos[3 * i + 1]), th = pos[3 * i + 2];
        const c = Math.cos(th), s = Math.sin(th), r = ROBOT_PX;
        ctx.moveTo(x + r * c, y - r * s);
        ctx.lineTo(x - 0.6 * r * c - 0.55 * r * s, y + 0.6 * r * s - 0.55 * r * c);
        ctx.lineTo(x - 0.6 * r * c + 0.55 * r * s, y + 0.6 * r * s + 0.55 * r * c);
        ctx.closePath();
      }
      ctx.fillStyle = color; ctx.fill();
      ctx.strokeStyle = ink; ctx.lineWidth = 0.8; ctx.stroke();
    }
    // Names, when there are few enough to read.
    if (n <= 12) {
      ctx.font = "12px sans-serif"; ctx.fillStyle = ink;
      for (let i = 0; i < n; i++) ctx.fillText(data.agents[i].name, X(pos[3 * i]) + 10, Y(pos[3 * i + 1]) - 8);
    }
    // Scale bar.
    const target = 120 / view.s, p10 = Math.pow(10, Math.floor(Math.log10(target)));
    const len = [5, 2, 1].map((m) => m * p10).find((v) => v <= target) || p10;
    ctx.beginPath(); ctx.moveTo(16, cssH - 16); ctx.lineTo(16 + len * view.s, cssH - 16);
    ctx.strokeStyle = ink; ctx.lineWidth = 2; ctx.stroke();
    ctx.font = "12px sans-serif"; ctx.fillStyle = ink; ctx.fillText(len + " m", 16, cssH - 22);

    state.framesDrawn += 1;
    state.drawMs += performance.now() - started;
    ui.frames.textContent = String(state.framesDrawn);
    ui.clock.textContent = "t = " + state.time.toFixed(2) + " s";
    ui.time.value = String(Math.round(10000 * (state.time - t0) / Math.max(t1 - t0, 1e-9)));
  }

  function setPlaying(p) {
    if (p && state.time >= t1) state.time = t0;
    state.playing = p;
    ui.play.textContent = p ? "❚❚ Pause" : "▶ Play";
    ui.play.setAttribute("aria-label", p ? "pause" : "play");
    last = null; dirty = true;
  }
  let last = null;
  function tick(now) {
    if (state.playing) {
      if (last !== null) {
        state.time = Math.min(t1, state.time + ((now - last) / 1000) * Number(ui.speed.value));
        if (state.time >= t1) setPlaying(false);
      }
      last = now; dirty = true;
    }
    if (dirty) { dirty = false; draw(); }
    requestAnimationFrame(tick);
  }

  ui.play.addEventListener("click", () => setPlaying(!state.playing));
  ui.fit.addEventListener("click", fit);
  ui.time.addEventListener("input", () => {
    state.time = t0 + (t1 - t0) * Number(ui.time.value) / 10000; dirty = true;
  });
  ui.trails.addEventListener("change", () => { dirty = true; });
  ui.links.addEventListener("change", () => { dirty = true; });
  canvas.addEventListener("wheel", (e) => {
    e.preventDefault();
    const r = canvas.getBoundingClientRect();
    const mx = e.clientX - r.left, my = e.clientY - r.top;
    const f = Math.exp(-e.deltaY * 0.0015);
    view.ox = mx - (mx - view.ox) * f; view.oy = my - (my - view.oy) * f; view.s *= f;
    dirty = true;
  }, { passive: false });
  let drag = null;
  canvas.addEventListener("pointerdown", (e) => {
    drag = { x: e.clientX, y: e.clientY }; canvas.setPointerCapture(e.pointerId); canvas.classList.add("dragging");
  });
  canvas.addEventListener("pointermove", (e) => {
    if (!drag) return;
    view.ox += e.clientX - drag.x; view.oy += e.clientY - drag.y;
    drag = { x: e.clientX, y: e.clientY }; dirty = true;
  });
  const endDrag = () => { drag = null; canvas.classList.remove("dragging"); };
  canvas.addEventListener("pointerup", endDrag);
  canvas.addEventListener("pointercancel", endDrag);
  canvas.addEventListener("dblclick", fit);
  document.addEventListener("keydown", (e) => {
    if (e.target instanceof HTMLInputElement || e.target instanceof HTMLSelectElement) return;
    const [k] = locate(state.time);
    if (e.key === " ") { e.preventDefault(); setPlaying(!state.playing); }
    else if (e.key === "ArrowRight") { state.time = times[Math.min(k + 1, frames - 1)]; dirty = true; }
    else if (e.key === "ArrowLeft") { state.time = times[Math.max(k - 1, 0)]; dirty = true; }
  });
  window.addEventListener("resize", resize);
  resize();
  requestAnimationFrame(tick);
})();
