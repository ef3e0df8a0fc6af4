// facepuppet force-graph editor: curves layered over a take, edited on a canvas, saved by the server.
"use strict";
(function () {
  const $ = (id) => document.getElementById(id);
  const E = { take: null, curves: [], target: null, sel: new Set(), undo: [], redo: [], clip: null, armed: new Set(),
              view: { t0: 0, t1: 1, v0: 0, v1: 1 }, playhead: 0, playing: false, recording: null, lock: "",
              inputs: {}, lastRecord: null };
  window.puppetEditor = E;  // for tests and the curious
  const cv = $("graph"), ctx = cv.getContext("2d");
  const M = { l: 46, r: 10, t: 24, b: 18 };
  const msg = (s) => { $("msg").textContent = s; };

  // --- the model: curves [{target, interp, mode, keys: [{t, v, seg}]}] in layering order ---------
  const rate = () => E.take.rate, dur = () => Math.max(E.take.ticks / E.take.rate, 1 / E.take.rate);
  function chIndex(name) { return E.take.channels.findIndex((c) => c.name === name); }
  function targetChannels(t) {  // [[channel index, weight, direct]]
    const i = chIndex(t); if (i >= 0) return [[i, 1, true]];
    const l = chIndex(t + "_l"), r = chIndex(t + "_r"); if (l >= 0 && r >= 0) return [[l, 1, true], [r, 1, true]];
    return (E.take.targets[t] || []).map(([i, w]) => [i, w, false]);
  }
  function range(t) {
    const cs = targetChannels(t);
    if (cs.length && cs[0][2]) { const c = E.take.channels[cs[0][0]]; return [c.lo, c.hi]; }
    return [0, 1];
  }
  function recorded(t, k) {  // the take's value of a target at tick k (a weight target: none)
    const cs = targetChannels(t); if (!cs.length || !cs[0][2]) return null;
    const name = E.take.channels[cs[0][0]].name, col = E.take.values[name];
    if (!col) return E.take.first[cs[0][0]];
    return col[Math.min(col.length - 1, Math.max(0, k))];
  }
  function curveAt(c, t) {  // puppet.curves.Curve.at
    const ks = c.keys; if (!ks.length || t < ks[0].t - 1e-6 || t > ks[ks.length - 1].t + 1e-6) return null;
    let k = 0; while (k + 1 < ks.length && ks[k + 1].t <= t) k++;
    const seg = ks[k].seg || c.interp;
    if (k === ks.length - 1 || seg === "step") return ks[k].v;
    const span = ks[k + 1].t - ks[k].t; let u = span <= 0 ? 0 : (t - ks[k].t) / span;
    if (seg === "smooth") u = u * u * (3 - 2 * u);
    return ks[k].v + (ks[k + 1].v - ks[k].v) * u;
  }
  function effective(t, k) {  // the target's value after its own curves (the preview is exact)
    let v = recorded(t, k); const time = k / rate();
    for (const c of E.curves) {
      if (c.target !== t) continue;
      const x = curveAt(c, time); if (x === null) continue;
      if (c.mode === "replace" || v === null) v = x; else if (c.mode === "add") v += x; else v = Math.max(v, x);
    }
    if (v === null) return null;
    const [lo, hi] = range(t); return Math.min(hi, Math.max(lo, v));
  }
  const snapshot = () => JSON.stringify(E.curves);
  function push() { E.undo.push(snapshot()); if (E.undo.length > 300) E.undo.shift(); E.redo = []; }
  function restore(s) { E.curves = JSON.parse(s); E.sel.clear(); changed(); }
  function changed() { refreshList(); draw(); sendCurves(false); }

  // --- server ---------------------------------------------------------------------------------------
  function toJson() {
    return E.curves.filter((c) => c.keys.length).map((c) => ({ target: c.target, interp: c.interp, mode: c.mode,
      keys: c.keys.map((k) => [Math.round(k.t * 1e6) / 1e6, k.v, k.seg || c.interp]) }));
  }
  let sendTimer = null;
  function sendCurves(save) {
    clearTimeout(sendTimer);
    const go = () => fetch("/api/curves" + location.search, { method: "POST", headers: { "Content-Type": "application/json" },
      body: JSON.stringify({ curves: toJson(), save, name: $("curvesname").value }) })
      .then((r) => r.json()).then((j) => {
        if (!j.ok) msg("not accepted: " + j.error); else if (save) { msg("saved " + j.saved + " beside the take"); E.saved = j.saved; }
        else msg(""); preview(true);
      });
    if (save) return go();
    sendTimer = setTimeout(go, 150);
  }
  // the preview: the face at the playhead from the server's stream, as the live page's face view (a
  // picture rendered by the server, or the mesh drawn here with WebGL 2); failing that, an image
  const face = E.face = window.PuppetFace($("face"));
  let faceWs = null, lastAt = null;
  if (face.ok) {
    $("preview").hidden = true;
    const open = () => {
      faceWs = new WebSocket("ws://" + location.host + "/ws/face" + location.search); faceWs.binaryType = "arraybuffer";
      faceWs.onmessage = (ev) => { if (typeof ev.data !== "string") face.message(ev.data); };
      faceWs.onopen = () => { lastAt = null; preview(true); };
    };
    open();
  } else $("face").hidden = true;
  let inflight = false, again = false;
  function preview(force) {
    if (face.ok) {
      if (faceWs && faceWs.readyState === 1 && (force || lastAt !== E.playhead)) {
        lastAt = E.playhead; faceWs.send(JSON.stringify({ t: "at", time: E.playhead, w: face.width() }));
      }
      return;
    }
    if (inflight) { again = true; return; }
    inflight = true;
    const img = new Image();
    img.onload = img.onerror = () => { $("preview").src = img.src; inflight = false; if (again) { again = false; preview(); } };
    const sep = location.search ? "&" : "?";
    img.src = "/api/frame" + location.search + sep + "t=" + E.playhead.toFixed(4) + (force ? "&n=" + Date.now() : "");
  }

  // --- list of graphs -------------------------------------------------------------------------------
  function listTargets() {
    const names = E.take.channels.map((c) => c.name), out = [], seen = new Set();
    for (const n of names) {
      if (seen.has(n)) continue;
      const base = n.slice(0, -2);
      if (n.endsWith("_l") && names.includes(base + "_r")) {
        const l = E.take.values[n], r = E.take.values[base + "_r"];
        const same = JSON.stringify(l || null) === JSON.stringify(r || null);
        if (same) { out.push(base); seen.add(n); seen.add(base + "_r"); continue; }
      }
      out.push(n); seen.add(n);
    }
    for (const c of E.curves) if (!out.includes(c.target)) out.push(c.target);
    return out;
  }
  function refreshList() {
    const box = $("targets"), had = document.activeElement && box.contains(document.activeElement) ? document.activeElement : null;
    const focus = had && (had.dataset.arm !== undefined ? `[data-arm="${CSS.escape(had.dataset.arm)}"]` : `[data-target="${CSS.escape(had.dataset.target)}"]`);
    box.textContent = "";
    for (const t of listTargets()) {
      const d = document.createElement("div"); d.setAttribute("role", "listitem");
      const moving = targetChannels(t).some(([i]) => E.take.values[E.take.channels[i].name]);
      if (t === E.target) d.classList.add("sel");
      if (E.curves.some((c) => c.target === t)) d.classList.add("edited");
      // a button to show the graph, and a toggle to arm it for re-recording: both keyboard controls
      const name = document.createElement("button"); name.className = "name"; name.dataset.target = t;
      name.textContent = t + (moving ? " ~" : "");
      name.setAttribute("aria-pressed", String(t === E.target));
      name.setAttribute("aria-label", t + (moving ? ", moved by the take" : "") + (d.classList.contains("edited") ? ", edited" : ""));
      name.onclick = () => selectTarget(t);
      const arm = document.createElement("button"); arm.className = "arm" + (E.armed.has(t) ? " on" : ""); arm.textContent = "arm";
      arm.dataset.arm = t; arm.setAttribute("aria-pressed", String(E.armed.has(t))); arm.setAttribute("aria-label", "arm " + t + " for re-recording");
      arm.onclick = (ev) => { ev.stopPropagation(); E.armed.has(t) ? E.armed.delete(t) : E.armed.add(t); refreshList(); refreshArmed(); };
      d.append(name, arm);
      box.append(d);
    }
    if (focus) { const again = box.querySelector(focus); if (again) again.focus(); }  // the list is rebuilt: keep the keyboard's place
  }
  function selectTarget(t) {
    E.target = t; E.sel.clear(); $("graphname").textContent = t;
    const [lo, hi] = range(t), pad = (hi - lo) * 0.06; E.view.v0 = lo - pad; E.view.v1 = hi + pad;
    refreshList(); draw();
  }
  function refreshArmed() {
    const box = $("armed"); box.textContent = "";
    for (const t of E.armed) {
      const [lo, hi] = range(t), row = document.createElement("div"); row.className = "tools";
      const lab = document.createElement("span"); lab.className = "stat"; lab.textContent = t; lab.style.width = "110px";
      const s = document.createElement("input"); s.type = "range"; s.min = 0; s.max = 1000; s.dataset.armed = t; s.style.flex = "1";
      s.setAttribute("aria-label", "re-record " + t);
      const k = Math.round(E.playhead * rate()); const v = effective(t, k) ?? lo;
      s.value = Math.round((v - lo) / ((hi - lo) || 1) * 1000);
      const chans = targetChannels(t);
      // a box driving the graph's channel takes over from the slider (and moves it)
      E.inputs[t] = () => {
        if (E.box && chans.length && chans[0][2] && E.box.driven.includes(E.take.channels[chans[0][0]].name)) {
          const bv = E.box.values[chans[0][0]]; s.value = Math.round((bv - lo) / ((hi - lo) || 1) * 1000); return bv;
        }
        return lo + (hi - lo) * s.value / 1000;
      };
      row.append(lab, s); box.append(row);
    }
  }

  // --- drawing --------------------------------------------------------------------------------------
  const W = () => cv.clientWidth, H = () => cv.clientHeight;
  const X = (t) => M.l + (t - E.view.t0) / (E.view.t1 - E.view.t0) * (W() - M.l - M.r);
  const Y = (v) => M.t + (1 - (v - E.view.v0) / (E.view.v1 - E.view.v0)) * (H() - M.t - M.b);
  const T = (x) => E.view.t0 + (x - M.l) / (W() - M.l - M.r) * (E.view.t1 - E.view.t0);
  const V = (y) => E.view.v0 + (1 - (y - M.t) / (H() - M.t - M.b)) * (E.view.v1 - E.view.v0);
  function nice(span, px) { const raw = span / Math.max(1, px / 80), p = Math.pow(10, Math.floor(Math.log10(raw)));
    return [1, 2, 5, 10].map((m) => m * p).find((s) => s >= raw) || raw; }
  function draw() {
    const dpr = window.devicePixelRatio || 1, w = W(), h = H();
    if (cv.width !== Math.round(w * dpr) || cv.height !== Math.round(h * dpr)) { cv.width = Math.round(w * dpr); cv.height = Math.round(h * dpr); }
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0); ctx.clearRect(0, 0, w, h);
    ctx.font = "10px system-ui, sans-serif"; ctx.lineWidth = 1;
    if (!E.take || !E.target) return;
    const pin = parseFloat($("pin").value), pout = parseFloat($("pout").value);
    if (isFinite(pin) && isFinite(pout) && pout > pin) { ctx.fillStyle = "rgba(224,69,58,.12)"; ctx.fillRect(X(pin), M.t, X(pout) - X(pin), h - M.t - M.b); }
    const st = nice(E.view.t1 - E.view.t0, w); ctx.strokeStyle = "#222731"; ctx.fillStyle = "#8a919c";
    for (let t = Math.ceil(E.view.t0 / st) * st; t <= E.view.t1; t += st) {
      ctx.beginPath(); ctx.moveTo(X(t), M.t); ctx.lineTo(X(t), h - M.b); ctx.stroke(); ctx.fillText(t.toFixed(st < 0.1 ? 2 : st < 1 ? 1 : 0) + " s", X(t) + 2, 14);
    }
    const sv = nice(E.view.v1 - E.view.v0, h);
    for (let v = Math.ceil(E.view.v0 / sv) * sv; v <= E.view.v1; v += sv) {
      ctx.beginPath(); ctx.moveTo(M.l, Y(v)); ctx.lineTo(w - M.r, Y(v)); ctx.stroke(); ctx.fillText(v.toFixed(sv < 0.1 ? 2 : 1), 4, Y(v) + 3);
    }
    ctx.fillStyle = "#1d2026"; ctx.fillRect(0, 0, w, M.t - 4);
    ctx.fillStyle = "#8a919c";
    for (let t = Math.ceil(E.view.t0 / st) * st; t <= E.view.t1; t += st) ctx.fillText(t.toFixed(st < 0.1 ? 2 : st < 1 ? 1 : 0) + " s", X(t) + 2, 13);
    ctx.setLineDash([3, 3]); ctx.strokeStyle = "#6b5c3a";
    for (const [t, label] of E.take.markers) { ctx.beginPath(); ctx.moveTo(X(t), M.t); ctx.lineTo(X(t), h - M.b); ctx.stroke(); ctx.fillText(label, X(t) + 3, M.t + 10); }
    ctx.setLineDash([]);
    const k0 = Math.max(0, Math.floor(E.view.t0 * rate())), k1 = Math.min(E.take.ticks - 1, Math.ceil(E.view.t1 * rate()));
    const step = Math.max(1, Math.floor((k1 - k0) / (w * 2)));
    const line = (fn, color, width) => { ctx.strokeStyle = color; ctx.lineWidth = width; ctx.beginPath(); let on = false;
      for (let k = k0; k <= k1; k += step) { const v = fn(k); if (v === null) { on = false; continue; }
        if (!on) { ctx.moveTo(X(k / rate()), Y(v)); on = true; } else ctx.lineTo(X(k / rate()), Y(v)); } ctx.stroke(); ctx.lineWidth = 1; };
    line((k) => recorded(E.target, k), "#5d6470", 2);
    line((k) => effective(E.target, k), "#ffb347", 1.5);
    for (const c of E.curves) {
      if (c.target !== E.target) continue;
      for (const key of c.keys) {
        const x = X(key.t), y = Y(key.v); if (x < M.l - 5 || x > w) continue;
        const s = E.sel.has(key); ctx.fillStyle = s ? "#ffb347" : "#14161a"; ctx.strokeStyle = s ? "#ffb347" : "#d9dde3";
        ctx.fillRect(x - 3.5, y - 3.5, 7, 7); ctx.strokeRect(x - 3.5, y - 3.5, 7, 7);
      }
    }
    if (drag && drag.kind === "box") { ctx.strokeStyle = "#4fa3ff"; ctx.strokeRect(drag.x0, drag.y0, drag.x - drag.x0, drag.y - drag.y0); }
    ctx.strokeStyle = E.recording ? "#e0453a" : "#4fa3ff"; ctx.lineWidth = 2;
    ctx.beginPath(); ctx.moveTo(X(E.playhead), 0); ctx.lineTo(X(E.playhead), h); ctx.stroke(); ctx.lineWidth = 1;
    $("time").textContent = E.playhead.toFixed(2);
    const one = [...E.sel][0]; if (one && document.activeElement !== $("kt") && document.activeElement !== $("kv")) { $("kt").value = one.t.toFixed(3); $("kv").value = one.v.toFixed(4); }
  }

  // --- editing --------------------------------------------------------------------------------------
  function snapT(t) {
    const mode = $("snap").value, r = rate();
    if (mode === "tick") t = Math.round(t * r) / r;
    else if (mode === "second") t = Math.round(t);
    else if (mode === "marker" && E.take.markers.length) t = E.take.markers.map((m) => m[0]).reduce((a, b) => Math.abs(b - t) < Math.abs(a - t) ? b : a);
    return Math.min(dur(), Math.max(0, t));
  }
  function sortCurves() { for (const c of E.curves) c.keys.sort((a, b) => a.t - b.t); }
  function blockFor(target, t) {
    const own = E.curves.filter((c) => c.target === target);
    let best = null;
    for (const c of own) if (c.keys.length && t >= c.keys[0].t - 1e-9 && t <= c.keys[c.keys.length - 1].t + 1e-9) best = c;
    if (best) return best;
    if (own.length) return own.reduce((a, b) => Math.min(Math.abs(a.keys[0].t - t), Math.abs(a.keys[a.keys.length - 1].t - t)) <=
      Math.min(Math.abs(b.keys[0].t - t), Math.abs(b.keys[b.keys.length - 1].t - t)) ? a : b);
    const c = { target, interp: "linear", mode: "replace", keys: [] }; E.curves.push(c); return c;
  }
  function insertKey(t, v) {
    push(); const [lo, hi] = range(E.target);
    const key = { t: snapT(t), v: Math.min(hi, Math.max(lo, v)), seg: "linear" };
    const c = blockFor(E.target, key.t); c.keys.push(key); sortCurves(); E.sel = new Set([key]); changed(); return key;
  }
  function deleteSelected() {
    if (!E.sel.size) return; push();
    for (const c of E.curves) c.keys = c.keys.filter((k) => !E.sel.has(k));
    E.curves = E.curves.filter((c) => c.keys.length); E.sel.clear(); changed();
  }
  function setSeg(seg) { if (!E.sel.size) return; push(); for (const k of E.sel) k.seg = seg; changed(); }
  function rdp(pts, tol) {  // Ramer-Douglas-Peucker over (time, value): indices to keep
    const n = pts.length; if (n <= 2) return pts.map((_, i) => i);
    const keep = new Array(n).fill(false); keep[0] = keep[n - 1] = true; const stack = [[0, n - 1]];
    while (stack.length) { const [a, b] = stack.pop(); if (b - a < 2) continue;
      let worst = -1, wi = -1;
      for (let i = a + 1; i < b; i++) { const u = (pts[i].t - pts[a].t) / ((pts[b].t - pts[a].t) || 1);
        const e = Math.abs(pts[i].v - (pts[a].v + (pts[b].v - pts[a].v) * u)); if (e > worst) { worst = e; wi = i; } }
      if (worst > tol) { keep[wi] = true; stack.push([a, wi], [wi, b]); } }
    return keep.map((k, i) => k ? i : -1).filter((i) => i >= 0);
  }
  const tolerance = (t) => { const [lo, hi] = range(t); return Math.max(0, parseFloat($("tol").value) || 0) / 100 * (hi - lo); };
  function keysFromSamples(target, k0, samples) {  // dense per-tick samples -> reduced linear keys
    const pts = samples.map((v, i) => ({ t: (k0 + i) / rate(), v, seg: "linear" }));
    return rdp(pts, tolerance(target)).map((i) => pts[i]);
  }
  function fromRecording() {
    const t = E.target; if (recorded(t, 0) === null) { msg("nothing recorded for " + t + ": double-click to insert keys"); return; }
    push(); E.curves = E.curves.filter((c) => c.target !== t);
    const samples = []; for (let k = 0; k < E.take.ticks; k++) samples.push(recorded(t, k));
    const keys = keysFromSamples(t, 0, samples);
    E.curves.push({ target: t, interp: "linear", mode: "replace", keys }); E.sel.clear();
    msg(`${keys.length} keys for ${E.take.ticks} ticks at ${$("tol").value} % of the range`); changed();
  }
  function reduceKeys() {
    push(); let before = 0, after = 0;
    for (const c of E.curves) { if (c.target !== E.target) continue; before += c.keys.length;
      const sel = E.sel.size ? c.keys.filter((k) => E.sel.has(k)) : c.keys;
      if (sel.length < 3) { after += c.keys.length; continue; }
      const keep = new Set(rdp(sel, tolerance(c.target)).map((i) => sel[i]));
      c.keys = c.keys.filter((k) => !sel.includes(k) || keep.has(k)); after += c.keys.length; }
    msg(`reduced ${before} keys to ${after} at ${$("tol").value} % of the range`); changed();
  }
  function copy() { const ks = [...E.sel].sort((a, b) => a.t - b.t); if (!ks.length) return;
    E.clip = ks.map((k) => ({ t: k.t - ks[0].t, v: k.v, seg: k.seg })); msg(`copied ${ks.length} keys`); }
  function paste() { if (!E.clip || !E.target) return; push(); const at = snapT(E.playhead); const c = blockFor(E.target, at);
    const added = E.clip.map((k) => ({ t: Math.min(dur(), at + k.t), v: k.v, seg: k.seg })); c.keys.push(...added); sortCurves();
    E.sel = new Set(added); changed(); }
  function undo() { if (!E.undo.length) return; E.redo.push(snapshot()); restore(E.undo.pop()); }
  function redo() { if (!E.redo.length) return; E.undo.push(snapshot()); restore(E.redo.pop()); }
  function fit() { E.view.t0 = 0; E.view.t1 = dur(); draw(); }

  // --- mouse ----------------------------------------------------------------------------------------
  let drag = null;
  function keyAt(x, y) { let best = null, bd = 49;
    for (const c of E.curves) if (c.target === E.target) for (const k of c.keys) { const d = (X(k.t) - x) ** 2 + (Y(k.v) - y) ** 2; if (d < bd) { bd = d; best = k; } }
    return best; }
  const pos = (ev) => { const r = cv.getBoundingClientRect(); return [ev.clientX - r.left, ev.clientY - r.top]; };
  cv.addEventListener("contextmenu", (ev) => ev.preventDefault());
  cv.addEventListener("pointerdown", (ev) => {
    if (!E.target) return; const [x, y] = pos(ev); cv.setPointerCapture(ev.pointerId);
    if (ev.button === 2 || ev.button === 1 || ev.altKey) { drag = { kind: "pan", x, y, view: { ...E.view } }; return; }
    if (y < M.t) { drag = { kind: "scrub" }; setPlayhead(T(x)); return; }
    const k = keyAt(x, y);
    if (k) { if (!E.sel.has(k)) { if (!ev.shiftKey) E.sel.clear(); E.sel.add(k); }
      drag = { kind: "move", x, y, orig: [...E.sel].map((s) => [s, s.t, s.v]), pushed: false };
    } else drag = { kind: "box", x0: x, y0: y, x, y, add: ev.shiftKey };
    draw();
  });
  cv.addEventListener("pointermove", (ev) => {
    if (!drag) return; const [x, y] = pos(ev);
    if (drag.kind === "pan") { const dt = (x - drag.x) / (W() - M.l - M.r) * (drag.view.t1 - drag.view.t0), dv = (y - drag.y) / (H() - M.t - M.b) * (drag.view.v1 - drag.view.v0);
      E.view = { t0: drag.view.t0 - dt, t1: drag.view.t1 - dt, v0: drag.view.v0 + dv, v1: drag.view.v1 + dv }; draw(); return; }
    if (drag.kind === "scrub") { setPlayhead(T(x)); return; }
    if (drag.kind === "box") { drag.x = x; drag.y = y; draw(); return; }
    if (!drag.pushed) { push(); drag.pushed = true; }
    const dt = T(x) - T(drag.x), dv = V(y) - V(drag.y), [lo, hi] = range(E.target);
    for (const [k, t, v] of drag.orig) {
      if (E.lock !== "time") k.t = snapT(t + dt);
      if (E.lock !== "value") k.v = Math.min(hi, Math.max(lo, v + dv));
    }
    sortCurves(); draw();
  });
  cv.addEventListener("pointerup", () => {
    if (drag && drag.kind === "box") {
      const [ta, tb] = [T(Math.min(drag.x0, drag.x)), T(Math.max(drag.x0, drag.x))], [va, vb] = [V(Math.max(drag.y0, drag.y)), V(Math.min(drag.y0, drag.y))];
      if (!drag.add) E.sel.clear();
      for (const c of E.curves) if (c.target === E.target) for (const k of c.keys) if (k.t >= ta && k.t <= tb && k.v >= va && k.v <= vb) E.sel.add(k);
    }
    if (drag && drag.kind === "move" && drag.pushed) changed();
    drag = null; draw();
  });
  // the graph from the keyboard: [ and ] select the previous / next key, arrows move the selected
  // keys (up/down 1 % of the range, Page Up/Down 10 %; left/right one tick), Enter inserts a key at
  // the playhead; with nothing selected left/right move the playhead a tick
  cv.addEventListener("keydown", (ev) => {
    if (!E.target) return;
    const own = E.curves.filter((c) => c.target === E.target).flatMap((c) => c.keys).sort((a, b) => a.t - b.t);
    if (ev.key === "[" || ev.key === "]") {
      ev.preventDefault(); if (!own.length) return;
      const cur = [...E.sel][0], i = cur ? own.indexOf(cur) : (ev.key === "]" ? -1 : own.length);
      const k = own[Math.min(own.length - 1, Math.max(0, i + (ev.key === "]" ? 1 : -1)))];
      E.sel = new Set([k]); setPlayhead(k.t); keyStatus(); return;
    }
    if (ev.key === "Enter") { ev.preventDefault(); insertKey(E.playhead, effective(E.target, Math.round(E.playhead * rate())) ?? range(E.target)[0]); keyStatus(); return; }
    const [lo, hi] = range(E.target), span = hi - lo;
    const dv = { ArrowUp: 0.01, ArrowDown: -0.01, PageUp: 0.1, PageDown: -0.1 }[ev.key], dt = { ArrowLeft: -1, ArrowRight: 1 }[ev.key];
    if (dv === undefined && dt === undefined) return;
    ev.preventDefault();
    if (!E.sel.size) { if (dt !== undefined) setPlayhead(E.playhead + dt / rate()); return; }
    push();
    for (const k of E.sel) {
      if (dv !== undefined && E.lock !== "value") k.v = Math.min(hi, Math.max(lo, k.v + dv * span));
      if (dt !== undefined && E.lock !== "time") k.t = Math.min(dur(), Math.max(0, k.t + dt / rate()));
    }
    sortCurves(); changed(); keyStatus();
  });
  function keyStatus() {  // what the graph's keyboard did, for a screen reader (aria-live)
    const k = [...E.sel][0]; $("graphstatus").textContent = k ? `${E.target}: key at ${k.t.toFixed(3)} s, value ${k.v.toFixed(3)}` + (E.sel.size > 1 ? ` (${E.sel.size} selected)` : "") : "";
  }
  cv.addEventListener("dblclick", (ev) => { const [x, y] = pos(ev); if (y > M.t && !keyAt(x, y)) insertKey(T(x), V(y)); });
  cv.addEventListener("wheel", (ev) => { ev.preventDefault(); const [x, y] = pos(ev), f = ev.deltaY > 0 ? 1.2 : 1 / 1.2;
    if (ev.shiftKey) { const v = V(y); E.view.v0 = v + (E.view.v0 - v) * f; E.view.v1 = v + (E.view.v1 - v) * f; }
    else { const t = T(x); E.view.t0 = t + (E.view.t0 - t) * f; E.view.t1 = t + (E.view.t1 - t) * f; } draw(); }, { passive: false });

  // --- transport and re-recording -------------------------------------------------------------------
  function setPlayhead(t) { E.playhead = Math.min(dur(), Math.max(0, t)); draw(); preview(); }
  let last = 0;
  function frame(now) {
    if (E.playing) {
      const t = E.playhead + (now - last) / 1000; last = now;
      if (E.recording) recordUpTo(t); else { E.playhead = Math.min(dur(), t); if (E.playhead >= dur()) stop(); }
      draw(); preview();
    }
    requestAnimationFrame(frame);
  }
  function play() { if (E.playing) return stop(); E.playing = true; last = performance.now(); $("play").textContent = "❚❚ pause"; }
  function stop() { E.playing = false; $("play").textContent = "▶ play"; if (E.recording) finishRecording(); }
  function record() {
    const pin = parseFloat($("pin").value), pout = parseFloat($("pout").value);
    if (!E.armed.size) { msg("arm a graph first"); return; }
    if (!(isFinite(pin) && isFinite(pout) && pout > pin)) { msg("set punch in and out first"); return; }
    const k0 = Math.round(pin * rate()), k1 = Math.min(E.take.ticks - 1, Math.round(pout * rate()));
    E.recording = { k0, k1, next: k0, samples: Object.fromEntries([...E.armed].map((t) => [t, []])) };
    E.playhead = k0 / rate(); E.playing = true; last = performance.now();
    recordUpTo(E.playhead);  // the punch-in tick holds the input as it is when recording starts
    $("record").textContent = "■ recording"; msg("recording " + [...E.armed].join(", "));
  }
  function recordUpTo(t) {  // one sample per tick, each the armed slider's value when that tick came
    const R = E.recording, kt = Math.min(R.k1, Math.floor(t * rate() + 1e-9));
    while (R.next <= kt) { for (const a of E.armed) R.samples[a].push(E.inputs[a]()); R.next++; }
    E.playhead = Math.min(t, R.k1 / rate());
    if (R.next > R.k1) stop();
  }
  function finishRecording() {
    const R = E.recording; E.recording = null; $("record").textContent = "● record";
    if (!R || R.next <= R.k0) return;
    commitPass(R.k0, R.samples, $("recmode").value === "overdub");
  }
  function commitPass(k0, samples, overdub) {  // {target: [value per tick from k0]} -> curves
    push(); let n = 0, ticks = 0;
    for (const [t, s] of Object.entries(samples)) {
      ticks = Math.max(ticks, s.length);
      if (!overdub) { E.curves.push({ target: t, interp: "linear", mode: "replace", keys: keysFromSamples(t, k0, s) }); n++; continue; }
      // overdub: only the runs of ticks where the input moved (stills shorter than 0.1 s joined)
      const gap = Math.round(0.1 * rate());
      let i = 1;
      while (i < s.length) {
        if (s[i] === s[i - 1]) { i++; continue; }
        let j = i, still = 0;
        for (let m = i + 1; m < s.length; m++) {
          if (s[m] === s[m - 1]) { if (++still >= gap) break; } else { still = 0; j = m; }
        }
        E.curves.push({ target: t, interp: "linear", mode: "replace", keys: keysFromSamples(t, k0 + i, s.slice(i, j + 1)) }); n++;
        i = j + 1;
      }
    }
    E.lastRecord = { k0, k1: k0 + ticks - 1, passes: n };
    msg(`recorded ${ticks} ticks into ${n} curve${n === 1 ? "" : "s"} (${overdub ? "overdub" : "replace"})`); changed();
  }

  // --- wiring ---------------------------------------------------------------------------------------
  $("play").onclick = play; $("record").onclick = record; $("fromrec").onclick = fromRecording; $("reduce").onclick = reduceKeys;
  $("del").onclick = deleteSelected; $("undo").onclick = undo; $("redo").onclick = redo; $("copy").onclick = copy; $("paste").onclick = paste; $("fit").onclick = fit;
  document.querySelectorAll("[data-seg]").forEach((b) => { b.onclick = () => setSeg(b.dataset.seg); });
  $("setin").onclick = () => { $("pin").value = E.playhead.toFixed(3); draw(); };
  $("setout").onclick = () => { $("pout").value = E.playhead.toFixed(3); draw(); };
  $("pin").oninput = $("pout").oninput = draw;
  $("locktime").onclick = () => { E.lock = E.lock === "time" ? "" : "time"; $("locktime").classList.toggle("on", E.lock === "time"); $("lockvalue").classList.remove("on"); };
  $("lockvalue").onclick = () => { E.lock = E.lock === "value" ? "" : "value"; $("lockvalue").classList.toggle("on", E.lock === "value"); $("locktime").classList.remove("on"); };
  $("save").onclick = () => sendCurves(true);
  $("export").onclick = () => { const name = E.take.take.replace(/\.jsonl$/, "") + "-edit" + $("exportname").value; msg("exporting " + name + " …");
    fetch("/api/export" + location.search, { method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify({ name }) })
      .then((r) => r.json()).then((j) => msg(j.ok ? j.message : j.busy ? j.error : "export failed: " + j.error)); };
  $("addbtn").onclick = () => { const t = $("addtarget").value; if (!t) return;
    if (!E.curves.some((c) => c.target === t)) { push(); E.curves.push({ target: t, interp: "linear", mode: "replace", keys: [{ t: 0, v: 0, seg: "linear" }, { t: dur(), v: 0, seg: "linear" }] }); }
    changed(); selectTarget(t); };
  const keyEdit = () => { const one = [...E.sel][0]; if (!one) return; push(); const t = parseFloat($("kt").value), v = parseFloat($("kv").value);
    if (isFinite(t)) one.t = snapT(t); if (isFinite(v)) { const [lo, hi] = range(E.target); one.v = Math.min(hi, Math.max(lo, v)); } sortCurves(); changed(); };
  $("kt").onchange = keyEdit; $("kv").onchange = keyEdit;
  document.addEventListener("keydown", (ev) => {
    if (ev.target.tagName === "INPUT" || ev.target.tagName === "SELECT") return;
    if (ev.target.tagName === "BUTTON" && (ev.key === " " || ev.key === "Enter")) return;  // the button's own press
    const c = ev.ctrlKey || ev.metaKey, k = ev.key.toLowerCase();
    if (c && k === "z") { ev.preventDefault(); ev.shiftKey ? redo() : undo(); }
    else if (c && k === "y") { ev.preventDefault(); redo(); }
    else if (c && k === "c") copy(); else if (c && k === "v") paste();
    else if (k === "delete" || k === "backspace") deleteSelected();
    else if (k === " ") { ev.preventDefault(); play(); }
    else if (k === "x") $("locktime").click(); else if (k === "y") $("lockvalue").click();
    else if (k === "i") $("setin").click(); else if (k === "o") $("setout").click();
    else if (k === "f") fit(); else if (k === "home") setPlayhead(0);
  });
  window.addEventListener("resize", draw);
  E.keyPixel = (target, i) => { const ks = E.curves.filter((c) => c.target === target).flatMap((c) => c.keys).sort((a, b) => a.t - b.t);
    const r = cv.getBoundingClientRect(); return [X(ks[i].t) - r.width / 2, Y(ks[i].v) - r.height / 2]; };  // offsets from the centre
  E.api = { selectTarget, insertKey, fromRecording, setPlayhead, record, play, stop, toJson, sendCurves, commitPass };

  fetch("/api/take" + location.search).then((r) => r.json()).then((take) => {
    E.take = take; $("take").textContent = take.take; $("dur").textContent = dur().toFixed(2);
    $("curvesname").value = take.curves_name;
    E.curves = take.curves.map((c) => ({ target: c.target, interp: c.interp, mode: c.mode, keys: c.keys.map(([t, v, seg]) => ({ t, v, seg })) }));
    const add = $("addtarget"); for (const t of [...take.aus, ...take.expressions.map((e) => "expr:" + e)]) { const o = document.createElement("option"); o.textContent = t; add.append(o); }
    fit(); const moving = listTargets().find((t) => targetChannels(t).some(([i]) => take.values[take.channels[i].name]));
    selectTarget(moving || listTargets()[0]); preview(); E.ready = true; requestAnimationFrame(frame);
    if (take.boxes.length) {  // control boxes given to `puppet edit --device`: their mapped values, live
      const ws = new WebSocket("ws://" + location.host + "/ws" + location.search);
      ws.onmessage = (ev) => { E.box = JSON.parse(ev.data); $("boxes").textContent = "boxes: " +
        E.box.devices.map(([d, ok]) => d + (ok ? "" : " (lost)")).join(", ") + (E.box.driven.length ? " · driving " + E.box.driven.join(", ") : ""); };
    }
  });
})();
