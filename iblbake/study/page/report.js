// The interactive report of an iblbake study or sheet (iblbake/study/html.py writes the page).
// Plain JavaScript and 2D canvases: the tone mapping is a per-pixel loop over at most a few
// hundred thousand pixels, which a canvas does in milliseconds; its nearest-neighbour zoom and
// getImageData read back exactly what is shown (the browser tests rely on it).
'use strict';
(() => {
const D = window.IBL_DATA;
const $ = (id) => document.getElementById(id);
const IBL = window.IBL = {data: D, state: null};

// ---- tone mapping: a port of iblbake/core/tonemap.py (float64 throughout, as numpy) ----
const INPUT_CAP = 1e18, HABLE_WHITE = 11.2;
const sanitize = (x) => (x > 0 ? (x < INPUT_CAP ? x : INPUT_CAP) : 0);   // NaN, negatives -> 0
const clip01 = (x) => (x < 0 ? 0 : x > 1 ? 1 : x);
const hableCurve = (x) => {
  const a = 0.15, b = 0.50, c = 0.10, d = 0.20, e = 0.02, f = 0.30;
  return (x * (a * x + c * b) + d * e) / (x * (a * x + b) + d * f) - e / f;
};
const HABLE_W = hableCurve(HABLE_WHITE);
const CURVES = {
  aces: (x) => clip01((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14)),
  reinhard: (x) => x / (1 + x),
  hable: (x) => clip01(hableCurve(x) / HABLE_W),
  linear: clip01,
};
function pbrNeutral(rgb) {          // Khronos PBR Neutral, on a colour (3 values)
  const f90 = 0.04, kd = 0.15, ks = 0.8 - f90;
  const x = Math.min(rgb[0], rgb[1], rgb[2]);
  const f = x <= 2 * f90 ? x - x * x / (4 * f90) : f90;
  const c = [rgb[0] - f, rgb[1] - f, rgb[2] - f];
  const p = Math.max(c[0], c[1], c[2]);
  if (p <= ks) return c;
  const pn = 1 - (1 - ks) ** 2 / (p + 1 - 2 * ks);
  const g = 1 / (kd * (p - pn) + 1);
  return c.map((v) => v * (pn / Math.max(p, 1e-30)) * g + pn * (1 - g));
}
const srgbEncode = (x) => { x = clip01(x); return x <= 0.0031308 ? 12.92 * x : 1.055 * Math.pow(x, 1 / 2.4) - 0.055; };
// linear HDR RGB -> display values in [0, 1], as tonemap.tonemap(hdr, op, ev, transfer, gamma)
function tonemap(rgb, op, ev, transfer, gamma) {
  const k = Math.pow(2, ev);
  let x = rgb.map((v) => sanitize(sanitize(v) * k));
  x = op === 'pbr_neutral' ? pbrNeutral(x) : x.map(CURVES[op]);
  return x.map((v) => (transfer === 'srgb' ? srgbEncode(clip01(v)) : Math.pow(clip01(v), 1 / gamma)));
}
const toU8 = (v) => Math.min(255, Math.max(0, Math.floor(v * 255 + 0.5)));
IBL.tonemap = tonemap;

// ---- data: one script per image, loaded when first shown (fetch() is refused on file://) ----
const F16 = new Float32Array(65536);
for (let h = 0; h < 65536; h++) {
  const s = h & 0x8000 ? -1 : 1, e = (h >> 10) & 31, m = h & 1023;
  F16[h] = e === 0 ? s * m * 2 ** -24 : e === 31 ? (m ? NaN : s * Infinity) : s * (1 + m / 1024) * 2 ** (e - 15);
}
const waiting = new Map(), cache = new Map(), CACHE_MAX = 48;
IBL.arrive = (key, b64) => { const w = waiting.get(key); if (w) w(b64); };
async function inflate(b64) {
  const raw = Uint8Array.from(atob(b64), (c) => c.charCodeAt(0));
  const stream = new Blob([raw]).stream().pipeThrough(new DecompressionStream('deflate'));
  return new Uint8Array(await new Response(stream).arrayBuffer());
}
function script(key, file) {
  return new Promise((resolve, reject) => {
    waiting.set(key, (b64) => { waiting.delete(key); resolve(b64); });
    const s = document.createElement('script');
    s.src = file;
    s.onerror = () => reject(new Error(`${file}: missing (the report's data files sit beside index.html)`));
    s.onload = () => s.remove();
    document.head.appendChild(s);
  });
}
function load(i) {                   // -> {rgb: Float32Array, mask: Uint8Array (0/1)}
  if (cache.has(i)) { const v = cache.get(i); cache.delete(i); cache.set(i, v); return v; }
  const p = script(String(i), D.entries[i].file).then(inflate).then((bytes) => {
    const n = D.width * D.height, rgb = new Float32Array(3 * n), mask = new Uint8Array(n);
    for (let k = 0; k < 3 * n; k++) rgb[k] = F16[bytes[k] | (bytes[3 * n + k] << 8)];   // low, high bytes
    for (let k = 0; k < n; k++) mask[k] = (bytes[6 * n + (k >> 3)] >> (7 - (k & 7))) & 1;
    return {rgb, mask};
  });
  cache.set(i, p);
  if (cache.size > CACHE_MAX) cache.delete(cache.keys().next().value);
  return p;
}
let objects = null;
if (D.objects) script('objects', D.objects).then(inflate).then((b) => { objects = new Int16Array(b.buffer); });

// ---- state ----
const W = D.width, H = D.height, N = D.entries.length;
const rungs = D.entries.map((e, i) => i).filter((i) => !D.entries[i].is_reference);
const first = rungs.length ? rungs[0] : 0;
const S = IBL.state = {
  a: first, b: D.kind === 'sheet' ? Math.min(1, N - 1) : (D.entries[first].reference ?? first), pinB: false,
  flipped: false, split: false, splitPos: 0.5, ev: 0, op: '', err: 'relative', top: 0.5,
  zoom: 1, cx: W / 2, cy: H / 2, sortKey: null, sortDir: 1, preview: null,
};
const shownA = () => (S.preview ?? S.a);

// ---- drawing ----
const panes = ['paneA', 'paneB', 'paneE'].map($);
let fitZoom = 1;
function layout() {
  const avail = Math.max(120, (window.innerWidth - 60) / 3);
  fitZoom = avail >= W ? Math.floor(avail / W) : avail / W;
  for (const c of panes) {
    c.className = 'pane';
    c.width = Math.round(W * fitZoom); c.height = Math.round(H * fitZoom);
  }
}
const off = new Map();              // an image's tone-mapped pixels, keyed by what made them
function toned(i, data) {
  const key = `${i}|${S.ev}|${S.op}`;
  if (off.has(key)) return off.get(key);
  const c = document.createElement('canvas'); c.width = W; c.height = H;
  const ctx = c.getContext('2d'), img = ctx.createImageData(W, H), t = D.entries[i].tonemap || D.tonemap;
  const ev = t.exposure + S.ev, px = img.data, rgb = data.rgb, op = S.op || t.operator;
  for (let k = 0; k < W * H; k++) {
    const d = tonemap([rgb[3 * k], rgb[3 * k + 1], rgb[3 * k + 2]], op, ev, t.transfer, t.gamma);
    px[4 * k] = toU8(d[0]); px[4 * k + 1] = toU8(d[1]); px[4 * k + 2] = toU8(d[2]); px[4 * k + 3] = 255;
  }
  ctx.putImageData(img, 0, 0);
  if (off.size > 2 * CACHE_MAX) off.delete(off.keys().next().value);
  off.set(key, c);
  return c;
}
const LUM = [0.2126, 0.7152, 0.0722];
const MAGMA = Uint8Array.from(D.magma.match(/../g), (h) => parseInt(h, 16));
const lum = (rgb, k) => rgb[3 * k] * LUM[0] + rgb[3 * k + 1] * LUM[1] + rgb[3 * k + 2] * LUM[2];
function meanRefLum(ref, mask) {
  let sum = 0, n = 0;
  for (let k = 0; k < W * H; k++) if (mask[k]) { sum += lum(ref.rgb, k); n++; }
  return n ? sum / n : 0;
}
// the error map of got against ref, as metrics.error_image (relative) or |dL| (absolute)
function errorMap(got, ref) {
  const c = document.createElement('canvas'); c.width = W; c.height = H;
  const ctx = c.getContext('2d'), img = ctx.createImageData(W, H), px = img.data;
  const mask = got.mask.map((m, k) => m & ref.mask[k]);
  const eps = 0.01 * Math.max(meanRefLum(ref, mask), 1e-30);
  for (let k = 0; k < W * H; k++) {
    px[4 * k + 3] = 255;
    if (!mask[k]) continue;
    const lg = lum(got.rgb, k), lr = lum(ref.rgb, k);
    const e = S.err === 'relative' ? Math.abs(lg - lr) / (lr + eps) : Math.abs(lg - lr);
    const j = Math.min(255, Math.floor(clip01(e / S.top) * 256));
    px[4 * k] = MAGMA[3 * j]; px[4 * k + 1] = MAGMA[3 * j + 1]; px[4 * k + 2] = MAGMA[3 * j + 2];
  }
  ctx.putImageData(img, 0, 0);
  return {canvas: c, eps, mask};
}
function drawPane(canvas, img, img2) {
  const ctx = canvas.getContext('2d'), z = S.zoom * fitZoom;
  ctx.setTransform(1, 0, 0, 1, 0, 0);
  ctx.fillStyle = '#000'; ctx.fillRect(0, 0, canvas.width, canvas.height);
  ctx.imageSmoothingEnabled = false;
  const tx = canvas.width / 2 - S.cx * z, ty = canvas.height / 2 - S.cy * z;
  ctx.setTransform(z, 0, 0, z, tx, ty);
  ctx.drawImage(img, 0, 0);
  if (img2) {                       // the split: B right of the line
    const x = canvas.width * S.splitPos;
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.save(); ctx.beginPath(); ctx.rect(x, 0, canvas.width - x, canvas.height); ctx.clip();
    ctx.setTransform(z, 0, 0, z, tx, ty); ctx.drawImage(img2, 0, 0); ctx.restore();
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.fillStyle = '#fff'; ctx.fillRect(Math.round(x), 0, 1, canvas.height);
  }
}
let token = 0, current = null;
async function render() {
  const mine = ++token, a = shownA(), b = S.b;
  let da, db;
  try {
    [da, db] = await Promise.all([load(a), load(b)]);
  } catch (e) {                     // a data file missing or damaged: said on the page
    cache.delete(a); cache.delete(b);
    $('status').textContent = e.message;
    return;
  }
  if (mine !== token) return;
  const ta = toned(a, da), tb = toned(b, db), em = errorMap(da, db);
  const [x, y] = S.flipped ? [tb, ta] : [ta, tb];
  drawPane(panes[0], x, S.split ? y : null);
  drawPane(panes[1], y);
  drawPane(panes[2], em.canvas);
  current = {a, b, da, db, em};
  captions();
  $('status').textContent = `${N} images, ${W} x ${H}`;
  document.body.dataset.ready = '1';
}
IBL.render = render;
const label = (i) => { const e = D.entries[i]; return e.term && !e.is_reference ? `${e.term}: ${e.label}` : e.label; };
function captions() {
  const [p, q] = S.flipped ? [S.b, shownA()] : [shownA(), S.b];
  $('capA').textContent = (S.flipped ? 'B: ' : 'A: ') + label(p) + (S.split ? `  |  ${label(q)}` : '');
  $('capB').textContent = (S.flipped ? 'A: ' : 'B: ') + label(q);
  $('capE').textContent = `error of A against B (${S.err}), over the pixels both measure`;
  $('legHi').textContent = S.err === 'relative' ? `${(100 * S.top).toPrecision(3)}%` : S.top.toPrecision(3);
  $('evText').textContent = `${S.ev >= 0 ? '+' : ''}${S.ev} EV`;
  $('selA').value = String(S.a); $('selB').value = String(S.b);
  for (const tr of document.querySelectorAll('#table tbody tr')) {
    tr.classList.toggle('sel', +tr.dataset.entry === S.a); tr.classList.toggle('selB', +tr.dataset.entry === S.b);
  }
  for (const c of document.querySelectorAll('#plot .pt')) {
    c.classList.toggle('sel', +c.dataset.entry === S.a); c.classList.toggle('selB', +c.dataset.entry === S.b);
  }
  regions();
}
// what the canvas shows at image pixel (x, y) of a pane: [r, g, b] 8-bit (the tests read it)
IBL.displayed = (pane, x, y) => {
  const c = $(pane), z = S.zoom * fitZoom;
  const px = Math.floor(c.width / 2 + (x + 0.5 - S.cx) * z), py = Math.floor(c.height / 2 + (y + 0.5 - S.cy) * z);
  return Array.from(c.getContext('2d').getImageData(px, py, 1, 1).data.slice(0, 3));
};

// ---- selection ----
function select(i, asB) {
  if (asB) { S.b = i; S.pinB = true; } else {
    S.a = i;
    if (!S.pinB && D.entries[i].reference != null) S.b = D.entries[i].reference;
  }
  S.preview = null;
  return render();
}
IBL.select = select;
function step(d) {
  const order = sortedRows(), k = order.indexOf(S.a);
  select(order[(k + d + order.length) % order.length] ?? order[0]);
}

// ---- pixel readout ----
const fmt = (v) => (Math.abs(v) >= 1e5 || (v !== 0 && Math.abs(v) < 1e-3) ? v.toExponential(4) : v.toPrecision(5));
const triple = (rgb, k) => `${fmt(rgb[3 * k])} ${fmt(rgb[3 * k + 1])} ${fmt(rgb[3 * k + 2])}`;
function readout(x, y) {
  if (!current || x < 0 || y < 0 || x >= W || y >= H) return;
  const k = y * W + x, {a, b, da, db, em} = current;
  const lg = lum(da.rgb, k), lr = lum(db.rgb, k);
  const e = em.mask[k] ? (S.err === 'relative' ? `${(100 * Math.abs(lg - lr) / (lr + em.eps)).toPrecision(4)}%`
                                               : Math.abs(lg - lr).toPrecision(4)) : 'not measured';
  let obj = '';
  if (objects && objects[k] >= 0) {
    const name = D.object_names[objects[k]] ?? `object ${objects[k]}`, r = D.entries[a].regions[name];
    obj = `  object ${name}` + (r != null ? ` (A's mean error there ${(100 * r).toFixed(2)}%)` : '');
  }
  $('readout').innerHTML = '';
  const line = (t, id) => { const s = document.createElement('div'); s.id = id; s.textContent = t; $('readout').append(s); };
  line(`(${x}, ${y})  A ${label(a)}: ${triple(da.rgb, k)}`, 'roA');
  line(`${' '.repeat(String(x).length + String(y).length + 6)}B ${label(b)}: ${triple(db.rgb, k)}  error ${e}${obj}`, 'roB');
}
IBL.readout = readout;

// ---- zoom and pan, one view for every pane ----
function imagePixel(c, ev) {
  const r = c.getBoundingClientRect(), z = S.zoom * fitZoom;
  return [Math.floor(S.cx + (ev.clientX - r.left - c.width / 2) / z), Math.floor(S.cy + (ev.clientY - r.top - c.height / 2) / z)];
}
let drag = null;
for (const c of panes) {
  c.addEventListener('mousemove', (ev) => {
    if (drag) {
      const z = S.zoom * fitZoom;
      S.cx = drag.cx - (ev.clientX - drag.x) / z; S.cy = drag.cy - (ev.clientY - drag.y) / z;
      render();
    }
    readout(...imagePixel(c, ev));
  });
  c.addEventListener('mousedown', (ev) => { drag = {x: ev.clientX, y: ev.clientY, cx: S.cx, cy: S.cy}; });
  c.addEventListener('wheel', (ev) => {
    ev.preventDefault();
    const r = c.getBoundingClientRect(), z0 = S.zoom * fitZoom;
    const ix = S.cx + (ev.clientX - r.left - c.width / 2) / z0, iy = S.cy + (ev.clientY - r.top - c.height / 2) / z0;
    S.zoom = Math.min(256, Math.max(0.25, S.zoom * (ev.deltaY < 0 ? 1.25 : 0.8)));
    const z = S.zoom * fitZoom;           // the pixel under the cursor stays there
    S.cx = ix - (ev.clientX - r.left - c.width / 2) / z; S.cy = iy - (ev.clientY - r.top - c.height / 2) / z;
    render();
  }, {passive: false});
}
window.addEventListener('mouseup', () => { drag = null; });
function fit() { S.zoom = 1; S.cx = W / 2; S.cy = H / 2; render(); }

// ---- the table, sortable ----
function sortedRows() {
  const rows = D.kind === 'sheet' ? D.entries.map((e, i) => i) : rungs.slice();
  if (S.sortKey) {
    const v = (i) => D.entries[i].row[S.sortKey];
    rows.sort((p, q) => {
      const x = v(p), y = v(q);
      if (x == null || y == null) return (x == null) - (y == null);
      return (typeof x === 'number' ? x - y : String(x).localeCompare(String(y))) * S.sortDir;
    });
  }
  return rows;
}
function cell(key, v) {
  if (v == null) return '-';
  if (key === 'pareto') return v ? '*' : '';
  if (['relative_rmse', 'mean_relative_error', 'max_relative_error', 'worst_region_error'].includes(key)) return `${(100 * v).toFixed(2)}%`;
  if (key === 'flip') return v.toFixed(4);
  if (key === 'bake_s') return v.toFixed(3);
  if (key === 'bytes' || key === 'samples') return String(v);
  if (typeof v === 'number') return v.toPrecision(3);
  return String(v);
}
function table() {
  const head = $('table').tHead, body = $('table').tBodies[0];
  head.innerHTML = ''; body.innerHTML = '';
  const tr = head.insertRow();
  for (const [key, name] of D.columns) {
    const th = document.createElement('th');
    th.textContent = name + (S.sortKey === key ? (S.sortDir > 0 ? ' \u25b2' : ' \u25bc') : '');
    th.dataset.key = key;
    th.onclick = () => { S.sortDir = S.sortKey === key ? -S.sortDir : 1; S.sortKey = key; table(); captions(); };
    tr.append(th);
  }
  for (const i of sortedRows()) {
    const r = body.insertRow();
    r.dataset.entry = i;
    for (const [key] of D.columns) r.insertCell().textContent = cell(key, D.entries[i].row[key]);
    r.onclick = (ev) => select(i, ev.shiftKey);
  }
}

// ---- the error-time plot: a log-log panel per term, the Pareto frontier drawn ----
const SVG = 'http://www.w3.org/2000/svg';
function el(name, attrs, parent) {
  const e = document.createElementNS(SVG, name);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
  if (parent) parent.append(e);
  return e;
}
// log10 of the 1, 2, 5 of each decade between lo and hi (log10); the decades alone when many
function ticks(lo, hi) {
  const out = [];
  for (let d = Math.floor(lo); d <= hi; d++) {
    for (const f of hi - lo > 3 ? [1] : [1, 2, 5]) { const v = d + Math.log10(f); if (v >= lo && v <= hi) out.push(v); }
  }
  return out;
}
function plot() {
  const terms = [...new Set(rungs.map((i) => D.entries[i].term))];
  const ok = (i) => D.entries[i].row.time_ms > 0 && D.entries[i].row.relative_rmse > 0;
  if (D.kind === 'sheet' || !terms.length) return;
  const pw = 360, ph = 260, m = {l: 46, r: 10, t: 18, b: 30};
  for (const t of terms) {
    const pts = rungs.filter((i) => D.entries[i].term === t && ok(i));
    if (!pts.length) continue;
    const xs = pts.map((i) => Math.log10(D.entries[i].row.time_ms)), ys = pts.map((i) => Math.log10(D.entries[i].row.relative_rmse));
    const range = (v) => { let lo = Math.min(...v), hi = Math.max(...v); if (hi - lo < 0.5) { lo -= 0.25; hi += 0.25; } const p = 0.05 * (hi - lo); return [lo - p, hi + p]; };
    const [x0, x1] = range(xs), [y0, y1] = range(ys);
    const X = (v) => m.l + (v - x0) / (x1 - x0) * (pw - m.l - m.r), Y = (v) => ph - m.b - (v - y0) / (y1 - y0) * (ph - m.t - m.b);
    const svg = el('svg', {width: pw, height: ph, 'data-term': t}, $('plot'));
    el('text', {x: m.l, y: 12}, svg).textContent = `${t}: relative RMSE against time (ms), log-log`;
    for (const v of ticks(x0, x1)) {
      el('line', {x1: X(v), x2: X(v), y1: m.t, y2: ph - m.b, stroke: '#444'}, svg);
      el('text', {x: X(v) - 8, y: ph - m.b + 14}, svg).textContent = `${+(10 ** v).toPrecision(2)}`;
    }
    for (const v of ticks(y0, y1)) {
      el('line', {x1: m.l, x2: pw - m.r, y1: Y(v), y2: Y(v), stroke: '#444'}, svg);
      el('text', {x: 2, y: Y(v) + 3}, svg).textContent = `${+(100 * 10 ** v).toPrecision(2)}%`;
    }
    const front = pts.filter((i) => D.entries[i].row.pareto).sort((p, q) => D.entries[p].row.time_ms - D.entries[q].row.time_ms);
    el('polyline', {points: front.map((i) => `${X(Math.log10(D.entries[i].row.time_ms))},${Y(Math.log10(D.entries[i].row.relative_rmse))}`).join(' '),
                    fill: 'none', stroke: '#e04040', 'stroke-width': 1.5}, svg);
    for (const i of pts) {
      const r = D.entries[i].row;
      const c = el('circle', {cx: X(Math.log10(r.time_ms)), cy: Y(Math.log10(r.relative_rmse)), r: r.pareto ? 5 : 3.5,
                              fill: r.pareto ? '#e04040' : '#999', class: 'pt', 'data-entry': i}, svg);
      el('title', {}, c).textContent = `${D.entries[i].label}: ${(100 * r.relative_rmse).toFixed(2)}% in ${r.time_ms.toPrecision(3)} ms`;
      c.addEventListener('mouseenter', () => { S.preview = i; render(); });
      c.addEventListener('mouseleave', () => { S.preview = null; render(); });
      c.addEventListener('click', (ev) => select(i, ev.shiftKey));
    }
  }
}

// ---- the shown rung's error per object ----
function regions() {
  const r = D.entries[shownA()].regions, names = Object.keys(r || {});
  $('regions').innerHTML = '';
  if (!names.length) return;
  const t = document.createElement('table');
  t.insertRow().innerHTML = '<th>object</th><th>mean error</th>';
  for (const n of names.sort((p, q) => r[q] - r[p])) {
    const row = t.insertRow();
    row.insertCell().textContent = n; row.insertCell().textContent = `${(100 * r[n]).toFixed(2)}%`;
  }
  $('regions').append(t);
}

// ---- controls and keys ----
function controls() {
  if (D.kind === 'sheet')          // a sheet has no references and no plot
    $('keys').textContent = 'keys: up/down or j/k the previous/next cell, space flips A and B, s split, ' +
      'e error mode, [ and ] exposure, 0 fit; click a table row to show it (shift: as B).';
  for (const id of ['selA', 'selB']) {
    for (let i = 0; i < N; i++) { const o = document.createElement('option'); o.value = i; o.textContent = label(i); $(id).append(o); }
  }
  $('selA').onchange = () => select(+$('selA').value);
  $('selB').onchange = () => select(+$('selB').value, true);
  $('flip').onclick = () => { S.flipped = !S.flipped; render(); };
  $('split').onchange = () => { S.split = $('split').checked; render(); };
  $('splitPos').oninput = () => { S.splitPos = +$('splitPos').value; render(); };
  $('exposure').oninput = () => { S.ev = +$('exposure').value; render(); };
  $('operator').value = S.op;
  $('operator').onchange = () => { S.op = $('operator').value; render(); };
  $('errMode').onchange = () => setErr($('errMode').value);
  $('errTop').onchange = () => { const v = +$('errTop').value; if (v > 0) { S.top = S.err === 'relative' ? v / 100 : v; render(); } };
  $('errTop').value = 100 * S.top;
  $('fit').onclick = fit;
  const g = $('legendBar').getContext('2d'), img = g.createImageData(256, 10);
  for (let x = 0; x < 256; x++) for (let y = 0; y < 10; y++) { img.data.set([MAGMA[3 * x], MAGMA[3 * x + 1], MAGMA[3 * x + 2], 255], 4 * (y * 256 + x)); }
  g.putImageData(img, 0, 0);
  window.addEventListener('keydown', (ev) => {
    if (ev.target.tagName === 'INPUT' || ev.target.tagName === 'SELECT') return;
    const k = ev.key, act = {
      ArrowDown: () => step(1), j: () => step(1), ArrowUp: () => step(-1), k: () => step(-1),
      ' ': () => { S.flipped = !S.flipped; render(); },
      s: () => { $('split').checked = S.split = !S.split; render(); },
      r: () => { S.pinB = false; if (D.entries[S.a].reference != null) S.b = D.entries[S.a].reference; render(); },
      e: () => setErr(S.err === 'relative' ? 'absolute' : 'relative'),
      '[': () => exposure(S.ev - 0.5), ']': () => exposure(S.ev + 0.5), 0: fit,
    }[k];
    if (act) { ev.preventDefault(); act(); }
  });
}
function exposure(ev) { S.ev = Math.max(-10, Math.min(10, ev)); $('exposure').value = S.ev; render(); }
async function setErr(mode) {
  S.err = mode; $('errMode').value = mode;
  if (mode === 'relative') S.top = 0.5;
  else {                              // absolute: scaled to half the reference's mean luminance
    const db = await load(S.b), da = await load(shownA());
    S.top = 0.5 * meanRefLum(db, da.mask.map((m, k) => m & db.mask[k])) || 1;
  }
  $('errTop').value = mode === 'relative' ? 100 * S.top : +S.top.toPrecision(4);
  render();
}
IBL.exposure = exposure;

$('title').textContent = D.title;
document.title = D.title;
layout();
controls();
table();
plot();
window.addEventListener('resize', () => { layout(); render(); });
IBL.ready = render();
})();
