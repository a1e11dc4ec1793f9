// echelon's replay drawing: one scene on a canvas, drawn from what a driver
// hands it each frame. Two drivers use it: the report's replay (replay.js, a
// recorded run interpolated in time) and the fleet's live dashboard (the
// robots' states as they arrive over a WebSocket).
// Batched paths (one per colour), trails thinned by the driver.
"use strict";
// `scene`: `agents` (each `{name, leader, color}`: leader a 0-based agent
// index, -1 for the reference, null if unknown), `path` (the reference's path,
// flat `[x0, y0, x1, y1, …]`, or null) and, for a run with a safety filter,
// `safety` (`{radius, l, obstacles}`). Returns the view (world m, y up ->
// CSS px: px = ox + s x, py = oy - s y), `fit(bounds)`, `resize()`,
// `draw(frame)` and `toWorld(px, py)`.
function echelonDrawing(canvas, scene) {
  const ROBOT_PX = 9;
  const ctx = canvas.getContext("2d");
  const agents = scene.agents, n = agents.length, path = scene.path;
  const safety = scene.safety || null;
  // Agents grouped by colour: one path per group per layer.
  const groups = new Map();
  agents.forEach((a, i) => {
    if (!groups.has(a.color)) groups.set(a.color, []);
    groups.get(a.color).push(i);
  });
  const view = { s: 1, ox: 0, oy: 0, moved: false };
  let cssW = 0, cssH = 0, dpr = 1, world = [-1, 1, -1, 1];
  const onChange = [];

  // Frames `[x0, x1, y0, y1]` (world m) in the canvas.
  function fit(bounds) {
    if (bounds) world = bounds;
    const [x0, x1, y0, y1] = world;
    const w = Math.max(x1 - x0, 1e-3), h = Math.max(y1 - y0, 1e-3);
    view.s = 0.92 * Math.min(cssW / w, cssH / h);
    view.ox = cssW / 2 - view.s * (x0 + x1) / 2;
    view.oy = cssH / 2 + view.s * (y0 + y1) / 2;
    view.moved = false;
    changed();
  }
  function resize() {
    dpr = window.devicePixelRatio || 1;
    const r = canvas.getBoundingClientRect();
    const first = cssW === 0;
    cssW = Math.max(1, r.width); cssH = Math.max(1, r.height);
    canvas.width = Math.round(cssW * dpr); canvas.height = Math.round(cssH * dpr);
    if (first) fit(); else changed();
  }
  function changed() { for (const f of onChange) f(); }

  const css = (name) => getComputedStyle(document.documentElement).getPropertyValue(name).trim() || "#888";
  const X = (x) => view.ox + view.s * x;
  const Y = (y) => view.oy - view.s * y;
  // A trail's points, handed one at a time by the driver (no allocation).
  let started = false;
  const visit = (x, y) => {
    if (started) ctx.lineTo(X(x), Y(y)); else { ctx.moveTo(X(x), Y(y)); started = true; }
  };
  const known = (pos, i) => pos[3 * i] === pos[3 * i];  // NaN: not seen yet

  // `frame`: `pos` (Float64Array [agent][x, y, θ]; NaN x: not seen yet),
  // `ref` ([x, y] of the reference now, or null), `trails` and `links`
  // (whether to draw them), `trail(i, visit)` (calls visit(x, y) for agent
  // i's trail, oldest first) and, with a safety filter, `action(i)` (what
  // agent i's filter does now: outcome 0 nominal, 1 filtered, 2 braked, + 3
  // while breaking a deadlock).
  function draw(f) {
    const pos = f.pos, refPos = f.ref;
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    ctx.clearRect(0, 0, cssW, cssH);
    ctx.lineJoin = "round"; ctx.lineCap = "round";
    const muted = css("--muted"), ink = css("--ink");
    // Reference path (thinned to about one point per 2 px of canvas width).
    if (path && path.length >= 4) {
      const count = path.length / 2;
      ctx.beginPath();
      const step = Math.max(1, Math.floor(count / (cssW / 2)));
      for (let j = 0; j < count; j += step) {
        const x = X(path[2 * j]), y = Y(path[2 * j + 1]);
        if (j === 0) ctx.moveTo(x, y); else ctx.lineTo(x, y);
      }
      ctx.lineTo(X(path[2 * (count - 1)]), Y(path[2 * (count - 1) + 1]));
      ctx.setLineDash([7, 5]); ctx.strokeStyle = muted; ctx.lineWidth = 1.5; ctx.stroke();
      ctx.setLineDash([]);
    }
    // Trails.
    if (f.trails) {
      ctx.lineWidth = 2; ctx.globalAlpha = 0.75;
      for (const [color, members] of groups) {
        ctx.beginPath();
        for (const i of members) {
          if (!known(pos, i)) continue;
          started = false;
          f.trail(i, visit);
        }
        ctx.strokeStyle = color; ctx.stroke();
      }
      ctx.globalAlpha = 1;
    }
    // Leader links.
    if (f.links) {
      ctx.beginPath();
      agents.forEach((a, i) => {
        if (a.leader === null || !known(pos, i)) return;
        let lx, ly;
        if (a.leader < 0) { if (!refPos) return; lx = refPos[0]; ly = refPos[1]; }
        else { if (!known(pos, a.leader)) return; lx = pos[3 * a.leader]; ly = pos[3 * a.leader + 1]; }
        ctx.moveTo(X(pos[3 * i]), Y(pos[3 * i + 1])); ctx.lineTo(X(lx), Y(ly));
      });
      ctx.setLineDash([2, 4]); ctx.strokeStyle = muted; ctx.lineWidth = 1.2; ctx.stroke();
      ctx.setLineDash([]);
    }
    if (refPos) {
      ctx.beginPath(); ctx.arc(X(refPos[0]), Y(refPos[1]), 4, 0, 2 * Math.PI);
      ctx.fillStyle = muted; ctx.fill();
    }
    // Robots: oriented triangles, one filled path per colour.
    for (const [color, members] of groups) {
      ctx.beginPath();
      for (const i of members) {
        if (!known(pos, i)) continue;
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
      for (let i = 0; i < n; i++) {
        if (known(pos, i)) ctx.fillText(agents[i].name, X(pos[3 * i]) + 10, Y(pos[3 * i + 1]) - 8);
      }
    }
    // Scale bar.
    const target = 120 / view.s, p10 = Math.pow(10, Math.floor(Math.log10(target)));
    const len = [5, 2, 1].map((m) => m * p10).find((v) => v <= target) || p10;
    ctx.beginPath(); ctx.moveTo(16, cssH - 16); ctx.lineTo(16 + len * view.s, cssH - 16);
    ctx.strokeStyle = ink; ctx.lineWidth = 2; ctx.stroke();
    ctx.font = "12px sans-serif"; ctx.fillStyle = ink; ctx.fillText(len + " m", 16, cssH - 22);
  }

  // Wheel or pinch: zoom; drag: pan; double-click: fit.
  canvas.addEventListener("wheel", (e) => {
    e.preventDefault();
    const r = canvas.getBoundingClientRect();
    const mx = e.clientX - r.left, my = e.clientY - r.top;
    const k = Math.exp(-e.deltaY * 0.0015);
    view.ox = mx - (mx - view.ox) * k; view.oy = my - (my - view.oy) * k; view.s *= k;
    view.moved = true; changed();
  }, { passive: false });
  let drag = null;
  canvas.addEventListener("pointerdown", (e) => {
    drag = { x: e.clientX, y: e.clientY }; canvas.setPointerCapture(e.pointerId); canvas.classList.add("dragging");
  });
  canvas.addEventListener("pointermove", (e) => {
    if (!drag) return;
    view.ox += e.clientX - drag.x; view.oy += e.clientY - drag.y;
    drag = { x: e.clientX, y: e.clientY }; view.moved = true; changed();
  });
  const endDrag = () => { drag = null; canvas.classList.remove("dragging"); };
  canvas.addEventListener("pointerup", endDrag);
  canvas.addEventListener("pointercancel", endDrag);
  canvas.addEventListener("dblclick", () => fit());
  window.addEventListener("resize", resize);
  resize();
  return {
    view, fit, resize, draw, X, Y,
    size: () => [cssW, cssH],
    toWorld: (px, py) => [(px - view.ox) / view.s, (view.oy - py) / view.s],
    onChange: (f) => onChange.push(f),
  };
}
