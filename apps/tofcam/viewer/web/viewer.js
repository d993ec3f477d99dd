// tofcam view: the page. Fetches the latest frame (binary, docs/viewer.md), draws it, and posts
// control changes. window.viewerState is what the browser test reads.
'use strict';

const state = {
  seq: 0, frames: 0, dropped: 0, validPct: null, serverValidPct: null, fps: 0,
  history: [], meta: null, rays: null, last: null, paused: false, recording: false,
  chartUpdates: 0, lastError: '', client: 'c' + Math.random().toString(36).slice(2, 10),
  // ?cloud=off skips the 3D view (a machine without a GPU draws it in software).
  cloudOff: new URLSearchParams(location.search).get('cloud') === 'off',
};
window.viewerState = state;

// 'denoise' is the stage before the filters (each pixel the mean, or with fit_plane in the
// configuration the fitted plane, of its own surface's 3x3); 'prediction' the neighbours'
// prediction, which the uncertainty judges residuals against and kept pixels are combined with.
const FILTERS = ['saturation', 'accuracy', 'amplitude', 'jump_edge', 'flying_pixel',
                 'weingarten', 'uncertainty', 'denoise', 'prediction'];
// Which filter removed a pixel, in the order they are judged; colours for the cause image.
const CAUSES = [
  ['saturated', [255, 255, 255]], ['low-amplitude', [80, 80, 255]],
  ['high-delta-l', [255, 60, 60]], ['jump-edge', [255, 200, 0]],
  ['flying-pixel', [255, 120, 0]], ['out-of-range', [160, 0, 160]],
  ['sparse-cell', [0, 200, 200]], ['inconsistent', [0, 255, 0]],
  ['low-confidence', [255, 0, 255]], ['invalid', [120, 120, 120]],
];

const $ = (id) => document.getElementById(id);
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

function showError(text) {
  state.lastError = text;
  $('error').textContent = text;
}

// The server's recording state, not the page's guess: a recording that failed to start or
// stopped on an error turns the button back.
function showRecording(path) {
  state.recording = !!path;
  $('record').textContent = state.recording ? 'stop recording' : 'start recording';
}

// The camera loop's errors: shown when the count grows, so an error from before the page was
// opened is not shown again.
function showLoopErrors(count, text) {
  if (count === undefined) return;
  if (state.loopErrors === undefined) state.loopErrors = count;
  if (count > state.loopErrors && text) showError('camera loop: ' + text);
  state.loopErrors = count;
}

// After a recording request: the loop begins or ends the file at its next step, also while
// paused (when no frame comes to tell the page), so /status is asked until it shows.
async function followRecording(wanted) {
  for (let k = 0; k < 20; ++k) {
    await sleep(100);
    try {
      const s = await (await fetch('/status', {cache: 'no-store'})).json();
      showRecording(s.recording);
      showLoopErrors(s.errors, s.last_error);
      if (state.recording === wanted) return;
    } catch (e) {
      return;
    }
  }
}

async function post(controls) {
  try {
    const r = await fetch('/control', {
      method: 'POST', headers: {'Content-Type': 'application/json'},
      body: JSON.stringify(controls),
    });
    const body = await r.json();
    if (!r.ok) { showError('refused: ' + body.error); return false; }
    showError('');
    // Show what is in effect now (a script or another page may have changed it too).
    state.meta = await (await fetch('/meta')).json();
    refreshControls();
    return true;
  } catch (e) {
    showError('control failed: ' + e);
    return false;
  }
}

function flagBit(name) {
  const f = state.meta.flags.find((x) => x.name === name);
  return f ? f.bit : 0;
}

function parse(buf) {
  const dv = new DataView(buf);
  if (dv.getUint32(0, true) !== 0x56464f54) throw new Error('not a tofcam frame');
  const hlen = dv.getUint32(8, true);
  const header = JSON.parse(new TextDecoder().decode(new Uint8Array(buf, 12, hlen)));
  const base = 12 + hlen;
  const planes = {};
  for (const p of header.planes) {
    const off = base + p.offset;
    if (p.type === 'u8') planes[p.name] = new Uint8Array(buf, off, p.bytes);
    else if (p.type === 'u16') planes[p.name] = new Uint16Array(buf, off, p.bytes / 2);
    else planes[p.name] = new Float32Array(buf, off, p.bytes / 4);
  }
  return {header, planes};
}

// Images are shown 260 px wide whatever the camera's size (pixelated, aspect kept).
function sizeCanvas(c, w, h) {
  if (c.width !== w || c.height !== h) {
    c.width = w; c.height = h;
    c.style.width = '260px'; c.style.height = Math.round(260 * h / w) + 'px';
  }
}

function putRgb(id, w, h, rgb) {
  const c = $(id);
  sizeCanvas(c, w, h);
  const ctx = c.getContext('2d');
  const img = ctx.createImageData(w, h);
  const out = new Uint32Array(img.data.buffer);  // little-endian RGBA: 0xAABBGGRR
  for (let i = 0, j = 0; i < w * h; ++i, j += 3) {
    out[i] = 0xff000000 | (rgb[j + 2] << 16) | (rgb[j + 1] << 8) | rgb[j];
  }
  ctx.putImageData(img, 0, 0);
}

// Grey image of a float plane scaled between its 1st and 99th percentile (of a sample).
function putGrey(id, w, h, values) {
  const c = $(id);
  sizeCanvas(c, w, h);
  if (!values) return;
  const sample = [];
  const stride = Math.max(1, Math.floor(values.length / 2000));
  for (let i = 0; i < values.length; i += stride) if (isFinite(values[i])) sample.push(values[i]);
  sample.sort((a, b) => a - b);
  const lo = sample.length ? sample[Math.floor(0.01 * (sample.length - 1))] : 0;
  const hi = sample.length ? sample[Math.floor(0.99 * (sample.length - 1))] : 1;
  const k = hi > lo ? 255 / (hi - lo) : 0;
  const ctx = c.getContext('2d');
  const img = ctx.createImageData(w, h);
  for (let i = 0; i < w * h; ++i) {
    const v = values[i];
    const g = isFinite(v) ? Math.max(0, Math.min(255, (v - lo) * k)) : 0;
    img.data[4 * i] = img.data[4 * i + 1] = img.data[4 * i + 2] = g;
    img.data[4 * i + 3] = 255;
  }
  ctx.putImageData(img, 0, 0);
}

function putCauses(w, h, flags, inputFlags) {
  const c = $('causes_img');
  sizeCanvas(c, w, h);
  const ctx = c.getContext('2d');
  const img = ctx.createImageData(w, h);
  const reject = state.meta.reject_mask;
  const bits = CAUSES.map(([name, colour]) => [flagBit(name), colour]);
  for (let i = 0; i < w * h; ++i) {
    let col = [0, 0, 0];
    const raised = flags[i] & ~inputFlags[i] & reject;
    if (inputFlags[i] & reject) col = [70, 70, 70];  // the camera's own rejection
    else if (raised) for (const [bit, colour] of bits) if (raised & bit) { col = colour; break; }
    img.data[4 * i] = col[0]; img.data[4 * i + 1] = col[1]; img.data[4 * i + 2] = col[2];
    img.data[4 * i + 3] = 255;
  }
  ctx.putImageData(img, 0, 0);
}

function drawLegend() {
  const c = $('legend');
  const ctx = c.getContext('2d');
  const lut = state.meta.legend;
  for (let x = 0; x < c.width; ++x) {
    const col = lut[Math.min(lut.length - 1, Math.floor(x * lut.length / c.width))];
    ctx.fillStyle = `rgb(${col[0]},${col[1]},${col[2]})`;
    ctx.fillRect(x, 0, 1, 20);
  }
  ctx.fillStyle = '#ddd';
  ctx.font = '11px sans-serif';
  const range = state.meta.range_m;
  for (let k = 0; k <= 4; ++k) {
    const x = Math.min(c.width - 24, k * c.width / 4);
    ctx.fillText((range * k / 4).toFixed(1), x, 34);
  }
  $('causes').innerHTML = CAUSES.map(([name, c]) =>
    `<span><i style="background:rgb(${c[0]},${c[1]},${c[2]})"></i>${name}</span>`).join('') +
    '<span><i style="background:rgb(70,70,70)"></i>camera</span>';
}

// ---- 3D ------------------------------------------------------------------------------------
const view = {renderer: null, scene: null, camera: null, controls: null, points: null};

function setup3d() {
  if (typeof THREE === 'undefined') {
    $('view3d').textContent = 'three.js is not available (apt-get install libjs-three)';
    return;
  }
  const el = $('view3d');
  view.renderer = new THREE.WebGLRenderer({antialias: false, preserveDrawingBuffer: true});
  view.renderer.setSize(el.clientWidth, el.clientHeight);
  el.appendChild(view.renderer.domElement);
  view.scene = new THREE.Scene();
  view.camera = new THREE.PerspectiveCamera(50, el.clientWidth / el.clientHeight, 0.05, 100);
  // Camera frame: x right, y down, z forward; looked at from behind the camera, y flipped up.
  view.camera.position.set(0, 0, -1.5);
  view.camera.up.set(0, -1, 0);
  if (THREE.OrbitControls) {
    view.controls = new THREE.OrbitControls(view.camera, view.renderer.domElement);
    view.controls.target.set(0, 0, 2.5);
    view.controls.update();
  } else {
    view.camera.lookAt(0, 0, 2.5);
  }
  const n = state.meta.width * state.meta.height;
  const geometry = new THREE.BufferGeometry();
  geometry.setAttribute('position', new THREE.BufferAttribute(new Float32Array(3 * n), 3));
  geometry.setAttribute('color', new THREE.BufferAttribute(new Float32Array(3 * n), 3));
  view.points = new THREE.Points(geometry, new THREE.PointsMaterial({size: 2, sizeAttenuation: false,
                                                                      vertexColors: true}));
  view.scene.add(view.points);
  // Drawn when a frame arrives or the view moves, not on every animation frame: a software
  // WebGL (no GPU) would otherwise spend the page's time redrawing the same cloud.
  if (view.controls) view.controls.addEventListener('change', draw3d);
}

function draw3d() {
  if (view.renderer) view.renderer.render(view.scene, view.camera);
}

function update3d(f) {
  if (!view.points || state.cloudOff) return;
  // Large frames refresh the cloud at most 10 times a second: without a GPU the browser draws
  // it in software, which would otherwise hold back the images.
  const now = performance.now();
  if (f.planes.distance_m.length > 80000 && now - (view.lastDraw || 0) < 100) return;
  view.lastDraw = now;
  const {distance_m: d, flags, delta_l_m: dl} = f.planes;
  const rays = state.rays;
  const n = d.length;
  const pos = view.points.geometry.attributes.position.array;
  const col = view.points.geometry.attributes.color.array;
  const reject = state.meta.reject_mask;
  const byDl = $('cloud_colour').value === 'delta_l' && dl;
  const lut = state.meta.legend;
  const range = f.header.range_m;
  // At most ~80k points (every 2nd row and column of a VGA frame): enough to see the scene.
  const step = n > 80000 ? 2 : 1;
  const w = f.header.width;
  let k = 0;
  for (let i = 0; i < n; ++i) {
    if (step > 1 && ((i % w) % step || Math.floor(i / w) % step)) continue;
    if (flags[i] & reject || !isFinite(d[i])) continue;
    pos[3 * k] = d[i] * rays[i]; pos[3 * k + 1] = d[i] * rays[n + i];
    pos[3 * k + 2] = d[i] * rays[2 * n + i];
    // Clamped to [0, 1] (NaN to 0): a kept pixel with a negative distance or no ΔL must not
    // index outside the legend and stop the page.
    const raw = byDl ? dl[i] / 0.1 : d[i] / range;
    const t = raw > 0 ? Math.min(1, raw) : 0;
    const c = lut[Math.min(lut.length - 1, Math.floor(t * (lut.length - 1)))];
    col[3 * k] = c[0] / 255; col[3 * k + 1] = c[1] / 255; col[3 * k + 2] = c[2] / 255;
    ++k;
  }
  view.points.geometry.setDrawRange(0, k);
  view.points.geometry.attributes.position.needsUpdate = true;
  view.points.geometry.attributes.color.needsUpdate = true;
  draw3d();
}

// ---- strip chart -----------------------------------------------------------------------------
function drawChart() {
  const c = $('chart');
  const ctx = c.getContext('2d');
  ctx.fillStyle = '#111';
  ctx.fillRect(0, 0, c.width, c.height);
  const rows = [
    ['integration register', (h) => [h.register], ['#ffd24a']],
    ['mean intensity (yellow) vs I_A (grey)', (h) => [h.mean_intensity, h.target_intensity],
     ['#ffd24a', '#888']],
    ['valid %', (h) => [h.valid_pct], ['#6f6']],
    ['mean ΔL, mm', (h) => [h.mean_delta_l_mm], ['#f66']],
  ];
  const hgt = c.height / rows.length;
  const hist = state.history;
  rows.forEach(([label, get, colours], r) => {
    const y0 = r * hgt;
    let lo = Infinity, hi = -Infinity;
    for (const h of hist) for (const v of get(h)) if (isFinite(v)) { lo = Math.min(lo, v); hi = Math.max(hi, v); }
    if (!(hi > lo)) { hi = lo + 1; lo -= 1; }
    ctx.strokeStyle = '#333';
    ctx.strokeRect(0, y0, c.width, hgt);
    colours.forEach((colour, s) => {
      ctx.strokeStyle = colour;
      ctx.beginPath();
      hist.forEach((h, i) => {
        const v = get(h)[s];
        if (!isFinite(v)) return;
        const x = i * c.width / Math.max(1, hist.length - 1);
        const y = y0 + hgt - 4 - (v - lo) / (hi - lo) * (hgt - 18);
        if (i === 0) ctx.moveTo(x, y); else ctx.lineTo(x, y);
      });
      ctx.stroke();
    });
    ctx.fillStyle = '#ccc';
    ctx.font = '11px sans-serif';
    const lastV = hist.length ? get(hist[hist.length - 1])[0] : NaN;
    ctx.fillText(`${label}: ${isFinite(lastV) ? lastV.toFixed(1) : '-'}  [${lo.toFixed(0)}, ${hi.toFixed(0)}]`, 4, y0 + 12);
  });
  state.chartUpdates++;
}

// ---- hover -----------------------------------------------------------------------------------
function hover(ev) {
  const f = state.last;
  if (!f) return;
  const c = ev.target;
  const r = c.getBoundingClientRect();
  const x = Math.floor((ev.clientX - r.left) * c.width / r.width);
  const y = Math.floor((ev.clientY - r.top) * c.height / r.height);
  if (x < 0 || y < 0 || x >= f.header.width || y >= f.header.height) return;
  const i = y * f.header.width + x;
  const p = f.planes;
  const names = state.meta.flags.filter((g) => p.flags[i] & g.bit).map((g) => g.name);
  const fmt = (v, d) => (v === undefined || !isFinite(v)) ? '-' : v.toFixed(d);
  let text = `pixel (${x}, ${y})\ndistance  ${fmt(p.distance_m[i], 3)} m\n` +
             `amplitude ${fmt(p.amplitude[i], 0)}\n`;
  if (p.intensity) text += `intensity ${fmt(p.intensity[i], 0)}\n`;
  if (p.delta_l_m) text += `ΔL        ${fmt(p.delta_l_m[i] * 1000, 1)} mm\n`;
  if (p.error_m) text += `error     ${fmt(p.error_m[i] * 1000, 1)} mm (truth)\n`;
  text += `flags     ${names.join(', ') || 'none'}`;
  $('hover').textContent = text;
}

// ---- frames ----------------------------------------------------------------------------------
function render(f) {
  const {header: h, planes: p} = f;
  const w = h.width, ht = h.height;
  putRgb('raw', w, ht, p.raw_rgb);
  putRgb('filtered', w, ht, p.filtered_rgb);
  putGrey('amplitude', w, ht, p.amplitude);
  putGrey('intensity', w, ht, p.intensity);
  putGrey('delta_l', w, ht, p.delta_l_m);
  putCauses(w, ht, p.flags, p.input_flags);
  let valid = 0;
  const reject = state.meta.reject_mask;
  for (let i = 0; i < p.flags.length; ++i) if (!(p.flags[i] & reject)) ++valid;
  state.validPct = 100 * valid / p.flags.length;
  state.serverValidPct = h.valid_fraction === null ? null : 100 * h.valid_fraction;
  $('valid_pct').textContent = state.validPct.toFixed(1) + ' %';
  update3d(f);
  state.history.push({
    register: h.register, mean_intensity: h.mean_intensity ?? NaN,
    target_intensity: h.controller ? h.target_intensity : NaN, valid_pct: state.validPct,
    mean_delta_l_mm: h.mean_delta_l_m === null ? NaN : 1000 * h.mean_delta_l_m,
  });
  if (state.history.length > 300) state.history.shift();
  drawChart();
  state.fps = h.frames_per_s;
  $('status').textContent =
      `frame ${h.seq}  ${h.frames_per_s.toFixed(0)} frames/s (camera loop)  register ${h.register}` +
      ` (${(h.integration_time_us / 1000).toFixed(2)} ms)  controller ${h.controller || 'off'}` +
      `  valid ${state.validPct.toFixed(1)} %  mean ΔL ${h.mean_delta_l_m === null ? '-' : (1000 * h.mean_delta_l_m).toFixed(1) + ' mm'}` +
      (h.rmse_m === null ? '' : `  RMSE ${(1000 * h.rmse_m).toFixed(0)} mm`) +
      `  dropped here ${state.dropped} (server ${h.dropped})` + (h.recording ? `  recording ${h.recording}` : '');
  // The server's state, not the page's guess: a recording that failed to start or stopped on an
  // error turns the button back, and the camera loop's last error is shown.
  showRecording(h.recording);
  showLoopErrors(h.errors, h.last_error);
  state.last = f;
}

async function loop() {
  for (;;) {
    try {
      const r = await fetch(`/frame?after=${state.seq}&client=${state.client}`, {cache: 'no-store'});
      if (r.status === 204) continue;
      if (!r.ok) { showError(`frame: HTTP ${r.status}`); await sleep(500); continue; }
      const f = parse(await r.arrayBuffer());
      if (state.meta.session && f.header.session !== state.meta.session) {
        // Another server on this port (a restart): its camera, rays and frame numbers are new.
        location.reload();
        return;
      }
      if (state.seq && f.header.seq > state.seq + 1) state.dropped += f.header.seq - state.seq - 1;
      state.seq = f.header.seq;
      state.frames++;
      const t0 = performance.now();
      render(f);
      state.renderMs = performance.now() - t0;
    } catch (e) {
      showError('connection: ' + e);
      await sleep(1000);
    }
  }
}

function refreshControls() {
  const m = state.meta;
  $('controller').value = m.controller;
  $('target_intensity').value = m.target_intensity;
  $('gain').value = m.gain_register_per_intensity;
  $('bias').value = m.bias_register;
  $('max_delta_l_m').value = m.max_delta_l_m;
  $('min_amplitude').value = m.min_amplitude;
  $('max_uncertainty_m').value = m.max_uncertainty_m;
  for (const f of FILTERS) $('filter_' + f).checked = !!m.filters[f];
}

function setupControls() {
  const m = state.meta;
  $('camera').textContent = `${m.camera} (${m.model}, ${m.width}x${m.height}, L ${m.range_m.toFixed(2)} m)`;
  $('fixed_register').min = m.min_register; $('fixed_register').max = m.max_register;
  $('filter_boxes').innerHTML = FILTERS.map((f) =>
    `<label><input type="checkbox" id="filter_${f}"> ${f}</label>`).join('');
  refreshControls();
  for (const f of FILTERS) {
    $('filter_' + f).addEventListener('change', (ev) => post({filters: {[f]: ev.target.checked}}));
  }
  $('pause').addEventListener('click', async () => {
    if (await post({paused: !state.paused})) {
      state.paused = !state.paused;
      $('pause').textContent = state.paused ? 'resume' : 'pause';
    }
  });
  $('step').addEventListener('click', () => post({step: 1}));
  $('apply_controller').addEventListener('click', () => post({
    controller: $('controller').value, target_intensity: Number($('target_intensity').value),
    gain_register_per_intensity: Number($('gain').value), bias_register: Number($('bias').value),
  }));
  $('apply_fixed').addEventListener('click', () => post({fixed_register: Number($('fixed_register').value)}));
  $('apply_thresholds').addEventListener('click', () => post({
    max_delta_l_m: Number($('max_delta_l_m').value), min_amplitude: Number($('min_amplitude').value),
    max_uncertainty_m: Number($('max_uncertainty_m').value),
  }));
  if (!m.pan_supported) $('pan_box').style.display = 'none';
  $('pan').addEventListener('input', () => {
    $('pan_value').textContent = $('pan').value;
    post({pan_deg: Number($('pan').value)});
  });
  if (!m.scene_parameters_supported) $('scene_box').style.display = 'none';
  $('apply_scene').addEventListener('click', () => {
    const params = {};
    for (const kv of $('scene_params').value.split('&')) {
      const [k, v] = kv.split('=');
      if (!k) continue;
      params[k.trim()] = isFinite(Number(v)) ? Number(v) : (v || '').trim();
    }
    post({scene: params});
  });
  $('record').addEventListener('click', async () => {
    // The button follows the server (frames' and /status's `recording`): the camera loop
    // begins and ends the file.
    const wanted = !state.recording;
    if (await post({record: wanted ? 'start' : 'stop'})) await followRecording(wanted);
  });
  for (const id of ['raw', 'filtered', 'amplitude', 'intensity', 'delta_l', 'causes_img']) {
    $(id).addEventListener('mousemove', hover);
  }
}

async function init() {
  try {
    state.meta = await (await fetch('/meta')).json();
    state.rays = new Float32Array(await (await fetch('/rays')).arrayBuffer());
  } catch (e) {
    showError('cannot reach the server: ' + e);
    return;
  }
  setupControls();
  drawLegend();
  try {
    setup3d();
  } catch (e) {
    $('view3d').textContent = '3D view unavailable: ' + e;
  }
  loop();
}

// Used by the browser test: change controls without clicking.
window.viewerPost = post;
init();
