// The interactive map of trackkit's report.html (trackkit/report/track_map.py writes the
// data this draws). Plain ES5, no library, no network.
(function () {
"use strict";
var D = JSON.parse(document.getElementById("tk-map-data").textContent);
var root = document.getElementById("tk-map"), cv = document.getElementById("tk-canvas");
var ctx = cv.getContext("2d"), tip = document.getElementById("tk-tip");
var slider = document.getElementById("tk-time"), label = document.getElementById("tk-time-label");
var mode = document.getElementById("tk-mode"), play = document.getElementById("tk-play");
var readout = document.getElementById("tk-readout");
document.getElementById("tk-bg-label").textContent = D.background_label;
var T = D.times, q = D.quantum, RECENT = 600;
function sum(a, s) { var o = new Float64Array(a.length), v = s; for (var i = 0; i < a.length; i++) { v += a[i]; o[i] = v; } return o; }
var tracks = D.tracks.map(function (r) {
  var sc = sum(r[3], r[2]), n = r[4].length, t = new Float64Array(n), x = sum(r[4], 0), y = sum(r[5], 0);
  t[0] = T[r[2]]; for (var i = 1; i < n; i++) t[i] = T[sc[i - 1]];
  for (i = 0; i < n; i++) { x[i] *= q; y[i] *= q; }
  return {id: r[0], who: r[1], t: t, x: x, y: y, color: D.palette[r[0] % D.palette.length]};
});
var bx = sum(D.background[0], 0), by = sum(D.background[1], 0);
for (var i = 0; i < bx.length; i++) { bx[i] *= D.cell; by[i] *= D.cell; }
var view = {cx: D.centre[0], cy: D.centre[1], s: 1}, W = 0, H = 0, hover = null, drag = null;
function resetView() { view.cx = D.centre[0]; view.cy = D.centre[1]; view.s = Math.min(W, H) / D.width; }
function sx(x) { return W / 2 + (x - view.cx) * view.s; }
function sy(y) { return H / 2 - (y - view.cy) * view.s; }
function pad(n) { return (n < 10 ? "0" : "") + n; }
function clock(t) {
  if (D.epoch_ms === null) return "t = " + t.toFixed(0) + " s";
  var d = new Date(D.epoch_ms + t * 1000);
  return d.toISOString().slice(0, 10) + " " + pad(d.getUTCHours()) + ":" + pad(d.getUTCMinutes()) + ":" + pad(d.getUTCSeconds()) + " UTC";
}
function span(tr) { var m = (tr.t[tr.t.length - 1] - tr.t[0]) / 60; return m < 1 ? (m * 60).toFixed(0) + " s" : m.toFixed(1) + " min"; }
function now() { return T.length ? T[+slider.value] : 0; }
function window_() { var t = now(); return mode.value === "all" ? [-Infinity, Infinity] : [mode.value === "recent" ? t - RECENT : -Infinity, t]; }
function at(tr, t) {  // the track's position at time t (linear between its kept points)
  var n = tr.t.length; if (t <= tr.t[0]) return [tr.x[0], tr.y[0]];
  if (t >= tr.t[n - 1]) return [tr.x[n - 1], tr.y[n - 1]];
  var lo = 0, hi = n - 1; while (hi - lo > 1) { var m = (lo + hi) >> 1; if (tr.t[m] <= t) lo = m; else hi = m; }
  var f = (t - tr.t[lo]) / (tr.t[hi] - tr.t[lo]); return [tr.x[lo] + f * (tr.x[hi] - tr.x[lo]), tr.y[lo] + f * (tr.y[hi] - tr.y[lo])];
}
function visible(tr, w) { return tr.t[0] <= w[1] && tr.t[tr.t.length - 1] >= w[0]; }
function path(tr, w) {  // the part of the track inside the time window, as screen points
  var out = [], n = tr.t.length;
  if (w[0] > tr.t[0]) { var p = at(tr, w[0]); out.push([sx(p[0]), sy(p[1])]); }
  for (var i = 0; i < n; i++) if (tr.t[i] >= w[0] && tr.t[i] <= w[1]) out.push([sx(tr.x[i]), sy(tr.y[i])]);
  if (w[1] < tr.t[n - 1] && w[1] >= tr.t[0]) { var e = at(tr, w[1]); out.push([sx(e[0]), sy(e[1])]); }
  return out;
}
function drawScale() {
  var m = 120 / view.s, e = Math.pow(10, Math.floor(Math.log10(m))), L = [5, 2, 1].map(function (k) { return k * e; }).filter(function (v) { return v <= m; })[0];
  var px = L * view.s, x0 = 14, y0 = H - 16;
  ctx.strokeStyle = "#333"; ctx.lineWidth = 2; ctx.beginPath(); ctx.moveTo(x0, y0); ctx.lineTo(x0 + px, y0); ctx.stroke();
  ctx.fillStyle = "#333"; ctx.font = "12px sans-serif"; ctx.fillText(L >= 1000 ? L / 1000 + " km" : L + " m", x0, y0 - 6);
  ctx.fillText("N \u2191", W - 34, 18);
}
function draw() {
  ctx.setTransform(window.devicePixelRatio || 1, 0, 0, window.devicePixelRatio || 1, 0, 0);
  ctx.clearRect(0, 0, W, H);
  var r = Math.max(1.5, Math.min(3, D.cell * view.s));
  ctx.fillStyle = "#c2c2c2";
  for (var i = 0; i < bx.length; i++) ctx.fillRect(sx(bx[i]) - r / 2, sy(by[i]) - r / 2, r, r);
  var w = window_(), t = now(), shown = 0;
  ctx.lineJoin = "round";
  function one(tr) {
    if (!visible(tr, w)) return;
    var p = path(tr, w); if (!p.length) return; shown++;
    ctx.strokeStyle = tr.color; ctx.lineWidth = tr === hover ? 3.5 : 1.5;
    ctx.beginPath(); ctx.moveTo(p[0][0], p[0][1]); for (var k = 1; k < p.length; k++) ctx.lineTo(p[k][0], p[k][1]);
    if (p.length === 1) ctx.lineTo(p[0][0] + 0.1, p[0][1]);
    ctx.stroke();
    if (mode.value !== "all" && tr.t[tr.t.length - 1] >= t) {  // alive at the time: its head
      var h = p[p.length - 1]; ctx.fillStyle = tr.color; ctx.beginPath(); ctx.arc(h[0], h[1], 3.5, 0, 2 * Math.PI); ctx.fill();
    }
  }
  tracks.forEach(function (tr) { if (tr !== hover) one(tr); });
  if (hover) one(hover);  // the hovered track on top
  if (D.site) {
    var X = sx(D.site[0]), Y = sy(D.site[1]);
    if (D.max_range) { ctx.setLineDash([6, 4]); ctx.strokeStyle = "#777"; ctx.lineWidth = 1; ctx.beginPath(); ctx.arc(X, Y, D.max_range * view.s, 0, 2 * Math.PI); ctx.stroke(); ctx.setLineDash([]); }
    ctx.fillStyle = "#000"; ctx.strokeStyle = "#fff"; ctx.lineWidth = 1.5; ctx.beginPath(); ctx.moveTo(X, Y - 8); ctx.lineTo(X - 7, Y + 6); ctx.lineTo(X + 7, Y + 6); ctx.closePath(); ctx.fill(); ctx.stroke();
  }
  drawScale();
  root.dataset.rendered = "true"; root.dataset.tracksDrawn = String(shown); root.dataset.tracks = String(tracks.length);
  label.textContent = mode.value === "all" ? "all " + T.length + " scans" : clock(t);
}
function nearest(mx, my) {
  var w = window_(), best = null, bd = 8;
  tracks.forEach(function (tr) {
    if (!visible(tr, w)) return; var p = path(tr, w);
    for (var k = 0; k < p.length; k++) {
      var a = p[k], b = p[Math.min(k + 1, p.length - 1)], dx = b[0] - a[0], dy = b[1] - a[1], L = dx * dx + dy * dy;
      var f = L > 0 ? Math.max(0, Math.min(1, ((mx - a[0]) * dx + (my - a[1]) * dy) / L)) : 0;
      var d = Math.hypot(mx - a[0] - f * dx, my - a[1] - f * dy); if (d < bd) { bd = d; best = tr; }
    }
  });
  return best;
}
function showTip(tr, mx, my) {
  if (!tr) { tip.hidden = true; return; }
  tip.textContent = "track " + tr.id + "\n" + D.identity_label + " " + (tr.who || "unknown (no object matched)") +
    "\n" + clock(tr.t[0]) + "\nto " + clock(tr.t[tr.t.length - 1]) + " (" + span(tr) + ")";
  tip.hidden = false; tip.style.left = Math.min(mx + 14, W - tip.offsetWidth - 4) + "px"; tip.style.top = Math.max(4, my - tip.offsetHeight - 10) + "px";
}
function geo(x, y) {
  if (!D.geo) return ((x / 1000).toFixed(2) + " km E, " + (y / 1000).toFixed(2) + " km N");
  var u = (x - D.centre[0]) / 1000, v = (y - D.centre[1]) / 1000, b = [1, u, v, u * u, u * v, v * v];
  var f = function (c) { var s = 0; for (var i = 0; i < 6; i++) s += c[i] * b[i]; return s; };
  var la = f(D.geo[0]), lo = f(D.geo[1]);
  return Math.abs(la).toFixed(4) + (la >= 0 ? " N, " : " S, ") + Math.abs(lo).toFixed(4) + (lo >= 0 ? " E" : " W");
}
function resize() {
  var r = cv.getBoundingClientRect(), dpr = window.devicePixelRatio || 1, first = W === 0;
  W = Math.max(r.width, 100); H = Math.max(r.height, 100); cv.width = Math.round(W * dpr); cv.height = Math.round(H * dpr);
  if (first) resetView(); draw();
}
function zoom(f, mx, my) {
  var wx = view.cx + (mx - W / 2) / view.s, wy = view.cy - (my - H / 2) / view.s;
  view.s *= f; view.cx = wx - (mx - W / 2) / view.s; view.cy = wy + (my - H / 2) / view.s; draw();
}
function pos(e) { var r = cv.getBoundingClientRect(); return [e.clientX - r.left, e.clientY - r.top]; }
cv.addEventListener("wheel", function (e) { e.preventDefault(); var p = pos(e); zoom(Math.exp(-e.deltaY * 0.0015), p[0], p[1]); }, {passive: false});
cv.addEventListener("pointerdown", function (e) {
  drag = pos(e); cv.style.cursor = "grabbing"; tip.hidden = true;
  try { cv.setPointerCapture(e.pointerId); } catch (err) { /* a pointer that is gone */ }
});
cv.addEventListener("pointerup", function () { drag = null; cv.style.cursor = "grab"; });
cv.addEventListener("pointermove", function (e) {
  var p = pos(e);
  if (drag) { view.cx -= (p[0] - drag[0]) / view.s; view.cy += (p[1] - drag[1]) / view.s; drag = p; draw(); return; }
  readout.textContent = geo(view.cx + (p[0] - W / 2) / view.s, view.cy - (p[1] - H / 2) / view.s);
  var h = nearest(p[0], p[1]); if (h !== hover) { hover = h; draw(); } showTip(h, p[0], p[1]);
});
cv.addEventListener("pointerleave", function () { tip.hidden = true; if (hover) { hover = null; draw(); } });
cv.addEventListener("dblclick", function () { resetView(); draw(); });
cv.tabIndex = 0;
cv.addEventListener("keydown", function (e) { if (e.key === "+" || e.key === "=") zoom(1.25, W / 2, H / 2); if (e.key === "-") zoom(0.8, W / 2, H / 2); });
document.getElementById("tk-reset").addEventListener("click", function () { resetView(); draw(); });
slider.max = String(Math.max(T.length - 1, 0)); slider.value = slider.max;
slider.addEventListener("input", function () { if (mode.value === "all") mode.value = "upto"; draw(); });
mode.addEventListener("change", draw);
var timer = null;
play.addEventListener("click", function () {
  if (timer) { clearInterval(timer); timer = null; play.textContent = "\u25B6"; return; }
  if (mode.value === "all") mode.value = "upto";
  if (+slider.value >= T.length - 1) slider.value = "0";
  var stepBy = Math.max(1, Math.round(T.length / 300));
  play.textContent = "\u275A\u275A";
  timer = setInterval(function () {
    var v = Math.min(+slider.value + stepBy, T.length - 1); slider.value = String(v); draw();
    if (v >= T.length - 1) { clearInterval(timer); timer = null; play.textContent = "\u25B6"; }
  }, 50);
});
window.addEventListener("resize", resize);
resize();
// for checks in a browser: where a point of the local frame is on the canvas (CSS px)
root.tkMap = {tracks: tracks, toScreen: function (x, y) { return [sx(x), sy(y)]; }};
})();
