// fusionloc viewer page: draws what fl-viewer sends over its WebSocket (docs/VIEWER.md).
// Frames: uint32 LE header length | JSON header | padding to 4 bytes | payload.
// Plain script over Debian's three.js (r111, globals THREE and THREE.OrbitControls).
'use strict';

(function () {
  const COLORS = {
    FUSED_POSE: 0x33dd55, RBPF_POSE: 0xff8833, VO_POSE: 0x3399ff, ODOMETRY: 0xbbbbbb,
    GROUND_TRUTH: 0xffee44, RBPF_TRAJECTORY: 0xff5511, FUSED_TRAJECTORY: 0x00ffaa,
    VO_POINTS: 0x88aaff, FUSED_MAP: 0xeeeeff, scan: 0xff3366,
  };
  const LABELS = {
    grid: 'grid', scan: 'scan', FUSED_POSE: 'fused', RBPF_POSE: 'RBPF', VO_POSE: 'VO',
    ODOMETRY: 'odometry', GROUND_TRUTH: 'ground truth', RBPF_TRAJECTORY: 'RBPF keyframes',
    FUSED_TRAJECTORY: 'fused trajectory', VO_POINTS: 'VO cloud', FUSED_MAP: 'fused map',
  };

  // ---- three.js scene: z up, the map frame ----
  const canvas = document.getElementById('canvas');
  const renderer = new THREE.WebGLRenderer({ canvas: canvas, antialias: false,
                                             preserveDrawingBuffer: true });
  renderer.setPixelRatio(1);
  renderer.setClearColor(0x1e2430, 1);
  const scene = new THREE.Scene();
  const persp = new THREE.PerspectiveCamera(55, 1, 0.05, 2000);
  persp.up.set(0, 0, 1);
  persp.position.set(-15, -15, 20);
  const ortho = new THREE.OrthographicCamera(-10, 10, 10, -10, -100, 100);
  ortho.up.set(0, 1, 0);
  ortho.position.set(0, 0, 50);
  const perspControls = new THREE.OrbitControls(persp, canvas);
  const orthoControls = new THREE.OrbitControls(ortho, canvas);
  orthoControls.enableRotate = false;
  orthoControls.screenSpacePanning = true;
  perspControls.enabled = false;
  let camera = ortho;
  let follow = false;

  const layers = {};  // name -> {object3d, visible}
  function layer(name) {
    if (!layers[name]) {
      const g = new THREE.Group();
      g.name = name;
      scene.add(g);
      layers[name] = { group: g, visible: true };
      addLayerToggle(name);
    }
    return layers[name].group;
  }
  function addLayerToggle(name) {
    const box = document.getElementById('layers');
    const label = document.createElement('label');
    const input = document.createElement('input');
    input.type = 'checkbox';
    input.checked = true;
    input.id = 'layer-' + name;
    input.addEventListener('change', function () {
      layers[name].visible = input.checked;
      layers[name].group.visible = input.checked;
    });
    const sw = document.createElement('span');
    sw.className = 'swatch';
    sw.style.background = '#' + (COLORS[name] !== undefined ? COLORS[name] : 0x888888)
      .toString(16).padStart(6, '0');
    label.appendChild(input);
    label.appendChild(sw);
    label.appendChild(document.createTextNode(LABELS[name] || name));
    box.appendChild(label);
  }

  // ---- occupancy grid: one texture ----
  const state = {
    connected: false, mode: '', frames: 0, types: {}, grid: null, trails: {}, trajectories: {},
    clouds: {}, poses: {}, robot: null, processes: [], deputies: [], rates: [], clock: null,
    errors: [],
  };
  let gridMesh = null;
  function onGrid(h, payload) {
    const cells = new Int8Array(payload, 0, h.width * h.height);
    const rgba = new Uint8Array(h.width * h.height * 4);
    for (let i = 0; i < cells.length; ++i) {
      const v = cells[i];
      const g = v < 0 ? 128 : Math.round(255 - 2.55 * Math.min(100, v));
      rgba[4 * i] = g; rgba[4 * i + 1] = g; rgba[4 * i + 2] = g; rgba[4 * i + 3] = 255;
    }
    const tex = new THREE.DataTexture(rgba, h.width, h.height, THREE.RGBAFormat);
    tex.magFilter = THREE.NearestFilter;
    tex.minFilter = THREE.NearestFilter;
    tex.generateMipmaps = false;
    tex.needsUpdate = true;
    const w = h.width * h.resolution, ht = h.height * h.resolution;
    const g = layer('grid');
    if (gridMesh) {
      g.remove(gridMesh);
      gridMesh.geometry.dispose();
      gridMesh.material.map.dispose();
      gridMesh.material.dispose();
    }
    gridMesh = new THREE.Mesh(new THREE.PlaneBufferGeometry(w, ht),
                              new THREE.MeshBasicMaterial({ map: tex }));
    gridMesh.position.set(h.origin_x + w / 2, h.origin_y + ht / 2, -0.01);
    g.add(gridMesh);
    const first = !state.grid;
    state.grid = { utime: h.utime, resolution: h.resolution, width: h.width, height: h.height,
                   origin_x: h.origin_x, origin_y: h.origin_y };
    if (first) fit();
  }

  // ---- growable line / point buffers ----
  function makeBuffer(kind, color) {
    const geom = new THREE.BufferGeometry();
    const attr = new THREE.BufferAttribute(new Float32Array(3 * 1024), 3);
    attr.setUsage(THREE.DynamicDrawUsage);
    geom.setAttribute('position', attr);
    geom.setDrawRange(0, 0);
    const obj = kind === 'line'
      ? new THREE.Line(geom, new THREE.LineBasicMaterial({ color: color }))
      : new THREE.Points(geom, new THREE.PointsMaterial({ color: color, size: kind === 'scan' ? 3 : 2,
                                                          sizeAttenuation: false }));
    obj.frustumCulled = false;
    return { obj: obj, n: 0 };
  }
  function setPoints(buf, xyz, n, append) {
    const geom = buf.obj.geometry;
    let attr = geom.getAttribute('position');
    const start = append ? buf.n : 0;
    const need = 3 * (start + n);
    if (need > attr.array.length) {
      let cap = attr.array.length;
      while (cap < need) cap *= 2;
      const bigger = new Float32Array(cap);
      bigger.set(attr.array.subarray(0, 3 * start));
      attr = new THREE.BufferAttribute(bigger, 3);
      attr.setUsage(THREE.DynamicDrawUsage);
      geom.setAttribute('position', attr);
    }
    attr.array.set(xyz.subarray(0, 3 * n), 3 * start);
    attr.needsUpdate = true;
    buf.n = start + n;
    geom.setDrawRange(0, buf.n);
  }
  // x, y, z, yaw per pose -> x, y, z per vertex
  function posesToXyz(p, n) {
    const xyz = new Float32Array(3 * n);
    for (let i = 0; i < n; ++i) {
      xyz[3 * i] = p[4 * i]; xyz[3 * i + 1] = p[4 * i + 1]; xyz[3 * i + 2] = p[4 * i + 2] + 0.02;
    }
    return xyz;
  }

  const trailBufs = {};
  function onTrail(h, payload) {
    if (!trailBufs[h.source]) {
      trailBufs[h.source] = makeBuffer('line', COLORS[h.source] || 0x888888);
      layer(h.source).add(trailBufs[h.source].obj);
    }
    const p = new Float32Array(payload, 0, 4 * h.count);
    setPoints(trailBufs[h.source], posesToXyz(p, h.count), h.count, !h.replace);
    state.trails[h.source] = trailBufs[h.source].n;
  }
  const trajBufs = {};
  function onTrajectory(h, payload) {
    if (!trajBufs[h.source]) {
      trajBufs[h.source] = makeBuffer('line', COLORS[h.source] || 0x888888);
      layer(h.source).add(trajBufs[h.source].obj);
    }
    const p = new Float32Array(payload, 0, 4 * h.count);
    setPoints(trajBufs[h.source], posesToXyz(p, h.count), h.count, false);
    state.trajectories[h.source] = h.count;
  }
  const cloudBufs = {};
  function onCloud(h, payload) {
    if (!cloudBufs[h.source]) {
      cloudBufs[h.source] = makeBuffer('points', COLORS[h.source] || 0xffffff);
      layer(h.source).add(cloudBufs[h.source].obj);
    }
    setPoints(cloudBufs[h.source], new Float32Array(payload, 0, 3 * h.count), h.count, !h.replace);
    state.clouds[h.source] = cloudBufs[h.source].n;
  }

  // ---- the robot: an arrow per pose source, the scan at the robot's pose ----
  const arrows = {};
  function arrow(source) {
    if (!arrows[source]) {
      const shape = new THREE.Shape();
      shape.moveTo(0.45, 0); shape.lineTo(-0.25, 0.22); shape.lineTo(-0.12, 0);
      shape.lineTo(-0.25, -0.22); shape.lineTo(0.45, 0);
      const m = new THREE.Mesh(new THREE.ShapeBufferGeometry(shape),
                               new THREE.MeshBasicMaterial({ color: COLORS[source] || 0x888888,
                                                             side: THREE.DoubleSide }));
      arrows[source] = m;
      layer(source).add(m);
    }
    return arrows[source];
  }
  function place(obj, p) {
    obj.position.set(p[0], p[1], p[2] + 0.05);
    obj.rotation.set(0, 0, p[3]);
  }
  function onPoses(h) {
    for (const source in h.poses) {
      place(arrow(source), h.poses[source]);
      state.poses[source] = h.poses[source];
    }
    state.robot = h.robot ? { source: h.robot, pose: h.poses[h.robot] } : null;
    if (follow && state.robot) {
      const p = state.robot.pose;
      const c = camera === ortho ? orthoControls : perspControls;
      const d = new THREE.Vector3(p[0], p[1], 0).sub(c.target);
      c.target.add(d); camera.position.add(d);
    }
  }
  let scanBuf = null, scanGroup = null;
  function onScan(h, payload) {
    if (!scanBuf) {
      scanBuf = makeBuffer('scan', COLORS.scan);
      scanGroup = new THREE.Group();
      scanGroup.add(scanBuf.obj);
      layer('scan').add(scanGroup);
    }
    const xy = new Float32Array(payload, 0, 2 * h.count);
    const xyz = new Float32Array(3 * h.count);
    for (let i = 0; i < h.count; ++i) {
      xyz[3 * i] = xy[2 * i]; xyz[3 * i + 1] = xy[2 * i + 1]; xyz[3 * i + 2] = 0.03;
    }
    setPoints(scanBuf, xyz, h.count, false);
    scanGroup.visible = !!h.pose;
    if (h.pose) place(scanGroup, h.pose);
    state.scan = { utime: h.utime, count: h.count, source: h.source };
  }

  // ---- panels ----
  const LEVELS = ['ok', 'warn', 'error', 'starting'];
  function esc(s) {
    return String(s).replace(/[&<>"]/g, function (c) {
      return { '&': '&amp;', '<': '&lt;', '>': '&gt;', '"': '&quot;' }[c];
    });
  }
  function fmt(v, d) { return v === null || v === undefined ? '-' : Number(v).toFixed(d); }
  function onProcesses(h) {
    state.processes = h.processes;
    state.deputies = h.deputies;
    let rows = '';
    for (const p of h.processes) {
      const lv = LEVELS[p.level] || 'warn';
      const cls = lv === 'error' ? 'bad' : lv;
      rows += '<tr class="process"><td>' + esc(p.process || p.channel) + '</td><td class="' + cls +
        '">' + lv + '</td><td>' + p.in + '/' + p.out + (p.dropped ? ' <span class="warn">(' +
        p.dropped + ' dropped)</span>' : '') + '</td><td>' + fmt(p.cpu_ms_per_item, 2) +
        '</td></tr><tr><td colspan="4" class="msg">' + esc(p.message) + '</td></tr>';
    }
    document.querySelector('#processes tbody').innerHTML = rows;
    rows = '';
    for (const d of h.deputies) {
      rows += '<tr><th colspan="4">deputy ' + esc(d.host) + ': CPU ' + fmt(100 * d.cpu_load, 0) +
        ' %, free ' + fmt(d.mem_free / 1048576, 0) + ' MiB</th></tr>';
      for (const c of d.commands) {
        const running = c.pid > 0;
        rows += '<tr class="command"><td>' + esc((c.group ? c.group + '/' : '') + c.name) +
          '</td><td class="' + (running ? 'ok' : 'warn') + '">' +
          (running ? c.pid : 'stopped' + (c.runid ? ' (' + c.exit_code + ')' : '')) +
          '</td><td>' + fmt(100 * c.cpu, 0) + ' %</td><td>' + fmt(c.rss / 1048576, 0) +
          ' MiB</td></tr>';
      }
    }
    document.querySelector('#deputies tbody').innerHTML = rows;
    const f = h.processes.find(function (p) { return p.process === 'fl-fusion'; });
    if (f) {
      let html = '<div>' + esc(f.message) + '</div>';
      const keys = ['nodes', 'factors', 'full_solves', 'rejected', 'pending_factors',
                    'odometry_factors', 'map_keyframes', 'update_ms'];
      html += keys.filter(function (k) { return k in f.values; }).map(function (k) {
        return k + ' ' + (Number.isInteger(f.values[k]) ? f.values[k] : fmt(f.values[k], 2));
      }).join(', ');
      document.getElementById('fusion').innerHTML = html;
    }
  }
  function onRates(h) {
    state.rates = h.channels;
    let rows = '';
    for (const c of h.channels) {
      rows += '<tr><td>' + esc(c.name) + '</td><td>' + fmt(c.hz, 1) + '</td><td>' + c.count +
        '</td></tr>';
    }
    document.querySelector('#rates tbody').innerHTML = rows;
    const v = h.viewer;
    document.getElementById('viewer-stats').textContent = 'viewer: ' + v.clients +
      ' browser(s), ' + v.frames_sent + ' frames, ' + fmt(v.bytes_sent / 1048576, 1) + ' MiB sent, ' +
      v.frames_dropped + ' dropped for slow browsers';
  }

  // ---- log mode: the time slider ----
  const player = document.getElementById('player');
  const slider = document.getElementById('slider');
  const playBtn = document.getElementById('btn-play');
  const speedSel = document.getElementById('speed');
  let dragging = false;
  function onClock(h) {
    state.clock = h;
    const len = (h.end - h.start) / 1e6, t = (h.utime - h.start) / 1e6;
    slider.max = len.toFixed(1);
    if (!dragging) slider.value = t.toFixed(1);
    document.getElementById('time').textContent = t.toFixed(1) + ' / ' + len.toFixed(1) + ' s';
    playBtn.textContent = h.playing ? 'Pause' : 'Play';
    if (Number(speedSel.value) !== h.speed) speedSel.value = String(h.speed);
  }
  let lastSeekMs = 0;
  slider.addEventListener('input', function () {
    dragging = true;
    const now = performance.now();
    if (now - lastSeekMs > 150) { send('seek ' + slider.value); lastSeekMs = now; }
  });
  slider.addEventListener('change', function () { dragging = false; send('seek ' + slider.value); });
  playBtn.addEventListener('click', function () {
    send(state.clock && state.clock.playing ? 'pause' : 'play');
  });
  speedSel.addEventListener('change', function () { send('speed ' + speedSel.value); });

  function onReset() {
    for (const s in trailBufs) setPoints(trailBufs[s], new Float32Array(0), 0, false);
    for (const s in trajBufs) setPoints(trajBufs[s], new Float32Array(0), 0, false);
    for (const s in cloudBufs) setPoints(cloudBufs[s], new Float32Array(0), 0, false);
    if (scanBuf) setPoints(scanBuf, new Float32Array(0), 0, false);
    state.trails = {}; state.trajectories = {}; state.clouds = {};
  }

  // ---- the WebSocket ----
  let ws = null;
  function send(text) { if (ws && ws.readyState === 1) ws.send(text); }
  const decoder = new TextDecoder();
  function onFrame(buf) {
    const dv = new DataView(buf);
    const n = dv.getUint32(0, true);
    const h = JSON.parse(decoder.decode(new Uint8Array(buf, 4, n)));
    const payload = buf.slice(Math.ceil((4 + n) / 4) * 4);
    state.frames++;
    state.types[h.type] = (state.types[h.type] || 0) + 1;
    switch (h.type) {
      case 'hello':
        state.mode = h.mode;
        document.getElementById('source').textContent = (h.mode === 'log' ? 'log ' : 'live ') + h.source;
        player.hidden = h.mode !== 'log';
        document.getElementById('view').classList.toggle('with-player', h.mode === 'log');
        resize();
        break;
      case 'grid': onGrid(h, payload); break;
      case 'scan': onScan(h, payload); break;
      case 'trail': onTrail(h, payload); break;
      case 'trajectory': onTrajectory(h, payload); break;
      case 'cloud': onCloud(h, payload); break;
      case 'poses': onPoses(h); break;
      case 'processes': onProcesses(h); break;
      case 'rates': onRates(h); break;
      case 'clock': onClock(h); break;
      case 'reset': onReset(); break;
      default: break;
    }
  }
  function connect() {
    const url = (location.protocol === 'https:' ? 'wss://' : 'ws://') + location.host + '/ws' +
      location.search;
    ws = new WebSocket(url);
    ws.binaryType = 'arraybuffer';
    const conn = document.getElementById('conn');
    ws.onopen = function () { state.connected = true; conn.textContent = 'connected'; conn.className = 'ok'; };
    ws.onmessage = function (e) {
      try { onFrame(e.data); } catch (err) { state.errors.push(String(err)); console.warn(err); }
    };
    ws.onclose = function () {
      state.connected = false;
      conn.textContent = 'disconnected, retrying…';
      conn.className = 'bad';
      setTimeout(connect, 1000);
    };
  }

  // ---- view controls ----
  function setCamera(which) {
    camera = which === '3d' ? persp : ortho;
    perspControls.enabled = camera === persp;
    orthoControls.enabled = camera === ortho;
    document.getElementById('btn-top').classList.toggle('on', camera === ortho);
    document.getElementById('btn-3d').classList.toggle('on', camera === persp);
  }
  function fit() {
    let cx = 0, cy = 0, half = 10;
    if (state.grid) {
      const g = state.grid;
      const w = g.width * g.resolution, h = g.height * g.resolution;
      cx = g.origin_x + w / 2; cy = g.origin_y + h / 2;
      const aspect = canvas.clientWidth / Math.max(1, canvas.clientHeight);
      half = Math.max(h / 2, w / 2 / aspect) * 1.02;
    }
    orthoControls.target.set(cx, cy, 0);
    ortho.position.set(cx, cy, 50);
    ortho.zoom = 10 / half;
    ortho.updateProjectionMatrix();
    orthoControls.update();
    perspControls.target.set(cx, cy, 0);
    persp.position.set(cx - half, cy - half * 1.5, half * 1.2);
    perspControls.update();
  }
  document.getElementById('btn-top').addEventListener('click', function () { setCamera('top'); });
  document.getElementById('btn-3d').addEventListener('click', function () { setCamera('3d'); });
  document.getElementById('btn-fit').addEventListener('click', fit);
  document.getElementById('btn-follow').addEventListener('click', function (e) {
    follow = !follow;
    e.target.classList.toggle('on', follow);
  });
  function resize() {
    const w = canvas.clientWidth, h = canvas.clientHeight;
    if (w === 0 || h === 0) return;
    renderer.setSize(w, h, false);
    persp.aspect = w / h;
    persp.updateProjectionMatrix();
    const a = w / h;
    ortho.left = -10 * a; ortho.right = 10 * a; ortho.top = 10; ortho.bottom = -10;
    ortho.updateProjectionMatrix();
  }
  window.addEventListener('resize', resize);
  resize();
  function render() {
    renderer.render(scene, camera);
  }
  function loop() {
    render();
    requestAnimationFrame(loop);
  }
  ['grid', 'scan'].forEach(layer);

  // ---- hooks for tests and the console ----
  window.flViewer = {
    state: state,
    setView: function (which) { setCamera(which); render(); },
    fit: function () { fit(); render(); },
    // Canvas pixel (x right, y down, CSS pixels) of a map-frame point.
    worldToCanvas: function (x, y, z) {
      const v = new THREE.Vector3(x, y, z || 0).project(camera);
      return [(v.x + 1) / 2 * canvas.clientWidth, (1 - v.y) / 2 * canvas.clientHeight];
    },
    // [r, g, b, a] of a canvas pixel (CSS pixels, y down), after rendering.
    readPixel: function (px, py) {
      render();
      const gl = renderer.getContext();
      const out = new Uint8Array(4);
      const scale = gl.drawingBufferWidth / canvas.clientWidth;
      gl.readPixels(Math.floor(px * scale), Math.floor(gl.drawingBufferHeight - 1 - py * scale), 1, 1,
                    gl.RGBA, gl.UNSIGNED_BYTE, out);
      return Array.from(out);
    },
    // The pixels of the (2r+1)^2 square around a canvas pixel, after rendering.
    readRegion: function (px, py, r) {
      render();
      const gl = renderer.getContext();
      const scale = gl.drawingBufferWidth / canvas.clientWidth;
      const n = 2 * r + 1;
      const out = new Uint8Array(4 * n * n);
      gl.readPixels(Math.floor(px * scale) - r, Math.floor(gl.drawingBufferHeight - 1 - py * scale) - r,
                    n, n, gl.RGBA, gl.UNSIGNED_BYTE, out);
      const pixels = [];
      for (let i = 0; i < n * n; ++i) pixels.push(Array.from(out.subarray(4 * i, 4 * i + 4)));
      return pixels;
    },
    showOnly: function (names) {
      for (const n in layers) {
        layers[n].group.visible = names.indexOf(n) >= 0;
        const box = document.getElementById('layer-' + n);
        if (box) box.checked = layers[n].group.visible;
      }
      render();
    },
    send: send,
  };
  connect();
  loop();
})();
