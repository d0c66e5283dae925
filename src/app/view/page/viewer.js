// verisplat view: the page. The server renders; this file keeps the camera and the
// settings, turns mouse and keys into camera moves, sends view requests over the
// WebSocket and draws the frames that come back. Protocol: src/app/view/protocol.rs.
'use strict';
(() => {
  const $ = (id) => document.getElementById(id);
  const canvas = $('view');
  const ctx2d = canvas.getContext('2d');

  // ---- vector helpers (arrays of 3 numbers) ----
  const add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
  const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
  const mul = (a, s) => [a[0] * s, a[1] * s, a[2] * s];
  const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
  const len = (a) => Math.sqrt(dot(a, a));
  const unit = (a) => { const l = len(a); return l > 1e-12 ? mul(a, 1 / l) : [0, 0, 0]; };
  // Rotation of v about the unit axis k by angle a (Rodrigues).
  const rotate = (v, k, a) => {
    const c = Math.cos(a), s = Math.sin(a);
    return add(add(mul(v, c), mul(cross(k, v), s)), mul(k, dot(k, v) * (1 - c)));
  };

  // ---- state ----
  const cam = {
    pos: [0, 0, -5], right: [1, 0, 0], down: [0, 1, 0], fwd: [0, 0, 1],
    focus: [0, 0, 0], vfov: 50, aspect: 1, // aspect: fx / fy
    principal: [0.5, 0.5], // cx / width, cy / height
    lens: null, // a cameras.json "lens" other than the pinhole, kept as it came
  };
  const settings = {
    scale_modifier: 1, max_scale: null, min_opacity: 0, sh_degree: null,
    background: [0, 0, 0], mode: 'rgb',
  };
  const V = window.verisplatViewer = {
    connected: false, ready: false, hello: null, scenes: 0, frames: 0, previewFrames: 0, fullFrames: 0, lastSeq: 0,
    lastFrame: null, errors: [], cameraIndex: -1, keyframes: [], screenshots: 0,
    lastExport: null, pathFrames: 0, upFlipped: false, turntable: false, sent: 0,
    get camera() { return entry(); },
    get focus() { return cam.focus.slice(); },
    get settings() { return JSON.parse(JSON.stringify(settings)); },
  };
  let ws = null;
  let seq = 0;
  let dirty = false; // the view changed since the last request
  let dirtyInteractive = false;
  let movedAt = 0; // when the last interactive request went out
  let restPending = false;
  let frameRequested = 0; // seq of the last view or rest request
  let answered = 0; // seq of the last frame (or error) that came back
  let lastFrameAt = 0; // when it came
  let reconnectDelay = 500;

  const upSign = () => (V.upFlipped ? -1 : 1);
  const worldUp = () => mul(V.hello ? V.hello.up : [0, -1, 0], upSign());
  const size = () => (V.hello ? V.hello.size : 1);

  // Re-derive the axes so the camera looks at `target` with no roll about world up.
  function lookAt(target) {
    const fwd = unit(sub(target, cam.pos));
    if (len(fwd) === 0) return;
    let right = unit(cross(mul(worldUp(), -1), fwd));
    if (len(right) === 0) right = cam.right; // looking straight along the up axis
    cam.fwd = fwd;
    cam.right = unit(sub(right, mul(fwd, dot(right, fwd))));
    cam.down = cross(fwd, cam.right);
  }

  // The view as a cameras.json entry at the canvas's size.
  function entry() {
    const w = Math.max(1, canvas.width), h = Math.max(1, canvas.height);
    const fy = h / (2 * Math.tan((cam.vfov * Math.PI) / 360));
    const r = cam.right, d = cam.down, f = cam.fwd;
    const e = {
      id: 0, img_name: 'view', width: w, height: h, position: cam.pos.slice(),
      rotation: [[r[0], d[0], f[0]], [r[1], d[1], f[1]], [r[2], d[2], f[2]]],
      fx: fy * cam.aspect, fy,
    };
    // An off-centre principal point (a COLMAP camera's) is kept, in proportion.
    if (cam.principal[0] !== 0.5 || cam.principal[1] !== 0.5) {
      e.cx = cam.principal[0] * w;
      e.cy = cam.principal[1] * h;
    }
    // The lens of the camera last snapped to (a fisheye, a panorama): the view moves
    // and zooms through it.
    if (cam.lens) e.lens = cam.lens;
    return e;
  }

  // Takes pose and intrinsics from a cameras.json entry; the focus goes in front of it
  // at the distance of the scene's centre.
  function snapTo(e, interactive = false) {
    const col = (k) => [e.rotation[0][k], e.rotation[1][k], e.rotation[2][k]];
    cam.pos = e.position.slice();
    cam.right = unit(col(0)); cam.down = unit(col(1)); cam.fwd = unit(col(2));
    cam.vfov = (2 * Math.atan(e.height / (2 * e.fy)) * 180) / Math.PI;
    cam.aspect = e.fx / e.fy;
    cam.principal = [
      typeof e.cx === 'number' ? e.cx / e.width : 0.5,
      typeof e.cy === 'number' ? e.cy / e.height : 0.5,
    ];
    cam.lens = e.lens || null;
    const centre = V.hello ? V.hello.centre : [0, 0, 0];
    const depth = dot(sub(centre, cam.pos), cam.fwd);
    cam.focus = add(cam.pos, mul(cam.fwd, depth > 1e-3 * size() ? depth : size()));
    changed(interactive);
  }

  function changed(interactive) {
    dirty = true;
    dirtyInteractive = interactive;
  }

  // ---- camera moves ----
  function orbit(yaw, pitch) {
    const up = worldUp();
    let off = sub(cam.pos, cam.focus);
    off = rotate(off, up, yaw);
    const right = unit(cross(mul(up, -1), unit(mul(off, -1))));
    const tilted = len(right) > 0 ? rotate(off, right, pitch) : off;
    // Stay clear of the poles so the view never flips over.
    const cosUp = dot(unit(tilted), up);
    if (Math.abs(cosUp) < 0.995) off = tilted;
    cam.pos = add(cam.focus, off);
    lookAt(cam.focus);
    changed(true);
  }

  function pan(dx, dy) {
    const dist = len(sub(cam.focus, cam.pos));
    const perPixel = (2 * dist * Math.tan((cam.vfov * Math.PI) / 360)) / Math.max(1, canvas.clientHeight);
    const move = add(mul(cam.right, -dx * perPixel), mul(cam.down, -dy * perPixel));
    cam.pos = add(cam.pos, move);
    cam.focus = add(cam.focus, move);
    changed(true);
  }

  function zoom(factor) {
    const dist = Math.max(len(sub(cam.focus, cam.pos)) * factor, 1e-4 * size());
    cam.pos = sub(cam.focus, mul(cam.fwd, dist));
    changed(true);
  }

  function fly(delta) {
    cam.pos = add(cam.pos, delta);
    cam.focus = add(cam.focus, delta);
    changed(true);
  }

  // ---- mouse ----
  let drag = null;
  canvas.addEventListener('contextmenu', (e) => e.preventDefault());
  canvas.addEventListener('pointerdown', (e) => {
    canvas.focus();
    if (preview) stopPreview();
    canvas.setPointerCapture(e.pointerId);
    drag = { x: e.clientX, y: e.clientY, pan: e.button === 2 || e.button === 1 || e.shiftKey };
  });
  canvas.addEventListener('pointermove', (e) => {
    if (!drag) return;
    const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
    drag.x = e.clientX; drag.y = e.clientY;
    if (drag.pan) pan(dx, dy);
    else orbit(-dx * 0.005, dy * 0.005);
  });
  const endDrag = () => { drag = null; };
  canvas.addEventListener('pointerup', endDrag);
  canvas.addEventListener('pointercancel', endDrag);
  canvas.addEventListener('wheel', (e) => {
    e.preventDefault();
    const step = e.deltaMode === 1 ? e.deltaY * 33 : e.deltaY;
    zoom(Math.exp(Math.max(-200, Math.min(200, step)) * 0.0015));
  }, { passive: false });

  // ---- keys ----
  const held = new Set();
  let shiftDown = false; // fly faster
  for (const type of ['keydown', 'keyup']) {
    window.addEventListener(type, (e) => { shiftDown = e.shiftKey; });
  }
  const typing = (e) => /^(INPUT|SELECT|TEXTAREA)$/.test(e.target.tagName) && e.target.type !== 'range' && e.target.type !== 'checkbox';
  window.addEventListener('keydown', (e) => {
    if (typing(e) || e.ctrlKey || e.metaKey || e.altKey) return;
    const k = e.key.toLowerCase();
    if ('wasdqe'.includes(k) && k.length === 1) { held.add(k); e.preventDefault(); return; }
    if (e.key === '+' || e.key === '=') setScale(settings.scale_modifier * 1.1);
    else if (e.key === '-' || e.key === '_') setScale(settings.scale_modifier / 1.1);
    else if (k === 'n') stepCamera(1);
    else if (k === 'p') stepCamera(-1);
    else if (k === 't') toggleTurntable();
    else if (k === 'k') addKeyframe();
    else if (k === 'r') resetView();
    else return;
    e.preventDefault();
  });
  window.addEventListener('keyup', (e) => { held.delete(e.key.toLowerCase()); });
  window.addEventListener('blur', () => { held.clear(); shiftDown = false; });

  // ---- controls ----
  const scaleSlider = $('scale');
  function setScale(s) {
    s = Math.min(Math.max(s, 0.1), 10); // the slider's range
    settings.scale_modifier = Math.round(s * 1e4) / 1e4;
    scaleSlider.value = Math.log10(settings.scale_modifier);
    $('scale-out').textContent = settings.scale_modifier.toFixed(2);
    changed(false);
  }
  scaleSlider.addEventListener('input', () => {
    settings.scale_modifier = Math.round(10 ** Number(scaleSlider.value) * 1e4) / 1e4;
    $('scale-out').textContent = settings.scale_modifier.toFixed(2);
    changed(true);
  });

  // Max scale: log-spaced over the scene's range; the rightmost position is off.
  const maxSlider = $('maxscale');
  function maxScaleAt(t) {
    if (!V.hello || t >= 1000) return null;
    const [lo, hi] = V.hello.max_scale_range;
    return lo * (hi / lo) ** (t / 1000);
  }
  maxSlider.addEventListener('input', () => {
    const m = maxScaleAt(Number(maxSlider.value));
    settings.max_scale = m === null ? null : Number(m.toPrecision(4));
    $('maxscale-out').textContent = m === null ? 'off' : settings.max_scale.toPrecision(3);
    drawHistogram();
    changed(true);
  });

  // The scene's max-scale histogram under the slider: bar widths follow the log-spaced
  // slider, bars below the threshold are lit, and the share kept is estimated from them
  // (within the threshold's bin, log-linearly; the readout's "visible" is exact).
  function drawHistogram() {
    const h = V.hello && V.hello.max_scale_histogram;
    const box = $('hist');
    if (!h || !h.counts.length) { box.hidden = true; return; }
    const lo = Math.log(h.edges[0]), span = Math.log(h.edges[h.edges.length - 1]) - lo;
    const peak = Math.max(...h.counts.map((c) => Math.log1p(c)));
    const t = settings.max_scale;
    if (box.children.length !== h.counts.length) {
      box.textContent = '';
      h.counts.forEach((c, i) => {
        const bar = document.createElement('div');
        bar.style.flexGrow = String((Math.log(h.edges[i + 1]) - Math.log(h.edges[i])) / span);
        bar.style.height = `${(100 * Math.log1p(c)) / peak}%`;
        bar.title = `${h.edges[i].toPrecision(2)}–${h.edges[i + 1].toPrecision(2)}: ${c.toLocaleString()}`;
        box.appendChild(bar);
      });
    }
    const total = h.counts.reduce((a, b) => a + b, 0);
    let kept = 0;
    h.counts.forEach((c, i) => {
      const [a, b] = [h.edges[i], h.edges[i + 1]];
      const share = t === null || t >= b ? 1 : t <= a ? 0 : Math.log(t / a) / Math.log(b / a);
      kept += c * share;
      box.children[i].classList.toggle('kept', share > 0);
    });
    $('hist-label').textContent = t === null
      ? `${total.toLocaleString()} Gaussians, largest scale ${h.edges[0].toPrecision(2)}–${h.edges[h.edges.length - 1].toPrecision(2)}`
      : `≈ ${((100 * kept) / Math.max(1, total)).toFixed(1)} % kept (scale ≤ ${t.toPrecision(3)})`;
  }
  $('minopacity').addEventListener('input', (e) => {
    settings.min_opacity = Number(e.target.value);
    $('minopacity-out').textContent = settings.min_opacity.toFixed(2);
    changed(true);
  });
  $('sh').addEventListener('input', (e) => {
    const d = Number(e.target.value);
    settings.sh_degree = V.hello && d >= V.hello.sh_degree ? null : d;
    $('sh-out').textContent = String(d);
    changed(false);
  });
  $('background').addEventListener('input', (e) => {
    const hex = e.target.value;
    settings.background = [1, 3, 5].map((i) => parseInt(hex.slice(i, i + 2), 16) / 255);
    changed(false);
  });
  $('mode').addEventListener('change', (e) => { settings.mode = e.target.value; changed(false); });
  $('flip-up').addEventListener('change', (e) => {
    V.upFlipped = e.target.checked;
    lookAt(cam.focus);
    changed(false);
  });
  for (const el of [scaleSlider, maxSlider, $('minopacity')]) {
    el.addEventListener('change', () => changed(false)); // released: full quality
  }
  $('panel-toggle').addEventListener('click', () => {
    const collapsed = $('panel').classList.toggle('collapsed');
    document.body.classList.toggle('panel-collapsed', collapsed); // the canvas takes the width
    $('panel-toggle').textContent = collapsed ? 'Show' : 'Hide';
  });
  $('reset').addEventListener('click', resetView);
  $('turntable').addEventListener('click', toggleTurntable);
  $('shot-png').addEventListener('click', () => screenshot('png'));
  $('shot-exr').addEventListener('click', () => screenshot('exr'));
  $('kf-add').addEventListener('click', addKeyframe);
  $('kf-preview').addEventListener('click', togglePreview);
  $('kf-export').addEventListener('click', () => exportKeyframes('verisplat'));
  $('kf-export-ns').addEventListener('click', () => exportKeyframes('nerfstudio'));

  function resetView() {
    if (V.hello) { V.cameraIndex = V.hello.cameras.length ? 0 : -1; snapTo(V.hello.initial_camera); markCamera(); }
  }

  function toggleTurntable() {
    V.turntable = !V.turntable;
    $('turntable').textContent = V.turntable ? '❚❚ Turntable' : '▶ Turntable';
  }

  // ---- cameras ----
  function fillCameras() {
    const list = $('cameras');
    list.textContent = '';
    V.hello.cameras.forEach((c, i) => {
      const li = document.createElement('li');
      li.textContent = c.name;
      li.title = `${c.camera.width}x${c.camera.height}`;
      li.addEventListener('click', () => selectCamera(i));
      list.appendChild(li);
    });
  }
  function markCamera() {
    [...$('cameras').children].forEach((li, i) => li.classList.toggle('current', i === V.cameraIndex));
    const cur = $('cameras').children[V.cameraIndex];
    if (cur) cur.scrollIntoView({ block: 'nearest' });
  }
  function selectCamera(i) {
    const n = V.hello ? V.hello.cameras.length : 0;
    if (!n) return;
    V.cameraIndex = ((i % n) + n) % n;
    snapTo(V.hello.cameras[V.cameraIndex].camera);
    markCamera();
  }
  const stepCamera = (d) => selectCamera(V.cameraIndex < 0 ? 0 : V.cameraIndex + d);
  V.selectCamera = selectCamera;

  // ---- keyframes ----
  const pose = () => ({ pos: cam.pos.slice(), right: cam.right.slice(), down: cam.down.slice(), fwd: cam.fwd.slice(), focus: cam.focus.slice(), vfov: cam.vfov, aspect: cam.aspect, principal: cam.principal.slice() });
  function addKeyframe() { V.keyframes.push(pose()); fillKeyframes(); }
  function fillKeyframes() {
    const list = $('keyframes');
    list.textContent = '';
    V.keyframes.forEach((k, i) => {
      const li = document.createElement('li');
      const label = document.createElement('span');
      label.textContent = `t = ${(i * spacing()).toFixed(1)} s`;
      label.title = 'go to this keyframe';
      label.addEventListener('click', () => { Object.assign(cam, JSON.parse(JSON.stringify(k))); changed(false); });
      li.appendChild(label);
      const button = (text, title, fn) => {
        const b = document.createElement('button');
        b.textContent = text; b.title = title; b.addEventListener('click', fn); li.appendChild(b);
      };
      button('↑', 'earlier', () => { if (i > 0) { [V.keyframes[i - 1], V.keyframes[i]] = [V.keyframes[i], V.keyframes[i - 1]]; fillKeyframes(); } });
      button('↓', 'later', () => { if (i + 1 < V.keyframes.length) { [V.keyframes[i + 1], V.keyframes[i]] = [V.keyframes[i], V.keyframes[i + 1]]; fillKeyframes(); } });
      button('✕', 'delete', () => { V.keyframes.splice(i, 1); fillKeyframes(); });
      list.appendChild(li);
    });
  }
  // A number input's value within its min..max (whole with step 1): a value outside, or
  // not a number, is replaced in the input by the nearest allowed one and the banner
  // says so; nothing is changed silently.
  function checkedNumber(input, name) {
    const lo = Number(input.min), hi = Number(input.max), whole = input.step === '1';
    const raw = input.value.trim();
    const given = raw === '' ? NaN : Number(raw);
    let v = Number.isFinite(given) ? Math.min(hi, Math.max(lo, given)) : Number(input.defaultValue);
    if (whole) v = Math.round(v);
    if (v !== given) {
      input.value = String(v);
      showError(`${name} must be a number from ${lo} to ${hi}${whole ? ' (whole)' : ''}; ` +
        `${raw === '' ? 'nothing' : `"${raw}"`} was given, ${v} is used`);
    }
    return v;
  }
  const spacing = () => checkedNumber($('kf-spacing'), 'Seconds apart');
  const fps = () => checkedNumber($('kf-fps'), 'Frames/s');
  $('kf-spacing').addEventListener('change', fillKeyframes);
  $('kf-fps').addEventListener('change', fps);

  // A keyframe's camera at the canvas's size.
  function keyframeEntry(k) {
    const saved = pose();
    Object.assign(cam, k);
    const e = entry();
    Object.assign(cam, saved);
    return e;
  }
  function exportKeyframes(format) {
    if (!V.keyframes.length) { showError('no keyframes yet: "Add" puts the current camera in the path'); return; }
    send({
      type: 'export_keyframes', seq: ++seq, format, fps: fps(),
      keyframes: keyframeList(),
    });
  }

  // Preview: the server samples the path as `render --cameras` will (Catmull-Rom
  // positions, slerped rotations, docs/cameras.md); the page plays those frames.
  let preview = null;
  function keyframeList() {
    return V.keyframes.map((k, i) => ({ time: Math.round(i * spacing() * 1e6) / 1e6, camera: keyframeEntry(k) }));
  }
  function togglePreview() {
    if (preview) { stopPreview(); return; }
    if (V.keyframes.length < 2) { showError('a path needs two keyframes to preview'); return; }
    send({ type: 'sample_keyframes', seq: ++seq, fps: fps(), keyframes: keyframeList() });
    $('kf-preview').textContent = '… Preview';
  }
  function stopPreview() {
    preview = null;
    $('kf-preview').textContent = '▶ Preview';
    changed(false);
  }
  function startPreview(m) {
    if (!m.cameras.length) return;
    preview = { frames: m.cameras, fps: m.fps, start: performance.now(), shown: -1 };
    V.pathFrames = m.cameras.length;
    $('kf-preview').textContent = '■ Stop';
  }
  function previewStep(now) {
    const n = preview.frames.length;
    const k = Math.floor(((now - preview.start) / 1000) * preview.fps) % n;
    if (k === preview.shown) return;
    preview.shown = k;
    snapTo(preview.frames[k], true);
  }

  // ---- screenshots and downloads ----
  function screenshot(format) {
    send({ type: 'screenshot', seq: ++seq, format, camera: entry(), settings });
  }
  function download(blob, name) {
    const a = document.createElement('a');
    a.href = URL.createObjectURL(blob);
    a.download = name;
    document.body.appendChild(a);
    a.click();
    a.remove();
    setTimeout(() => URL.revokeObjectURL(a.href), 10000);
  }

  // ---- errors ----
  let bannerTimer = null;
  function showBanner(message, notice) {
    const b = $('banner');
    b.textContent = message;
    b.classList.toggle('notice', notice);
    b.hidden = false;
    clearTimeout(bannerTimer);
    bannerTimer = setTimeout(() => { b.hidden = true; }, 8000);
  }
  function showError(message) {
    V.errors.push(message);
    showBanner(message, false);
  }
  const showNotice = (message) => showBanner(message, true);
  $('banner').addEventListener('click', () => { $('banner').hidden = true; });

  // ---- connection ----
  function send(msg) {
    if (!ws || ws.readyState !== WebSocket.OPEN) return false;
    ws.send(JSON.stringify(msg));
    V.sent += 1;
    return true;
  }
  V.send = send; // for tests and the console
  // Why the server closed the connection, from its close code and reason (RFC 6455).
  function closeText(ev) {
    const reason = ev.reason ? `: ${ev.reason}` : '';
    if (ev.code === 1001) return `the viewer server stopped${reason}`;
    if (ev.code === 1009) return `the server refused a message as too big${reason} (close code 1009)`;
    if (ev.code === 1006 || ev.code === 1005) return 'disconnected from the viewer server';
    return `the server closed the connection${reason} (close code ${ev.code})`;
  }
  function connect() {
    ws = new WebSocket(`ws://${location.host}/ws`);
    ws.binaryType = 'arraybuffer';
    ws.onopen = () => { V.connected = true; reconnectDelay = 500; };
    ws.onclose = (ev) => {
      if (V.connected) {
        V.lastClose = { code: ev.code, reason: ev.reason };
        showError(`${closeText(ev)}; reconnecting…`);
      }
      V.connected = false;
      V.ready = false; // until the next server's hello
      setTimeout(connect, reconnectDelay);
      reconnectDelay = Math.min(reconnectDelay * 2, 10000);
    };
    ws.onmessage = (ev) => (typeof ev.data === 'string' ? onText(ev.data) : onBinary(ev.data));
  }
  function onText(text) {
    let m;
    try { m = JSON.parse(text); } catch (e) { showError(`bad message from the server: ${e}`); return; }
    if (m.type === 'hello') onHello(m);
    else if (m.type === 'error') {
      if (typeof m.seq === 'number') answered = Math.max(answered, m.seq);
      showError(m.message);
      if (!preview) $('kf-preview').textContent = '▶ Preview';
    }
    else if (m.type === 'camera') { snapTo(m.camera); }
    else if (m.type === 'path') { startPreview(m); }
    else if (m.type === 'export') {
      V.lastExport = m;
      download(new Blob([m.text], { type: 'application/json' }), m.filename);
    }
  }
  // Everything but the device: two hellos alike describe the same scene and cameras.
  const sceneOf = (h) => JSON.stringify({ ...h, device: null });
  function onHello(h) {
    if (h.version !== 1) { showError(`the server speaks protocol ${h.version}; reload the page`); return; }
    const previous = V.hello;
    V.hello = h;
    V.ready = true;
    answered = frameRequested; // requests to the old connection are not answered
    restPending = false;
    if (previous && sceneOf(previous) === sceneOf(h)) {
      changed(false); // reconnected to the same scene: render the current view again
      return;
    }
    setUpScene(h);
    if (previous) {
      showNotice(`the server now shows ${sceneName(h)} (${h.gaussians.toLocaleString()} Gaussians, ` +
        `${h.cameras.length} camera${h.cameras.length === 1 ? '' : 's'}): the page was set up for it` +
        (V.keyframes.length ? '; your keyframes are kept' : ''));
    }
  }
  const sceneName = (h) => h.scene.split('/').filter(Boolean).pop() || h.scene;
  // The controls that depend on the scene, from its hello (on the first connection and
  // whenever the server serves another scene): name, SH range, max-scale range and
  // histogram, camera list, and the view at its first camera.
  function setUpScene(h) {
    V.scenes += 1;
    V.lastFrame = null; // the readout waits for this scene's first frame
    $('scene-name').textContent = sceneName(h);
    $('scene-name').title = h.scene;
    $('sh').max = String(h.sh_degree);
    $('sh').value = String(h.sh_degree);
    $('sh-out').textContent = String(h.sh_degree);
    settings.sh_degree = null;
    maxSlider.value = maxSlider.max;
    settings.max_scale = null;
    $('maxscale-out').textContent = 'off';
    $('hist').textContent = ''; // new bars
    drawHistogram();
    fillCameras();
    resetView();
    $('readout').textContent = `${sceneName(h)}: ${h.gaussians.toLocaleString()} Gaussians\n${h.device}`;
  }
  let drawToken = 0;
  const fpsTimes = [];
  function onBinary(buf) {
    const view = new DataView(buf);
    if (buf.byteLength < 4) return;
    const n = view.getUint32(0, true);
    let h;
    try { h = JSON.parse(new TextDecoder().decode(new Uint8Array(buf, 4, n))); } catch (e) { showError(`bad frame header: ${e}`); return; }
    const payload = new Uint8Array(buf, 4 + n);
    if (h.kind === 'screenshot') {
      V.screenshots += 1;
      download(new Blob([payload], { type: h.format === 'png' ? 'image/png' : 'image/x-exr' }), h.filename);
      return;
    }
    if (h.kind !== 'frame') return;
    answered = Math.max(answered, h.seq);
    lastFrameAt = performance.now();
    const token = ++drawToken;
    createImageBitmap(new Blob([payload], { type: `image/${h.encoding}` })).then((bmp) => {
      if (token === drawToken) {
        ctx2d.imageSmoothingEnabled = true;
        ctx2d.drawImage(bmp, 0, 0, canvas.width, canvas.height);
      }
      bmp.close();
      V.frames += 1;
      if (h.quality === 'full') V.fullFrames += 1; else V.previewFrames += 1;
      V.lastSeq = h.seq;
      V.lastFrame = h;
      const now = performance.now();
      fpsTimes.push(now);
      while (fpsTimes.length && now - fpsTimes[0] > 1000) fpsTimes.shift();
      readout();
    }, (e) => showError(`cannot decode a frame: ${e}`));
  }
  // The readout's first words: frames/s while frames come; once none came for a second,
  // "at rest" when every request was answered, else that the server is still rendering.
  function rate(now) {
    while (fpsTimes.length && now - fpsTimes[0] > 1000) fpsTimes.shift();
    if (!V.connected) return 'disconnected';
    if (fpsTimes.length) return `${fpsTimes.length} frames/s`;
    if (answered < frameRequested) return `rendering… (${((now - lastFrameAt) / 1000).toFixed(0)} s)`;
    return 'at rest';
  }
  let shownRate = '';
  function readout() {
    const h = V.lastFrame;
    if (!h) return;
    shownRate = rate(performance.now());
    V.rate = shownRate;
    const t = h.timings;
    const f = (v) => v.toFixed(2).padStart(7);
    $('readout').textContent =
      `${shownRate}   ${h.width}x${h.height} ${h.quality}\n` +
      `frame ${h.wall_ms.toFixed(1)} ms (encode ${h.encode_ms.toFixed(1)})\n` +
      `preprocess ${f(t.preprocess)}\norder      ${f(t.order)}\nscan       ${f(t.scan)}\n` +
      `keys       ${f(t.keys)}\nsort       ${f(t.sort)}\nranges     ${f(t.ranges)}\n` +
      `blend      ${f(t.blend)}\nreadback   ${f(t.readback)}\ntotal      ${f(t.total)} ms\n` +
      `visible ${h.visible.toLocaleString()} of ${h.gaussians.toLocaleString()}` +
      (V.hello && h.gaussians < V.hello.gaussians ? ' (preview: the most important)' : '') +
      `  pairs ${h.pairs.toLocaleString()}\n` +
      (V.hello ? V.hello.device : '');
  }

  // ---- the loop: canvas size, fly, turntable, requests ----
  function fitCanvas() {
    const dpr = window.devicePixelRatio || 1;
    const w = Math.max(1, Math.round(canvas.clientWidth * dpr));
    const h = Math.max(1, Math.round(canvas.clientHeight * dpr));
    if (w !== canvas.width || h !== canvas.height) {
      canvas.width = w; canvas.height = h;
      changed(true); // a resize is a move: previews, then the full frame at rest
    }
  }
  let last = performance.now();
  function tick(now) {
    const dt = Math.min(0.1, (now - last) / 1000);
    last = now;
    fitCanvas();
    if (held.size) {
      const speed = size() * 0.6 * (shiftDown ? 4 : 1) * dt;
      let d = [0, 0, 0];
      if (held.has('w')) d = add(d, cam.fwd);
      if (held.has('s')) d = sub(d, cam.fwd);
      if (held.has('d')) d = add(d, cam.right);
      if (held.has('a')) d = sub(d, cam.right);
      if (held.has('e')) d = add(d, worldUp());
      if (held.has('q')) d = sub(d, worldUp());
      if (len(d) > 0) fly(mul(unit(d), speed));
    }
    if (V.turntable) orbit((20 * Math.PI / 180) * dt, 0);
    if (preview) previewStep(now);
    if (dirty && V.ready && send({ type: 'view', seq: ++seq, camera: entry(), settings, interactive: dirtyInteractive })) {
      dirty = false;
      restPending = dirtyInteractive;
      movedAt = now;
      frameRequested = seq;
    } else if (restPending && V.ready && now - movedAt > 150 && !drag) {
      if (send({ type: 'rest', seq: ++seq })) { restPending = false; frameRequested = seq; }
    }
    if (V.lastFrame && rate(now) !== shownRate) readout();
    requestAnimationFrame(tick);
  }
  connect();
  requestAnimationFrame(tick);
})();
