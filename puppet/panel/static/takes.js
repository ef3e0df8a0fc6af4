// The page's take list: search the take library, open a take in the editor, export it.
// Its own panel, added to the page's side column; talks to /api/takes (puppet/panel/takes.py).
(() => {
  "use strict";
  const column = document.querySelector("main > div:last-child");
  if (!column) return;
  const q = location.search;  // carries the LAN token, if any
  const box = document.createElement("section");
  box.id = "takes";
  box.setAttribute("aria-labelledby", "takes-title");
  box.innerHTML = `<h2 id="takes-title">takes</h2>
    <form id="takes-form" role="search"><label for="takes-q" class="stat">search</label>
      <input id="takes-q" type="search" placeholder="smile performer:ana tag:keeper" autocomplete="off">
      <button type="submit">find</button></form>
    <p id="takes-status" class="stat" role="status" aria-live="polite"></p>
    <ul id="takes-list" class="plain takes"></ul>`;
  column.appendChild(box);
  const style = document.createElement("style");  // kept here: the panel is self-contained
  style.textContent = `#takes form { display: flex; gap: 6px; align-items: center; }
    #takes input { flex: 1; min-width: 0; }
    .takes li.take { display: flex; gap: 6px; align-items: center; flex-wrap: wrap; padding: 4px 0;
      border-top: 1px solid var(--line); }
    .takes li.take > div { flex: 1; min-width: 140px; } .takes li.missing { opacity: .6; }`;
  document.head.appendChild(style);
  const $ = (id) => document.getElementById(id);
  const say = (text) => { $("takes-status").textContent = text; };
  const api = (path, opts) => fetch(path + (path.includes("?") ? q.replace("?", "&") : q), opts).then((r) => r.json());

  const STATES = { recording: " (recording)", died: " (show died: run takes check)",
    crashed: " (show died; kept to its last tick)", damaged: " (damaged)" };

  function item(t) {
    const unfinished = t.state === "recording" || t.state === "died";  // no duration known yet
    const li = document.createElement("li");
    li.className = "take" + (t.missing ? " missing" : "");
    if (t.thumbnail) {
      const img = document.createElement("img");
      img.src = `/api/takes/${t.id}/thumbnail${q}`;
      img.alt = `take ${t.id}, middle frame`;
      img.width = 96; img.height = 54;
      li.appendChild(img);
    }
    const text = document.createElement("div");
    const when = (t.recorded || "").slice(0, 16).replace("T", " ");
    const bits = [when, unfinished ? "" : `${t.duration.toFixed(1)} s`, t.performer, t.tags.join(", "), t.expressions.join(", ")];
    text.innerHTML = "<b></b><br><span class='stat'></span>";
    text.querySelector("b").textContent = `${t.id} · ${t.name}` + (t.missing ? " (missing)" : "") + (STATES[t.state] || "");
    text.querySelector("span").textContent = bits.filter((b) => b).join(" · ");
    li.appendChild(text);
    const edit = document.createElement("button");
    edit.textContent = "edit";
    edit.setAttribute("aria-label", `edit take ${t.id} in the editor`);
    edit.onclick = () => {
      const tab = window.open("", "_blank");
      api(`/api/takes/${t.id}/edit`, { method: "POST" }).then((j) => {
        if (j.ok) { if (tab) tab.location = j.url; else location.assign(j.url); }
        else { if (tab) tab.close(); say(j.error); }
      });
    };
    li.appendChild(edit);
    for (const kind of ["mp4", "pc2", "csv"]) {
      const b = document.createElement("button");
      b.textContent = kind;
      b.setAttribute("aria-label", `export take ${t.id} to ${kind}`);
      b.onclick = () => api(`/api/takes/${t.id}/export?to=${kind}`, { method: "POST" }).then((j) => {
        say(!j.ok ? j.error : j.state === "waiting" ? `${j.out}: waits for ${j.ahead} export${j.ahead === 1 ? "" : "s"} before it`
          : `exporting to ${j.out}`);
        if (j.ok) watchExports();
      });
      li.appendChild(b);
    }
    return li;
  }

  function search() {
    const query = $("takes-q").value;
    api(`/api/takes?q=${encodeURIComponent(query)}`).then((j) => {
      const list = $("takes-list");
      list.replaceChildren();
      if (!j.ok) { say(j.error); return; }
      j.takes.forEach((t) => list.appendChild(item(t)));
      say(j.takes.length ? `${j.takes.length} take${j.takes.length === 1 ? "" : "s"}` : "no takes");
    }).catch(() => say("the take library cannot be read"));
  }

  let watching = null;
  function watchExports() {
    if (watching) return;
    watching = setInterval(() => api("/api/takes/exports").then((j) => {
      const running = j.exports.filter((e) => e.state === "running" || e.state === "waiting");
      const last = j.exports[j.exports.length - 1];
      if (!running.length) {
        clearInterval(watching); watching = null;
        if (last) say(last.state === "done" ? `exported ${last.out}` : `export failed: ${last.error}`);
      }
    }), 1000);
  }

  $("takes-form").addEventListener("submit", (ev) => { ev.preventDefault(); search(); });
  search();
})();
