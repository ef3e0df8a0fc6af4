// facepuppet performer's page: sends control events over one WebSocket, draws what the face does.
"use strict";
(function () {
  const $ = (id) => document.getElementById(id);
  const params = new URLSearchParams(location.search);
  const q = new URLSearchParams();
  for (const k of ["name", "role", "only"]) if (params.get(k)) q.set(k, params.get(k));
  const state = { layout: null, allowed: new Set(), me: "", index: {}, sliders: {}, own: {}, pads: {}, ws: null,
                  values: null, ageRow: null, sent: 0 };
  window.puppetPanel = state;  // for tests and the curious

  function send(control, value) {
    if (!state.ws || state.ws.readyState !== 1 || !state.allowed.has(control)) return;
    state.ws.send(JSON.stringify({ t: "in", c: control, v: value }));
    state.own[control] = value;
    state.sent++;
  }

  function el(tag, cls, text) { const e = document.createElement(tag); if (cls) e.className = cls; if (text !== undefined) e.textContent = text; return e; }

  // a slider: role=slider, focusable; a pointer drag anywhere on the track sets the value (several
  // fingers, several sliders), and the keys of a slider (arrows 1 %, Page Up/Down 10 %, Home/End) too
  const STEP = 0.01, PAGE = 0.1;
  function channelOf(name) { return state.layout.channels[state.index[name]]; }
  function fmt(x) { return (Math.round(x * 100) / 100).toFixed(2); }
  function makeSlider(channel, label, onValue) {
    const s = el("div", "slider"); s.dataset.channel = channel;
    const fill = el("div", "fill"), own = el("div", "own"), ap = el("div", "applied"), num = el("div", "num");
    s.append(fill, ap, own, num);
    const c = channelOf(channel);
    s.setAttribute("role", "slider");
    s.setAttribute("aria-label", label);
    s.setAttribute("aria-valuemin", String(c.lo));
    s.setAttribute("aria-valuemax", String(c.hi));
    s.setAttribute("aria-valuenow", String(c.default));
    num.setAttribute("aria-hidden", "true");
    const locked = !state.allowed.has("slider:" + channel);
    if (locked) { s.classList.add("locked"); s.setAttribute("aria-disabled", "true"); s.tabIndex = -1; }
    else s.tabIndex = 0;
    function at(ev) { const r = s.getBoundingClientRect(); return Math.min(1, Math.max(0, (ev.clientX - r.left) / r.width)); }
    s.addEventListener("pointerdown", (ev) => { if (locked) return; s.setPointerCapture(ev.pointerId); s.dragging = true; s.focus({ preventScroll: true }); onValue(at(ev)); ev.preventDefault(); });
    s.addEventListener("pointermove", (ev) => { if (s.dragging) onValue(at(ev)); });
    const end = () => { s.dragging = false; };
    s.addEventListener("pointerup", end); s.addEventListener("pointercancel", end);
    s.addEventListener("keydown", (ev) => {
      if (locked) return;
      const u0 = current(channel);
      const u = keyed(ev.key, u0);
      if (u === null) return;
      ev.preventDefault();
      onValue(u);
    });
    state.sliders[channel] = { el: s, fill, own, ap, num, others: {}, label, linked: false };
    return s;
  }
  // the next value of a slider at u0 (0..1) for a key, or null when the key is not a slider's
  function keyed(key, u0) {
    const step = { ArrowRight: STEP, ArrowUp: STEP, ArrowLeft: -STEP, ArrowDown: -STEP, PageUp: PAGE, PageDown: -PAGE }[key];
    if (step !== undefined) return Math.min(1, Math.max(0, Math.round((u0 + step) * 1000) / 1000));
    if (key === "Home") return 0;
    if (key === "End") return 1;
    return null;
  }
  // where a slider stands (0..1): the page's own value once touched, else what the face gets
  function current(channel) {
    const own = state.own["slider:" + channel];
    if (own !== undefined) return own;
    const c = channelOf(channel), v = state.values ? state.values[state.index[channel]] : c.default;
    return (v - c.lo) / ((c.hi - c.lo) || 1);
  }

  function showOwn(channel, u) {
    const sl = state.sliders[channel]; if (!sl) return;
    sl.own.style.display = "block"; sl.own.style.left = (u * 100) + "%"; sl.fill.style.width = (u * 100) + "%";
    const c = channelOf(channel), v = c.lo + u * (c.hi - c.lo);
    sl.el.setAttribute("aria-valuenow", fmt(v));
    sl.el.setAttribute("aria-valuetext", fmt(v) + (sl.linked ? ", left and right together" : ""));
  }

  function setChannel(channel, u) { send("slider:" + channel, u); showOwn(channel, u); }

  function build(layout) {
    const regions = $("regions"); regions.textContent = "";
    layout.channels.forEach((c, i) => { state.index[c.name] = i; });
    for (const reg of layout.regions) {
      const sec = el("section"); sec.append(el("h2", "", reg.name));
      for (const row of reg.rows) {
        const r = el("div", "row" + (row.channels.length === 1 ? " single" : ""));
        const lab = el("span", "label", row.label); lab.title = row.channels.join(", "); r.append(lab);
        const pair = row.channels.length === 2;
        let linked = pair;
        const sides = pair ? [row.label + " left", row.label + " right"] : [row.label];
        row.channels.forEach((ch, j) => {
          r.append(makeSlider(ch, sides[j], (u) => {
            if (linked) row.channels.forEach((c2) => setChannel(c2, u)); else setChannel(ch, u);
          }));
        });
        if (row.channels.every((ch) => !state.allowed.has("slider:" + ch))) r.classList.add("locked");
        if (pair) {
          // L=R: a toggle button; its state is announced, and so is a linked slider's value
          const link = el("button", "link on", "L=R");
          if (r.classList.contains("locked")) link.disabled = true;
          link.title = "move left and right together";
          link.setAttribute("aria-label", "L=R " + row.label + ": left and right together");
          link.setAttribute("aria-pressed", "true");
          const mark = () => row.channels.forEach((ch) => { state.sliders[ch].linked = linked;
            state.sliders[ch].el.setAttribute("aria-valuetext", fmt(current(ch) * (channelOf(ch).hi - channelOf(ch).lo) + channelOf(ch).lo) + (linked ? ", left and right together" : "")); });
          link.onclick = () => { linked = !linked; link.classList.toggle("on", linked); link.setAttribute("aria-pressed", String(linked)); mark(); };
          mark();
          r.append(link);
        } else r.append(el("span"));
        sec.append(r);
      }
      regions.append(sec);
    }
    const pad = (box, control, label, hold) => {
      const b = el("button", "", label); b.dataset.control = control;
      if (!state.allowed.has(control)) { b.classList.add("locked"); b.disabled = true; }
      if (hold) { b.setAttribute("aria-pressed", "false"); b.title = "held while pressed (pointer, Space or Enter)"; }
      const down = () => { send(control, 1); if (hold) { b.classList.add("on"); b.setAttribute("aria-pressed", "true"); } };
      const up = () => { send(control, 0); if (hold) { b.classList.remove("on"); b.setAttribute("aria-pressed", "false"); } };
      pressable(b, down, up);
      state.pads[control] = b; box.append(b);
    };
    $("expr").textContent = ""; $("aus").textContent = "";
    for (const e of layout.expressions) pad($("expr"), "pad:expr:" + e, e, false);
    for (const a of layout.aus) pad($("aus"), "pad:" + a, a, true);
    state.ageRow = layout.age;
    if (layout.age) setupAge(layout.age);
  }

  function arc(u) {  // a 270-degree arc from the bottom left, u in 0..1
    const a0 = Math.PI * 0.75, a1 = a0 + u * Math.PI * 1.5, r = 38;
    const p = (a) => [Math.cos(a) * r, Math.sin(a) * r];
    const [x0, y0] = p(a0), [x1, y1] = p(a1);
    return `M ${x0} ${y0} A ${r} ${r} 0 ${u > 2 / 3 ? 1 : 0} 1 ${x1} ${y1}`;
  }
  function setupAge(age) {
    const svg = $("age"); const control = "slider:" + age.name;
    let u = (age.default - age.lo) / (age.hi - age.lo), startY = 0, startU = 0;
    svg.setAttribute("role", "slider"); svg.setAttribute("aria-label", "age, years");
    svg.setAttribute("aria-valuemin", String(age.lo)); svg.setAttribute("aria-valuemax", String(age.hi));
    const locked = !state.allowed.has(control);
    if (locked) svg.setAttribute("aria-disabled", "true"); else svg.setAttribute("tabindex", "0");
    const show = () => { $("agearc").setAttribute("d", arc(u)); const v = age.lo + u * (age.hi - age.lo);
      svg.setAttribute("aria-valuenow", v.toFixed(0)); svg.setAttribute("aria-valuetext", v.toFixed(0) + " years"); };
    show();
    const set = (x) => { u = x; show(); send(control, u); };
    svg.addEventListener("pointerdown", (ev) => { if (locked) return; svg.setPointerCapture(ev.pointerId); svg.dragging = true; svg.focus({ preventScroll: true }); startY = ev.clientY; startU = u; ev.preventDefault(); });
    svg.addEventListener("pointermove", (ev) => { if (!svg.dragging) return; set(Math.min(1, Math.max(0, startU + (startY - ev.clientY) / 200))); });
    const end = () => { svg.dragging = false; }; svg.addEventListener("pointerup", end); svg.addEventListener("pointercancel", end);
    svg.addEventListener("keydown", (ev) => { if (locked) return; const x = keyed(ev.key, u); if (x === null) return; ev.preventDefault(); set(x); });
  }

  // a button pressed by a pointer (held while down) or by the keyboard (Space / Enter held while
  // down; a key's auto-repeat is not a new press); the browser's own click is not used
  function pressable(b, down, up) {
    let by = null;
    b.addEventListener("pointerdown", (ev) => { ev.preventDefault(); if (b.setPointerCapture && ev.pointerId !== undefined) b.setPointerCapture(ev.pointerId); by = "pointer"; down(); });
    const release = () => { if (by === "pointer") { by = null; up(); } };
    b.addEventListener("pointerup", release); b.addEventListener("pointercancel", release);
    b.addEventListener("keydown", (ev) => {
      if (ev.key !== " " && ev.key !== "Enter") return;
      ev.preventDefault();
      if (ev.repeat || by) return;
      by = "key"; down();
    });
    b.addEventListener("keyup", (ev) => { if ((ev.key === " " || ev.key === "Enter") && by === "key") { ev.preventDefault(); by = null; up(); } });
    b.addEventListener("blur", () => { if (by === "key") { by = null; up(); } });
  }

  // the page is redrawn only where something changed: 30 states a second on a slow phone (or a
  // software-composited browser) must leave it time for the performer's fingers and the face
  const last = {};
  // every figure on the page (the sliders', the age's, the header's) is written in one animation
  // frame at most TEXT_MS apart: a text change costs the browser a layout of the whole page (the
  // regions' columns are laid out together), so four a second, all in one frame, never one per frame
  const TEXT_MS = 250;
  function setText(e, text) { if (e.textContent !== text) e.textContent = text; }
  function changed(key, value) { const j = JSON.stringify(value); if (last[key] === j) return false; last[key] = j; return true; }
  function update(st) {
    const now = performance.now();
    const texts = now - (last.textAt || 0) >= TEXT_MS;  // this frame writes the figures
    if (texts) last.textAt = now;
    if (st.values) {
      state.values = st.values;
      for (const [ch, sl] of Object.entries(state.sliders)) {
        const c = state.layout.channels[state.index[ch]]; const v = st.values[state.index[ch]];
        const u = (v - c.lo) / ((c.hi - c.lo) || 1);
        // the needle slides on its own layer (a transform: no layout, no repaint of the page)
        if (sl.u !== u) { sl.u = u; sl.ap.style.transform = `translateX(${(Math.min(1, Math.max(0, u)) * 100).toFixed(2)}%)`; }
        if (!texts) continue;  // nobody reads 30 figures a second; the last value always shows
        setText(sl.num, v.toFixed(2));
        if (state.own["slider:" + ch] === undefined && sl.now !== fmt(v)) {  // untouched: it stands where the face is
          sl.now = fmt(v); sl.el.setAttribute("aria-valuenow", sl.now);
          sl.el.setAttribute("aria-valuetext", sl.now + (sl.linked ? ", left and right together" : ""));
        }
      }
      if (state.ageRow) {
        const a = state.ageRow, v = st.values[state.index[a.name]], u = (v - a.lo) / (a.hi - a.lo);
        if (changed("age", u)) {
          const ang = Math.PI * 0.75 + u * Math.PI * 1.5;
          $("ageapplied").setAttribute("x2", Math.cos(ang) * 40); $("ageapplied").setAttribute("y2", Math.sin(ang) * 40);
        }
        if (texts) setText($("agetext"), v.toFixed(0));
      }
    }
    if (texts && now - (last.statsAt || 0) > 500) {  // figures a person reads: twice a second is plenty
      last.statsAt = now;
      if (st.fps !== undefined) { setText($("fps"), String(st.fps)); setText($("tps"), String(st.tps)); }
      if (st.latency) { setText($("p50"), st.latency[0].toFixed(1)); setText($("p99"), st.latency[1].toFixed(1)); }
    }
    if (st.devices && changed("devices", st.devices)) {
      const d = $("devices"); d.textContent = "";
      for (const [spec, ok, drops, level] of st.devices) {  // [spec, connected, drops (or null), level (a microphone)]
        const tag = el("span", "dev " + (ok ? "ok" : "lost"), (ok ? "● " : "○ ") + spec + (drops ? ` · ${drops} dropped` : ""));
        tag.title = (ok ? "connected" : "lost") + (typeof drops === "number" ? `, ${drops} inputs dropped` : "");
        if (typeof level === "number") {  // an audio input: how loud it hears
          const m = document.createElement("meter");
          m.min = 0; m.max = 1; m.value = level; m.className = "level";
          m.setAttribute("aria-label", "level of " + spec);
          tag.append(" ", m);
        }
        d.append(tag);
      }
    }
    // the other pages: what they touch, drawn as dots on our sliders, listed with their roles
    if (changed("clients", st.clients || [])) others(st.clients || []);
    if (st.markers && changed("markers", st.markers)) {
      const m = $("markers"); m.textContent = "";
      for (const [t, label] of st.markers.slice().reverse()) m.append(el("li", "", `${t.toFixed(2)} s  ${label}`));
    }
  }
  function others(clients) {
    const cl = $("clients"); cl.textContent = "";
    for (const sl of Object.values(state.sliders)) for (const o of Object.values(sl.others)) o.remove(), 0;
    for (const sl of Object.values(state.sliders)) sl.others = {};
    for (const c of clients) {
      const touching = Object.keys(c.own || {}).filter((k) => k.startsWith("slider:")).length;
      cl.append(el("li", "", `${c.name === state.me ? "▶ " : ""}${c.name}${c.role ? " (" + c.role + ")" : ""}` +
        `${c.only && c.only.length ? " — only " + c.only.join(", ") : ""} · ${touching} sliders touched`));
      if (c.name === state.me) continue;
      for (const [ctl, u] of Object.entries(c.own || {})) {
        const sl = state.sliders[ctl.slice(7)];
        if (!ctl.startsWith("slider:") || !sl) continue;
        const dot = el("div", "other"); dot.style.left = (u * 100) + "%"; dot.title = c.name;
        sl.el.append(dot); sl.others[c.name] = dot;
      }
    }
  }

  let pingAt = 0, bestRtt = Infinity, pendingState = null;
  // the face, live (face.js draws it with WebGL 2 from the server's stream); hidden, nothing is sent
  const face = state.face = window.PuppetFace($("face"));
  // each frame drawn is reported: the server sends a page at most two frames ahead of its drawing
  face.onDrawn = () => {
    if (state.ws && state.ws.readyState === 1) state.ws.send('{"t":"drawn"}');
    if (face.drawn === 1 && faceOn) faceReadout(true);  // not "waiting" for up to a second more
  };
  let faceOn = face.ok && params.get("face") !== "0";  // ?face=0: a page that starts without the face
  if (!face.ok) { $("facetoggle").disabled = true; $("faceinfo").textContent = "no WebGL 2 here"; }
  const faceWish = () => { if (state.ws && state.ws.readyState === 1) state.ws.send(JSON.stringify({ t: "face", on: faceOn, w: face.width() })); };
  face.onResize = () => { if (faceOn) faceWish(); };  // a smaller view asks for smaller pictures
  const showFace = () => { $("facetoggle").setAttribute("aria-pressed", String(faceOn));
    $("facetoggle").textContent = faceOn ? "face shown" : "face hidden"; $("face").style.visibility = faceOn ? "" : "hidden"; };
  $("facetoggle").onclick = () => { faceOn = !faceOn && face.ok; showFace(); faceWish(); };
  showFace();
  // the face's readout, once a second (and at the first picture): how many pictures a second and how
  // far behind the show, or, with the face still (the server sends nothing while it does not move),
  // how long it has not moved
  let lastDrawn = 0, lastAt = performance.now(), stateAt = 0;
  const ago = (s) => (s < 90 ? `${s.toFixed(0)} s` : s < 5400 ? `${(s / 60).toFixed(0)} min` : `${(s / 3600).toFixed(1)} h`);
  function faceReadout(first) {
    const now = performance.now(), n = face.moved - lastDrawn, fps = n / ((now - lastAt) / 1000);
    if (!first) { lastDrawn = face.moved; lastAt = now; }
    if (!face.ok) return;
    let text;
    if (!faceOn) text = "not sent to this page";
    else if (!face.drawn) text = "waiting for the first picture";
    else {
      const age = (now - face.drawnAt) / 1000, l = face.lags.slice(-30).sort((a, b) => a - b);
      const lag = l.length ? ` · ${l[l.length >> 1].toFixed(0)} ms behind the show` : "";
      // since the face last moved: the server's clock now minus when the last picture was made
      const still = face.offset !== null && face.frameT !== undefined ? (now + face.offset) / 1000 - face.frameT : age;
      if ((first || n > 0) && !face.stale) text = (first ? "first picture" : `${fps.toFixed(0)} frames/s`) + lag;
      else if (now - stateAt < 1500) text = `still · unchanged for ${ago(Math.max(0, still))}`;
      else text = `no picture for ${ago(age)}`;  // nor states: the connection says why
    }
    setText($("faceinfo"), text);
  }
  setInterval(() => faceReadout(false), 1000);
  function connect() {
    const ws = new WebSocket((location.protocol === "https:" ? "wss://" : "ws://") + location.host + "/ws?" + q.toString());
    ws.binaryType = "arraybuffer";
    state.ws = ws;
    ws.onopen = () => { $("conn").textContent = "connected"; $("conn").className = "up"; bestRtt = Infinity; ping(); faceWish(); };
    ws.onclose = () => {
      $("conn").textContent = "disconnected (retrying)"; $("conn").className = "down";
      // what the devices do is unknown until the show answers again: none is shown connected (the
      // list stayed green while the show was gone), and the next state redraws the list
      for (const tag of document.querySelectorAll("#devices .dev")) {
        tag.className = "dev lost"; tag.title = "unknown: the show does not answer";
        if (tag.firstChild && tag.firstChild.nodeType === 3) tag.firstChild.textContent = tag.firstChild.textContent.replace(/^● /, "○ ");
      }
      delete last.devices;
      setTimeout(connect, 1000);
    };
    ws.onmessage = (ev) => {
      if (typeof ev.data !== "string") { face.message(ev.data); return; }
      const msg = JSON.parse(ev.data);
      if (msg.t === "hello") {
        // a show (re)started: it holds nothing from this page, so no slider stands at a value this
        // page sent to the show before (they stayed there, frozen, no longer following the face)
        state.own = {};
        state.me = msg.you; state.allowed = new Set(msg.allowed); state.layout = msg.layout;
        $("me").textContent = msg.you; build(msg.layout);
      } else if (msg.t === "state") {  // applied in the next animation frame, with the face's: one redraw
        stateAt = performance.now();
        if (!pendingState) { pendingAt = stateAt; requestAnimationFrame(applyState); }
        pendingState = msg;
      }
      else if (msg.t === "pong") {
        const now = performance.now(), rtt = now - pingAt;
        $("rtt").textContent = rtt.toFixed(1);
        // the server's clock against ours, from the quickest round trip: the face's lag is measured on it
        if (rtt <= bestRtt) { bestRtt = rtt; face.offset = msg.s * 1000 - (pingAt + now) / 2; }
      }
    };
  }
  // the server sends a cycle's picture just before its state: the state waits (HOLD_MS at most) for
  // the picture being decoded, so both are shown in one redraw, not two
  const HOLD_MS = 50;
  let pendingAt = 0;
  function applyState() {
    if (face.decoding > 0 && performance.now() - pendingAt < HOLD_MS) { requestAnimationFrame(applyState); return; }
    const st = pendingState; pendingState = null; update(st);
  }
  function ping() { if (state.ws && state.ws.readyState === 1) { pingAt = performance.now(); state.ws.send('{"t":"ping"}'); } }
  setInterval(ping, 1000);
  const hold = (id, control) => pressable($(id), () => send(control, 1), () => send(control, 0));
  hold("panic", "button:panic"); hold("marker", "button:marker");
  $("edit").onclick = () => {
    const tab = window.open("", "_blank");
    fetch("/api/edit" + location.search, { method: "POST" }).then((r) => r.json()).then((j) => {
      if (j.ok) { if (tab) tab.location = j.url; else location.assign(j.url); }
      else { if (tab) tab.close(); alert(j.error); }
    });
  };
  document.addEventListener("keydown", (ev) => { if (ev.key === "Escape") { send("button:panic", 1); send("button:panic", 0); } });
  connect();
})();
