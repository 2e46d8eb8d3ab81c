/* vloop viewer: draws a mechanism from the page's data (script#vloop-data) with plain SVG.
 * World coordinates (x, y) in the file's length unit are drawn at SVG (x, -y); a body's group
 * carries translate(x, -y) rotate(-θ) and its shapes in its own frame. No network, no library. */
(() => {
  "use strict";
  const NS = "http://www.w3.org/2000/svg";
  const DEG = 180 / Math.PI;
  const PALETTE = ["#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9", "var(--fg)"]; // Okabe–Ito
  const LOOP_COLORS = ["#E69F00", "#56B4E9", "#009E73", "#CC79A7", "#0072B2", "#D55E00", "var(--fg)"];
  const DASHES = ["", "7 4", "2 3", "9 3 2 3"];
  // the page's data; a host that edits the mechanism (the studio) hands a new one to vloopViewer.load
  const dataTag = document.getElementById("vloop-data");
  let D = dataTag && dataTag.textContent.trim() ? JSON.parse(dataTag.textContent) : null;
  const $ = (id) => document.getElementById(id);
  let U = D ? D.units : "";
  const SPEEDS = [0.01, 0.02, 0.05, 0.1, 0.25, 0.5, 1, 2, 5];
  const GAINS = [0.25, 0.5, 1, 2, 4, 8];
  const S = {
    i: 0, playing: false, clock: 0, last: null, speed: 1, repeat: true, zoomed: false, gain: 1, wired: false,
    over: { loops: true, vel: false, acc: false, paths: false, forces: false, labels: true },
    hiddenLoops: new Set(), numbersAt: 0, stats: { frames: 0, drawMs: new Float64Array(600), k: 0 },
  };
  let C = {}; // column name -> Float64Array over samples
  let T = null; // time [s]
  let N = 0;

  // ------------------------------------------------------------------ helpers

  function svg(tag, attrs, parent) {
    const e = document.createElementNS(NS, tag);
    for (const k in attrs) e.setAttribute(k, attrs[k]);
    if (parent) parent.appendChild(e);
    return e;
  }
  function html(tag, props, parent, text) {
    const e = document.createElement(tag);
    for (const k in props || {}) {
      if (k === "class") e.className = props[k];
      else e.setAttribute(k, props[k]);
    }
    if (text !== undefined) e.textContent = text;
    if (parent) parent.appendChild(e);
    return e;
  }
  const fontScale = () => (document.documentElement.classList.contains("large") ? 1.5 : 1);
  const seriesStyle = (k) => ({ color: PALETTE[k % PALETTE.length], dash: DASHES[Math.floor(k / PALETTE.length) % DASHES.length] });
  function fmt(x) {
    if (x === 0) return "0";
    const a = Math.abs(x);
    if (a >= 1e-3 && a < 1e7) return String(Number(x.toPrecision(9)));
    return x.toExponential(6);
  }
  // A value read against its quantity's scale (the run's peak of that kind of quantity): SIG significant
  // digits at the peak's decade, in fixed notation with the trailing zeros dropped; round-off below
  // ZERO of the peak shows as 0; a value too small for the fixed digits but above round-off keeps two.
  const SIG = 7, ZERO = 1e-12;
  function fmtScaled(x, scale) {
    const a = Math.abs(x);
    if (!(scale > 0) || !(a > ZERO * scale)) return "0";
    const top = Math.floor(Math.log10(scale));
    if (top < -4 || top >= 9) {
      const sig = Math.max(1, Math.min(SIG, SIG - (top - Math.floor(Math.log10(a)))));
      return x.toExponential(sig - 1).replace(/\.?0+e/, "e");
    }
    const dec = Math.max(0, SIG - 1 - top);
    let text = x.toFixed(dec);
    if (dec > 0) text = text.replace(/\.?0+$/, "");
    if (text === "0" || text === "-0") return x.toExponential(1).replace(/\.0e/, "e");
    return text;
  }
  function scaledWidth(scale) {
    // the longest text fmtScaled writes for this scale (characters): sign, digits, point, decimals or exponent
    if (!(scale > 0)) return 1;
    const top = Math.floor(Math.log10(scale));
    if (top < -4 || top >= 9) return SIG + 7;
    const dec = Math.max(0, SIG - 1 - top);
    return Math.max(1 + Math.max(top + 1, 1) + (dec ? 1 + dec : 0), 8);
  }
  // the kind of quantity a column holds; every column of a kind shares one scale
  function kindOf(col) {
    if (col.startsWith("force:")) return D.forces.units[col.slice(6)] === "N·m" ? "moment" : "force";
    if (col.startsWith("health.")) return col;
    const q = col.slice(col.lastIndexOf(".") + 1);
    return { x: "length", y: "length", s: "length", vx: "velocity", vy: "velocity", v: "velocity",
      ax: "acceleration", ay: "acceleration", a: "acceleration" }[q] || q;
  }
  let SCALES = null;
  function scaleOf(col) {
    if (!SCALES) {
      SCALES = {};
      for (const c of D.data.columns) {
        const k = kindOf(c), v = C[c];
        let m = SCALES[k] || 0;
        for (let i = 0; i < N; i++) { const a = Math.abs(v[i]); if (a > m) m = a; }
        SCALES[k] = m;
      }
    }
    return SCALES[kindOf(col)] || 0;
  }
  function fmtHealth(x) { return x === 0 ? "0" : Math.abs(x) >= 1e-3 && Math.abs(x) < 1e6 ? String(Number(x.toPrecision(3))) : x.toExponential(2); }
  function niceDown(x) {
    const m = Math.pow(10, Math.floor(Math.log10(x)));
    const f = x / m;
    return (f >= 5 ? 5 : f >= 2 ? 2 : 1) * m;
  }
  function nearestIndex(t) {
    let lo = 0, hi = N - 1;
    if (t <= T[0]) return 0;
    if (t >= T[hi]) return hi;
    while (hi - lo > 1) {
      const mid = (lo + hi) >> 1;
      if (T[mid] <= t) lo = mid; else hi = mid;
    }
    return t - T[lo] <= T[hi] - t ? lo : hi;
  }
  function floorIndex(t) {
    let lo = 0, hi = N - 1;
    if (t >= T[hi]) return hi;
    while (hi - lo > 1) {
      const mid = (lo + hi) >> 1;
      if (T[mid] <= t) lo = mid; else hi = mid;
    }
    return lo;
  }

  // ------------------------------------------------------------------ data

  async function decode(block) {
    const bin = atob(block.data);
    const bytes = new Uint8Array(bin.length);
    for (let i = 0; i < bin.length; i++) bytes[i] = bin.charCodeAt(i);
    if (block.encoding === "f64le-base64") return columnsOf(new Float64Array(bytes.buffer), block.columns); // a live host's frames: no deflate
    const stream = new Blob([bytes]).stream().pipeThrough(new DecompressionStream("deflate"));
    const shuffled = new Uint8Array(await new Response(stream).arrayBuffer());
    const count = shuffled.length >> 3;
    const raw = new Uint8Array(shuffled.length);
    for (let b = 0; b < 8; b++) {
      const off = b * count;
      for (let k = 0; k < count; k++) raw[8 * k + b] = shuffled[off + k];
    }
    return columnsOf(new Float64Array(raw.buffer), block.columns);
  }
  function columnsOf(values, names) {
    const n = values.length / names.length;
    const cols = {};
    names.forEach((name, k) => { cols[name] = values.subarray(k * n, (k + 1) * n); });
    return cols;
  }
  const X = (p, i) => C[p + ".x"][i];
  const Y = (p, i) => C[p + ".y"][i];
  function pose(body, i) {
    if (body.kind === "ground") return [0, 0, 0];
    return [X(body.origin, i), Y(body.origin, i), C[body.name + ".theta"][i]];
  }
  function loopVertices(lp, i) {
    let x = 0, y = 0;
    if (lp.start) { x = X(lp.start, i); y = Y(lp.start, i); }
    const out = [[x, y]];
    for (const v of lp.vectors) {
      const m = v.r + (v.slider ? C[v.slider + ".s"][i] : 0);
      const a = (v.link ? C[v.link + ".theta"][i] : 0) + v.delta;
      x += m * Math.cos(a);
      y += m * Math.sin(a);
      out.push([x, y]);
    }
    return out;
  }

  // ------------------------------------------------------------------ the drawing

  const V = { svg: $("view"), layers: {}, upp: 1, box: null, bodies: [], pins: [], labels: [], linkLabels: [], loops: [],
    vel: [], acc: [], forces: [], kv: 1, ka: 1, kf: 1 };

  function layer(name) {
    V.layers[name] = svg("g", { class: "layer-" + name, "data-layer": name }, V.svg);
    return V.layers[name];
  }

  function buildScene() {
    // paths over the links' plates (a coupler curve runs across a ternary link), under the pins
    ["ground", "bodies", "blocks", "paths", "pins", "loops", "vel", "acc", "forces", "labels"].forEach(layer);
    buildGround();
    buildBodies();
    buildPins();
    buildLoops();
    buildArrows();
    buildPaths();
    computeArrowScales();
  }

  function buildGround() {
    const g = V.layers.ground;
    const h = 0.045 * D.scale;
    let hatch = "";
    for (const j of D.joints) {
      if (!j.ground) continue;
      const x = X(j.name, 0), y = -Y(j.name, 0);
      svg("polygon", { class: "v-pivot ns", "stroke-width": 1.5,
        points: `${x},${y} ${x - 0.6 * h},${y + h} ${x + 0.6 * h},${y + h}` }, g);
      hatch += `M${x - 0.9 * h} ${y + h}L${x + 0.9 * h} ${y + h}`;
      for (let k = 0; k < 5; k++) {
        const x0 = x - 0.8 * h + k * 0.4 * h;
        hatch += `M${x0} ${y + h}L${x0 - 0.3 * h} ${y + 1.35 * h}`;
      }
    }
    for (const s of D.sliders) {
      if (!s.ground) continue;
      const [ux, uy] = s.axis, nx = -uy, ny = ux, off = -D.block[1] / 2;
      const [a, b] = s.ends.map(([px, py]) => [px + off * nx, py + off * ny]);
      svg("line", { class: "v-rail ns", x1: a[0], y1: -a[1], x2: b[0], y2: -b[1], "data-rail": s.name }, g);
      const len = Math.hypot(b[0] - a[0], b[1] - a[1]), step = 0.025 * D.scale, tick = 0.022 * D.scale;
      for (let t = step / 2; t < len; t += step) {
        const px = a[0] + ux * t, py = a[1] + uy * t;
        hatch += `M${px} ${-py}L${px - (nx + 0.6 * ux) * tick} ${-(py - (ny + 0.6 * uy) * tick)}`; // away from the block
      }
    }
    if (hatch) svg("path", { class: "v-ground ns", "stroke-width": 1.2, d: hatch }, g);
    const usesOrigin = D.loops.some((lp) => !lp.start);
    const atOrigin = D.points.some((p) => Math.hypot(X(p, 0), Y(p, 0)) < 1e-9 * D.scale);
    if (usesOrigin && !atOrigin) {
      const r = 0.03 * D.scale;
      svg("path", { class: "v-origin ns", "stroke-width": 1.5, d: `M${-r} 0L${r} 0M0 ${-r}L0 ${r}` }, g);
      V.labels.push({ el: svg("text", { class: "v-label", "text-anchor": "middle", "dominant-baseline": "central" }, V.layers.labels), fixed: [0, 0], dir: [-0.7, -0.7], text: "O" });
    }
  }

  function buildBodies() {
    const sliders = Object.fromEntries(D.sliders.map((s) => [s.name, s]));
    // slotted links first: what runs in or across a slot is drawn over it
    const order = [...D.bodies].sort((a, b) => (b.slots || []).length - (a.slots || []).length);
    for (const b of order) {
      if (b.kind === "ground") continue;
      const parent = b.kind === "block" ? V.layers.blocks : V.layers.bodies;
      const g = svg("g", { "data-body": b.name }, parent);
      if (b.kind === "block") {
        const [w, h] = D.block;
        svg("rect", { class: "v-block ns", "stroke-width": 1.5, x: -w / 2, y: -h / 2, width: w, height: h, rx: h * 0.12 }, g);
      } else {
        const o = b.outline;
        if (o.length >= 3) svg("polygon", { class: "v-plate ns", "stroke-width": 2, points: o.map(([x, y]) => `${x},${-y}`).join(" ") }, g);
        else if (o.length === 2) svg("line", { class: "v-bar ns", "stroke-width": 9, x1: o[0][0], y1: -o[0][1], x2: o[1][0], y2: -o[1][1] }, g);
        for (const name of b.slots) {
          const [[x1, y1], [x2, y2]] = sliders[name].ends;
          const a = { x1, y1: -y1, x2, y2: -y2 };
          svg("line", Object.assign({ class: "v-slot-edge ns", "stroke-width": 13 }, a), g);
          svg("line", Object.assign({ class: "v-slot ns", "stroke-width": 8, "data-slot": name }, a), g);
        }
        if (b.label) {
          const t = svg("text", { class: "v-link-label", "text-anchor": "middle", "dominant-baseline": "central", "data-link": b.name }, V.layers.labels);
          t.textContent = b.name;
          V.linkLabels.push({ el: t, body: b });
        }
      }
      V.bodies.push({ g, body: b });
    }
  }

  function buildPins() {
    for (const j of D.joints) {
      const c = svg("circle", { class: (j.kind === "pin" ? "v-pin" : "v-point") + " ns", "stroke-width": 2, "data-joint": j.name }, V.layers.pins);
      V.pins.push({ el: c, name: j.name, kind: j.kind });
      const t = svg("text", { class: "v-label", "text-anchor": "middle", "dominant-baseline": "central", "data-label": j.name }, V.layers.labels);
      V.labels.push({ el: t, point: j.name, dir: D.labels[j.name], text: j.name });
    }
    for (const l of V.labels) l.el.textContent = l.text;
  }

  function buildLoops() {
    D.loops.forEach((lp, k) => {
      const color = LOOP_COLORS[k % LOOP_COLORS.length];
      const g = svg("g", { "data-loop": lp.number }, V.layers.loops);
      g.style.color = color;
      const arrows = lp.vectors.map((v) => {
        const p = svg("path", { class: "v-arrow ns", "stroke-width": 2.6, "data-vector": v.letter }, g);
        p.style.stroke = color; p.style.fill = color;
        const t = svg("text", { class: "v-letter", "text-anchor": "middle", "dominant-baseline": "central" }, g);
        t.style.fill = color;
        t.textContent = v.letter;
        return { path: p, text: t };
      });
      const badge = svg("g", { class: "v-badge" }, g);
      const circle = svg("circle", {}, badge);
      circle.style.fill = color;
      const num = svg("text", { class: "v-badge-text", "text-anchor": "middle", "dominant-baseline": "central" }, badge);
      num.textContent = String(lp.number);
      V.loops.push({ lp, g, arrows, circle, num, color });
    });
  }

  function buildArrows() {
    for (const p of D.points) {
      const moves = (q) => C[p + "." + q].some((v) => v !== 0);
      if (moves("vx") || moves("vy")) V.vel.push({ point: p, el: svg("path", { class: "v-arrow v-vel ns", "stroke-width": 2, "data-point": p }, V.layers.vel) });
      if (moves("ax") || moves("ay")) V.acc.push({ point: p, el: svg("path", { class: "v-arrow v-acc ns", "stroke-width": 2, "data-point": p }, V.layers.acc) });
    }
    if (!D.forces) return;
    for (const [point, fx, fy, label] of D.forces.arrows) {
      const el = svg("path", { class: "v-arrow v-force ns", "stroke-width": 2.2, "data-point": point, "data-force": label }, V.layers.forces);
      const text = svg("text", { class: "v-force-label", "dominant-baseline": "central" }, V.layers.forces);
      text.textContent = label;
      V.forces.push({ point, fx: C["force:" + fx], fy: C["force:" + fy], el, text });
    }
  }

  function buildPaths() {
    const stride = Math.max(1, Math.ceil(N / 2000)); // drawing only: the numbers use every sample
    const tracers = new Set(D.tracers);
    for (const p of D.points) {
      const xs = C[p + ".x"], ys = C[p + ".y"];
      let moved = 0;
      for (let i = 0; i < N; i++) moved = Math.max(moved, Math.hypot(xs[i] - xs[0], ys[i] - ys[0]));
      if (moved <= 1e-9 * D.scale) continue;
      let d = "";
      for (let i = 0; i < N; i += stride) d += (d ? "L" : "M") + xs[i] + " " + -ys[i];
      d += "L" + xs[N - 1] + " " + -ys[N - 1];
      svg("path", { class: "v-path ns" + (tracers.has(p) ? " tracer" : ""), "stroke-width": tracers.has(p) ? 2 : 1.3, d, "data-path": p }, V.layers.paths);
    }
    buildTargets();
  }

  function buildTargets() {
    // a synthesis's targets: a cross at each point, a tick along the body's angle for a pose, its number
    const r = 0.025 * D.scale;
    (D.targets || []).forEach((t, k) => {
      let d = `M${t.x - r} ${-(t.y - r)}L${t.x + r} ${-(t.y + r)}M${t.x - r} ${-(t.y + r)}L${t.x + r} ${-(t.y - r)}`;
      if (t.angle !== undefined) d += `M${t.x} ${-t.y}L${t.x + 3 * r * Math.cos(t.angle)} ${-(t.y + 3 * r * Math.sin(t.angle))}`;
      svg("path", { class: "v-target ns", "stroke-width": 2, d, "data-target": k + 1 }, V.layers.paths);
      V.labels.push({ el: svg("text", { class: "v-label v-target-label", "text-anchor": "middle", "dominant-baseline": "central" }, V.layers.labels), fixed: [t.x, t.y], dir: [0.7, 0.7], text: String(k + 1) });
    });
    for (const l of V.labels) l.el.textContent = l.text;
  }

  function maxNorm(ax, ay) {
    let m = 0;
    for (let i = 0; i < N; i++) m = Math.max(m, Math.hypot(ax[i], ay[i]));
    return m;
  }
  function computeArrowScales() {
    // the longest arrow of the run is a quarter of the mechanism's size
    const peak = (list, a, b) => Math.max(0, ...list.map((e) => (e.fx ? maxNorm(e.fx, e.fy) : maxNorm(C[e.point + a], C[e.point + b]))));
    const vmax = peak(V.vel, ".vx", ".vy"), amax = peak(V.acc, ".ax", ".ay"), fmax = peak(V.forces);
    // S.gain: the reader's arrow scale (the select beside the overlays), the same for every kind
    V.kv = S.gain * (vmax > 0 ? 0.25 * D.scale / vmax : 1);
    V.ka = S.gain * (amax > 0 ? 0.25 * D.scale / amax : 1);
    V.kf = S.gain * (fmax > 0 ? 0.25 * D.scale / fmax : 1);
    V.peaks = { vel: vmax, acc: amax, forces: fmax };
  }

  function arrowPath(x1, y1, x2, y2) {
    const dx = x2 - x1, dy = y2 - y1, len = Math.hypot(dx, dy);
    if (!(len > 1e-9 * D.scale)) return "";
    const hl = Math.min(11 * V.upp, 0.45 * len), hw = 0.42 * hl, ux = dx / len, uy = dy / len;
    const bx = x2 - ux * hl, by = y2 - uy * hl;
    // SVG y is down: the shaft, then a closed head with its tip at (x2, y2)
    return `M${x1} ${-y1}L${bx} ${-by}M${bx - uy * hw} ${-(by + ux * hw)}L${x2} ${-y2}L${bx + uy * hw} ${-(by - ux * hw)}Z`;
  }

  // ------------------------------------------------------------------ per frame

  function draw(i) {
    const t0 = performance.now();
    for (const { g, body } of V.bodies) {
      const [x, y, th] = pose(body, i);
      g.setAttribute("transform", `translate(${x} ${-y}) rotate(${-th * DEG})`);
    }
    for (const p of V.pins) {
      p.el.setAttribute("cx", X(p.name, i));
      p.el.setAttribute("cy", -Y(p.name, i));
    }
    if (S.over.labels) drawLabels(i);
    if (S.over.loops) drawLoops(i);
    if (S.over.vel) drawPointArrows(V.vel, ".vx", ".vy", V.kv, i);
    if (S.over.acc) drawPointArrows(V.acc, ".ax", ".ay", V.ka, i);
    if (S.over.forces) drawForces(i);
    const ms = performance.now() - t0;
    S.stats.drawMs[S.stats.k++ % S.stats.drawMs.length] = ms;
  }

  function drawLabels(i) {
    const off = 15 * V.upp * fontScale();
    for (const l of V.labels) {
      const [x, y] = l.fixed || [X(l.point, i), Y(l.point, i)];
      l.el.setAttribute("x", x + l.dir[0] * off);
      l.el.setAttribute("y", -(y + l.dir[1] * off));
    }
    for (const l of V.linkLabels) {
      const [x, y, th] = pose(l.body, i), [lx, ly] = l.body.label, c = Math.cos(th), s = Math.sin(th);
      l.el.setAttribute("x", x + c * lx - s * ly);
      l.el.setAttribute("y", -(y + s * lx + c * ly));
    }
  }

  function drawLoops(i) {
    const off = 9 * V.upp * fontScale();
    for (const L of V.loops) {
      if (S.hiddenLoops.has(L.lp.number)) continue;
      const vs = loopVertices(L.lp, i);
      let cx = 0, cy = 0;
      L.arrows.forEach((a, k) => {
        const [x1, y1] = vs[k], [x2, y2] = vs[k + 1];
        a.path.setAttribute("d", arrowPath(x1, y1, x2, y2));
        const len = Math.hypot(x2 - x1, y2 - y1) || 1;
        // the letter sits to the left of its arrow, at its middle
        a.text.setAttribute("x", (x1 + x2) / 2 - ((y2 - y1) / len) * off);
        a.text.setAttribute("y", -((y1 + y2) / 2 + ((x2 - x1) / len) * off));
        a.text.setAttribute("visibility", len > 1e-9 * D.scale ? "visible" : "hidden");
        cx += x1; cy += y1;
      });
      const m = Math.max(L.arrows.length, 1);
      L.circle.setAttribute("cx", cx / m); L.circle.setAttribute("cy", -cy / m);
      L.num.setAttribute("x", cx / m); L.num.setAttribute("y", -cy / m);
    }
  }

  function drawPointArrows(list, a, b, k, i) {
    for (const e of list) {
      const x = X(e.point, i), y = Y(e.point, i);
      e.el.setAttribute("d", arrowPath(x, y, x + k * C[e.point + a][i], y + k * C[e.point + b][i]));
    }
  }

  function drawForces(i) {
    const off = 6 * V.upp;
    for (const f of V.forces) {
      const x = X(f.point, i), y = Y(f.point, i), x2 = x + V.kf * f.fx[i], y2 = y + V.kf * f.fy[i];
      f.el.setAttribute("d", arrowPath(x, y, x2, y2));
      f.text.setAttribute("x", x2 + off);
      f.text.setAttribute("y", -y2 - off);
    }
  }

  // sizes that stay constant on screen: pins, text, arrow heads
  function resize() {
    const r = V.svg.getBoundingClientRect();
    if (!r.width || !r.height || !V.box) return;
    const [, , w, h] = V.box;
    V.upp = Math.max(w / r.width, h / r.height);
    const fs = fontScale();
    for (const p of V.pins) p.el.setAttribute("r", (p.kind === "pin" ? 5.5 : 3.8) * V.upp * fs);
    V.layers.labels.setAttribute("font-size", 14 * V.upp * fs);
    V.layers.labels.setAttribute("stroke-width", 3.5 * V.upp * fs);
    V.layers.loops.setAttribute("font-size", 15 * V.upp * fs);
    V.layers.loops.setAttribute("stroke-width", 3 * V.upp * fs);
    V.layers.forces.setAttribute("font-size", 12 * V.upp * fs);
    V.layers.forces.setAttribute("stroke-width", 3 * V.upp * fs);
    for (const L of V.loops) {
      L.circle.setAttribute("r", 10 * V.upp * fs);
      L.num.setAttribute("font-size", 12 * V.upp * fs);
      L.num.setAttribute("stroke-width", 0);
    }
    draw(S.i);
    drawScaleLegend();
  }

  function setBox(box) {
    V.box = box;
    V.svg.setAttribute("viewBox", box.join(" "));
    resize();
  }

  function fit() {
    let x0 = Infinity, x1 = -Infinity, y0 = Infinity, y1 = -Infinity;
    const take = (x, y) => { x0 = Math.min(x0, x); x1 = Math.max(x1, x); y0 = Math.min(y0, y); y1 = Math.max(y1, y); };
    for (const p of D.points) {
      const xs = C[p + ".x"], ys = C[p + ".y"];
      for (let i = 0; i < N; i++) take(xs[i], ys[i]);
    }
    for (const s of D.sliders) if (s.ground) s.ends.forEach(([x, y]) => take(x, y));
    for (const j of D.joints) if (j.ground) take(X(j.name, 0), Y(j.name, 0) - 0.07 * D.scale);
    for (const t of D.targets || []) take(t.x, t.y);
    const grow = (list, k, fx, fy) => {
      for (const e of list) {
        const ax = fx(e), ay = fy(e);
        for (let i = 0; i < N; i++) take(X(e.point, i) + k * ax[i], Y(e.point, i) + k * ay[i]);
      }
    };
    if (S.over.vel) grow(V.vel, V.kv, (e) => C[e.point + ".vx"], (e) => C[e.point + ".vy"]);
    if (S.over.acc) grow(V.acc, V.ka, (e) => C[e.point + ".ax"], (e) => C[e.point + ".ay"]);
    if (S.over.forces) grow(V.forces, V.kf, (e) => e.fx, (e) => e.fy);
    const m = 0.08 * Math.max(D.scale, x1 - x0, y1 - y0);
    setBox([x0 - m, -(y1 + m), x1 - x0 + 2 * m, y1 - y0 + 2 * m]);
    S.zoomed = false;
  }

  function drawScaleLegend() {
    const host = $("scale-legend");
    host.replaceChildren();
    const items = [
      ["vel", "velocity", V.kv, V.peaks.vel, `${U}/s`],
      ["acc", "acceleration", V.ka, V.peaks.acc, `${U}/s²`],
      ["forces", "reaction", V.kf, V.peaks.forces, "N"],
    ];
    for (const [key, name, k, peak, unit] of items) {
      if (!S.over[key] || !(peak > 0)) continue;
      const value = niceDown(0.5 * peak);
      const px = Math.max(8, (value * k) / V.upp);
      const row = html("div", { class: "row", "data-scale-for": key, "data-scale": k }, host);
      const s = svg("svg", { width: px + 4, height: 12 }, row);
      const p = svg("path", { d: `M0 6L${px - 7} 6M${px - 8} 1.5L${px} 6L${px - 8} 10.5Z`, "stroke-width": 2 }, s);
      p.setAttribute("class", "v-" + (key === "forces" ? "force" : key));
      html("span", {}, row, `${name}: ${fmt(value)} ${unit}`);
    }
  }

  // zoom with the wheel, pan by dragging, double-click to fit
  function wireView() {
    const toWorld = (ev) => {
      const m = V.svg.getScreenCTM().inverse();
      const p = new DOMPoint(ev.clientX, ev.clientY).matrixTransform(m);
      return [p.x, p.y];
    };
    V.svg.addEventListener("wheel", (ev) => {
      ev.preventDefault();
      if (!V.box) return;
      const [px, py] = toWorld(ev), f = Math.exp(Math.max(-0.5, Math.min(0.5, ev.deltaY * 0.0015)));
      const [x, y, w, h] = V.box;
      setBox([px - (px - x) * f, py - (py - y) * f, w * f, h * f]);
      S.zoomed = true;
    }, { passive: false });
    let drag = null;
    V.svg.addEventListener("pointerdown", (ev) => {
      if (!V.box) return;
      drag = { x: ev.clientX, y: ev.clientY, box: V.box.slice() };
      V.svg.setPointerCapture(ev.pointerId);
      V.svg.classList.add("dragging");
    });
    V.svg.addEventListener("pointermove", (ev) => {
      if (!drag) return;
      const [x, y, w, h] = drag.box;
      setBox([x - (ev.clientX - drag.x) * V.upp, y - (ev.clientY - drag.y) * V.upp, w, h]);
      S.zoomed = true;
    });
    const end = () => { drag = null; V.svg.classList.remove("dragging"); };
    V.svg.addEventListener("pointerup", end);
    V.svg.addEventListener("pointercancel", end);
    V.svg.addEventListener("dblclick", () => D && fit());
    $("fit").addEventListener("click", fit);
  }

  // ------------------------------------------------------------------ loop legend (equations)

  function equationNodes(text, parent) {
    // "a·e^{jθ_l2} + …" -> a·e<sup>jθ<sub>l2</sub></sup> + …
    const re = /e\^\{([^{}]*)\}/g;
    let at = 0, m;
    while ((m = re.exec(text))) {
      parent.append(text.slice(at, m.index) + "e");
      const sup = html("sup", {}, parent);
      const parts = m[1].split(/θ_([A-Za-z0-9_-]+)/);
      parts.forEach((part, k) => {
        if (k % 2) { sup.append("θ"); html("sub", {}, sup, part); } else if (part) sup.append(part);
      });
      at = re.lastIndex;
    }
    parent.append(text.slice(at));
  }

  function buildLoopLegend() {
    const box = $("loop-legend");
    box.replaceChildren();
    V.loops.forEach((L) => {
      const row = html("div", { class: "row", "data-loop": L.lp.number }, box);
      const num = html("span", { class: "num" }, row, `${L.lp.number}`);
      num.style.color = L.color;
      html("span", { class: "muted" }, row, `(${L.lp.label})`);
      equationNodes(L.lp.equation, html("span", { class: "eq" }, row));
    });
    const panel = html("details", { id: "loop-details" });
    $("overlays").after(panel);
    html("summary", {}, panel, "vector loops: show / hide each loop, what each letter stands for");
    const line = html("div", { class: "plot-legend" }, panel);
    V.loops.forEach((L) => {
      const b = html("button", { type: "button", "aria-pressed": String(!S.hiddenLoops.has(L.lp.number)), "data-loop-toggle": L.lp.number }, line);
      html("span", { class: "swl" }, b).style.borderColor = L.color;
      b.append(`loop ${L.lp.number} (${L.lp.label})`);
      if (S.hiddenLoops.has(L.lp.number)) { L.g.setAttribute("display", "none"); box.querySelector(`[data-loop="${L.lp.number}"]`).hidden = true; }
      b.addEventListener("click", () => {
        const n = L.lp.number, hide = !S.hiddenLoops.has(n);
        if (hide) S.hiddenLoops.add(n); else S.hiddenLoops.delete(n);
        b.setAttribute("aria-pressed", String(!hide));
        L.g.setAttribute("display", hide ? "none" : "inline");
        box.querySelector(`[data-loop="${n}"]`).hidden = hide;
        draw(S.i);
      });
    });
    const where = html("div", { class: "where eq" }, panel);
    for (const l of D.legend) html("div", {}, where, l);
  }

  // ------------------------------------------------------------------ plots

  function ticks(lo, hi, count) {
    const span = hi - lo;
    const raw = span / count, m = Math.pow(10, Math.floor(Math.log10(raw))), f = raw / m;
    const step = (f < 1.5 ? 1 : f < 3.5 ? 2 : f < 7.5 ? 5 : 10) * m;
    const out = [];
    for (let v = Math.ceil(lo / step) * step; v <= hi + step * 1e-9; v += step) out.push(Math.abs(v) < step * 1e-9 ? 0 : v);
    const dec = Math.max(0, -Math.floor(Math.log10(step) + 1e-9));
    const label = (v) => (step >= 1e-4 && Math.abs(v) < 1e6 ? v.toFixed(Math.min(dec, 8)) : v.toExponential(1));
    return out.map((v) => [v, label(v)]);
  }

  function curvePath(values, sx, sy, wrap) {
    // every sample when they fit; otherwise first/min/max/last per pixel column (drawing only)
    const n = values.length;
    const idx = [];
    if (n <= 4000) for (let i = 0; i < n; i++) idx.push(i);
    else {
      let col = null, first = 0, lo = 0, hi = 0, last = 0;
      const flush = () => { for (const k of [...new Set([first, lo, hi, last])].sort((a, b) => a - b)) idx.push(k); };
      for (let i = 0; i < n; i++) {
        const c = Math.floor(sx(T[i]));
        if (c !== col) { if (col !== null) flush(); col = c; first = lo = hi = i; }
        last = i;
        if (values[i] < values[lo]) lo = i;
        if (values[i] > values[hi]) hi = i;
      }
      flush();
    }
    let d = "", prev = null;
    for (const i of idx) {
      const jump = wrap && prev !== null && Math.abs(values[i] - values[prev]) > Math.PI; // a wrapped angle's seam
      d += (d && !jump ? "L" : "M") + sx(T[i]).toFixed(2) + " " + sy(values[i]).toFixed(2);
      prev = i;
    }
    return d;
  }

  let plots = [];

  class Plot {
    constructor(host, spec) {
      this.spec = spec;
      this.host = html("div", { class: "plot", "data-plot": spec.key }, host);
      this.svg = svg("svg", { role: "img", "aria-label": `${spec.title} [${spec.unit}] against time` }, this.host);
      this.tip = html("div", { class: "tooltip", hidden: "" }, this.host);
      this.svg.addEventListener("mousemove", (ev) => this.hover(ev));
      this.svg.addEventListener("mouseleave", () => { this.tip.hidden = true; if (this.hoverLine) this.hoverLine.setAttribute("visibility", "hidden"); });
      this.svg.addEventListener("click", (ev) => { pause(); setIndex(this.indexAt(ev)); });
    }
    visible() { return this.spec.series.filter((s) => !s.group.hidden.has(s.name)); }
    render(width) {
      // width: the plots' column, measured once for every plot (reading it per plot would lay the page out again
      // after each one)
      const fs = fontScale(), W = width || this.host.clientWidth;
      if (!W) return;
      const H = Math.round(150 * (0.5 + 0.5 * fs));
      const m = { l: 62 * fs, r: 10, t: 20 * fs, b: 22 * fs };
      this.m = m; this.W = W;
      this.svg.setAttribute("viewBox", `0 0 ${W} ${H}`);
      this.svg.setAttribute("height", H);
      this.svg.replaceChildren();
      const series = this.visible();
      let lo = Infinity, hi = -Infinity;
      const vals = (s) => s.plot || s.values;
      for (const s of series) { const v = vals(s); for (let i = 0; i < N; i++) { lo = Math.min(lo, v[i]); hi = Math.max(hi, v[i]); } }
      if (!isFinite(lo)) { lo = -1; hi = 1; }
      if (hi - lo <= 1e-12 * Math.max(1, Math.abs(hi))) { const c = (hi + lo) / 2, d = Math.max(Math.abs(c) * 0.1, 1e-9); lo = c - d; hi = c + d; }
      const pad = 0.06 * (hi - lo); lo -= pad; hi += pad;
      const t0 = T[0], t1 = N > 1 ? T[N - 1] : T[0] + 1;
      const sx = (t) => m.l + ((t - t0) / (t1 - t0)) * (W - m.l - m.r);
      const sy = (v) => m.t + ((hi - v) / (hi - lo)) * (H - m.t - m.b);
      this.sx = sx; this.t0 = t0; this.t1 = t1;
      const font = 11 * fs;
      for (const [v, label] of ticks(lo, hi, 4)) {
        svg("line", { class: "grid", x1: m.l, x2: W - m.r, y1: sy(v), y2: sy(v) }, this.svg);
        svg("text", { class: "tick", x: m.l - 4, y: sy(v), "text-anchor": "end", "dominant-baseline": "central", "font-size": font }, this.svg).textContent = label;
      }
      for (const [v, label] of ticks(t0, t1, Math.max(2, Math.floor((W - m.l) / (70 * fs))))) {
        svg("line", { class: "axis", x1: sx(v), x2: sx(v), y1: H - m.b, y2: H - m.b + 4 }, this.svg);
        svg("text", { class: "tick", x: sx(v), y: H - m.b + 6, "text-anchor": "middle", "dominant-baseline": "hanging", "font-size": font }, this.svg).textContent = label;
      }
      svg("line", { class: "axis", x1: m.l, x2: W - m.r, y1: H - m.b, y2: H - m.b }, this.svg);
      svg("line", { class: "axis", x1: m.l, x2: m.l, y1: m.t, y2: H - m.b }, this.svg);
      svg("text", { class: "ylabel", x: m.l + 4, y: 2, "dominant-baseline": "hanging", "font-size": font * 1.1 }, this.svg).textContent = `${this.spec.title} [${this.spec.unit}]`;
      svg("text", { class: "tick", x: W - m.r, y: 2, "text-anchor": "end", "dominant-baseline": "hanging", "font-size": font }, this.svg).textContent = "t [s]";
      for (const s of series) {
        const p = svg("path", { class: "curve", d: curvePath(vals(s), sx, sy, this.spec.wrap), "data-series": s.name }, this.svg);
        p.style.stroke = s.style.color;
        if (s.style.dash) p.setAttribute("stroke-dasharray", s.style.dash);
        if (N === 1) svg("circle", { cx: sx(T[0]), cy: sy(vals(s)[0]), r: 3.5 * fs }, this.svg).style.fill = s.style.color;
      }
      this.hoverLine = svg("line", { class: "hover", y1: m.t, y2: H - m.b, visibility: "hidden" }, this.svg);
      // the cursor is an HTML element moved by a transform: moving it repaints no curve
      if (!this.cursor) this.cursor = html("div", { class: "cursor" }, this.host);
      this.cursor.style.top = `${m.t - 4}px`;
      this.cursor.style.height = `${H - m.b - m.t + 4}px`;
      this.setCursor(S.i);
    }
    setCursor(i) {
      if (!this.cursor || !this.sx) return;
      const x = this.sx(T[i]);
      this.cursor.style.transform = `translateX(${x - 0.75}px)`;
      this.cursor.dataset.x = String(x);
      this.cursor.dataset.index = String(i);
    }
    indexAt(ev) {
      const r = this.svg.getBoundingClientRect();
      const x = ((ev.clientX - r.left) / r.width) * this.W;
      const t = this.t0 + ((x - this.m.l) / (this.W - this.m.l - this.m.r)) * (this.t1 - this.t0);
      return nearestIndex(t);
    }
    hover(ev) {
      const i = this.indexAt(ev), x = this.sx(T[i]);
      this.hoverLine.setAttribute("x1", x); this.hoverLine.setAttribute("x2", x);
      this.hoverLine.setAttribute("visibility", "visible");
      this.tip.replaceChildren();
      html("div", { class: "mono" }, this.tip, `t = ${fmt(T[i])} s`);
      for (const s of this.visible()) {
        const row = html("div", {}, this.tip);
        html("span", { class: "swl" }, row).style.borderColor = s.style.color;
        row.append(`${s.name}: `);
        html("span", { class: "mono" }, row, `${fmtScaled(s.values[i], s.scale)} ${this.spec.unit}`);
      }
      this.tip.hidden = false;
      const r = this.svg.getBoundingClientRect(), px = ev.clientX - r.left;
      const w = this.tip.offsetWidth;
      this.tip.style.left = `${px + 14 + w > r.width ? px - 14 - w : px + 14}px`;
    }
  }

  // Series of a group that coincide in every plot of it (within COINCIDE of the plot's range at every
  // sample; the eight-bar's mirror sliders l6 and l8): index of a later series -> the earlier one it lies on.
  const COINCIDE = 0.005;
  function coincident(names, quantities) {
    const col = (n, q) => C[n.column || `${n}.${q}`];
    const out = {};
    const ranges = quantities.map(([q]) => {
      let lo = Infinity, hi = -Infinity;
      for (const n of names) for (const v of col(n, q)) { lo = Math.min(lo, v); hi = Math.max(hi, v); }
      return hi - lo;
    });
    names.forEach((b, m) => {
      for (let k = 0; k < m && !(m in out); k++) {
        const same = quantities.every(([q], j) => {
          const x = col(names[k], q), y = col(b, q), tol = COINCIDE * ranges[j];
          for (let i = 0; i < N; i++) if (!(Math.abs(x[i] - y[i]) <= tol)) return false;
          return true;
        });
        if (same) out[m] = k;
      }
    });
    return out;
  }

  function plotGroup(title, names, quantities) {
    if (!names.length) return;
    const host = html("div", { class: "plot-group", "data-group": title }, $("plots"));
    html("h2", {}, host, title);
    S.hiddenSeries = S.hiddenSeries || {};
    const group = { hidden: (S.hiddenSeries[title] = S.hiddenSeries[title] || new Set()), plots: [] };
    const legend = html("div", { class: "plot-legend" }, host);
    const on = coincident(names, quantities);
    const label = (n) => n.label || n;
    // a series lying on an earlier one is dashed over it, so both show
    const style = (k) => (k in on ? { color: seriesStyle(k).color, dash: DASHES[1 + (Object.keys(on).indexOf(String(k)) % (DASHES.length - 1))] } : seriesStyle(k));
    const series = (q, wrap) => names.map((n, k) => {
      const col = n.column || `${n}.${q}`;
      return { name: label(n), col, values: C[col], plot: wrap ? wrapped(C[col]) : null, scale: scaleOf(col), style: style(k), group };
    });
    names.forEach((n, k) => {
      const name = label(n);
      const b = html("button", { type: "button", "aria-pressed": String(!group.hidden.has(name)), "data-series-toggle": name }, legend);
      const sw = html("span", { class: "swl" }, b);
      sw.style.borderColor = style(k).color;
      if (k in on) { sw.style.borderTopStyle = "dashed"; b.dataset.coincides = label(names[on[k]]); }
      b.append(k in on ? `${name} (= ${label(names[on[k]])})` : name);
      b.addEventListener("click", () => {
        const hide = !group.hidden.has(name);
        if (hide) group.hidden.add(name); else group.hidden.delete(name);
        b.setAttribute("aria-pressed", String(!hide));
        group.plots.forEach((p) => p.render());
      });
    });
    if (names.length === 1) legend.hidden = true;
    for (const [q, symbol, unit, wrapAngles] of quantities) {
      // a crank's θ grows by 2π a turn and would squash every other curve: angles that travel more than a
      // turn are drawn wrapped to (−π, π] (the tooltip and the numbers keep the unwrapped value)
      const wrap = wrapAngles && names.some((n) => span(C[n.column || `${n}.${q}`]) > 2 * Math.PI);
      const p = new Plot(host, { key: `${title}:${q}`, title: wrap ? `${symbol} (wrapped to ±π)` : symbol, unit, series: series(q, wrap), wrap });
      group.plots.push(p);
      plots.push(p);
    }
  }

  function span(v) {
    let lo = Infinity, hi = -Infinity;
    for (const x of v) { if (x < lo) lo = x; if (x > hi) hi = x; }
    return hi - lo;
  }
  function wrapped(v) {
    const out = new Float64Array(v.length);
    for (let i = 0; i < v.length; i++) out[i] = v[i] - 2 * Math.PI * Math.round(v[i] / (2 * Math.PI));
    return out;
  }

  function buildPlots() {
    plotGroup("Links", D.links, [["theta", "θ", "rad", true], ["omega", "ω", "rad/s"], ["alpha", "α", "rad/s²"]]);
    plotGroup("Sliders", D.slider_names, [["s", "s", U], ["v", "v", `${U}/s`], ["a", "a", `${U}/s²`]]);
    const F = D.forces;
    if (F) {
      for (const d of F.drivers) plotGroup(d.label, [{ label: d.column, column: "force:" + d.column }], [["", d.column.endsWith(".torque") ? "τ" : "F", d.unit]]);
      if (F.shaking.length) plotGroup("Shaking force", F.shaking.map((c) => ({ label: c, column: "force:" + c })), [["", "F", "N"]]);
    }
    const width = $("plots").clientWidth;
    plots.forEach((p) => p.render(width));
  }

  function watchSizes() {
    let scrolled = false;
    const onScroll = () => { if (!scrolled) { scrolled = true; requestAnimationFrame(() => { scrolled = false; catchUp(); }); } };
    addEventListener("scroll", onScroll, { passive: true });
    $("plots").addEventListener("scroll", onScroll, { passive: true });
    // rebuild the plots only when their column changes width; the drawing when its box changes size
    let pending = false, plotWidth = $("plots").clientWidth;
    const observer = new ResizeObserver(() => {
      if (pending) return;
      pending = true;
      requestAnimationFrame(() => {
        pending = false;
        if ($("plots").clientWidth !== plotWidth) { plotWidth = $("plots").clientWidth; plots.forEach((p) => p.render()); }
        resize();
      });
    });
    observer.observe($("plots"));
    observer.observe($("view-wrap"));
    observer.observe(V.svg);
  }

  // ------------------------------------------------------------------ numbers panel

  let cells = [];
  function table(parent, caption, head, rows) {
    const wrap = html("div", { class: "table-wrap" }, parent);
    const t = html("table", {}, wrap);
    html("caption", {}, t, caption);
    const tr = html("tr", {}, html("thead", {}, t));
    const heads = head.map((h) => html("th", { scope: "col" }, tr, h));
    const body = html("tbody", {}, t);
    const widths = [];
    for (const [name, cols, unit] of rows) {
      const r = html("tr", {}, body);
      html("th", { scope: "row" }, r, name);
      cols.forEach(([col, f], k) => {
        const td = html("td", { class: "num", "data-col": col }, r);
        f = f || ((x) => x);
        const health = col.startsWith("health."), scale = scaleOf(col) * Math.abs(f(1));
        cells.push({ td, col, values: C[col], f, format: health ? fmtHealth : (x) => fmtScaled(x, scale) });
        widths[k] = Math.max(widths[k] || 0, health ? 9 : scaledWidth(scale));
      });
      if (unit !== undefined) html("td", {}, r, unit);
    }
    // each column as wide as its longest value can be: the numbers never wrap, and do not jiggle in play
    widths.forEach((w, k) => { if (heads[k + 1]) heads[k + 1].style.width = `${w + 1}ch`; });
  }

  function buildNumbers() {
    const host = $("numbers-body");
    const cols = (name, qs) => qs.map((q) => [`${name}.${q}`]);
    table(host, "Links", ["link", "θ [rad]", "θ [°]", "ω [rad/s]", "α [rad/s²]"],
      D.links.map((n) => [n, [[`${n}.theta`], [`${n}.theta`, (x) => x * DEG], [`${n}.omega`], [`${n}.alpha`]]]));
    if (D.slider_names.length)
      table(host, "Sliders", ["slider", `s [${U}]`, `v [${U}/s]`, `a [${U}/s²]`], D.slider_names.map((n) => [n, cols(n, ["s", "v", "a"])]));
    table(host, "Joints and points", ["point", `x [${U}]`, `y [${U}]`, `vx [${U}/s]`, `vy [${U}/s]`, `ax [${U}/s²]`, `ay [${U}/s²]`],
      D.points.map((n) => [n, cols(n, ["x", "y", "vx", "vy", "ax", "ay"])]));
    const health = [];
    if (C["health.residual"]) health.push(["closure residual", [["health.residual"]], "of the size"]);
    if (C["health.cond"]) health.push(["condition number", [["health.cond"]], ""]);
    if (health.length) table(host, "Health", ["", "value", ""], health);
    if (D.forces) table(host, "Forces", ["", "value", "unit"], D.forces.columns.map((c) => [c, [[`force:${c}`]], D.forces.units[c]]));
  }

  function updateNumbers(i) {
    $("numbers-time").textContent = `t = ${fmt(T[i])} s · sample ${sampleNo(i)} of ${D.thinned ? D.thinned.of : N}`;
    for (const c of cells) {
      const v = c.values[i];
      c.td.textContent = c.format(c.f(v));
      c.td.dataset.value = String(c.f(v)); // full precision (shortest round trip)
    }
  }

  function unitOf(col) {
    if (col === "t") return "s";
    if (col.startsWith("force:")) return D.forces.units[col.slice(6)];
    if (col.startsWith("health.")) return "";
    const q = col.slice(col.lastIndexOf(".") + 1);
    return { theta: "rad", omega: "rad/s", alpha: "rad/s²", x: U, y: U, s: U, vx: `${U}/s`, vy: `${U}/s`, v: `${U}/s`,
      ax: `${U}/s²`, ay: `${U}/s²`, a: `${U}/s²` }[q] || "";
  }

  function copyValues() {
    const lines = ["quantity\tvalue\tunit"];
    for (const col of D.data.columns) lines.push(`${col.replace(/^force:/, "")}\t${String(C[col][S.i])}\t${unitOf(col)}`);
    const text = lines.join("\n") + "\n";
    const done = (how) => { $("copied").textContent = how; setTimeout(() => { $("copied").textContent = ""; }, 2500); };
    const fallback = () => {
      const ta = html("textarea", {}, document.body, text);
      ta.select();
      const ok = document.execCommand && document.execCommand("copy");
      ta.remove();
      done(ok ? "copied" : "copy failed: select the table instead");
    };
    if (navigator.clipboard && window.isSecureContext) navigator.clipboard.writeText(text).then(() => done("copied"), fallback);
    else fallback();
    window.vloopViewer.lastCopy = text;
  }

  // ------------------------------------------------------------------ time

  function setIndex(i, playing) {
    i = Math.max(0, Math.min(N - 1, Math.round(i)));
    S.i = i;
    if (!playing) S.clock = T[i];
    $("time").value = String(i);
    $("time-text").textContent = `t = ${fmt(T[i])} s (${i + 1}/${N})`;
    V.svg.setAttribute("aria-label", `${D.name} at t = ${fmt(T[i])} s`);
    draw(i);
    for (const p of plots) p.setCursor(i);
    // while playing, the numbers change faster than anyone reads them: refresh them 10 times a second
    const now = performance.now();
    if (!playing || now - S.numbersAt > 100) { updateNumbers(i); S.numbersAt = now; }
  }

  function play() {
    if (N < 2) return;
    if (S.i >= N - 1) { S.clock = T[0]; setIndex(0); }
    S.playing = true;
    S.last = null;
    $("play").setAttribute("aria-pressed", "true");
    $("play").textContent = "❚❚ Pause";
    requestAnimationFrame(tick);
  }
  function pause() {
    if (S.playing) updateNumbers(S.i);
    S.playing = false;
    $("play").setAttribute("aria-pressed", "false");
    $("play").textContent = "▶ Play";
  }
  function tick(now) {
    if (!S.playing) return;
    const dt = S.last === null ? 0 : Math.min((now - S.last) / 1000, 0.1); // a hidden tab does not jump ahead
    S.last = now;
    S.clock += dt * S.speed;
    S.stats.frames++;
    if (S.clock > T[N - 1]) {
      if (S.repeat) { S.clock = T[0] + ((S.clock - T[N - 1]) % Math.max(T[N - 1] - T[0], 1e-9)); }
      else { setIndex(N - 1, true); pause(); return; }
    }
    const j = floorIndex(S.clock);
    if (j !== S.i) setIndex(j, true);
    requestAnimationFrame(tick);
  }

  function wireControls() {
    const slider = $("time");
    slider.addEventListener("input", () => { pause(); setIndex(+slider.value); });
    $("play").addEventListener("click", () => (S.playing ? pause() : play()));
    $("prev").addEventListener("click", () => { pause(); setIndex(S.i - 1); });
    $("next").addEventListener("click", () => { pause(); setIndex(S.i + 1); });
    $("speed").addEventListener("change", (e) => { S.speed = +e.target.value; S.speedChosen = true; });
    $("arrow-scale").addEventListener("change", (e) => {
      S.gain = +e.target.value;
      computeArrowScales();
      if (!S.zoomed && (S.over.vel || S.over.acc || S.over.forces)) fit();
      draw(S.i);
      drawScaleLegend();
    });
    $("repeat").addEventListener("click", (e) => { S.repeat = !S.repeat; e.currentTarget.setAttribute("aria-pressed", String(S.repeat)); });
    $("copy").addEventListener("click", copyValues);
    for (const b of document.querySelectorAll("[data-overlay]")) {
      const key = b.dataset.overlay;
      b.addEventListener("click", () => setOverlay(key, !S.over[key]));
    }
    document.addEventListener("keydown", (e) => {
      const tag = e.target.tagName;
      if (tag === "SELECT" || tag === "TEXTAREA" || (tag === "INPUT" && e.target.type !== "range")) return;
      if (e.altKey || e.ctrlKey || e.metaKey) return;
      const step = e.shiftKey ? 10 : 1;
      if (e.key === "ArrowRight") { pause(); setIndex(S.i + step); }
      else if (e.key === "ArrowLeft") { pause(); setIndex(S.i - step); }
      else if (e.key === "Home") { pause(); setIndex(0); }
      else if (e.key === "End") { pause(); setIndex(N - 1); }
      else if (e.key === " ") { if (e.repeat) { e.preventDefault(); return; } S.playing ? pause() : play(); }
      else return;
      e.preventDefault();
    });
    document.addEventListener("keyup", (e) => { if (e.key === " " && e.target.tagName === "BUTTON") e.preventDefault(); });
    $("theme").addEventListener("click", () => {
      const root = document.documentElement;
      const dark = root.dataset.theme ? root.dataset.theme === "dark" : matchMedia("(prefers-color-scheme: dark)").matches;
      root.dataset.theme = dark ? "light" : "dark";
      themeButton();
    });
    $("large").addEventListener("click", () => {
      const on = document.documentElement.classList.toggle("large");
      $("large").setAttribute("aria-pressed", String(on));
      plots.forEach((p) => p.render());
      resize();
    });
    themeButton();
  }
  function themeButton() {
    const root = document.documentElement;
    const dark = root.dataset.theme ? root.dataset.theme === "dark" : matchMedia("(prefers-color-scheme: dark)").matches;
    $("theme").textContent = dark ? "Light" : "Dark";
    $("theme").setAttribute("aria-pressed", String(dark));
  }

  function setOverlay(key, on) {
    S.over[key] = on;
    document.querySelector(`[data-overlay="${key}"]`).setAttribute("aria-pressed", String(on));
    V.layers[key].setAttribute("display", on ? "inline" : "none");
    if (key === "loops") $("loop-legend").hidden = !on || !V.loops.length;
    if (!S.zoomed && (key === "vel" || key === "acc" || key === "forces")) fit();
    draw(S.i);
    drawScaleLegend();
  }

  // ------------------------------------------------------------------ start

  // the run's own sample number (1-based) of page sample i (a thinned page carries every k-th and the last)
  function sampleNo(i) {
    if (!D.thinned) return i + 1;
    return i === N - 1 ? D.thinned.of : i * D.thinned.every + 1;
  }

  // the run's fastest link turns at most half a turn per second at the default speed (a textbook four-bar
  // at 25 rad/s would otherwise turn 4 times a second): the largest listed speed that keeps to it
  function defaultSpeed() {
    let w = 0;
    for (const n of D.links) { const v = C[n + ".omega"]; for (let i = 0; i < N; i++) w = Math.max(w, Math.abs(v[i])); }
    const turns = w / (2 * Math.PI);
    const fit = SPEEDS.filter((v) => v <= 1 && v * turns <= 0.5);
    return fit.length ? fit[fit.length - 1] : SPEEDS[0];
  }

  // what a new page's data replaces: every element built from the previous data
  function reset() {
    V.svg.replaceChildren();
    Object.assign(V, { layers: {}, bodies: [], pins: [], labels: [], linkLabels: [], loops: [], vel: [], acc: [], forces: [] });
    SCALES = null;
    plots = [];
    cells = [];
    $("plots").replaceChildren();
    $("numbers-body").replaceChildren();
    $("loop-legend").replaceChildren();
    const details = $("loop-details");
    if (details) details.remove();
    $("error").hidden = true;
    $("note").hidden = true;
  }

  function showMessages() {
    if (D.error) {
      const box = $("error");
      box.hidden = false;
      box.textContent = `The motion stopped: ${D.error}\nThe drawing shows the last assembled instant, t = ${fmt(T[N - 1])} s (sample ${sampleNo(N - 1)}).`;
    }
    if (D.thinned) {
      const note = $("note");
      note.hidden = false;
      note.textContent = `This page carries ${D.thinned.shown.toLocaleString()} of the run's ${D.thinned.of.toLocaleString()} samples (one in every ${D.thinned.every}, and the last), to keep the page small; each value shown is that sample's exact value. vloop run writes every sample.`;
    }
  }

  let layout = null;
  const layoutOf = (d) => JSON.stringify([d.data.columns, d.links, d.slider_names, d.points, d.loops.length, !!d.forces]);

  function refresh(opts, ms) {
    V.svg.replaceChildren();
    Object.assign(V, { layers: {}, bodies: [], pins: [], labels: [], linkLabels: [], loops: [], vel: [], acc: [], forces: [] });
    SCALES = null;
    const details = $("loop-details");
    const open = details && details.open;
    if (details) details.remove();
    buildScene();
    buildLoopLegend();
    if (open) $("loop-details").open = true;
    for (const key in S.over) V.layers[key].setAttribute("display", S.over[key] ? "inline" : "none");
    $("time").max = String(N - 1);
    ms.push(performance.now());
    for (const p of plots) {
      for (const sr of p.spec.series) { sr.values = C[sr.col]; if (sr.plot) sr.plot = wrapped(sr.values); sr.scale = scaleOf(sr.col); }
    }
    later();
    ms.push(performance.now());
    for (const c of cells) c.values = C[c.col];
    $("error").hidden = true;
    $("note").hidden = true;
    showMessages();
    ms.push(performance.now());
    const start = Math.max(0, Math.min(N - 1, opts.index !== undefined ? opts.index : D.error ? N - 1 : 0));
    S.i = start;
    if (opts.keepView && V.box) setBox(V.box); else fit();
    setIndex(start, true);
    ms.push(performance.now());
    S.stats.load = ms.slice(1).map((t, k) => t - ms[k]);
  }

  // While new data streams in (a drag), the drawing is redrawn at once and the plots and numbers just after the
  // frame is shown, a slice of them per frame (LATER_MS of script, at least one plot), a new pass at most every
  // LATER_GAP ms: the mechanism under the pointer never waits for the plots, no frame waits for all of them (each
  // plot redrawn is laid out and painted again), and a stream of drags leaves the processor to the drawing.
  // What is scrolled out of view is brought up to date when it comes back into view.
  const LATER_MS = 4, LATER_GAP = 100;
  let pendingPlots = false, laterMs = 0, lastPass = -Infinity;
  const onScreen = (el) => { const r = el.getBoundingClientRect(); return r.bottom > 0 && r.top < innerHeight && r.height > 0; };
  function later() {
    for (const p of plots) p.stale = true;
    S.numbersStale = true;
    if (pendingPlots) return;
    pendingPlots = true;
    laterMs = 0;
    const slice = () => requestAnimationFrame(() => setTimeout(laterSlice, 0));
    const wait = lastPass + LATER_GAP - performance.now();
    if (wait > 0) setTimeout(slice, wait); else slice();
  }
  function laterSlice() {
    const t0 = performance.now();
    const more = catchUp(t0 + LATER_MS);
    laterMs += performance.now() - t0;
    if (more) { requestAnimationFrame(() => setTimeout(laterSlice, 0)); return; }
    pendingPlots = false;
    lastPass = performance.now();
    S.stats.later = laterMs; // the plots' and numbers' script time after the drawing's frame, over its slices [ms]
  }
  // the stale plots and numbers in view redrawn (until ``until``, performance.now()'s clock, if given): whether some
  // in view are left for later
  function catchUp(until = Infinity) {
    const width = $("plots").clientWidth;
    for (const p of plots) {
      if (!p.stale || !onScreen(p.host)) continue;
      if (performance.now() > until) return true;
      p.stale = false; p.render(width); p.setCursor(S.i);
    }
    if (S.numbersStale && onScreen($("numbers"))) {
      if (performance.now() > until) return true;
      S.numbersStale = false; updateNumbers(S.i);
    }
    return false;
  }

  // Draw ``data`` (the page's payload). ``opts.keepView``: keep the zoom and pan (a drag redraws under the pointer);
  // ``opts.index``: the sample to show (default: the first, or the last before a stop).
  async function load(data, opts = {}) {
    if (typeof DecompressionStream === "undefined") throw new Error("this browser has no DecompressionStream: use a current Firefox, Chrome, Edge or Safari");
    const ms = [performance.now()];
    const cols = await decode(data.data);
    D = data;
    U = D.units;
    C = cols;
    T = C.t;
    N = T.length;
    ms.push(performance.now());
    // a drag's new data with the same columns: the plots and tables stay, fed the new numbers
    const same = layout === layoutOf(D);
    layout = layoutOf(D);
    if (same && plots.length) return refresh(opts, ms);
    reset();
    if ((D.targets || []).length) S.over.paths = true; // a synthesis's page: its targets (and paths) shown at once
    buildScene();
    buildLoopLegend();
    if (!S.wired) { wireControls(); wireView(); }
    for (const key in S.over) V.layers[key].setAttribute("display", S.over[key] ? "inline" : "none");
    document.querySelector('[data-overlay="forces"]').hidden = !(D.forces && D.forces.arrows.length);
    $("time").max = String(N - 1);
    ms.push(performance.now());
    buildPlots();
    if (!S.wired) watchSizes();
    S.wired = true;
    ms.push(performance.now());
    buildNumbers();
    $("loop-legend").hidden = !S.over.loops || !V.loops.length;
    if (!S.speedChosen) { S.speed = defaultSpeed(); $("speed").value = String(S.speed); }
    showMessages();
    ms.push(performance.now());
    const start = Math.max(0, Math.min(N - 1, opts.index !== undefined ? opts.index : D.error ? N - 1 : 0));
    S.i = start;
    if (opts.keepView && V.box) setBox(V.box); else fit();
    setIndex(start);
    ms.push(performance.now());
    // where a load's time goes [ms]: decode, scene, plots, numbers, first draw (read by the studio's benchmark)
    S.stats.load = ms.slice(1).map((t, k) => t - ms[k]);
    window.vloopViewer.ready = true;
    document.body.dataset.ready = "1";
  }

  window.vloopViewer = { ready: false, stats: S.stats, setIndex: (i) => setIndex(i), play, pause, setOverlay, load, fit,
    get index() { return S.i; }, get playing() { return S.playing; }, get unitsPerPixel() { return V.upp; },
    get speed() { return S.speed; }, get samples() { return N; }, get data() { return D; }, column: (name) => C[name],
    toWorld: (clientX, clientY) => { const p = new DOMPoint(clientX, clientY).matrixTransform(V.svg.getScreenCTM().inverse()); return [p.x, -p.y]; },
    scales: () => ({ vel: V.kv, acc: V.ka, forces: V.kf }) };
  if (D) load(D).catch((err) => {
    const box = $("error");
    box.hidden = false;
    box.textContent = `The viewer could not start: ${err && err.message ? err.message : err}`;
    throw err;
  });
})();
