// The 3-D viewer of a lidarfx report page.
//
// The page (written by lidarfx.report) holds a JSON description in
// <script type="application/json" id="lidarfx-meta"> and the binary data as
// base64 in <script type="application/octet-stream"> blocks: point positions
// (float32, relative to meta.centre), per-attribute codes (uint8/16/32 with a
// min and scale per attribute), original point indices when subsampled, and
// line vertices.  Nothing is fetched, so the page works from file://.
//
// Picking projects every point with the camera's matrices in one pass over the
// positions and returns the point whose drawn square covers the clicked pixel
// nearest to the camera (else the nearest square within a few pixels): the point
// seen there, exact for any cloud size, without a GPU read-back (slow on software
// WebGL).  Lines are picked the same way, by distance to their projected segments.
// Frames are drawn on demand (after a change), not in a loop.

import * as THREE from 'three';
import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';
import { LineSegments2 } from 'three/examples/jsm/lines/LineSegments2.js';
import { LineSegmentsGeometry } from 'three/examples/jsm/lines/LineSegmentsGeometry.js';
import { LineMaterial } from 'three/examples/jsm/lines/LineMaterial.js';

// colours are sRGB bytes shown as they are: no linear working space
THREE.ColorManagement.enabled = false;

const hook = window.lidarfxViewer || (window.lidarfxViewer = { ready: false, errors: [] });
hook.errors = hook.errors || [];
hook.ready = false;

const NAN_RGB = [154, 154, 154];
const PICK_RADIUS = 6; // CSS pixels searched around a click
const LINE_PICK_RADIUS = 5;

// viridis, 9 stops (matplotlib)
const VIRIDIS = [
  [68, 1, 84], [71, 44, 122], [59, 81, 139], [44, 113, 142], [33, 144, 141],
  [39, 173, 129], [92, 200, 99], [170, 220, 50], [253, 231, 37],
];

// ASPRS LAS 1.4 classes
const ASPRS = {
  0: '#a0a0a0', 1: '#c8c8c8', 2: '#b08040', 3: '#a6d96a', 4: '#4daf4a', 5: '#1b7837',
  6: '#d6453d', 7: '#ff00ff', 8: '#ffa500', 9: '#3b7dd8', 10: '#8c564b', 11: '#505050',
  12: '#e0e000', 13: '#f4a300', 14: '#ffd21f', 15: '#7b3294', 16: '#c51b7d', 17: '#8c6d31',
  18: '#ff33cc', 19: '#35978f', 20: '#d8b365', 21: '#e0f3f8', 22: '#bbbbbb',
};

// categorical palette (tab10 then the light tab20 colours)
const PALETTE = [
  '#1f77b4', '#ff7f0e', '#2ca02c', '#d62728', '#9467bd', '#8c564b', '#e377c2', '#7f7f7f',
  '#bcbd22', '#17becf', '#aec7e8', '#ffbb78', '#98df8a', '#ff9896', '#c5b0d5', '#c49c94',
  '#f7b6d2', '#c7c7c7', '#dbdb8d', '#9edae5',
];

const LINE_COLOURS = ['#ff2d55', '#00c8ff', '#ffd400', '#ff7a00', '#7cff4f', '#c86bff', '#ffffff', '#00e0a0'];

function hexRGB(hex) {
  const v = parseInt(hex.slice(1), 16);
  return [(v >> 16) & 255, (v >> 8) & 255, v & 255];
}

function viridis(t) {
  const x = Math.min(1, Math.max(0, t)) * (VIRIDIS.length - 1);
  const i = Math.min(VIRIDIS.length - 2, Math.floor(x));
  const f = x - i;
  const a = VIRIDIS[i], b = VIRIDIS[i + 1];
  return [0, 1, 2].map((k) => Math.round(a[k] + (b[k] - a[k]) * f));
}

function bytesOf(id) {
  const el = document.getElementById(id);
  if (!el) throw new Error(`lidarfx viewer: data block ${id} is missing`);
  const text = el.textContent;
  if (typeof Uint8Array.fromBase64 === 'function') return Uint8Array.fromBase64(text.trim());
  const bin = atob(text.trim());
  const out = new Uint8Array(bin.length);
  for (let i = 0; i < bin.length; i++) out[i] = bin.charCodeAt(i);
  return out;
}

function typed(id, type) {
  const b = bytesOf(id);
  const T = { f32: Float32Array, u8: Uint8Array, u16: Uint16Array, u32: Uint32Array }[type];
  return new T(b.buffer, b.byteOffset, b.byteLength / T.BYTES_PER_ELEMENT);
}

function el(tag, attrs, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) {
    if (k === 'class') e.className = v;
    else if (k === 'text') e.textContent = v;
    else e.setAttribute(k, v);
  }
  for (const c of children) if (c != null) e.append(c);
  return e;
}

function fmtNumber(v, decimals) {
  if (!Number.isFinite(v)) return Number.isNaN(v) ? 'NaN' : String(v);
  if (decimals == null) {
    if (Number.isInteger(v)) return String(v);
    return String(Number(v.toPrecision(6)));
  }
  return v.toFixed(decimals);
}

function webgl2Available() {
  try {
    const c = document.createElement('canvas');
    return !!(window.WebGL2RenderingContext && c.getContext('webgl2'));
  } catch (e) {
    return false;
  }
}

class Attribute {
  constructor(spec) {
    Object.assign(this, spec);
    this.codes = typed(spec.block, spec.type);
    this.labels = spec.labels || {};
    this.integer = spec.scale === 1 && Number.isInteger(spec.min);
    // decimals that show the quantisation step (about 4-5 significant digits over the range)
    this.decimals = this.integer ? null : Math.min(10, Math.max(0, Math.ceil(-Math.log10(spec.scale || 1))));
  }

  value(i) {
    const c = this.codes[i];
    if (this.nan_code != null && c === this.nan_code) return NaN;
    return this.min + c * this.scale;
  }

  text(i) {
    const v = this.value(i);
    const s = fmtNumber(v, Number.isNaN(v) ? null : this.decimals);
    const label = this.labels[String(v)];
    return label != null ? `${s} (${label})` : s;
  }
}

class Viewer {
  constructor(root, meta) {
    this.root = root;
    this.meta = meta;
    this.centre = meta.centre;
    this.cloud = meta.cloud;
    this.frames = 0;
    this.size = this.cloud ? (this.cloud.n_shown > 400000 ? 1.5 : 2.5) : 2;
    this.attrs = new Map();
    if (this.cloud) {
      hook.timings.decode0 = performance.now();
      this.positions = typed(this.cloud.positions, 'f32');
      this.index = this.cloud.index ? typed(this.cloud.index, 'u32') : null;
      for (const spec of this.cloud.attributes) this.attrs.set(spec.name, new Attribute(spec));
    }
    hook.timings.decoded = performance.now();
    this.buildDom();
    this.buildScene();
    hook.timings.scene = performance.now();
    const names = [...this.attrs.keys()];
    this.colourNames = [];
    if (this.cloud) {
      this.colourNames = names.slice();
      if (!this.attrs.has('z')) this.colourNames.splice(names.indexOf('classification') + 1, 0, 'z');
      if (['red', 'green', 'blue'].every((n) => this.attrs.has(n))) this.colourNames.push('rgb');
      for (const n of this.colourNames) this.select.append(el('option', { value: n, text: n }));
      const first = this.colourNames.includes(this.cloud.colour_by) ? this.cloud.colour_by : this.colourNames[0];
      this.colourBy(first);
    }
    this.fitView();
    this.requestDraw();
  }

  // ---------------------------------------------------------------- DOM
  buildDom() {
    const r = this.root;
    r.textContent = '';
    this.toolbar = el('div', { class: 'lfx-toolbar' });
    if (this.cloud) {
      this.select = el('select', { 'aria-label': 'colour by', id: 'lfx-colour' });
      this.select.addEventListener('change', () => this.colourBy(this.select.value));
      this.toolbar.append(el('label', {}, 'colour by ', this.select));
      this.sizeInput = el('input', { type: 'range', min: '1', max: '10', step: '0.5', value: String(this.size), id: 'lfx-size' });
      this.sizeInput.addEventListener('input', () => this.setPointSize(Number(this.sizeInput.value)));
      this.toolbar.append(el('label', {}, 'point size ', this.sizeInput));
    }
    this.layerBox = el('span', { class: 'lfx-layers' });
    this.toolbar.append(this.layerBox);
    const reset = el('button', { type: 'button', text: 'reset view' });
    reset.addEventListener('click', () => { this.fitView(); this.requestDraw(); });
    const top = el('button', { type: 'button', text: 'top view' });
    top.addEventListener('click', () => { this.fitView(true); this.requestDraw(); });
    this.toolbar.append(reset, top);
    this.stage = el('div', { class: 'lfx-stage' });
    this.legend = el('div', { class: 'lfx-legend' });
    this.panel = el('div', { class: 'lfx-pick', hidden: '' });
    this.help = el('div', { class: 'lfx-help', text: 'drag: rotate · right-drag or shift-drag: pan · wheel: zoom · click: pick' });
    this.stage.append(this.legend, this.panel, this.help);
    r.append(this.toolbar, this.stage);
  }

  // -------------------------------------------------------------- scene
  buildScene() {
    const renderer = new THREE.WebGLRenderer({ antialias: false, preserveDrawingBuffer: true });
    renderer.setPixelRatio(window.devicePixelRatio || 1);
    renderer.outputColorSpace = THREE.LinearSRGBColorSpace;
    renderer.setClearColor(0x16181d, 1);
    this.renderer = renderer;
    this.canvas = renderer.domElement;
    this.canvas.className = 'lfx-canvas';
    this.stage.prepend(this.canvas);
    this.scene = new THREE.Scene();
    this.camera = new THREE.PerspectiveCamera(45, 1, 0.01, 1000);
    this.camera.up.set(0, 0, 1);
    this.controls = new OrbitControls(this.camera, this.canvas);
    this.controls.screenSpacePanning = true;
    this.controls.addEventListener('change', () => this.requestDraw());

    if (this.cloud) {
      const n = this.cloud.n_shown;
      const geom = new THREE.BufferGeometry();
      geom.setAttribute('position', new THREE.BufferAttribute(this.positions, 3));
      this.colours = new Uint8Array(n * 3);
      this.colourAttr = new THREE.BufferAttribute(this.colours, 3, true);
      geom.setAttribute('color', this.colourAttr);
      geom.computeBoundingSphere();
      this.material = new THREE.PointsMaterial({ size: this.size, sizeAttenuation: false, vertexColors: true });
      this.points = new THREE.Points(geom, this.material);
      this.points.frustumCulled = false;
      this.scene.add(this.points);
      // marker of the picked point
      const mg = new THREE.BufferGeometry();
      mg.setAttribute('position', new THREE.BufferAttribute(new Float32Array(3), 3));
      this.marker = new THREE.Points(mg, new THREE.PointsMaterial({
        size: 22, sizeAttenuation: false, map: ringTexture(), transparent: true, depthTest: false, color: 0xffffff,
      }));
      this.marker.visible = false;
      this.marker.renderOrder = 10;
      this.marker.frustumCulled = false;
      this.scene.add(this.marker);
    }
    this.buildLayers();
    this.resize();
    new ResizeObserver(() => { if (this.resize()) this.requestDraw(); }).observe(this.stage);

    let down = null;
    this.canvas.addEventListener('pointerdown', (e) => { down = { x: e.clientX, y: e.clientY, b: e.button }; });
    this.canvas.addEventListener('pointerup', (e) => {
      if (!down || down.b !== 0) return;
      const moved = Math.hypot(e.clientX - down.x, e.clientY - down.y);
      down = null;
      if (moved > 4) return;
      const rect = this.canvas.getBoundingClientRect();
      this.showPick(e.clientX - rect.left, e.clientY - rect.top);
    });
  }

  buildLayers() {
    this.layers = [];
    (this.meta.layers || []).forEach((spec, k) => {
      const v = typed(spec.block, 'f32');
      // polylines -> segment pairs
      let nseg = 0;
      for (const [, count] of spec.lines) nseg += Math.max(0, count - 1);
      const seg = new Float32Array(nseg * 6);
      const segLine = new Uint32Array(nseg);
      let s = 0;
      spec.lines.forEach(([start, count], li) => {
        for (let j = 0; j < count - 1; j++) {
          const a = (start + j) * 3, b = (start + j + 1) * 3;
          seg.set([v[a], v[a + 1], v[a + 2], v[b], v[b + 1], v[b + 2]], s * 6);
          segLine[s++] = li;
        }
      });
      const colour = spec.colour || LINE_COLOURS[k % LINE_COLOURS.length];
      const geom = new LineSegmentsGeometry();
      geom.setPositions(seg);
      const mat = new LineMaterial({ color: new THREE.Color(colour).getHex(), linewidth: 2.5, depthTest: true });
      const obj = new LineSegments2(geom, mat);
      obj.frustumCulled = false;
      obj.renderOrder = 5;
      this.scene.add(obj);
      const layer = { spec, obj, mat, seg, segLine, colour, visible: true };
      this.layers.push(layer);
      const box = el('input', { type: 'checkbox', 'data-layer': spec.name });
      box.checked = true;
      box.addEventListener('change', () => { layer.visible = obj.visible = box.checked; this.requestDraw(); });
      const swatch = el('span', { class: 'lfx-swatch', style: `background:${colour}` });
      this.layerBox.append(el('label', { class: 'lfx-layer' }, box, swatch, ` ${spec.name} (${spec.lines.length})`));
    });
  }

  // fit the drawing buffer to the stage; false when the size did not change
  resize() {
    const w = Math.max(1, this.stage.clientWidth), h = Math.max(1, this.stage.clientHeight);
    if (this.cssSize && this.cssSize[0] === w && this.cssSize[1] === h) return false;
    this.cssSize = [w, h];
    this.renderer.setSize(w, h, false);
    this.canvas.style.width = `${w}px`;
    this.canvas.style.height = `${h}px`;
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    for (const l of this.layers || []) l.mat.resolution.set(w, h);
    return true;
  }

  // the box around the points and lines, relative to the centre
  extent() {
    const box = new THREE.Box3();
    if (this.cloud) {
      const b = this.cloud.bounds;
      box.expandByPoint(new THREE.Vector3(...b.min.map((v, k) => v - this.centre[k])));
      box.expandByPoint(new THREE.Vector3(...b.max.map((v, k) => v - this.centre[k])));
    }
    for (const l of this.layers) {
      const s = l.seg;
      for (let i = 0; i < s.length; i += 3) box.expandByPoint(new THREE.Vector3(s[i], s[i + 1], s[i + 2]));
    }
    if (box.isEmpty()) box.set(new THREE.Vector3(-1, -1, -1), new THREE.Vector3(1, 1, 1));
    return box;
  }

  fitView(top = false) {
    const box = this.extent();
    const centre = box.getCenter(new THREE.Vector3());
    const radius = Math.max(box.getSize(new THREE.Vector3()).length() / 2, 1e-3);
    // the narrower of the vertical and horizontal fields of view frames the bounding sphere
    const vfov = THREE.MathUtils.degToRad(this.camera.fov);
    const hfov = 2 * Math.atan(Math.tan(vfov / 2) * this.camera.aspect);
    const dist = (radius / Math.tan(Math.min(vfov, hfov) / 2)) * 0.9;
    const dir = top ? new THREE.Vector3(0, -1e-3, 1) : new THREE.Vector3(0.35, -1, 0.75);
    dir.normalize();
    this.camera.near = Math.max(dist * 1e-4, radius * 1e-5);
    this.camera.far = dist * 50 + radius * 10;
    this.camera.position.copy(centre).addScaledVector(dir, dist);
    this.camera.updateProjectionMatrix();
    this.controls.target.copy(centre);
    this.controls.maxDistance = dist * 20;
    this.controls.update();
  }

  // ---------------------------------------------------------- drawing
  // draw at the next animation frame, once however many changes came before it
  requestDraw() {
    if (this.pending) return;
    this.pending = true;
    requestAnimationFrame(() => { this.pending = false; this.draw(); });
  }

  draw() {
    this.renderer.render(this.scene, this.camera);
    this.frames += 1;
    hook.frames = this.frames;
    if (!hook.ready && hook.timings) hook.timings.ready = performance.now();
    hook.ready = true;
  }

  setPointSize(s) {
    this.size = s;
    if (this.material) this.material.size = s;
    this.requestDraw();
  }

  // --------------------------------------------------------- colouring
  colourBy(name) {
    if (!this.cloud) return false;
    if (!this.colourNames.includes(name)) throw new Error(`no attribute ${name}`);
    const n = this.cloud.n_shown;
    const out = this.colours;
    this.select.value = name;
    this.current = name;
    if (name === 'z') {
      const zs = this.cloud.z;
      const lut = this.lut();
      const lo = zs.lo - this.centre[2], span = (zs.hi - zs.lo) || 1;
      const p = this.positions;
      for (let i = 0; i < n; i++) {
        const z = p[i * 3 + 2];
        const t = Math.min(255, Math.max(0, Math.round(((z - lo) / span) * 255))) * 3;
        out[i * 3] = lut[t]; out[i * 3 + 1] = lut[t + 1]; out[i * 3 + 2] = lut[t + 2];
      }
      this.showColourBar('z', zs.lo, zs.hi);
    } else if (name === 'rgb') {
      const [r, g, b] = ['red', 'green', 'blue'].map((k) => this.attrs.get(k));
      const top = Math.max(r.vmax, g.vmax, b.vmax) > 255 ? 65535 : 255;
      for (let i = 0; i < n; i++) {
        out[i * 3] = Math.round((r.value(i) / top) * 255) || 0;
        out[i * 3 + 1] = Math.round((g.value(i) / top) * 255) || 0;
        out[i * 3 + 2] = Math.round((b.value(i) / top) * 255) || 0;
      }
      this.legend.textContent = '';
      this.legend.append(el('div', { class: 'lfx-legend-title', text: 'rgb (red, green, blue)' }));
    } else {
      const a = this.attrs.get(name);
      const colourOf = a.kind === 'categorical' ? this.categoricalColours(a) : this.continuousColours(a);
      if (a.type === 'u32') {
        for (let i = 0; i < n; i++) {
          const c = colourOf(a.value(i));
          out[i * 3] = c[0]; out[i * 3 + 1] = c[1]; out[i * 3 + 2] = c[2];
        }
      } else {
        // one colour per code, then a table look-up per point
        const ncode = a.type === 'u8' ? 256 : 65536;
        const table = new Uint8Array(ncode * 3);
        const top = Math.min(ncode - 1, a.max_code == null ? ncode - 1 : a.max_code);
        for (let c = 0; c <= top; c++) {
          const v = a.nan_code != null && c === a.nan_code ? NaN : a.min + c * a.scale;
          table.set(colourOf(v), c * 3);
        }
        if (a.nan_code != null) table.set(NAN_RGB, a.nan_code * 3);
        const codes = a.codes;
        for (let i = 0; i < n; i++) {
          const t = codes[i] * 3;
          out[i * 3] = table[t]; out[i * 3 + 1] = table[t + 1]; out[i * 3 + 2] = table[t + 2];
        }
      }
      if (a.kind === 'categorical') this.showCategories(a, colourOf);
      else this.showColourBar(name, a.lo, a.hi);
    }
    this.colourAttr.needsUpdate = true;
    this.requestDraw();
    return true;
  }

  lut() {
    if (!this._lut) {
      this._lut = new Uint8Array(256 * 3);
      for (let i = 0; i < 256; i++) this._lut.set(viridis(i / 255), i * 3);
    }
    return this._lut;
  }

  continuousColours(a) {
    const lut = this.lut();
    const lo = a.lo, span = (a.hi - a.lo) || 1;
    return (v) => {
      if (!Number.isFinite(v)) return NAN_RGB;
      const t = Math.min(255, Math.max(0, Math.round(((v - lo) / span) * 255))) * 3;
      return [lut[t], lut[t + 1], lut[t + 2]];
    };
  }

  categoricalColours(a) {
    const rank = new Map();
    (a.categories || []).forEach(([v], k) => rank.set(v, k));
    const asprs = a.name === 'classification';
    const cache = new Map();
    return (v) => {
      if (!Number.isFinite(v)) return NAN_RGB;
      let c = cache.get(v);
      if (c) return c;
      if (asprs && ASPRS[v] != null) c = hexRGB(ASPRS[v]);
      else {
        let k = rank.get(v);
        if (k == null) k = Math.abs(Math.imul(v | 0, 2654435761) >>> 0);
        c = hexRGB(PALETTE[k % PALETTE.length]);
      }
      cache.set(v, c);
      return c;
    };
  }

  showCategories(a, colourOf) {
    const lg = this.legend;
    lg.textContent = '';
    lg.append(el('div', { class: 'lfx-legend-title', text: a.name }));
    if (!a.categories) {
      lg.append(el('div', { text: `${a.n_distinct} values, colours repeat` }));
      return;
    }
    const list = el('div', { class: 'lfx-legend-list' });
    for (const [v, count] of a.categories) {
      const rgb = colourOf(v);
      const label = a.labels[String(v)];
      list.append(el('div', { class: 'lfx-legend-row' },
        el('span', { class: 'lfx-swatch', style: `background:rgb(${rgb.join(',')})` }),
        ` ${v}${label != null ? ` ${label}` : ''} `,
        el('span', { class: 'lfx-count', text: count.toLocaleString('en') })));
    }
    if (a.nan_count) {
      list.append(el('div', { class: 'lfx-legend-row' },
        el('span', { class: 'lfx-swatch', style: `background:rgb(${NAN_RGB.join(',')})` }), ' no value ',
        el('span', { class: 'lfx-count', text: a.nan_count.toLocaleString('en') })));
    }
    lg.append(list);
  }

  showColourBar(name, lo, hi) {
    const stops = VIRIDIS.map((c, k) => `rgb(${c.join(',')}) ${(k / (VIRIDIS.length - 1)) * 100}%`).join(',');
    const lg = this.legend;
    lg.textContent = '';
    lg.append(
      el('div', { class: 'lfx-legend-title', text: `${name} (2–98 %)` }),
      el('div', { class: 'lfx-bar', style: `background:linear-gradient(to right,${stops})` }),
      el('div', { class: 'lfx-bar-labels' }, el('span', { text: fmtNumber(lo) }), el('span', { text: fmtNumber(hi) })),
    );
  }

  // ----------------------------------------------------------- picking
  // CSS pixels from the canvas' top-left corner of shown point i (null when outside the view)
  screenOf(i) {
    if (!this.cloud || !(i >= 0 && i < this.cloud.n_shown)) return null;
    const p = this.positions;
    return this.screenOfOffset(p[i * 3], p[i * 3 + 1], p[i * 3 + 2]);
  }

  // the same for absolute coordinates
  screenOfXYZ(x, y, z) {
    return this.screenOfOffset(x - this.centre[0], y - this.centre[1], z - this.centre[2]);
  }

  screenOfOffset(x, y, z) {
    this.camera.updateMatrixWorld();
    const v = new THREE.Vector3(x, y, z).project(this.camera);
    if (!(v.z >= -1 && v.z <= 1 && Math.abs(v.x) <= 1 && Math.abs(v.y) <= 1)) return null;
    const w = this.canvas.clientWidth, h = this.canvas.clientHeight;
    return [((v.x + 1) / 2) * w, ((1 - v.y) / 2) * h];
  }

  // The point drawn at (x, y) (CSS pixels from the canvas' top-left corner): among the
  // points whose square (the point size) covers that pixel the nearest to the camera,
  // else the point whose square is nearest within PICK_RADIUS pixels; -1 if none.
  // The same projection as the GPU's, evaluated for every point in one pass (about
  // 20 ms per million points), so no read-back of a picking render is needed.
  pickAt(x, y) {
    if (!this.cloud) return -1;
    const cam = this.camera;
    cam.updateMatrixWorld();
    const m = new THREE.Matrix4().multiplyMatrices(cam.projectionMatrix, cam.matrixWorldInverse).elements;
    const w = this.canvas.clientWidth, h = this.canvas.clientHeight;
    const half = this.size / 2, reach = half + PICK_RADIUS;
    const p = this.positions, n = this.cloud.n_shown;
    let best = -1, bestCovers = false, bestD = Infinity, bestZ = Infinity;
    for (let i = 0; i < n; i++) {
      const px = p[i * 3], py = p[i * 3 + 1], pz = p[i * 3 + 2];
      const cw = m[3] * px + m[7] * py + m[11] * pz + m[15];
      if (cw <= 0) continue;
      const dx = ((m[0] * px + m[4] * py + m[8] * pz + m[12]) / cw + 1) * 0.5 * w - x;
      if (dx > reach || dx < -reach) continue;
      const dy = (1 - (m[1] * px + m[5] * py + m[9] * pz + m[13]) / cw) * 0.5 * h - y;
      if (dy > reach || dy < -reach) continue;
      const z = (m[2] * px + m[6] * py + m[10] * pz + m[14]) / cw;
      if (z < -1 || z > 1) continue;
      const ax = Math.abs(dx), ay = Math.abs(dy);
      if (ax <= half && ay <= half) {
        if (!bestCovers || z < bestZ) { best = i; bestCovers = true; bestZ = z; }
      } else if (!bestCovers) {
        const ex = Math.max(0, ax - half), ey = Math.max(0, ay - half);
        const d = ex * ex + ey * ey;
        if (d <= PICK_RADIUS * PICK_RADIUS && (d < bestD || (d === bestD && z < bestZ))) { best = i; bestD = d; bestZ = z; }
      }
    }
    return best;
  }

  // the nearest visible line segment within LINE_PICK_RADIUS pixels: [layer, line] or null
  lineAt(x, y) {
    const w = this.canvas.clientWidth, h = this.canvas.clientHeight;
    const a = new THREE.Vector3(), b = new THREE.Vector3();
    let best = null, bestD = LINE_PICK_RADIUS;
    for (const l of this.layers) {
      if (!l.visible) continue;
      const s = l.seg;
      for (let k = 0; k < s.length / 6; k++) {
        a.set(s[k * 6], s[k * 6 + 1], s[k * 6 + 2]).project(this.camera);
        b.set(s[k * 6 + 3], s[k * 6 + 4], s[k * 6 + 5]).project(this.camera);
        if (a.z > 1 || b.z > 1 || a.z < -1 || b.z < -1) continue;
        const ax = ((a.x + 1) / 2) * w, ay = ((1 - a.y) / 2) * h;
        const bx = ((b.x + 1) / 2) * w, by = ((1 - b.y) / 2) * h;
        const dx = bx - ax, dy = by - ay;
        const len2 = dx * dx + dy * dy;
        const t = len2 > 0 ? Math.min(1, Math.max(0, ((x - ax) * dx + (y - ay) * dy) / len2)) : 0;
        const d = Math.hypot(x - ax - t * dx, y - ay - t * dy);
        if (d < bestD) { bestD = d; best = [l, l.segLine[k]]; }
      }
    }
    return best;
  }

  showPick(x, y) {
    const line = this.lineAt(x, y);
    if (line) return this.showLine(...line);
    const i = this.pickAt(x, y);
    if (i < 0) {
      this.panel.hidden = true;
      if (this.marker) this.marker.visible = false;
      this.requestDraw();
      return -1;
    }
    this.showPoint(i);
    return i;
  }

  panelHeader(title) {
    const p = this.panel;
    p.textContent = '';
    const close = el('button', { type: 'button', class: 'lfx-close', 'aria-label': 'close', text: '×' });
    close.addEventListener('click', () => {
      p.hidden = true;
      if (this.marker) this.marker.visible = false;
      this.requestDraw();
    });
    p.append(close, el('div', { class: 'lfx-pick-title', text: title }));
    p.hidden = false;
  }

  showPoint(i) {
    const p = this.positions, c = this.centre;
    const original = this.index ? this.index[i] : i;
    this.panelHeader(`point ${original}`);
    const rows = [['x', (p[i * 3] + c[0]).toFixed(3)], ['y', (p[i * 3 + 1] + c[1]).toFixed(3)], ['z', (p[i * 3 + 2] + c[2]).toFixed(3)]];
    for (const a of this.attrs.values()) rows.push([a.name, a.text(i)]);
    const table = el('table', { class: 'lfx-pick-table' });
    for (const [k, v] of rows) table.append(el('tr', { 'data-name': k }, el('th', { text: k }), el('td', { text: v })));
    this.panel.append(table);
    this.panel.dataset.point = String(i);
    this.marker.geometry.attributes.position.array.set([p[i * 3], p[i * 3 + 1], p[i * 3 + 2]]);
    this.marker.geometry.attributes.position.needsUpdate = true;
    this.marker.visible = true;
    this.requestDraw();
  }

  showLine(layer, li) {
    const count = layer.spec.lines[li][1];
    this.panelHeader(`${layer.spec.name}: line ${li + 1}`);
    const table = el('table', { class: 'lfx-pick-table' });
    const props = (layer.spec.properties || [])[li] || {};
    const rows = [['vertices', String(count)], ...Object.entries(props)];
    for (const [k, v] of rows) table.append(el('tr', { 'data-name': k }, el('th', { text: k }), el('td', { text: String(v) })));
    this.panel.append(table);
    if (this.marker) this.marker.visible = false;
    this.requestDraw();
    return li;
  }
}

// a white ring with a dark outline: the marker of the picked point
function ringTexture() {
  const c = document.createElement('canvas');
  c.width = c.height = 64;
  const g = c.getContext('2d');
  for (const [width, colour] of [[16, '#000'], [8, '#fff']]) {
    g.lineWidth = width;
    g.strokeStyle = colour;
    g.beginPath();
    g.arc(32, 32, 22, 0, Math.PI * 2);
    g.stroke();
  }
  return new THREE.CanvasTexture(c);
}

function start() {
  hook.timings = { start: performance.now() };
  const root = document.getElementById('lidarfx-viewer');
  const metaEl = document.getElementById('lidarfx-meta');
  if (!root || !metaEl) return;
  const meta = JSON.parse(metaEl.textContent);
  hook.attributes = [];
  if (!webgl2Available()) {
    root.textContent = '';
    root.append(el('div', { class: 'lfx-nowebgl', text: 'WebGL 2 is not available in this browser, so the 3-D view cannot be shown. '
      + 'The rest of the report is complete; open it in a browser with hardware acceleration or WebGL enabled.' }));
    hook.webgl = false;
    return;
  }
  hook.webgl = true;
  const v = new Viewer(root, meta);
  hook.timings.viewer = performance.now();
  Object.assign(hook, {
    viewer: v,
    attributes: v.colourNames.slice(),
    n: v.cloud ? v.cloud.n_shown : 0,
    colourBy: (name) => v.colourBy(name),
    screenOf: (i) => v.screenOf(i),
    screenOfXYZ: (x, y, z) => v.screenOfXYZ(x, y, z),
    pickAt: (x, y) => v.pickAt(x, y),
    pick: (x, y) => v.showPick(x, y),
    setPointSize: (s) => v.setPointSize(s),
  });

}

try {
  start();
} catch (e) {
  hook.errors.push(String((e && e.stack) || e));
  const root = document.getElementById('lidarfx-viewer');
  if (root) root.append(el('div', { class: 'lfx-nowebgl', text: `The 3-D view failed: ${e && e.message ? e.message : e}` }));
  throw e;
}
