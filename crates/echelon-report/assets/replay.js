// echelon replay: the run embedded in #echelon-data, interpolated in time and
// drawn with the replay drawing (replay-draw.js, before this script).
// Typed arrays, trails thinned to <= TRAIL_POINTS.
"use strict";
(function () {
  const TRAIL_SECONDS = 12;
  const TRAIL_POINTS = 120;
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

  const ui = {
    play: document.getElementById("play"), speed: document.getElementById("speed"),
    time: document.getElementById("time"), clock: document.getElementById("clock"),
    fit: document.getElementById("fit"), trails: document.getElementById("trails"),
    links: document.getElementById("links"), frames: document.getElementById("frames"),
  };
  const drawing = echelonDrawing(document.getElementById("view"), {
    agents: data.agents, path: ref, safety: data.safety,
  });
  let dirty = true;
  drawing.onChange(() => { dirty = true; });

  function bounds() {
    let x0 = Infinity, x1 = -Infinity, y0 = Infinity, y1 = -Infinity;
    const add = (x, y) => { if (x < x0) x0 = x; if (x > x1) x1 = x; if (y < y0) y0 = y; if (y > y1) y1 = y; };
    for (let k = 0; k < poses.length; k += 3) add(poses[k], poses[k + 1]);
    if (ref) for (let k = 0; k < ref.length; k += 2) add(ref[k], ref[k + 1]);
    return [x0, x1, y0, y1];
  }
  drawing.fit(bounds());

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

  // The frame handed to the drawing: the last TRAIL_SECONDS of each trail,
  // at most TRAIL_POINTS points per agent, then where it is now.
  const frame = {
    pos, ref: ref ? refPos : null, trails: true, links: true, k: 0, kStart: 0, step: 1,
    trail(i, visit) {
      for (let j = frame.kStart; j <= frame.k; j += frame.step) {
        visit(poses[3 * n * j + 3 * i], poses[3 * n * j + 3 * i + 1]);
      }
      visit(pos[3 * i], pos[3 * i + 1]);
    },
    action: (i) => data.safety.actions.charCodeAt(frame.k * n + i) - 48,
  };

  function draw() {
    const started = performance.now();
    const k = interpolate(state.time);
    const [kStart] = locate(state.time - TRAIL_SECONDS);
    frame.k = k; frame.kStart = kStart;
    frame.step = Math.max(1, Math.ceil((k - kStart) / TRAIL_POINTS));
    frame.trails = ui.trails.checked; frame.links = ui.links.checked;
    drawing.draw(frame);

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
  ui.fit.addEventListener("click", () => drawing.fit());
  ui.time.addEventListener("input", () => {
    state.time = t0 + (t1 - t0) * Number(ui.time.value) / 10000; dirty = true;
  });
  ui.trails.addEventListener("change", () => { dirty = true; });
  ui.links.addEventListener("change", () => { dirty = true; });
  document.addEventListener("keydown", (e) => {
    if (e.target instanceof HTMLInputElement || e.target instanceof HTMLSelectElement) return;
    const [k] = locate(state.time);
    if (e.key === " ") { e.preventDefault(); setPlaying(!state.playing); }
    else if (e.key === "ArrowRight") { state.time = times[Math.min(k + 1, frames - 1)]; dirty = true; }
    else if (e.key === "ArrowLeft") { state.time = times[Math.max(k - 1, 0)]; dirty = true; }
  });
  requestAnimationFrame(tick);
})();
