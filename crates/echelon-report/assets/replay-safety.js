  // Safety filter (inserted by the Rust side only for a scene with one): each
  // robot's point L ahead with a disc of radius/2, so two discs touch exactly
  // when two points are `radius` apart; obstacles with a dashed ring at
  // r + radius/2, which a robot's disc touches exactly when its point is
  // `radius` from the edge. A robot's disc is filled while its filter changes
  // the command, outlined in orange while it brakes, dashed while it breaks a
  // deadlock.
  function drawSafety(f, muted) {
    const pos = f.pos, half = safety.radius / 2;
    ctx.lineWidth = 1.2;
    for (const [x, y, r] of safety.obstacles) {
      ctx.beginPath(); ctx.arc(X(x), Y(y), r * view.s, 0, 2 * Math.PI);
      ctx.fillStyle = muted; ctx.globalAlpha = 0.45; ctx.fill(); ctx.globalAlpha = 1;
      ctx.beginPath(); ctx.arc(X(x), Y(y), (r + half) * view.s, 0, 2 * Math.PI);
      ctx.setLineDash([5, 4]); ctx.strokeStyle = muted; ctx.lineWidth = 1.2; ctx.stroke(); ctx.setLineDash([]);
    }
    for (let i = 0; i < n; i++) {
      if (!known(pos, i)) continue;
      const th = pos[3 * i + 2], l = safety.l[i] || 0, color = agents[i].color;
      const px = X(pos[3 * i] + l * Math.cos(th)), py = Y(pos[3 * i + 1] + l * Math.sin(th));
      const a = f.action(i); // outcome + 3 * deadlock
      const outcome = a % 3;
      ctx.beginPath(); ctx.arc(px, py, half * view.s, 0, 2 * Math.PI);
      if (outcome !== 0) { ctx.fillStyle = color; ctx.globalAlpha = 0.3; ctx.fill(); ctx.globalAlpha = 1; }
      ctx.strokeStyle = outcome === 2 ? "#d55e00" : color;
      ctx.lineWidth = outcome === 0 ? 1 : 2.5;
      if (a >= 3) ctx.setLineDash([4, 3]);
      ctx.stroke(); ctx.setLineDash([]);
      ctx.beginPath(); ctx.arc(px, py, 2, 0, 2 * Math.PI); ctx.fillStyle = color; ctx.fill();
    }
  }
