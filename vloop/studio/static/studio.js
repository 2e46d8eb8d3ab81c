/* vloop studio: the editing tools over the viewer (window.vloopViewer). Every number drawn comes from the
 * session in Python (vloop's own core): this script sends what the pointer and the forms do, and draws the
 * replies. Transport: the page's WebSocket (?token=…), or window.vloopStudioTransport (the notebook widget). */
(() => {
  "use strict";
  const NS = "http://www.w3.org/2000/svg";
  const $ = (id) => document.getElementById(id);
  const VW = () => window.vloopViewer;
  const ST = { tool: "drag", state: null, picked: [], pending: new Map(), next: 1, dragging: null, inflight: false,
    queued: null, gesture: 0, stats: { drags: [], frames: [], replies: [], server: [], loads: [], later: [] }, candidates: [] };

  // ------------------------------------------------------------------ transport

  function transport() {
    if (window.vloopStudioTransport) return window.vloopStudioTransport;
    const token = $("studio").dataset.token;
    const ws = new WebSocket(`ws://${location.host}/ws?token=${encodeURIComponent(token)}`);
    const t = { ready: new Promise((ok) => ws.addEventListener("open", ok)), send: (text) => ws.send(text), onmessage: null };
    ws.addEventListener("message", (e) => t.onmessage && t.onmessage(e.data));
    ws.addEventListener("close", () => status("disconnected: restart vloop studio"));
    return t;
  }
  const T = transport();
  T.onmessage = (text) => receive(JSON.parse(text));

  function send(op, args = {}) {
    const id = ST.next++;
    return new Promise((resolve) => {
      ST.pending.set(id, resolve);
      T.ready.then(() => T.send(JSON.stringify({ op, id, ...args })));
    });
  }
  function receive(reply) {
    if (reply.op === "drag" && ST.sentAt) { ST.stats.replies.push(performance.now() - ST.sentAt); ST.stats.server.push(reply.ms); }
    const done = ST.pending.get(reply.id);
    if (reply.started) { status(`${reply.op}: running…`); return; }
    if (done) ST.pending.delete(reply.id);
    if (!reply.ok) status(`${reply.op}: ${reply.error}`, true);
    const shown = reply.state ? show(reply.state) : Promise.resolve();
    if (reply.candidates) showCandidates(reply.candidates);
    if (reply.validation) showVerdict(reply.validation);
    shown.then(() => { if (done) done(reply); });
  }

  function status(text, bad) {
    const s = $("s-status");
    s.textContent = text;
    s.classList.toggle("bad", !!bad);
    document.body.dataset.studioStatus = text;
  }

  // ------------------------------------------------------------------ drawing a state

  async function show(state) {
    ST.state = state;
    const box = $("s-limit");
    box.hidden = !state.limit;
    box.textContent = state.limit || "";
    const problem = $("s-problem");
    problem.hidden = !state.draft;
    problem.textContent = state.draft ? `Not yet a mechanism: ${state.draft}` : "";
    if (state.payload) {
      const keep = !!VW().data && ST.keepView;
      await VW().load(state.payload, { keepView: keep, index: ST.dragging && ST.dragging.crank ? VW().index : 0 });
      ST.stats.loads.push(VW().stats.load);
      ST.keepView = true;
    } else drawDraft(state.doc);
    drawHandles();
    fillForms(state.doc);
    showInfo(state);
    $("s-undo").disabled = !state.undo;
    $("s-redo").disabled = !state.redo;
    document.body.dataset.studioReady = String(Date.now());
  }

  function svgEl(tag, attrs, parent) {
    const e = document.createElementNS(NS, tag);
    for (const k in attrs) e.setAttribute(k, attrs[k]);
    parent.appendChild(e);
    return e;
  }
  const view = () => $("view");
  const upp = () => { const r = view().getBoundingClientRect(), b = view().viewBox.baseVal; return b && b.width ? Math.max(b.width / r.width, b.height / r.height) : 1; };

  function drawDraft(doc) {
    // a drawing vloop cannot read yet: its joints and links as drawn (no solve)
    const v = view();
    v.replaceChildren();
    const pts = Object.values(doc.joints);
    const size = ST.box || draftBox(pts);
    ST.box = size;
    v.setAttribute("viewBox", size.join(" "));
    const g = svgEl("g", { class: "s-draft" }, v);
    const u = upp();
    for (const [name, lk] of Object.entries(doc.links)) {
      if (lk.ground) continue;
      const p = lk.joints.map((j) => doc.joints[j]).filter(Boolean);
      if (p.length >= 2) svgEl("polygon", { class: "s-draft-link", "stroke-width": 8 * u, fill: p.length > 2 ? "var(--plate)" : "none", points: p.map(([x, y]) => `${x},${-y}`).join(" "), "data-draft-link": name }, g);
    }
    for (const [name, [x, y]] of Object.entries(doc.joints)) {
      svgEl("circle", { class: "s-draft-joint", cx: x, cy: -y, r: 5 * u, "stroke-width": 2 * u, "data-draft-joint": name }, g);
      const t = svgEl("text", { x: x + 9 * u, y: -y - 9 * u, "font-size": 14 * u, fill: "var(--fg)" }, g);
      t.textContent = name;
    }
  }
  function draftBox(pts) {
    const units = ST.state ? ST.state.doc.units : "mm";
    const w = { mm: 250, cm: 25, m: 2.5, km: 0.0025, in: 10, ft: 1 }[units] || 250;
    if (pts.length < 2) return [-0.2 * w, -0.6 * w, w, 0.8 * w];
    const xs = pts.map((p) => p[0]), ys = pts.map((p) => p[1]);
    const x0 = Math.min(...xs), x1 = Math.max(...xs), y0 = Math.min(...ys), y1 = Math.max(...ys);
    const m = 0.3 * Math.max(x1 - x0, y1 - y0, 0.2 * w);
    return [x0 - m, -(y1 + m), x1 - x0 + 2 * m, y1 - y0 + 2 * m];
  }

  // where each joint is on the screen now: the displayed sample's solved position, else the document's
  function jointAt(name) {
    const d = VW().data;
    if (ST.state && ST.state.payload && d && VW().column(name + ".x")) return [VW().column(name + ".x")[VW().index], VW().column(name + ".y")[VW().index]];
    return ST.state.doc.joints[name];
  }
  function crankOf(name) {
    for (const d of ST.state.doc.drivers || []) {
      const lk = ST.state.doc.links[d.link];
      if (lk && lk.joints.includes(name) && name !== d.pivot && ST.state.payload) return d;
    }
    return null;
  }

  function drawHandles() {
    const v = view();
    const old = v.querySelector(".s-handles");
    if (old) old.remove();
    const g = svgEl("g", { class: "s-handles" }, v);
    const ground = new Set(Object.values(ST.state.doc.links).filter((l) => l.ground).flatMap((l) => l.joints));
    const locked = new Set(ST.state.locks.joints);
    const u = upp();
    for (const name of Object.keys(ST.state.doc.joints)) {
      const [x, y] = jointAt(name);
      const cls = ["s-handle", ground.has(name) ? "ground" : "", crankOf(name) ? "crank" : "", locked.has(name) ? "locked" : "", ST.picked.includes(name) ? "picked" : ""].join(" ");
      const c = svgEl("circle", { class: cls, cx: x, cy: -y, r: 11 * u, "stroke-width": 2 * u, "data-handle": name }, g);
      c.addEventListener("pointerdown", (ev) => handleDown(ev, name));
    }
    drawCandidatePaths(g);
    for (const b of v.querySelectorAll("g[data-body]")) b.toggleAttribute("data-locked", ST.state.locks.links.includes(b.dataset.body));
  }

  function drawCandidatePaths(g) {
    const colours = ["#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9"];
    ST.candidates.forEach((c, k) => {
      if (!c.path.length) return;
      const p = svgEl("path", { class: "s-cand-path", "stroke-width": 2 * upp(), "data-candidate": k + 1,
        d: c.path.map(([x, y], i) => `${i ? "L" : "M"}${x} ${-y}`).join("") }, g);
      p.style.stroke = colours[k % colours.length];
    });
    const u = upp();
    (ST.state.targets || []).forEach(([x, y], k) => {
      if (ST.state.payload) return; // the viewer draws them (numbered crosses)
      svgEl("path", { class: "v-target", "stroke-width": 2 * u, d: `M${x - 6 * u} ${-y - 6 * u}L${x + 6 * u} ${-y + 6 * u}M${x - 6 * u} ${-y + 6 * u}L${x + 6 * u} ${-y - 6 * u}`, "data-target": k + 1 }, g);
    });
  }

  // ------------------------------------------------------------------ pointer

  function world(ev) { return VW().toWorld(ev.clientX, ev.clientY); }

  function handleDown(ev, name) {
    if (ST.tool === "link" || ST.tool === "plate") { ev.stopPropagation(); return pick(name); }
    if (ST.tool === "slider") { ev.stopPropagation(); return send("add_slider", { joint: name, angle: Number($("s-axis").value || 0) * Math.PI / 180 }); }
    if (ST.tool === "lock") { ev.stopPropagation(); return send("lock", { kind: "joints", name, on: !ST.state.locks.joints.includes(name) }); }
    if (ST.tool === "delete") { ev.stopPropagation(); return send("delete", { name }); }
    if (ST.tool !== "drag") return;
    ev.stopPropagation();
    ev.preventDefault();
    const crank = crankOf(name);
    if (!crank && ST.state.payload && VW().index !== 0) VW().setIndex(0); // geometry is edited at t = 0
    ST.dragging = { name, crank, gesture: ++ST.gesture };
    view().setPointerCapture(ev.pointerId);
  }

  // pointermove is held back to the next animation frame; pointerrawupdate (where there is one) comes as the pointer
  // moves, so a drag's message leaves up to a frame sooner. A crank's turn is drawn on pointermove (no message).
  const RAW = "onpointerrawupdate" in window;
  function pointerMove(ev) {
    const d = ST.dragging;
    if (!d) return;
    ev.stopPropagation();
    const t0 = ev.timeStamp; // when the pointer moved (performance.now()'s clock): waiting for the page counts too
    if (d.crank) return ev.type === "pointermove" && turnCrank(d.crank, ...world(ev), t0);
    if (RAW && ev.type === "pointermove") return;
    const [x, y] = world(ev);
    ST.queued = { joint: d.name, x, y, gesture: d.gesture, t0 };
    pump();
  }

  // a crank turned by its pin: the displayed sample whose crank angle is nearest the pointer's (no new solve)
  function turnCrank(drv, x, y, t0) {
    const piv = jointAt(drv.pivot), th = VW().column(drv.link + ".theta"), n = VW().samples;
    const want = Math.atan2(y - piv[1], x - piv[0]);
    let best = VW().index, score = Infinity;
    for (let i = 0; i < n; i++) {
      const a = Math.abs(Math.atan2(Math.sin(th[i] - want), Math.cos(th[i] - want))) + 1e-4 * Math.abs(i - VW().index) / n;
      if (a < score) { score = a; best = i; }
    }
    VW().setIndex(best);
    drawHandles();
    requestAnimationFrame(() => ST.stats.frames.push(performance.now() - t0));
  }

  // one drag message in flight at a time; the newest pointer position waits for the reply (no backlog)
  async function pump() {
    if (ST.inflight || !ST.queued) return;
    const q = ST.queued;
    ST.queued = null;
    ST.inflight = true;
    ST.sentAt = performance.now();
    await send("drag", { joint: q.joint, x: q.x, y: q.y, gesture: q.gesture });
    requestAnimationFrame(() => { ST.stats.drags.push(performance.now() - q.t0); ST.stats.later.push(VW().stats.later || 0); });
    ST.inflight = false;
    pump();
  }

  function pointerUp() { ST.dragging = null; }

  function click(ev) {
    if (ST.dragging || ev.target.closest(".s-handle")) return;
    // the viewer captures the pointer for panning, so the click's target is the drawing: ask what is under it
    const hit = document.elementFromPoint(ev.clientX, ev.clientY);
    const body = hit && hit.closest("[data-body]");
    if (ST.tool === "lock" && body) {
      const name = body.dataset.body;
      return send("lock", { kind: "links", name, on: !ST.state.locks.links.includes(name) });
    }
    const [x, y] = world(ev);
    if (ST.tool === "pivot" || ST.tool === "joint") send("add_joint", { x, y, ground: ST.tool === "pivot" });
    else if (ST.tool === "target") {
      const pts = [...(ST.state.targets || []), [x, y]];
      send("targets", { points: pts });
    }
  }

  function pick(name) {
    ST.picked.push(name);
    const need = ST.tool === "plate" ? 3 : 2;
    if (ST.picked.length >= need) {
      const joints = ST.picked.slice(0, need);
      ST.picked = [];
      send("add_link", { joints });
    } else drawHandles();
  }

  // ------------------------------------------------------------------ forms and panels

  function options(sel, names, keep) {
    const before = sel.value;
    sel.replaceChildren(...names.map((n) => { const o = document.createElement("option"); o.textContent = n; return o; }));
    if (keep && names.includes(before)) sel.value = before;
  }
  function fillForms(doc) {
    // the lists change only when joints or links do: a drag rebuilds nothing here
    const key = JSON.stringify([Object.keys(doc.joints), Object.keys(doc.links), doc.drivers, doc.name, doc.units]);
    if (key === ST.formsKey) return;
    ST.formsKey = key;
    const moving = Object.entries(doc.links).filter(([, l]) => !l.ground);
    options($("f-joint").elements.name, Object.keys(doc.joints), true);
    options($("f-length").elements.link, moving.filter(([, l]) => l.joints.length === 2).map(([n]) => n), true);
    options($("f-driver").elements.link, moving.map(([n]) => n), true);
    options($("f-plate").elements.link, moving.filter(([, l]) => l.joints.length === 3).map(([n]) => n), true);
    $("f-plate").hidden = !moving.some(([, l]) => l.joints.length === 3);
    const drv = (doc.drivers || [])[0];
    const f = $("f-driver").elements;
    if (drv && document.activeElement.form !== $("f-driver")) {
      f.link.value = drv.link;
      if (drv.theta0 !== undefined) f.theta0.value = String(drv.theta0 * 180 / Math.PI);
      f.omega.value = String(drv.omega); f.alpha.value = String(drv.alpha || 0);
    }
    const tf = $("f-time").elements, tm = doc.time || {};
    if (document.activeElement.form !== $("f-time")) {
      const ts = tm.times;
      const [t0, t1, dt] = ts ? [ts[0], ts[ts.length - 1], ts.length > 1 ? ts[1] - ts[0] : 0] : [tm.start || 0, tm.stop, tm.step];
      tf.start.value = String(t0); if (t1 !== undefined) tf.stop.value = String(t1); if (dt) tf.step.value = String(dt);
    }
    const m = $("f-meta").elements;
    if (document.activeElement.form !== $("f-meta")) { m.name.value = doc.name || ""; m.units.value = doc.units || "m"; }
  }

  function showInfo(state) {
    const key = JSON.stringify([state.info, state.error]);
    if (key === ST.infoKey) return;
    ST.infoKey = key;
    const box = $("s-info");
    box.replaceChildren();
    const item = (key, text, cls) => { const s = document.createElement("span"); s.dataset.info = key; if (cls) s.className = cls; s.textContent = text; box.append(s); };
    const I = state.info;
    if (!I || !I.mobility) { item("draft", "draw pivots, pins and links, then set a driver"); return; }
    const m = I.mobility;
    item("mobility", `mobility M = 3(${m.L}−1) − 2·${m.J} = ${m.M}, drivers ${m.drivers}`);
    for (const lp of I.loops) item(`loop${lp.number}`, `loop ${lp.number} (${lp.label})${lp.branch ? `: ${lp.branch}` : lp.sigma !== null ? `: σ = ${lp.sigma > 0 ? "+" : "−"}1` : ""}`);
    for (const g of I.grashof) item(`grashof${g.loop}`, `loop ${g.loop}: ${g.class}`);
    for (const t of I.transmission) item(`transmission-${t.dyad}`, `transmission angle at ${t.dyad}: ${t.min.toFixed(1)}° to ${t.max.toFixed(1)}°`, t.min < 30 ? "bad" : "");
    if (I.health) item("health", `closure residual ≤ ${(I.health.residual || 0).toExponential(1)}, condition ≤ ${(I.health.cond || 0).toPrecision(3)}`);
    if (state.error) item("stop", `the motion stops: ${state.error}`, "bad");
  }

  function showCandidates(list) {
    ST.candidates = list;
    const box = $("s-candidates");
    box.replaceChildren();
    list.forEach((c, k) => {
      const d = document.createElement("div");
      d.className = "cand";
      d.dataset.candidate = String(k + 1);
      d.append(`${k + 1}. ${c.topology}, error ${c.error.toExponential(1)} of the size${c.grashof ? ", " + c.grashof : ""}${c.defects.length ? ", defects: " + c.defects.join("; ") : ", no defect"} `);
      const b = document.createElement("button");
      b.type = "button"; b.className = "chip"; b.textContent = "take"; b.dataset.take = String(k);
      b.addEventListener("click", () => { ST.keepView = false; send("take", { index: k }); });
      d.append(b);
      box.append(d);
    });
    status(`${list.length} candidates`);
    drawHandles();
  }

  function showVerdict(v) {
    const box = $("s-verdict");
    box.hidden = false;
    box.replaceChildren();
    const head = document.createElement("span");
    head.dataset.verdict = v.verdict;
    head.className = v.passed ? "ok" : "bad";
    head.textContent = v.passed ? "validated: Pinocchio and Exudyn agree with vloop" : `validation: ${v.verdict}${v.message ? " — " + v.message : ""}`;
    box.append(head);
    for (const e of v.engines) {
      const s = document.createElement("span");
      s.dataset.engine = e.engine;
      s.textContent = `${e.engine}: ${e.status}${e.comparison ? " (" + e.comparison + ")" : ""}`;
      box.append(s);
    }
    status(`check: ${v.verdict}`);
  }

  function wire() {
    for (const b of document.querySelectorAll(".s-tool")) b.addEventListener("click", () => {
      ST.tool = b.dataset.tool; ST.picked = [];
      for (const o of document.querySelectorAll(".s-tool")) o.setAttribute("aria-pressed", String(o === b));
      view().classList.toggle("s-placing", ["pivot", "joint", "target"].includes(ST.tool));
    });
    const v = view();
    v.addEventListener("pointermove", pointerMove, true);
    if (RAW) v.addEventListener("pointerrawupdate", pointerMove, true);
    v.addEventListener("pointerup", pointerUp, true);
    v.addEventListener("pointercancel", pointerUp, true);
    v.addEventListener("click", click);
    $("s-undo").addEventListener("click", () => send("undo"));
    $("s-redo").addEventListener("click", () => send("redo"));
    $("s-validate").addEventListener("click", () => { $("s-verdict").hidden = true; send("validate"); });
    document.addEventListener("keydown", (e) => {
      if (!(e.ctrlKey || e.metaKey) || e.target.tagName === "INPUT") return;
      if (e.key === "z") { e.preventDefault(); send("undo"); } else if (e.key === "y") { e.preventDefault(); send("redo"); }
    });
    const form = (id, fn) => $(id).addEventListener("submit", (e) => { e.preventDefault(); fn(e.target.elements, e.submitter); });
    const num = (el) => (el.value.trim() === "" ? null : Number(el.value));
    const showJoint = () => {
      const f = $("f-joint").elements, p = ST.state && ST.state.doc.joints[f.name.value];
      if (p) { f.x.value = String(p[0]); f.y.value = String(p[1]); }
    };
    $("f-joint").elements.name.addEventListener("change", showJoint);
    const showLength = () => {
      const f = $("f-length").elements, lk = ST.state && ST.state.doc.links[f.link.value];
      if (lk && lk.length !== undefined) f.namedItem("length").value = String(lk.length);
    };
    $("f-length").elements.link.addEventListener("change", showLength);
    form("f-joint", (f) => send("set_joint", { joint: f.name.value, x: num(f.x), y: num(f.y) }));
    form("f-length", (f) => send("set_length", { link: f.link.value, length: num(f.namedItem("length")) })); // f.length: the count
    form("f-driver", (f) => send("set_driver", { link: f.link.value, omega: num(f.omega), alpha: num(f.alpha) || 0,
      ...(num(f.theta0) === null ? {} : { theta0: num(f.theta0) * Math.PI / 180 }) }));
    form("f-plate", (f) => send("set_sides", { link: f.link.value, sides: [num(f.a), num(f.b)], angle: num(f.angle) * Math.PI / 180 }));
    form("f-time", (f) => send("set_time", { start: num(f.start), stop: num(f.stop), step: num(f.step) }));
    form("f-meta", (f) => send("set_meta", { name: f.name.value, units: f.units.value }));
    form("f-file", (f, by) => {
      const what = by ? by.value : "save";
      if (what === "export") send("export", { path: f.path.value.replace(/\.[a-z]+$/i, "") + "." + f.format.value, format: f.format.value, sample: VW().index || 0 }).then((r) => r.ok && status(`wrote ${r.path}`));
      else if (what === "open") { ST.keepView = false; send("open", { path: f.path.value }); }
      else send("save", { path: f.path.value }).then((r) => r.ok && status(`saved ${r.path}`));
    });
    form("f-catalog", (f, by) => { ST.keepView = false; ST.box = null; ST.candidates = []; send(by && by.value === "new" ? "new" : "open", by && by.value === "new" ? { units: $("f-meta").elements.units.value } : { catalog: f.catalog.value }); });
    $("f-synth").elements.kind.addEventListener("change", (e) => { $("f-synth").dataset.kind = e.target.value; });
    form("f-synth", (f, by) => {
      if (by && by.value === "clear") { ST.candidates = []; $("s-candidates").replaceChildren(); send("targets", { points: [] }); return; }
      const kind = f.kind.value, count = num(f.count) || 3, rad = (el) => num(el) * Math.PI / 180;
      if (kind === "function") {
        send("synthesize", { kind, count, expr: f.expr.value, x_range: [num(f.x0), num(f.x1)],
          input_range: [rad(f.i0), rad(f.i1)], output_range: [rad(f.o0), rad(f.o1)] });
      } else if (kind === "motion") {
        const angles = f.angles.value.split(",").map((a) => Number(a) * Math.PI / 180);
        send("synthesize", { kind, count, points: (ST.state.targets || []).map((p, k) => [p[0], p[1], angles[k]]) });
      } else send("synthesize", { kind, count, points: ST.state.targets });
    });
    $("s-view").addEventListener("click", (e) => {
      e.preventDefault();
      window.open(`/view?token=${encodeURIComponent($("studio").dataset.token)}`, "_blank", "noopener");
    });
  }

  async function start() {
    wire();
    if (window.vloopStudioTransport) $("s-view").hidden = true; // a notebook has no server page to open
    const files = await send("files");
    if (files.ok) {
      options($("f-catalog").elements.catalog, files.catalog);
      $("s-files").replaceChildren(...files.files.map((f) => { const o = document.createElement("option"); o.value = f; return o; }));
    }
    await send("state");
    status("ready");
  }
  window.vloopStudio = { send, stats: ST.stats, get state() { return ST.state; }, get tool() { return ST.tool; } };
  start();
})();
