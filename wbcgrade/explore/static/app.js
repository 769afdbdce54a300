// wbcgrade explore: the page. Plain JavaScript, no build step, no outside resource.
//
// The server computes colour maps (3-D LUTs); this page applies them to the
// preview picture itself (trilinear, as wbcgrade's remap does), at the strength
// of the slider. It opens on the grade `wbcgrade apply` gives (the "look" mode:
// one map per style source, fetched when a source is picked). In the palette
// mode a move of the weights is shown in three steps, each replacing the one before:
//   1. at once, extrapolated here from the last exact map and the slopes of
//      the fast map there (a sum of LUTs: no request);
//   2. the server's fast map, corrected by the nearest exact map (one small
//      request; while the point moves they go one at a time, the newest
//      settings next, stale answers dropped);
//   3. once the point rests, the exact map: what the export holds.
(() => {
  'use strict';

  const $ = (id) => document.getElementById(id);
  const SVG = 'http://www.w3.org/2000/svg';
  const RELAX_STEPS = [0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1, 2, 5, 10];
  const IDLE_MS = 350;          // rest before the exact map is asked for
  const GRID = 15;              // landscape samples per side of the polygon's box
  const NEAR = 0.10;            // "as good as the fit": loss within 10 % of the fit's
  const CENTER = [170, 170];
  const RADIUS = 90;

  const state = {
    meta: null,
    source: 0,                  // the preset picker's entry shown
    mode: 'look',               // 'look': the grade apply gives; 'palette': a mix of palettes
    blend: null,                // look mode: {source, amount}: another look's share, or null
    blendCommand: '',           // the command of a saved blend (its grade file)
    switched: 0,                // the version of the last source or mode switch
    history: [],                // undo: snapshots of what the page shows, the last is now
    future: [],                 // redo
    restoring: false,
    n: 0,
    vertices: [],
    look: {weights: [], strength: 1, relaxation: null, keep_lightness: false},
    version: 0,                 // bumped by every change of what the map depends on
    shown: {version: -1, kind: '', weights: null, weightsText: ''},
    lut: null,
    lutSize: 0,
    before: null,               // ImageData of the preview picture
    after: null,
    inFlight: false,
    dirty: false,
    seq: 0,
    idle: 0,
    exactAsked: -1,
    model: null,                // {family, weights, exact, slopes}: for step 1
    slopesAsked: '',
    client: Math.random().toString(36).slice(2, 12),
    changedAt: new Map(),       // version -> when it was asked for (ms)
  };
  // What a test or benchmark reads: move-to-pixels latencies (ms) and the renders done.
  const probe = {latencies: [], renders: 0, seen: new Set(), shown: () => ({...state.shown}),
                 mode: () => state.mode, source: () => state.source,
                 grade: () => state.meta && state.meta.look.grade,
                 strength: () => state.look.strength,
                 blend: () => state.blend && {...state.blend},
                 history: () => [state.history.length, state.future.length],
                 current: () => state.version, weights: () => state.look.weights.slice(),
                 extrapolates: () => Boolean(state.model && state.model.family === family())};
  window.wbcgradeExplore = probe;

  // ---------------------------------------------------------------- server
  async function post(path, body) {
    return fetch(path, {method: 'POST', headers: {'Content-Type': 'application/json'},
                        body: JSON.stringify(body)});
  }

  async function failure(response) {
    try {
      const data = await response.json();
      return data.error || `HTTP ${response.status}`;
    } catch (e) {
      return `HTTP ${response.status}`;
    }
  }

  function body() {
    const look = state.look;
    return {source: state.source, weights: look.weights.slice(), strength: look.strength,
            relaxation: look.relaxation, keep_lightness: look.keep_lightness};
  }

  function say(text, error) {
    const box = $('message');
    box.textContent = text || '';
    box.className = error ? 'error' : '';
  }

  // ---------------------------------------------------------------- grading
  // A map made stronger than itself (strength t > 1), as wbcgrade does: each node moved
  // t times as far, clipped to the cube; then applied in full.
  let strongCache = {lut: null, t: 0, out: null};
  function strengthened(lut, n, t) {
    if (strongCache.lut === lut && strongCache.t === t) return strongCache.out;
    const out = new Float32Array(lut.length);
    for (let i = 0; i < n; i++) {
      for (let j = 0; j < n; j++) {
        for (let k = 0; k < n; k++) {
          const q = ((i * n + j) * n + k) * 3;
          const node = [i / (n - 1), j / (n - 1), k / (n - 1)];
          for (let c = 0; c < 3; c++) {
            out[q + c] = Math.min(1, Math.max(0, node[c] + t * (lut[q + c] - node[c])));
          }
        }
      }
    }
    strongCache = {lut, t, out};
    return out;
  }

  function render() {
    if (!state.lut || !state.before) return;
    const src = state.before.data;
    const out = state.after.data;
    const n = state.lutSize;
    let lut = state.lut;
    let t = state.look.strength;
    if (t > 1) {
      lut = strengthened(lut, n, t);
      t = 1;
    }
    const scale = (n - 1) / 255;
    const dj = 3 * n;
    const di = 3 * n * n;
    for (let p = 0; p < src.length; p += 4) {
      const r = src[p] * scale, g = src[p + 1] * scale, b = src[p + 2] * scale;
      let i = r | 0, j = g | 0, k = b | 0;
      if (i > n - 2) i = n - 2;
      if (j > n - 2) j = n - 2;
      if (k > n - 2) k = n - 2;
      const fr = r - i, fg = g - j, fb = b - k;
      const base = ((i * n + j) * n + k) * 3;
      for (let c = 0; c < 3; c++) {
        const q = base + c;
        // the same order as wbcgrade.color.mapping.remap: blue, then green, then red
        const c00 = lut[q] * (1 - fb) + lut[q + 3] * fb;
        const c01 = lut[q + dj] * (1 - fb) + lut[q + dj + 3] * fb;
        const c10 = lut[q + di] * (1 - fb) + lut[q + di + 3] * fb;
        const c11 = lut[q + di + dj] * (1 - fb) + lut[q + di + dj + 3] * fb;
        const c0 = c00 * (1 - fg) + c01 * fg;
        const c1 = c10 * (1 - fg) + c11 * fg;
        const value = c0 * (1 - fr) + c1 * fr;
        out[p + c] = ((1 - t) * src[p + c] / 255 + t * value) * 255;
      }
      out[p + 3] = 255;
    }
    $('after').getContext('2d').putImageData(state.after, 0, 0);
  }

  const RANK = {extrapolated: 0, preview: 1, exact: 2};

  function showLut(lut, meta, version, kind) {
    const shown = state.shown;
    if (state.mode !== 'palette') return;  // a palette answer after a switch to the look
    if (version < shown.version || version < state.switched) return;
    if (version === shown.version && RANK[kind] < RANK[shown.kind]) return;
    state.lut = lut;
    state.lutSize = meta.size;
    state.shown = {version, kind, weights: meta.weights, weightsText: meta.weights_text};
    render();
    probe.renders += 1;
    if (kind === 'exact' && state.mode === 'palette') {  // moves from here: the slopes
      const settings = {weights: meta.weights, relaxation: meta.relaxation,
                        keep_lightness: meta.keep_lightness};
      const key = meta.weights_text + JSON.stringify([meta.relaxation, meta.keep_lightness]);
      if (!state.model || state.model.key !== key) requestSlopes(settings, key);
    }
    const asked = state.changedAt.get(version);
    if (asked !== undefined) {
      const first = !probe.seen.has(version);
      probe.seen.add(version);
      if (probe.seen.size > 500) probe.seen.clear();
      probe.latencies.push({ms: performance.now() - asked, kind, first});
    }
    status(kind, meta);
    updateCommand();
  }

  function status(kind, meta) {
    const badge = $('status');
    if (state.mode === 'look') {
      badge.textContent = state.blend ? 'a blend of two looks: exact'
        : 'the grade apply gives: exact';
      badge.className = 'badge exact';
    } else if (kind === 'exact') {
      badge.textContent = 'exact grade: what the export holds';
      badge.className = 'badge exact';
    } else if (kind === 'extrapolated') {
      badge.textContent = 'live preview; exact in a moment';
      badge.className = 'badge preview';
    } else {
      badge.textContent = `live preview (${Math.round(meta.ms)} ms); exact in a moment`;
      badge.className = 'badge preview';
    }
    badge.dataset.kind = kind;
    badge.dataset.version = String(state.shown.version);
  }

  async function requestPreview() {
    if (state.inFlight) {
      state.dirty = true;
      return;
    }
    state.inFlight = true;
    state.dirty = false;
    const version = state.version;
    try {
      const response = await post('api/preview',
                                  {...body(), client: state.client, seq: ++state.seq});
      if (response.ok) {
        const meta = JSON.parse(response.headers.get('X-Explore-Meta'));
        showLut(new Float32Array(await response.arrayBuffer()), meta, version, meta.kind);
      } else if (response.status !== 409 && version >= state.switched) {
        say(await failure(response), true);
      }
    } catch (e) {
      say(`the server did not answer (${e.message}); is wbcgrade explore still running?`, true);
    }
    state.inFlight = false;
    if (state.dirty && state.mode === 'palette') requestPreview();
  }

  async function requestExact() {
    const version = state.version;
    if (state.exactAsked === version) return;
    if (state.shown.version === version && state.shown.kind === 'exact') return;
    state.exactAsked = version;
    try {
      const response = await post('api/exact', body());
      if (response.ok) {
        const meta = JSON.parse(response.headers.get('X-Explore-Meta'));
        showLut(new Float32Array(await response.arrayBuffer()), meta, version, 'exact');
      } else if (response.status !== 409 && version >= state.switched) {
        say(await failure(response), true);
      }
    } catch (e) {
      say(`the server did not answer (${e.message})`, true);
    }
  }

  function family() {
    return JSON.stringify([state.look.relaxation, state.look.keep_lightness]);
  }

  // The exact map and the fast map's slopes at the exact map's weights: moves near
  // them are shown at once (step 1), before any answer from the server.
  async function requestSlopes(settings, key) {
    if (state.slopesAsked === key) return;
    state.slopesAsked = key;
    try {
      const response = await post('api/slopes', {...settings, source: state.source});
      if (!response.ok) return;  // superseded, or the page moved on
      const meta = JSON.parse(response.headers.get('X-Explore-Meta'));
      const data = new Float32Array(await response.arrayBuffer());
      const size = 3 * meta.size ** 3;
      const slopes = [];
      for (let s = 0; s < meta.styles; s++) {
        slopes.push(data.subarray((s + 1) * size, (s + 2) * size));
      }
      state.model = {key, family: JSON.stringify([settings.relaxation, settings.keep_lightness]),
                     weights: meta.weights, size: meta.size, exact: data.subarray(0, size),
                     slopes};
    } catch (e) {
      // step 1 waits for the next exact map
    }
  }

  function extrapolate() {
    const model = state.model;
    if (!model || model.family !== family()) return false;
    const dw = state.look.weights.map((w, s) => w - model.weights[s]);
    const sum = dw.reduce((a, b) => a + b, 0);
    const lut = Float32Array.from(model.exact);
    dw.forEach((d, s) => {
      const change = d - sum * model.weights[s];  // the move within the simplex
      if (change === 0) return;
      const slope = model.slopes[s];
      for (let q = 0; q < lut.length; q++) lut[q] += change * slope[q];
    });
    for (let q = 0; q < lut.length; q++) lut[q] = Math.min(1, Math.max(0, lut[q]));
    showLut(lut, {size: model.size, ms: 0, weights: null, weights_text: ''}, state.version,
            'extrapolated');
    return true;
  }

  function changed() {
    if (state.mode !== 'palette') return;
    state.version += 1;
    state.changedAt.set(state.version, performance.now());
    if (state.changedAt.size > 200) state.changedAt.delete(state.changedAt.keys().next().value);
    extrapolate();
    requestPreview();
    clearTimeout(state.idle);
    state.idle = setTimeout(requestExact, IDLE_MS);
  }

  // ---------------------------------------------------------------- the command line
  function updateCommand() {
    const meta = state.meta;
    const look = state.look;
    if (meta && state.mode === 'look' && state.blend) {
      $('command').textContent = state.blendCommand || 'A blend has no apply options of its '
        + 'own: Save writes its grade file beside the photo (and the exported LUT holds it); '
        + 'the command to apply that file appears here.';
      return;
    }
    if (meta && state.mode === 'look') {
      const parts = [meta.look.command];
      if (look.strength !== 1) parts.push('--strength', String(look.strength));
      $('command').textContent = parts.join(' ');
      return;
    }
    if (!meta || !state.shown.weightsText) return;
    const parts = [meta.command_prefix, '--weights', state.shown.weightsText, '--no-regrain'];
    if (look.strength !== 1) parts.push('--strength', String(look.strength));
    if (look.relaxation !== null) parts.push('--relax', String(look.relaxation));
    if (look.keep_lightness) parts.push('--preserve-luminance');
    $('command').textContent = parts.join(' ');
  }

  // ---------------------------------------------------------------- the polygon
  function polygon(n) {
    if (n === 1) return [CENTER.slice()];
    if (n === 2) return [[CENTER[0] - 110, CENTER[1]], [CENTER[0] + 110, CENTER[1]]];
    const out = [];
    for (let i = 0; i < n; i++) {
      const angle = -Math.PI / 2 + 2 * Math.PI * i / n;
      out.push([CENTER[0] + RADIUS * Math.cos(angle), CENTER[1] + RADIUS * Math.sin(angle)]);
    }
    const ys = out.map((v) => v[1]);
    const shift = CENTER[1] - (Math.min(...ys) + Math.max(...ys)) / 2;  // centred vertically
    return out.map((v) => [v[0], v[1] + shift]);
  }

  function cross(a, b) { return a[0] * b[1] - a[1] * b[0]; }

  // Mean value coordinates (Floater 2003) of p inside the convex polygon V: positive,
  // smooth, exact on the edges, barycentric coordinates for a triangle.
  function meanValue(p, V) {
    const m = V.length;
    const w = new Array(m).fill(0);
    if (m === 1) return [1];
    if (m === 2) {
      const d = [V[1][0] - V[0][0], V[1][1] - V[0][1]];
      let t = ((p[0] - V[0][0]) * d[0] + (p[1] - V[0][1]) * d[1]) / (d[0] * d[0] + d[1] * d[1]);
      t = Math.min(1, Math.max(0, t));
      return [1 - t, t];
    }
    const s = V.map((v) => [v[0] - p[0], v[1] - p[1]]);
    const r = s.map((d) => Math.hypot(d[0], d[1]));
    for (let i = 0; i < m; i++) {
      if (r[i] < 1e-9) { w[i] = 1; return w; }
    }
    const tan = new Array(m);
    for (let i = 0; i < m; i++) {
      const j = (i + 1) % m;
      const area = cross(s[i], s[j]);
      const dot = s[i][0] * s[j][0] + s[i][1] * s[j][1];
      if (Math.abs(area) <= 1e-9 * r[i] * r[j] && dot < 0) {  // on the edge i-j
        w[i] = r[j] / (r[i] + r[j]);
        w[j] = r[i] / (r[i] + r[j]);
        return w;
      }
      tan[i] = (r[i] * r[j] - dot) / area;  // tan(angle / 2), signed by orientation
    }
    let sum = 0;
    for (let i = 0; i < m; i++) {
      w[i] = (tan[(i - 1 + m) % m] + tan[i]) / r[i];
      sum += w[i];
    }
    return w.map((x) => Math.max(0, x / sum));
  }

  function inside(p, V) {
    if (V.length < 3) return false;
    let sign = 0;
    for (let i = 0; i < V.length; i++) {
      const a = V[i], b = V[(i + 1) % V.length];
      const c = cross([b[0] - a[0], b[1] - a[1]], [p[0] - a[0], p[1] - a[1]]);
      if (Math.abs(c) < 1e-12) continue;
      if (sign === 0) sign = Math.sign(c);
      else if (Math.sign(c) !== sign) return false;
    }
    return true;
  }

  function clamp(p, V) {
    if (V.length === 1) return V[0].slice();
    if (inside(p, V)) return p;
    let best = null, bestD = Infinity;
    const edges = V.length === 2 ? 1 : V.length;
    for (let i = 0; i < edges; i++) {
      const a = V[i], b = V[(i + 1) % V.length];
      const d = [b[0] - a[0], b[1] - a[1]];
      let t = ((p[0] - a[0]) * d[0] + (p[1] - a[1]) * d[1]) / (d[0] * d[0] + d[1] * d[1]);
      t = Math.min(1, Math.max(0, t));
      const q = [a[0] + t * d[0], a[1] + t * d[1]];
      const dist = Math.hypot(q[0] - p[0], q[1] - p[1]);
      if (dist < bestD) { bestD = dist; best = q; }
    }
    return best;
  }

  function pointOf(weights) {
    let x = 0, y = 0;
    weights.forEach((w, i) => { x += w * state.vertices[i][0]; y += w * state.vertices[i][1]; });
    return [x, y];
  }

  function el(name, attrs, parent) {
    const node = document.createElementNS(SVG, name);
    for (const [key, value] of Object.entries(attrs)) node.setAttribute(key, value);
    if (parent) parent.appendChild(node);
    return node;
  }

  function drawSpace() {
    const svg = $('space');
    const V = state.vertices;
    svg.textContent = '';
    const defs = el('defs', {}, svg);
    const clip = el('clipPath', {id: 'shape'}, defs);
    if (V.length >= 3) {
      el('polygon', {points: V.map((v) => v.join(',')).join(' ')}, clip);
    } else if (V.length === 2) {  // a band along the segment
      el('rect', {x: V[0][0], y: CENTER[1] - 8, width: V[1][0] - V[0][0], height: 16,
                  rx: 4}, clip);
    }
    el('image', {id: 'landscape', 'clip-path': 'url(#shape)', preserveAspectRatio: 'none'},
       svg);
    if (V.length >= 3) {
      el('polygon', {class: 'edge', points: V.map((v) => v.join(',')).join(' ')}, svg);
      const mid = [V.reduce((a, v) => a + v[0], 0) / V.length,
                 V.reduce((a, v) => a + v[1], 0) / V.length];
    V.forEach((v) => el('line', {class: 'spoke', x1: mid[0], y1: mid[1],
                                 x2: v[0], y2: v[1]}, svg));
    } else if (V.length === 2) {
      el('line', {class: 'edge', x1: V[0][0], y1: V[0][1], x2: V[1][0], y2: V[1][1]}, svg);
    }
    const middle = [V.reduce((a, v) => a + v[0], 0) / V.length,
                    V.reduce((a, v) => a + v[1], 0) / V.length];
    V.forEach((v, i) => {
      let out = [0, -1];
      if (V.length > 1) {
        const d = [v[0] - middle[0], v[1] - middle[1]];
        const len = Math.hypot(d[0], d[1]);
        out = [d[0] / len, d[1] / len];
      }
      const cx = v[0] + out[0] * 40, cy = v[1] + out[1] * 32;
      el('image', {href: `style/${i}.png?source=${state.source}`, x: cx - 28, y: cy - 21, width: 56, height: 42,
                   preserveAspectRatio: 'xMidYMid slice'}, svg);
      el('rect', {class: 'thumb-frame', x: cx - 28, y: cy - 21, width: 56, height: 42}, svg);
      // names on the outer side: above the picture at the top, below it elsewhere
      const above = out[1] < -0.5;
      const name = el('text', {class: 'name', x: cx, y: above ? cy - 37 : cy + 33}, svg);
      name.textContent = state.meta.names[i];
      el('text', {class: 'share', x: cx, y: above ? cy - 25 : cy + 45, id: `share-${i}`}, svg);
    });
    const fit = pointOf(state.meta.fit.weights);
    el('path', {class: 'fit', id: 'fit-mark',
                d: `M${fit[0]},${fit[1] - 7} l7,7 l-7,7 l-7,-7 z`}, svg);
    el('circle', {class: 'point', id: 'point', r: 7, cx: fit[0], cy: fit[1]}, svg);
  }

  function moveMarks() {
    const p = pointOf(state.look.weights);
    const point = $('point');
    if (point) {
      point.setAttribute('cx', p[0]);
      point.setAttribute('cy', p[1]);
    }
    state.look.weights.forEach((w, i) => {
      const share = $(`share-${i}`);
      if (share) share.textContent = `${Math.round(100 * w)} %`;
      const input = $(`weight-${i}`);
      if (input && document.activeElement !== input) input.value = w.toFixed(3);
    });
  }

  function svgPoint(event) {
    const svg = $('space');
    const pt = svg.createSVGPoint();
    pt.x = event.clientX;
    pt.y = event.clientY;
    const local = pt.matrixTransform(svg.getScreenCTM().inverse());
    return [local.x, local.y];
  }

  function setWeights(weights) {
    state.look.weights = weights;
    moveMarks();
    changed();
  }

  function bindSpace() {
    const svg = $('space');
    let dragging = false;
    const move = (event) => {
      const p = clamp(svgPoint(event), state.vertices);
      setWeights(meanValue(p, state.vertices));
    };
    svg.addEventListener('pointerdown', (event) => {
      if (state.n < 2) return;
      dragging = true;
      svg.setPointerCapture(event.pointerId);
      move(event);
    });
    svg.addEventListener('pointermove', (event) => { if (dragging) move(event); });
    const stop = () => { dragging = false; };
    svg.addEventListener('pointerup', () => { if (dragging) record(); stop(); });
    svg.addEventListener('pointercancel', stop);
  }

  // ---------------------------------------------------------------- the loss landscape
  async function landscape() {
    const V = state.vertices;
    if (V.length < 2) {
      $('space-hint').textContent = '';
      $('sure').textContent = `${fitSentence()} Strength and the options below still apply.`;
      return;
    }
    const xs = V.map((v) => v[0]), ys = V.map((v) => v[1]);
    let box = [Math.min(...xs), Math.min(...ys), Math.max(...xs), Math.max(...ys)];
    if (V.length === 2) box = [box[0], CENTER[1] - 8, box[2], CENTER[1] + 8];
    const rows = [], insideMask = [];
    for (let gy = 0; gy < GRID; gy++) {
      for (let gx = 0; gx < GRID; gx++) {
        const p = [box[0] + (box[2] - box[0]) * gx / (GRID - 1),
                   box[1] + (box[3] - box[1]) * gy / (GRID - 1)];
        insideMask.push(V.length === 2 || inside(p, V));
        rows.push(meanValue(clamp(p, V), V));
      }
    }
    let result;
    const switched = state.switched;  // an answer for another source or mode is dropped
    try {
      const response = await post('api/landscape', {source: state.source, rows});
      if (switched !== state.switched) return;
      if (!response.ok) { say(await failure(response), true); return; }
      result = await response.json();
      if (switched !== state.switched) return;
    } catch (e) {
      return;
    }
    const fitLoss = result.fit_loss;
    const excess = result.losses.map((loss) => (loss - fitLoss) / Math.max(fitLoss, 1e-300));
    // shades spread up to the 90th percentile: a far corner does not flatten the rest
    const sorted = excess.slice().sort((a, b) => a - b);
    const top = Math.max(sorted[Math.floor(0.9 * (sorted.length - 1))], 1e-9);
    const canvas = document.createElement('canvas');
    canvas.width = GRID;
    canvas.height = GRID;
    const ctx = canvas.getContext('2d');
    const image = ctx.createImageData(GRID, GRID);
    // green where a mix explains the photo about as well as the fit, darker the farther
    const span = Math.log1p(Math.max(top, NEAR) / NEAR);
    excess.forEach((e, index) => {
      const s = Math.min(1, Math.log1p(Math.max(0, e) / NEAR) / span);
      const green = Math.max(0, 1 - Math.max(0, e) / NEAR);
      image.data.set([Math.round(12 + 98 * green), Math.round(12 + 178 * green),
                      Math.round(12 + 118 * green), Math.round(60 + 140 * Math.max(s, 0.7 * green))],
                     index * 4);
    });
    ctx.putImageData(image, 0, 0);
    const picture = $('landscape');
    const half = [(box[2] - box[0]) / (GRID - 1) / 2, (box[3] - box[1]) / (GRID - 1) / 2];
    picture.setAttribute('href', canvas.toDataURL());
    picture.setAttribute('x', box[0] - half[0]);
    picture.setAttribute('y', box[1] - half[1]);
    picture.setAttribute('width', box[2] - box[0] + 2 * half[0]);
    picture.setAttribute('height', box[3] - box[1] + 2 * half[1]);
    const inner = excess.filter((e, i) => insideMask[i]);
    const share = inner.filter((e) => e <= NEAR).length / Math.max(1, inner.length);
    const word = share < 0.1 ? 'sure' : share < 0.3 ? 'fairly sure' : 'not sure';
    const sure = $('sure');
    sure.dataset.share = share.toFixed(3);
    sure.innerHTML = '';
    sure.append(`How sure the fit is: `);
    const strong = document.createElement('b');
    strong.textContent = word;
    sure.append(strong,
                ` (mixes within 10 % of its loss cover ${Math.round(100 * share)} % of the`
                + ` shape, in green). ${fitSentence()}`);
  }

  function fitSentence() {
    const fit = state.meta.fit;
    if (state.n === 1) return 'One style: nothing to mix.';
    const ratio = fit.best_single_loss / Math.max(fit.loss, 1e-300);
    if (fit.start === 'vertex') return `No mix beat the single style ${fit.best_single}.`;
    return `The best single style, ${fit.best_single}, is ${ratio.toFixed(2)}× the fit's loss.`;
  }

  // ---------------------------------------------------------------- the weights table
  function buildTable() {
    const body = $('weights').querySelector('tbody');
    body.textContent = '';
    state.meta.names.forEach((name, i) => {
      const row = document.createElement('tr');
      const thumb = document.createElement('td');
      const img = document.createElement('img');
      img.src = `style/${i}.png?source=${state.source}`;
      img.alt = '';
      thumb.appendChild(img);
      const label = document.createElement('td');
      label.textContent = name;
      const fitted = document.createElement('td');
      fitted.className = 'num';
      fitted.textContent = state.meta.fit.weights[i].toFixed(3);
      const cell = document.createElement('td');
      const input = document.createElement('input');
      input.type = 'number';
      input.min = '0';
      input.max = '1';
      input.step = '0.01';
      input.id = `weight-${i}`;
      input.setAttribute('aria-label', `weight of ${name}`);
      input.addEventListener('change', () => typed(i, input));
      cell.appendChild(input);
      row.append(thumb, label, fitted, cell);
      body.appendChild(row);
    });
  }

  // A typed weight is kept; the others share the rest in their current proportions.
  function typed(i, input) {
    const value = Number(input.value);
    if (!Number.isFinite(value) || value < 0 || value > 1 || input.value.trim() === '') {
      say(`a weight is a number from 0 to 1 (got "${input.value}")`, true);
      input.value = state.look.weights[i].toFixed(3);
      return;
    }
    const old = state.look.weights;
    const rest = old.reduce((sum, w, j) => (j === i ? sum : sum + w), 0);
    const weights = old.map((w, j) => {
      if (j === i) return value;
      if (state.n === 1) return 0;
      return rest > 1e-12 ? w * (1 - value) / rest : (1 - value) / (state.n - 1);
    });
    if (!(weights.reduce((a, b) => a + b, 0) > 0)) {
      say('the weights must not all be zero', true);
      input.value = state.look.weights[i].toFixed(3);
      return;
    }
    say('');
    setWeights(weights);
    record();
  }

  // ---------------------------------------------------------------- before / after
  function bindSplit() {
    const stage = $('stage');
    let dragging = false;
    let split = 50;
    let held = null;
    const place = (percent) => {
      split = Math.min(100, Math.max(0, percent));
      $('before').style.clipPath = `inset(0 ${100 - split}% 0 0)`;
      $('split').style.left = `${split}%`;
    };
    const at = (event) => {
      const rect = stage.getBoundingClientRect();
      place(100 * (event.clientX - rect.left) / rect.width);
    };
    stage.addEventListener('pointerdown', (event) => {
      dragging = true;
      stage.setPointerCapture(event.pointerId);
      at(event);
    });
    stage.addEventListener('pointermove', (event) => { if (dragging) at(event); });
    stage.addEventListener('pointerup', () => { dragging = false; });
    stage.addEventListener('pointercancel', () => { dragging = false; });
    document.addEventListener('keydown', (event) => {
      if (event.key !== '\\' || event.target.tagName === 'INPUT') return;
      if (held === null) { held = split; place(100); } else { place(held); held = null; }
    });
    place(50);
  }

  function fitStage() {
    const viewer = $('viewer');
    const stage = $('stage');
    const {width, height} = state.meta.preview;
    const room = [viewer.clientWidth - 24, viewer.clientHeight - 60];
    const scale = Math.min(room[0] / width, room[1] / height, 2.5);  // small photos enlarged
    stage.style.width = `${Math.max(80, Math.floor(width * scale))}px`;
  }

  async function loadPhoto() {
    const image = new Image();
    image.src = 'photo.png';
    await image.decode();
    const {width, height} = state.meta.preview;
    for (const id of ['before', 'after']) {
      $(id).width = width;
      $(id).height = height;
    }
    const ctx = $('before').getContext('2d');
    ctx.drawImage(image, 0, 0);
    state.before = ctx.getImageData(0, 0, width, height);
    state.after = new ImageData(width, height);
    $('after').getContext('2d').drawImage(image, 0, 0);
  }

  // ---------------------------------------------------------------- adjustments and export
  function bindControls() {
    const strength = $('strength');
    strength.addEventListener('input', () => {
      state.look.strength = Number(strength.value) / 100;
      $('strength-out').textContent = `${strength.value} %`;
      render();
      updateCommand();
    });
    strength.addEventListener('change', () => {
      record('strength');
      if (state.mode === 'look') describeLook(state.version);
    });
    $('mode-look').addEventListener('change', () => switchTo(state.source, 'look'));
    $('mode-palette').addEventListener('change', () => switchTo(state.source, 'palette'));
    $('source-pick').addEventListener('change',
                                      () => switchTo(Number($('source-pick').value), state.mode));
    $('blend-pick').addEventListener('change', async () => {
      const value = $('blend-pick').value;
      setBlend(value === '' ? null
        : {source: Number(value), amount: Number($('blend-amount').value) / 100});
      await showBlend();
      record();
    });
    $('blend-amount').addEventListener('input', () => {
      if (!state.blend) return;
      setBlend({...state.blend, amount: Number($('blend-amount').value) / 100});
      showBlend();
    });
    $('blend-amount').addEventListener('change', () => record('blend'));
    $('undo').addEventListener('click', undo);
    $('redo').addEventListener('click', redo);
    $('save').addEventListener('click', saveGraded);
    document.addEventListener('keydown', (event) => {
      const key = event.key.toLowerCase();
      if (!(event.ctrlKey || event.metaKey) || event.altKey) return;
      if (key === 'z' && !event.shiftKey) { event.preventDefault(); undo(); }
      else if ((key === 'z' && event.shiftKey) || key === 'y') { event.preventDefault(); redo(); }
      else if (key === 's') { event.preventDefault(); saveGraded(); }
    });
    const relaxOn = $('relax-on'), relax = $('relax');
    const relaxChanged = () => {
      relax.disabled = !relaxOn.checked;
      const value = RELAX_STEPS[Number(relax.value)];
      $('relax-out').textContent = String(value);
      state.look.relaxation = relaxOn.checked ? value : null;
      changed();
    };
    relaxOn.addEventListener('change', () => { relaxChanged(); record(); });
    relax.addEventListener('input', relaxChanged);
    relax.addEventListener('change', () => record('relax'));
    $('keep').addEventListener('change', () => {
      state.look.keep_lightness = $('keep').checked;
      changed();
      record();
    });
    $('to-fit').addEventListener('click', () => {
      setWeights(state.meta.fitted.weights.slice());
      record();
    });
    $('export-cube').addEventListener('click', () => exportLut('cube', $('export-cube')));
    $('export-clf').addEventListener('click', () => exportLut('clf', $('export-clf')));
    if (!state.meta.formats.includes('clf')) {
      $('export-clf').disabled = true;
      $('export-clf').title = 'needs the opencolorio package: pip install "wbcgrade[ocio]"';
    }
    $('copy').addEventListener('click', async () => {
      const text = $('command').textContent;
      try {
        await navigator.clipboard.writeText(text);
        say('command copied');
      } catch (e) {
        const range = document.createRange();
        range.selectNodeContents($('command'));
        getSelection().removeAllRanges();
        getSelection().addRange(range);
        say('command selected: copy it with Ctrl-C');
      }
    });
    window.addEventListener('resize', fitStage);
  }

  async function exportLut(format, button) {
    const size = Number($('size').value);
    // exactly what is shown: the weights of the picture on screen
    let request = {...body(), format, size};
    if (state.mode === 'look') {
      request = {...lookBody(), mode: 'look', format, size};
    } else if (state.shown.weights) {
      request.weights = state.shown.weights.slice();
    }
    button.disabled = true;
    say('computing the exact grade for the export…');
    try {
      const response = await post('api/export', request);
      if (!response.ok) {
        say(await failure(response), true);
        return;
      }
      const blob = await response.blob();
      const name = new TextDecoder().decode(
        Uint8Array.from(atob(response.headers.get('X-Explore-File')), (c) => c.charCodeAt(0)));
      const link = document.createElement('a');
      link.href = URL.createObjectURL(blob);
      link.download = name;
      document.body.appendChild(link);
      link.click();
      setTimeout(() => { URL.revokeObjectURL(link.href); link.remove(); }, 2000);
      say(`saved ${name} (${size}³) to the browser's downloads`);
      document.body.dataset.exported = name;
    } catch (e) {
      say(`the export failed (${e.message})`, true);
    } finally {
      button.disabled = false;
    }
  }

  // ---------------------------------------------------------------- save
  async function saveGraded() {
    const button = $('save');
    if (button.disabled) return;
    let request = {...lookBody(), mode: 'look'};
    if (state.mode === 'palette') {
      request = {...body(), mode: 'palette'};
      if (state.shown.weights) request.weights = state.shown.weights.slice();
    }
    button.disabled = true;
    say('grading the full-size photo…');
    try {
      const response = await post('api/save', request);
      if (!response.ok) {
        say(await failure(response), true);
        return;
      }
      const saved = await response.json();
      say(`saved ${saved.file} into ${saved.folder}`);
      document.body.dataset.saved = saved.file;
      document.body.dataset.savedCommand = saved.command;
      if (state.mode === 'look' && state.blend) {
        state.blendCommand = saved.command;
        updateCommand();
      }
    } catch (e) {
      say(`the save failed (${e.message})`, true);
    } finally {
      button.disabled = false;
    }
  }

  // ---------------------------------------------------------------- undo and redo
  function snapshot() {
    const look = state.look;
    return {source: state.source, mode: state.mode, strength: look.strength,
            blend: state.mode === 'look' && state.blend ? {...state.blend} : null,
            weights: state.mode === 'palette' ? look.weights.slice() : null,
            relaxation: look.relaxation, keep_lightness: look.keep_lightness};
  }

  // Keep what the page shows now as an undo step. Steps of one control in quick succession
  // (a slider moved with the arrow keys) make one step.
  const COALESCE_MS = 1500;
  function record(control) {
    if (state.restoring || !state.meta) return;
    const now = snapshot();
    const last = state.history[state.history.length - 1];
    if (last && JSON.stringify(last.snap) === JSON.stringify(now)) return;
    const at = performance.now();
    if (last && control && last.control === control && at - last.at < COALESCE_MS
        && state.history.length > 1) {
      state.history.pop();
    }
    state.history.push({snap: now, control, at});
    if (state.history.length > 100) state.history.shift();
    state.future = [];
    historyButtons();
  }

  function historyButtons() {
    $('undo').disabled = state.history.length < 2;
    $('redo').disabled = state.future.length === 0;
  }

  async function restore(snap) {
    state.restoring = true;
    try {
      const blendChanged = JSON.stringify(snap.blend) !== JSON.stringify(state.blend);
      if (snap.mode === 'look') setBlend(snap.blend);
      if (snap.source !== state.source || snap.mode !== state.mode) {
        await switchTo(snap.source, snap.mode, snap.weights);
      } else if (blendChanged) {
        await showBlend();
      }
      setStrength(snap.strength);
      if (snap.mode === 'palette') {
        state.look.relaxation = snap.relaxation;
        state.look.keep_lightness = snap.keep_lightness;
        $('relax-on').checked = snap.relaxation !== null;
        $('relax').disabled = snap.relaxation === null;
        if (snap.relaxation !== null) {
          $('relax').value = String(Math.max(0, RELAX_STEPS.indexOf(snap.relaxation)));
          $('relax-out').textContent = String(snap.relaxation);
        }
        $('keep').checked = snap.keep_lightness;
        if (snap.weights) setWeights(snap.weights.slice());
      }
    } finally {
      state.restoring = false;
      historyButtons();
    }
  }

  async function undo() {
    if (state.history.length < 2) return;
    state.future.push(state.history.pop());
    await restore(state.history[state.history.length - 1].snap);
  }

  async function redo() {
    if (!state.future.length) return;
    const step = state.future.pop();
    state.history.push({...step, control: null});
    await restore(step.snap);
  }

  function setStrength(value) {
    state.look.strength = value;
    $('strength').value = String(Math.round(100 * value));
    $('strength-out').textContent = `${Math.round(100 * value)} %`;
    render();
    updateCommand();
  }

  // ---------------------------------------------------------------- sources and modes
  function describe() {
    const grade = state.meta.look.grade;
    const box = $('grade-words');
    box.textContent = '';
    const lead = document.createElement('b');
    if (state.mode === 'look' && grade.source === 'blend') {
      box.append(grade.words[0].toUpperCase() + grade.words.slice(1), '.');
    } else if (state.mode === 'look') {
      lead.textContent = `${state.meta.styles}: `;
      box.append('The grade ', Object.assign(document.createElement('code'),
                                             {textContent: 'wbcgrade apply'}),
                 ' gives, with ', lead, grade.words, '.');
    } else {
      lead.textContent = `${state.meta.styles}: `;
      box.append('A palette mix of ', lead, 'the photo\'s colours moved onto the blend of '
                 + 'style palettes you choose (', Object.assign(
        document.createElement('code'), {textContent: 'apply'}), ' gives: ', grade.words, ').');
    }
    box.dataset.source = grade.source;
  }

  // What the look grade is at the page's strength (the sentence; the map is the same).
  function lookBody() {
    const out = {source: state.source, strength: state.look.strength};
    if (state.blend) out.blend = {...state.blend};
    return out;
  }

  async function describeLook(version) {
    const strength = state.look.strength;
    const response = await post('api/look', lookBody());
    if (!response.ok || version !== state.version || strength !== state.look.strength) return;
    state.meta.look.grade = JSON.parse(response.headers.get('X-Explore-Meta')).grade;
    describe();
  }

  async function showLook(version) {
    const response = await post('api/look', lookBody());
    if (!response.ok) {
      if (version === state.version) say(await failure(response), true);
      return;
    }
    const meta = JSON.parse(response.headers.get('X-Explore-Meta'));
    const lut = new Float32Array(await response.arrayBuffer());
    if (version !== state.version) return;  // another source or mode meanwhile
    state.meta.look.grade = meta.grade;
    describe();
    state.lut = lut;
    state.lutSize = meta.size;
    state.shown = {version, kind: 'exact', weights: null, weightsText: ''};
    render();
    probe.renders += 1;
    const asked = state.changedAt.get(version);
    if (asked !== undefined) probe.latencies.push({ms: performance.now() - asked, kind: 'look',
                                                   first: true});
    status('exact', meta);
    updateCommand();
  }

  function setBlend(blend) {
    state.blend = blend;
    state.blendCommand = '';
    $('blend-pick').value = blend ? String(blend.source) : '';
    $('blend-amount').disabled = !blend;
    if (blend) {
      $('blend-amount').value = String(Math.round(100 * blend.amount));
      $('blend-out').textContent = `${Math.round(100 * blend.amount)} %`;
    }
  }

  // The look with the blend of now (one request at a time, the newest settings next).
  let blendBusy = false, blendAgain = false;
  async function showBlend() {
    if (blendBusy) { blendAgain = true; return; }
    blendBusy = true;
    state.version += 1;
    state.changedAt.set(state.version, performance.now());
    try {
      await showLook(state.version);
    } finally {
      blendBusy = false;
    }
    if (blendAgain) {
      blendAgain = false;
      await showBlend();
    }
  }

  // Show source `index` in `mode` ('look' or 'palette'); `weights`: the palette mix to show
  // (default: the fitted one).
  async function switchTo(index, mode, weights) {
    clearTimeout(state.idle);
    state.version += 1;
    state.switched = state.version;
    state.changedAt.set(state.version, performance.now());
    const version = state.version;
    const sourceChanged = index !== state.source || !state.meta;
    state.source = index;
    state.mode = mode;
    $('source-pick').value = String(index);
    $(mode === 'look' ? 'mode-look' : 'mode-palette').checked = true;
    for (const id of ['palette-mix', 'palette-adjust', 'palette-weights']) {
      $(id).hidden = mode !== 'palette';
    }
    $('blend-row').hidden = mode !== 'look';
    const badge = $('status');
    badge.textContent = mode === 'palette' && !(state.meta && state.meta.fit && !sourceChanged)
      ? 'fitting the palette mix…' : 'loading…';
    badge.className = 'badge preview';
    badge.dataset.kind = '';
    const needPalette = mode === 'palette';
    if (sourceChanged || (needPalette && !state.meta.fit)) {
      const response = await fetch(`api/state?source=${index}${needPalette ? '&palette=1' : ''}`);
      if (!response.ok) {
        say(await failure(response), true);
        return;
      }
      const meta = await response.json();
      if (version !== state.version) return;
      state.meta = meta;
      state.n = meta.names.length;
      state.model = null;
      state.slopesAsked = '';
      $('source').textContent = `${meta.photo} · ${meta.styles} · ${state.n} style`
        + `${state.n === 1 ? '' : 's'}`;
      if (needPalette) {
        state.vertices = polygon(state.n);
        buildTable();
        drawSpace();
        state.look.weights = (weights || meta.fitted.weights).slice();
        moveMarks();
        $('sure').textContent = `${fitSentence()} Measuring how sure the fit is…`;
        landscape();
      }
    }
    describe();
    if (mode === 'look') {
      await showLook(version);
    } else {
      if (!sourceChanged && !state.vertices.length) {
        state.vertices = polygon(state.n);
        buildTable();
        drawSpace();
        landscape();
      }
      if (weights) state.look.weights = weights.slice();
      if (!state.look.weights.length || state.look.weights.length !== state.n) {
        state.look.weights = state.meta.fitted.weights.slice();
      }
      moveMarks();
      changed();
    }
    record();
  }

  // ---------------------------------------------------------------- start
  async function start() {
    const response = await fetch('api/state');
    if (!response.ok) {
      say(await failure(response), true);
      return;
    }
    state.meta = await response.json();
    state.n = state.meta.names.length;
    const pick = $('source-pick');
    state.meta.sources.forEach((choice, i) => {
      const option = document.createElement('option');
      option.value = String(i);
      option.textContent = choice.label;
      pick.appendChild(option);
      const other = document.createElement('option');
      other.value = String(i);
      other.textContent = `with ${choice.label}`;
      $('blend-pick').appendChild(other);
    });
    $('save-where').textContent = `into ${state.meta.save_dir} (new files, never replacing one)`;
    bindSpace();
    bindSplit();
    bindControls();
    await loadPhoto();
    fitStage();
    state.meta = null;  // loaded again by the switch
    await switchTo(0, 'look');
  }

  start().catch((e) => say(`the page could not start (${e.message})`, true));
})();
