// facepuppet: the face as the audience sees it, from the server's stream (render/stream.py), one
// of two ways. Pictures (the default): a JPEG of the show's frame, decoded off the page's thread and
// drawn on a 2D canvas. The mesh: drawn here with WebGL 2, the scene once (triangles, colours, rest
// places, cavities, eyes, camera, the renderer's own shaders), then per frame the quantised
// positions; normals are computed here, area-weighted over the same triangles as the show's renderer.
"use strict";
window.PuppetFace = function (canvas) {
  const F = { ok: true, scene: null, frames: 0, drawn: 0, moved: 0, shownTick: -1, tick: -1, lags: [], drawLog: [], offset: null,
              bytes: 0, error: null, mode: null, decoding: 0, cost: { decode: 0, normals: 0, draw: 0 } };
  let gl = null, ctx2d = null, picture = null;
  let S = null, pos = null, nrm = null, dirty = false, eye = [0, 0];
  // the width the face is shown at, in device pixels (at most 1.5 per CSS pixel): the server sends
  // pictures of about that size, never bigger than shown; F.onResize hears when it changes
  F.width = () => Math.round(canvas.clientWidth * Math.min(window.devicePixelRatio || 1, 1.5));
  let watcher = null, lastWidth = -1;
  function watch() {
    if (!window.ResizeObserver) return;
    if (watcher) watcher.disconnect();
    watcher = new ResizeObserver(() => { const w = F.width(); if (w !== lastWidth) { lastWidth = w; if (F.onResize) F.onResize(w); } });
    watcher.observe(canvas);
  }
  watch();
  // a canvas keeps the first kind of context it is asked for: the other kind gets a fresh canvas
  function fresh() { const c = canvas.cloneNode(false); canvas.replaceWith(c); canvas = c; gl = ctx2d = null; watch(); }
  function webgl() {
    if (gl) return gl;
    if (ctx2d) fresh();
    gl = canvas.getContext("webgl2", { antialias: false });  // MSAA triples a software rasteriser's time
    if (!gl) throw new Error("this browser has no WebGL 2");
    F.mode = "mesh"; return gl;
  }
  function context2d() { if (ctx2d) return ctx2d; if (gl) { fresh(); S = null; } ctx2d = canvas.getContext("2d"); F.mode = "picture"; return ctx2d; }

  function header(buf) {
    const dv = new DataView(buf), kind = dv.getUint8(0), n = dv.getUint32(4, true);
    const h = JSON.parse(new TextDecoder().decode(new Uint8Array(buf, 8, n)));
    return [kind, h, 8 + n];
  }
  function program(vs, fs) {
    const sh = (type, src) => { const s = gl.createShader(type); gl.shaderSource(s, src); gl.compileShader(s);
      if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s)); return s; };
    const p = gl.createProgram(); gl.attachShader(p, sh(gl.VERTEX_SHADER, vs)); gl.attachShader(p, sh(gl.FRAGMENT_SHADER, fs));
    gl.linkProgram(p); if (!gl.getProgramParameter(p, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(p));
    return p;
  }
  function buffer(data, target, usage) { const b = gl.createBuffer(); gl.bindBuffer(target || gl.ARRAY_BUFFER, b);
    gl.bufferData(target || gl.ARRAY_BUFFER, data, usage || gl.STATIC_DRAW); return b; }
  function attrib(prog, name, buf, size) { const loc = gl.getAttribLocation(prog, name); if (loc < 0) return;
    gl.bindBuffer(gl.ARRAY_BUFFER, buf); gl.enableVertexAttribArray(loc); gl.vertexAttribPointer(loc, size, gl.FLOAT, false, 0, 0); }
  function vao(prog, attrs, tris) {
    const v = gl.createVertexArray(); gl.bindVertexArray(v);
    for (const [name, buf, size] of attrs) attrib(prog, name, buf, size);
    const ibo = buffer(tris, gl.ELEMENT_ARRAY_BUFFER); gl.bindVertexArray(null);
    return { v, ibo, count: tris.length };
  }

  function setScene(buf, h, at) {
    webgl();
    const A = {};
    const types = { float32: Float32Array, uint32: Uint32Array };
    for (const [name, [dtype, off, count]] of Object.entries(h.blobs)) A[name] = new types[dtype](buf, at + off, count);
    const V = h.vertices;
    pos = new Float32Array(A.base); nrm = new Float32Array(V * 3);
    const sh = h.shaders;
    const P = { skin: program(sh.skin_vs, sh.skin_fs), scalp: program(sh.scalp_vs, sh.scalp_fs),
                eye: program(sh.eye_vs, sh.eye_fs), cavity: program(sh.cavity_vs, sh.cavity_fs) };
    const posBuf = buffer(pos, gl.ARRAY_BUFFER, gl.DYNAMIC_DRAW), nrmBuf = buffer(nrm, gl.ARRAY_BUFFER, gl.DYNAMIC_DRAW);
    const color = buffer(A.color), rest = buffer(A.rest), brow = buffer(A.brow);
    const skinAttrs = [["in_pos", posBuf, 3], ["in_normal", nrmBuf, 3], ["in_color", color, 3], ["in_rest", rest, 3], ["in_brow", brow, 2]];
    const cavPos = buffer(new Float32Array(0));  // the cavities' slice of pos, re-uploaded per frame
    S = { h, A, P, posBuf, nrmBuf, cavPos,
          skin: vao(P.skin, skinAttrs, A.skin_tris),
          head: A.head_tris.length ? vao(P.scalp, skinAttrs, A.head_tris) : null,
          cavity: A.cavity_tris.length ? vao(P.cavity, [["in_pos", cavPos, 3], ["in_depth", buffer(A.cavity_depth), 1],
            ["in_teeth", buffer(A.cavity_teeth), 1], ["in_rim", buffer(A.cavity_rim), 3]],
            A.cavity_tris.map((i) => i - h.rows)) : null,
          eye: vao(P.eye, [["in_pos", buffer(A.sphere), 3]], A.sphere_tris) };
    gl.useProgram(P.scalp);
    gl.uniform3fv(gl.getUniformLocation(P.scalp, "hair_albedo"), h.hair.albedo);
    gl.uniform3fv(gl.getUniformLocation(P.scalp, "hair_edge"), h.hair.edge);
    F.scene = h.face; F.tick = -1;
    normals(); redraw();
  }

  function normals() {  // area-weighted vertex normals of the rows (render.normals_kernel's sums)
    const t = S.A.normal_tris, rows = S.h.rows; nrm.fill(0, 0, rows * 3);
    for (let k = 0; k < t.length; k += 3) {
      const a = t[k] * 3, b = t[k + 1] * 3, c = t[k + 2] * 3;
      const e1x = pos[b] - pos[a], e1y = pos[b + 1] - pos[a + 1], e1z = pos[b + 2] - pos[a + 2];
      const e2x = pos[c] - pos[a], e2y = pos[c + 1] - pos[a + 1], e2z = pos[c + 2] - pos[a + 2];
      const cx = e1y * e2z - e1z * e2y, cy = e1z * e2x - e1x * e2z, cz = e1x * e2y - e1y * e2x;
      nrm[a] += cx; nrm[a + 1] += cy; nrm[a + 2] += cz; nrm[b] += cx; nrm[b + 1] += cy; nrm[b + 2] += cz;
      nrm[c] += cx; nrm[c + 1] += cy; nrm[c + 2] += cz;
    }
    for (let i = 0; i < rows * 3; i += 3) {
      const l = Math.hypot(nrm[i], nrm[i + 1], nrm[i + 2]) || 1e-12; nrm[i] /= l; nrm[i + 1] /= l; nrm[i + 2] /= l;
    }
    const dst = S.A.copy_dst, src = S.A.copy_src;  // the join's vertices take the mask's normals
    for (let k = 0; k < dst.length; k++) for (let j = 0; j < 3; j++) nrm[dst[k] * 3 + j] = nrm[src[k] * 3 + j];
  }

  async function setFrame(buf, h, at) {
    const t0 = performance.now();
    const ds = new DecompressionStream("deflate");
    const raw = await new Response(new Blob([new Uint8Array(buf, at)]).stream().pipeThrough(ds)).arrayBuffer();
    if (!S || h.face !== S.h.face || h.tick <= F.tick) { if (F.onDrawn) F.onDrawn(); return; }  // a newer frame, or another face, came first
    const q = new Int16Array(raw), base = S.A.base, k = S.h.quantum;
    for (let i = 0; i < q.length; i++) pos[i] = base[i] + q[i] * k;
    F.tick = h.tick; F.frameT = h.t; eye = h.eye; F.frames++; received++;
    const t1 = performance.now();
    normals();
    F.cost.decode += t1 - t0; F.cost.normals += performance.now() - t1;
    redraw();
  }

  async function setPicture(buf, h, at) {  // decoded off this thread; shown at the next animation frame
    const t0 = performance.now();
    let bmp;
    F.decoding++;  // the page holds its state's redraw for this picture (one redraw for both)
    try { bmp = await createImageBitmap(new Blob([new Uint8Array(buf, at)], { type: h.type })); } finally { F.decoding--; }
    const resized = F.size && (h.w !== F.size[0] || h.h !== F.size[1]);  // the same moment at the size now asked for
    if (h.tick < F.tick || (h.tick === F.tick && !resized)) { bmp.close(); if (F.onDrawn) F.onDrawn(); return; }  // a newer picture came first
    if (picture) { picture.close(); received--; if (F.onDrawn) F.onDrawn(); }  // passed over, never shown
    picture = bmp; F.scene = h.face; F.tick = h.tick; F.size = [h.w, h.h]; F.frameT = h.t; F.frames++; received++;
    F.cost.decode += performance.now() - t0;
    redraw();
  }

  F.message = function (buf) {
    F.bytes += buf.byteLength;
    const [kind, h, at] = header(buf);
    try {
      if (kind === 1) setScene(buf, h, at);
      else if (kind === 2 && S) setFrame(buf, h, at).catch((e) => { F.error = String(e); });
      else if (kind === 3) setPicture(buf, h, at).catch((e) => { F.error = String(e); });
    } catch (e) { F.error = String(e); F.ok = false; }
  };

  function eyeRotation(yaw, pitch) {  // render.meshdata.eye_rotation, column-major
    const cy = Math.cos(yaw), sy = Math.sin(yaw), cp = Math.cos(pitch), sp = Math.sin(pitch);
    // ry @ rx with ry = [[cy,0,sy],[0,1,0],[-sy,0,cy]], rx = [[1,0,0],[0,cp,sp],[0,-sp,cp]]
    const m = [[cy, -sy * sp, sy * cp], [0, cp, sp], [-sy, -cy * sp, cy * cp]];
    return [m[0][0], m[1][0], m[2][0], m[0][1], m[1][1], m[2][1], m[0][2], m[1][2], m[2][2]];
  }

  const STALE_MS = 1000;  // a moving face's picture is never this old when drawn (the server skips, never queues)
  let asked = false, received = 0;
  function redraw() { dirty = true; if (!asked) { asked = true; requestAnimationFrame(draw); } }
  function drawPicture() {
    const c = context2d(), p = picture; picture = null;
    if (canvas.width !== p.width || canvas.height !== p.height) { canvas.width = p.width; canvas.height = p.height; }
    c.drawImage(p, 0, 0); p.close();
  }
  function shown(c0) {
    F.drawn++; F.drawnAt = performance.now(); F.cost.draw += F.drawnAt - c0;
    // a moment already shown, drawn again at another size, is not the face moving
    const moved = F.tick !== F.shownTick;
    F.shownTick = F.tick;
    if (moved) F.moved++;
    if (moved) F.stale = false;
    if (moved && F.frameT !== undefined && F.offset !== null) {  // how far behind the server's read of the state
      const lag = performance.now() + F.offset - F.frameT * 1000;
      // a picture made over STALE_MS ago is a still face's last one, sent to a page that missed it
      // or has just opened: the face is not that far behind, it has not moved since
      F.stale = lag > STALE_MS;
      if (!F.stale) { F.lags.push(lag); if (F.lags.length > 600) F.lags.shift(); }
    }
    F.drawLog.push([F.tick, performance.now()]); if (F.drawLog.length > 4000) F.drawLog.shift();
    for (; received > 0; received--) if (F.onDrawn) F.onDrawn();  // every frame that came is now shown or passed over
  }
  function draw() {
    asked = false;
    if (!dirty) return;
    dirty = false;
    const c0 = performance.now();
    if (picture) { drawPicture(); shown(c0); return; }
    if (!S) return;
    const w = Math.round(canvas.clientWidth * Math.min(window.devicePixelRatio || 1, 1.5)), h = Math.round(w / S.h.aspect);
    if (canvas.width !== w || canvas.height !== h) { canvas.width = w; canvas.height = h; }
    gl.viewport(0, 0, w, h);
    const bg = S.h.background; gl.clearColor(bg[0], bg[1], bg[2], 1); gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    gl.enable(gl.DEPTH_TEST);
    gl.bindBuffer(gl.ARRAY_BUFFER, S.posBuf); gl.bufferData(gl.ARRAY_BUFFER, pos, gl.DYNAMIC_DRAW);
    gl.bindBuffer(gl.ARRAY_BUFFER, S.nrmBuf); gl.bufferData(gl.ARRAY_BUFFER, nrm, gl.DYNAMIC_DRAW);
    const mats = (p) => { gl.useProgram(p); gl.uniformMatrix4fv(gl.getUniformLocation(p, "mvp"), false, S.h.mvp);
      const v = gl.getUniformLocation(p, "view"); if (v) gl.uniformMatrix4fv(v, false, S.h.view); };
    mats(S.P.skin); gl.bindVertexArray(S.skin.v); gl.drawElements(gl.TRIANGLES, S.skin.count, gl.UNSIGNED_INT, 0);
    if (S.head) { mats(S.P.scalp); gl.enable(gl.CULL_FACE); gl.bindVertexArray(S.head.v);
      gl.drawElements(gl.TRIANGLES, S.head.count, gl.UNSIGNED_INT, 0); gl.disable(gl.CULL_FACE); }
    if (S.cavity) {  // a backdrop behind the openings, without depth writes (as the renderer does)
      gl.bindBuffer(gl.ARRAY_BUFFER, S.cavPos); gl.bufferData(gl.ARRAY_BUFFER, pos.subarray(S.h.rows * 3), gl.DYNAMIC_DRAW);
      mats(S.P.cavity); gl.depthMask(false); gl.bindVertexArray(S.cavity.v);
      gl.drawElements(gl.TRIANGLES, S.cavity.count, gl.UNSIGNED_INT, 0); gl.depthMask(true);
    }
    const E = S.h.eyes; mats(S.P.eye);
    gl.uniform1f(gl.getUniformLocation(S.P.eye, "radius"), E.radius);
    gl.enable(gl.CULL_FACE); gl.bindVertexArray(S.eye.v);
    const clamp = (a) => Math.max(-1, Math.min(1, a)), verge = clamp(eye[2] || 0);
    E.centers.forEach((c, i) => {  // the left eye turns by yaw - vergence, the right by yaw + vergence
      const yaw = clamp(clamp(eye[0]) + (i ? verge : -verge));
      gl.uniformMatrix3fv(gl.getUniformLocation(S.P.eye, "rot"), false,
        eyeRotation(yaw * E.yaw_max, clamp(eye[1]) * E.pitch_max));
      gl.uniform3fv(gl.getUniformLocation(S.P.eye, "center"), c);
      gl.drawElements(gl.TRIANGLES, S.eye.count, gl.UNSIGNED_INT, 0); });
    gl.disable(gl.CULL_FACE); gl.bindVertexArray(null);
    if (F.finish) gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, new Uint8Array(4));  // timing: wait for the raster
    shown(c0);
  }
  return F;
};
