// implc's viewer: the voxels as shaded point splats in WebGL2, streamed as chunks of the octree's levels
// of detail (implc/view/lod_chunks.py documents the chunk format), or a triangle mesh drawn whole
// (implc/view/mesh_payload.py documents mesh.bin). Written for implc; no library.
"use strict";

(function () {
  // shading and camera as implc's PNG renderer (implc/view/render.py: Style, View, perspective)
  const BACKGROUND = [0.08, 0.09, 0.11], COLOR = [0.85, 0.62, 0.35];
  const AMBIENT = 0.18, SPECULAR = 0.35, SHININESS = 40.0;
  const FOV = 35 * Math.PI / 180, FOCAL = 1.05 / Math.tan(FOV / 2), SPLAT = 1.2;
  const REFINE_PIXELS = 1.0;  // refine a chunk while its points cover more than this many pixels
  const MAX_REQUESTS = 6;
  const HEADER = 64, MAGIC = 0x43504D49, MESH_MAGIC = 0x484D4D49, MESH_HEADER = 32;

  const embed = window.IMPLC_EMBED || null;
  const params = new URLSearchParams(location.search);
  let budget = 1000000;  // points drawn at most: ?budget=N, else the model's meta.json
  const canvas = document.getElementById("view");
  const overlay = document.getElementById("overlay");
  const gl = canvas.getContext("webgl2", { antialias: false, preserveDrawingBuffer: true });
  // timings (ms, performance.now()): when this script started, and its first frame
  const api = { ready: null, requests: 0, deepest: -1, stats: null, setView: null, camera: null, errors: [],
                timings: { script: performance.now(), firstFrame: null, drawn: {} },
                generation: 0, drawnGeneration: -1, status: null };
  window.implcViewer = api;
  if (!gl) {
    overlay.textContent = "this browser has no WebGL2";
    api.ready = Promise.reject(new Error("no WebGL2"));
    return;
  }

  const VERTEX = `#version 300 es
    layout(location = 0) in vec3 cell;
    layout(location = 1) in vec2 oct;
    uniform vec3 origin, cellSize, eye, right, up, forward, fixedNormal;
    uniform float aspect, near, far, pixelsPerUnit, splat, clipLimit;
    uniform int clipAxis;  // -1: no cut; else points whose centre lies beyond clipLimit on that axis vanish
    uniform bool fixedNormals;
    out vec3 normal;
    void main() {
      vec3 world = origin + cell * cellSize;
      if (clipAxis >= 0 && world[clipAxis] > clipLimit) {
        gl_Position = vec4(2.0, 2.0, 2.0, 1.0);
        gl_PointSize = 0.0;
        normal = vec3(0.0, 0.0, 1.0);
        return;
      }
      vec3 p = world - eye;
      float x = dot(p, right), y = dot(p, up), z = dot(p, forward);
      gl_Position = vec4(x * ${FOCAL.toFixed(9)} / aspect, y * ${FOCAL.toFixed(9)},
                         (z - near) / (far - near) * 2.0 * z - z, z);
      gl_PointSize = max(1.0, ceil(splat * pixelsPerUnit / max(z, 1e-6)));
      vec2 f = oct * 2.0 - 1.0;
      vec3 n = vec3(f, 1.0 - abs(f.x) - abs(f.y));
      float t = max(-n.z, 0.0);
      n.x += n.x >= 0.0 ? -t : t;
      n.y += n.y >= 0.0 ? -t : t;
      normal = fixedNormals ? fixedNormal : normalize(n);
    }`;
  const FRAGMENT = `#version 300 es
    precision highp float;
    in vec3 normal;
    uniform vec3 right, up, forward;
    out vec4 color;
    void main() {
      vec3 n = normalize(normal);
      if (dot(n, -forward) < 0.0) n = -n;
      vec3 light = normalize(-forward + 0.6 * up - 0.4 * right);
      vec3 halfway = normalize(light - forward);
      float diffuse = clamp(dot(n, light), 0.0, 1.0);
      float spec = pow(clamp(dot(n, halfway), 0.0, 1.0), ${SHININESS.toFixed(1)});
      vec3 base = vec3(${COLOR.join(", ")});
      color = vec4(clamp(base * (${AMBIENT} + ${1 - AMBIENT} * diffuse) + ${SPECULAR} * spec, 0.0, 1.0), 1.0);
    }`;

  // a mesh: positions and normals per vertex, shaded as the splats are; the cut-away discards what lies beyond
  const MESH_VERTEX = `#version 300 es
    layout(location = 0) in vec3 position;
    layout(location = 1) in vec3 vertexNormal;
    uniform vec3 eye, right, up, forward;
    uniform float aspect, near, far;
    out vec3 normal;
    out vec3 world;
    void main() {
      vec3 p = position - eye;
      float x = dot(p, right), y = dot(p, up), z = dot(p, forward);
      gl_Position = vec4(x * ${FOCAL.toFixed(9)} / aspect, y * ${FOCAL.toFixed(9)},
                         (z - near) / (far - near) * 2.0 * z - z, z);
      normal = vertexNormal;
      world = position;
    }`;
  const MESH_FRAGMENT = FRAGMENT.replace("in vec3 normal;", `in vec3 normal;
    in vec3 world;
    uniform int clipAxis;
    uniform float clipLimit;`).replace("void main() {", `void main() {
      if (clipAxis >= 0 && world[clipAxis] > clipLimit) discard;`);

  function compile(type, source) {
    const shader = gl.createShader(type);
    gl.shaderSource(shader, source);
    gl.compileShader(shader);
    if (!gl.getShaderParameter(shader, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(shader));
    return shader;
  }
  const program = gl.createProgram();
  gl.attachShader(program, compile(gl.VERTEX_SHADER, VERTEX));
  gl.attachShader(program, compile(gl.FRAGMENT_SHADER, FRAGMENT));
  gl.linkProgram(program);
  if (!gl.getProgramParameter(program, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(program));
  const meshProgram = gl.createProgram();
  gl.attachShader(meshProgram, compile(gl.VERTEX_SHADER, MESH_VERTEX));
  gl.attachShader(meshProgram, compile(gl.FRAGMENT_SHADER, MESH_FRAGMENT));
  gl.linkProgram(meshProgram);
  if (!gl.getProgramParameter(meshProgram, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(meshProgram));
  const meshUniform = {};
  for (const name of ["eye", "right", "up", "forward", "aspect", "near", "far", "clipAxis", "clipLimit"]) {
    meshUniform[name] = gl.getUniformLocation(meshProgram, name);
  }
  const uniform = {};
  for (const name of ["origin", "cellSize", "eye", "right", "up", "forward", "aspect", "near", "far",
                      "pixelsPerUnit", "splat", "clipAxis", "clipLimit", "fixedNormal", "fixedNormals"]) {
    uniform[name] = gl.getUniformLocation(program, name);
  }

  // ---- camera: orbit around a target, azimuth around +z from +x, elevation above the xy plane ----
  let meta = null, radius = 1, center = [0, 0, 0], home = null;
  const camera = { azimuth: 35, elevation: 25, distance: 3, target: [0, 0, 0] };
  api.camera = camera;
  const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
  const add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
  const scale = (a, s) => [a[0] * s, a[1] * s, a[2] * s];
  const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
  const normalize = (a) => scale(a, 1 / Math.hypot(a[0], a[1], a[2]));

  function basis() {
    const az = camera.azimuth * Math.PI / 180, el = camera.elevation * Math.PI / 180;
    const eyeDir = [Math.cos(el) * Math.cos(az), Math.cos(el) * Math.sin(az), Math.sin(el)];
    const forward = scale(eyeDir, -1);
    let right = cross(forward, [0, 0, 1]);
    if (Math.hypot(...right) < 1e-9) right = forward[2] < 0 ? [0, 1, 0] : [0, -1, 0];
    right = normalize(right);
    const up = cross(right, forward);
    return { forward, right, up, eye: add(camera.target, scale(eyeDir, camera.distance)) };
  }

  function resetCamera() {
    Object.assign(camera, JSON.parse(JSON.stringify(home)));
    changed();
  }

  // ---- chunks ----
  const chunks = new Map();  // id -> {level, cell, m, count, children, state, vao, buffers}
  let inFlight = 0;
  const queue = [];

  function chunkId(level, cell) { return `${level}-${cell[0]}-${cell[1]}-${cell[2]}`; }

  function base64Bytes(text) {
    const raw = atob(text), out = new Uint8Array(raw.length);
    for (let i = 0; i < raw.length; i++) out[i] = raw.charCodeAt(i);
    return out.buffer;
  }

  async function fetchBytes(id) {
    if (embed) {
      if (!(id in embed.chunks)) return null;
      return base64Bytes(embed.chunks[id]);
    }
    const response = await fetch(`chunks/${id}.bin${fresh()}`);
    if (response.status === 404 || response.status === 409) return null;
    if (!response.ok) throw new Error(`chunk ${id}: HTTP ${response.status}`);
    return response.arrayBuffer();
  }

  // a live page names the generation it draws: the server answers 409 for an older one
  function fresh() { return meta && meta.live ? `?generation=${meta.generation}` : ""; }

  let requestedThisFrame = 0;
  function request(level, cell) {
    const id = chunkId(level, cell);
    if (chunks.has(id)) return chunks.get(id);
    requestedThisFrame++;
    const node = { id, level, cell, state: "queued", count: 0, children: null, m: 0, generation: api.generation };
    chunks.set(id, node);
    queue.push(node);
    pump();
    return node;
  }

  function pump() {
    while (inFlight < MAX_REQUESTS && queue.length) {
      const node = queue.shift();
      node.state = "loading";
      inFlight++;
      api.requests++;
      fetchBytes(node.id).then((bytes) => {
        inFlight--;
        if (node.generation !== api.generation) { node.state = "stale"; } else if (bytes === null) { node.state = "missing"; } else { upload(node, bytes); }
        pump();
        changed();
      }).catch((error) => {
        inFlight--;
        node.state = "missing";
        api.errors.push(String(error));
        overlay.textContent = String(error);
        pump();
      });
    }
  }

  function upload(node, bytes) {
    const header = new Uint32Array(bytes, 0, HEADER / 4);
    if (header[0] !== MAGIC) throw new Error(`chunk ${node.id}: not an implc chunk`);
    node.m = header[6];
    node.count = header[7];
    node.children = Array.from(header.subarray(8, 16));
    const cells = new Uint8Array(bytes, HEADER, 3 * node.count);
    const normals = new Uint8Array(bytes, HEADER + 3 * node.count, 2 * node.count);
    node.vao = gl.createVertexArray();
    gl.bindVertexArray(node.vao);
    node.buffers = [gl.createBuffer(), gl.createBuffer()];
    gl.bindBuffer(gl.ARRAY_BUFFER, node.buffers[0]);
    gl.bufferData(gl.ARRAY_BUFFER, cells, gl.STATIC_DRAW);
    gl.enableVertexAttribArray(0);
    gl.vertexAttribPointer(0, 3, gl.UNSIGNED_BYTE, false, 0, 0);
    gl.bindBuffer(gl.ARRAY_BUFFER, node.buffers[1]);
    gl.bufferData(gl.ARRAY_BUFFER, normals, gl.STATIC_DRAW);
    gl.enableVertexAttribArray(1);
    gl.vertexAttribPointer(1, 2, gl.UNSIGNED_BYTE, true, 0, 0);
    gl.bindVertexArray(null);
    // where the chunk's cells are: its first cell at its point level, and that level's cell size
    const n = 2 ** node.m, shift = 2 ** (node.m - node.level);
    node.cellSize = meta.bounds.map(([lo, hi]) => (hi - lo) / n);
    node.origin = meta.bounds.map(([lo], a) => lo + (node.cell[a] * shift + 0.5) * node.cellSize[a]);
    node.lo = meta.bounds.map(([lo], a) => lo + node.cell[a] * shift * node.cellSize[a]);
    node.hi = node.lo.map((v, a) => v + shift * node.cellSize[a]);
    node.state = "ready";
    api.deepest = Math.max(api.deepest, node.level);
  }

  // ---- a mesh: mesh.bin, uploaded whole ----
  const mesh = { state: "none", vao: null, vertices: 0, triangles: 0, buffers: [] };

  async function loadMesh() {
    mesh.state = "loading";
    inFlight++;
    api.requests++;
    try {
      let bytes;
      if (embed) { bytes = base64Bytes(embed.mesh); } else {
        const response = await fetch(`mesh.bin${fresh()}`);
        if (!response.ok) throw new Error(`mesh.bin: HTTP ${response.status}`);
        bytes = await response.arrayBuffer();
      }
      const header = new Uint32Array(bytes, 0, MESH_HEADER / 4);
      if (header[0] !== MESH_MAGIC) throw new Error("mesh.bin: not an implc mesh");
      const vertices = header[2], triangles = header[3];
      const positions = new Float32Array(bytes, MESH_HEADER, 3 * vertices);
      const normals = new Float32Array(bytes, MESH_HEADER + 12 * vertices, 3 * vertices);
      const indices = new Uint32Array(bytes, MESH_HEADER + 24 * vertices, 3 * triangles);
      mesh.vao = gl.createVertexArray();
      gl.bindVertexArray(mesh.vao);
      mesh.buffers = [];
      for (const [location, data] of [[0, positions], [1, normals]]) {
        mesh.buffers.push(gl.createBuffer());
        gl.bindBuffer(gl.ARRAY_BUFFER, mesh.buffers[mesh.buffers.length - 1]);
        gl.bufferData(gl.ARRAY_BUFFER, data, gl.STATIC_DRAW);
        gl.enableVertexAttribArray(location);
        gl.vertexAttribPointer(location, 3, gl.FLOAT, false, 0, 0);
      }
      mesh.buffers.push(gl.createBuffer());
      gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, mesh.buffers[mesh.buffers.length - 1]);
      gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, indices, gl.STATIC_DRAW);
      gl.bindVertexArray(null);
      Object.assign(mesh, { vertices, triangles, state: "ready" });
    } catch (error) {
      mesh.state = "missing";
      api.errors.push(String(error));
      overlay.textContent = String(error);
    }
    inFlight--;
    changed();
  }

  // the camera, as both programs (splats and mesh) read it
  function cameraUniforms(u, view, aspect, near, far) {
    gl.uniform3fv(u.eye, view.eye);
    gl.uniform3fv(u.right, view.right);
    gl.uniform3fv(u.up, view.up);
    gl.uniform3fv(u.forward, view.forward);
    gl.uniform1f(u.aspect, aspect);
    gl.uniform1f(u.near, near);
    gl.uniform1f(u.far, far);
  }

  function drawMesh(view, aspect, near, far) {
    gl.useProgram(meshProgram);
    cameraUniforms(meshUniform, view, aspect, near, far);
    gl.uniform1i(meshUniform.clipAxis, plane.axis);
    if (plane.axis >= 0) {
      const [lo, hi] = meta.bounds[plane.axis];
      gl.uniform1f(meshUniform.clipLimit, lo + plane.fraction * (hi - lo));
    }
    const shown = mesh.state === "ready" ? mesh : retired.mesh;  // a live page: the last model until the new one
    if (shown && shown.state === "ready") {
      gl.bindVertexArray(shown.vao);
      gl.drawElements(gl.TRIANGLES, 3 * shown.triangles, gl.UNSIGNED_INT, 0);
      gl.bindVertexArray(null);
    }
  }

  function meshOverlay() {
    overlay.textContent = `${meta.name ? meta.name + "\n" : ""}mesh: ${meta.triangles.toLocaleString("en")} triangles, ` +
      `${meta.vertices.toLocaleString("en")} vertices${plane.axis >= 0 ? ", cut " + "xyz"[plane.axis] : ""}` +
      `${mesh.state === "loading" ? ", loading" : ""}\nframe ${lastFrame.toFixed(1)} ms`;
  }

  // ---- a cut-away: the plane's axis and where it lies (a fraction of the bounds), the section drawn ----
  const plane = { axis: -1, fraction: 0.5 };
  const sections = new Map();  // "axis-index-level" -> {state, vao, count, level, axis, index}

  function wantSection(axis, index, level) {
    const id = `${axis}-${index}-${level}`;
    if (sections.has(id)) return sections.get(id);
    const entry = { id, axis, index, level, state: "loading", count: 0 };
    sections.set(id, entry);
    if (embed) { entry.state = "missing"; return entry; }  // an embedded page has no server to cut for it
    inFlight++;
    api.requests++;
    const generation = api.generation;
    fetch(`sections/${id}.bin${fresh()}`).then((r) => (r.ok ? r.arrayBuffer() : null)).then((bytes) => {
      inFlight--;
      if (generation !== api.generation) return;  // the model changed meanwhile: its sections were dropped
      if (bytes === null) { entry.state = "missing"; changed(); return; }
      const header = new Uint32Array(bytes, 0, 8), count = header[5];
      const uv = new Uint32Array(bytes, 32, 2 * count), cells = new Float32Array(3 * count);
      const [u, v] = [0, 1, 2].filter((a) => a !== axis);
      for (let i = 0; i < count; i++) {
        cells[3 * i + axis] = index; cells[3 * i + u] = uv[2 * i]; cells[3 * i + v] = uv[2 * i + 1];
      }
      entry.vao = gl.createVertexArray();
      gl.bindVertexArray(entry.vao);
      entry.buffer = gl.createBuffer();
      gl.bindBuffer(gl.ARRAY_BUFFER, entry.buffer);
      gl.bufferData(gl.ARRAY_BUFFER, cells, gl.STATIC_DRAW);
      gl.enableVertexAttribArray(0);
      gl.vertexAttribPointer(0, 3, gl.FLOAT, false, 0, 0);
      gl.disableVertexAttribArray(1);
      gl.bindVertexArray(null);
      entry.count = count;
      entry.state = "ready";
      for (const [other, old] of sections) {  // keep the latest only
        if (other !== id && old.state === "ready" && old.axis === axis) {
          gl.deleteBuffer(old.buffer); gl.deleteVertexArray(old.vao); sections.delete(other);
        }
      }
      changed();
    }).catch((error) => { inFlight--; entry.state = "missing"; api.errors.push(String(error)); });
    return entry;
  }

  function childCells(node) {
    const out = [];
    for (let c = 0; c < 8; c++) {
      if (node.children[c] > 0) {
        out.push([node.level + 1, [2 * node.cell[0] + (c & 1), 2 * node.cell[1] + ((c >> 1) & 1),
                                   2 * node.cell[2] + (c >> 2)], node.children[c]]);
      }
    }
    return out;
  }

  // how large one of the chunk's points looks (pixels) from its nearest corner; null when out of view
  function projected(node, view, pixelsPerUnit, aspect) {
    let nearest = Infinity, outside = [0, 0, 0, 0], behind = 0;
    for (let c = 0; c < 8; c++) {
      const corner = [c & 1 ? node.hi[0] : node.lo[0], c & 2 ? node.hi[1] : node.lo[1], c & 4 ? node.hi[2] : node.lo[2]];
      const p = sub(corner, view.eye);
      const z = dot(p, view.forward);
      if (z <= 1e-9) { behind++; nearest = 1e-9; continue; }
      nearest = Math.min(nearest, z);
      const x = dot(p, view.right) * FOCAL / aspect / z, y = dot(p, view.up) * FOCAL / z;
      if (x < -1) outside[0]++; if (x > 1) outside[1]++; if (y < -1) outside[2]++; if (y > 1) outside[3]++;
    }
    if (behind === 8 || outside.some((k) => k === 8)) return null;
    return Math.max(...node.cellSize) * pixelsPerUnit / nearest;
  }

  // the cut of the chunk tree to draw: refine the chunks whose points look largest first, within the budget
  function selectCut(view, pixelsPerUnit, aspect) {
    const root = chunks.get("0-0-0-0");
    if (!root || root.state !== "ready") return [];
    const cut = new Set([root]);
    let points = root.count;
    const heap = [[projected(root, view, pixelsPerUnit, aspect), root]];
    while (heap.length) {
      let best = 0;
      for (let i = 1; i < heap.length; i++) if (heap[i][0] > heap[best][0]) best = i;
      const [size, node] = heap.splice(best, 1)[0];
      if (size === null || size <= REFINE_PIXELS || node.level >= meta.max_chunk_level) continue;
      const kids = childCells(node);
      if (!kids.length) continue;
      const extra = kids.reduce((s, k) => s + k[2], 0) - node.count;
      if (points + extra > budget) continue;
      const nodes = kids.map(([level, cell]) => request(level, cell));
      if (nodes.some((k) => k.state !== "ready" && k.state !== "missing")) continue;
      cut.delete(node);
      points += extra;
      for (const k of nodes) {
        if (k.state !== "ready") continue;
        cut.add(k);
        const s = projected(k, view, pixelsPerUnit, aspect);
        if (s !== null) heap.push([s, k]);
      }
    }
    return Array.from(cut);
  }

  // ---- drawing, on demand ----
  let pending = false, lastFrame = 0, lastDrawn = 0, lastChunks = 0, lastRequested = 0, firstDrawn = null;
  api.ready = new Promise((resolve) => { firstDrawn = resolve; });

  let prefetch = [];  // a live page's new model: the chunks the camera needed of the last one
  function drewGeneration() {  // the first frame of each model: when (performance.now()), for live editing's timing
    if (api.drawnGeneration !== api.generation) {
      api.timings.drawn[api.generation] = performance.now();
      // its first frame is up: ask at once for what the last model's cut needed, not level by level
      for (const node of prefetch) request(node.level, node.cell);
      prefetch = [];
    }
    api.drawnGeneration = api.generation;
  }

  function changed() {
    if (!pending && meta) {
      pending = true;
      requestAnimationFrame(draw);
    }
  }

  function draw() {
    pending = false;
    const started = performance.now();
    const dpr = window.devicePixelRatio || 1;
    const width = Math.max(1, Math.round(canvas.clientWidth * dpr)), height = Math.max(1, Math.round(canvas.clientHeight * dpr));
    if (canvas.width !== width || canvas.height !== height) { canvas.width = width; canvas.height = height; }
    gl.viewport(0, 0, width, height);
    gl.clearColor(...BACKGROUND, 1);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    gl.enable(gl.DEPTH_TEST);
    const view = basis(), aspect = width / height, pixelsPerUnit = FOCAL * height / 2;
    const near = Math.max(camera.distance - 2 * radius, radius * 1e-3), far = camera.distance + 2 * radius;
    if (meta.kind === "mesh") {
      drawMesh(view, aspect, near, far);
      lastFrame = performance.now() - started;
      meshOverlay();
      lastRequested = 0;
      lastChunks = mesh.state === "ready" ? 1 : 0;
      if (mesh.state === "ready") { drewGeneration(); dropRetired(); }
      if (mesh.state === "ready" && firstDrawn) {
        api.timings.firstFrame = performance.now();
        firstDrawn();
        firstDrawn = null;
      }
      return;
    }
    requestedThisFrame = 0;
    let chunksDrawn = selectCut(view, pixelsPerUnit, aspect);
    if (chunksDrawn.length) { dropRetired(); } else if (retired.chunks.length) { chunksDrawn = retired.chunks; }
    lastCut = chunksDrawn;
    lastRequested = requestedThisFrame;
    gl.useProgram(program);
    cameraUniforms(uniform, view, aspect, near, far);
    gl.uniform1f(uniform.pixelsPerUnit, pixelsPerUnit);
    // the cut-away: at the finest point level drawn, the layer the plane falls in, cells beyond it hidden
    let section = null, clipLimit = 0;
    if (plane.axis >= 0 && chunksDrawn.length) {
      const level = Math.max(...chunksDrawn.map((c) => c.m)), [lo, hi] = meta.bounds[plane.axis];
      const index = Math.min(Math.floor(plane.fraction * 2 ** level), 2 ** level - 1);
      clipLimit = lo + index * (hi - lo) / 2 ** level;
      const wanted = wantSection(plane.axis, index, level);
      section = wanted.state === "ready" ? wanted : null;
      if (!section) {  // until it comes, the latest section on this axis
        for (const other of sections.values()) if (other.state === "ready" && other.axis === plane.axis) section = other;
      }
    }
    gl.uniform1i(uniform.clipAxis, plane.axis);
    gl.uniform1f(uniform.clipLimit, clipLimit);
    gl.uniform1i(uniform.fixedNormals, 0);
    let points = 0;
    for (const node of chunksDrawn) {
      gl.uniform3fv(uniform.origin, node.origin);
      gl.uniform3fv(uniform.cellSize, node.cellSize);
      gl.uniform1f(uniform.splat, SPLAT * Math.max(...node.cellSize));
      gl.bindVertexArray(node.vao);
      gl.drawArrays(gl.POINTS, 0, node.count);
      points += node.count;
    }
    if (section) {
      const n = 2 ** section.level, cellSize = meta.bounds.map(([lo, hi]) => (hi - lo) / n);
      gl.uniform1i(uniform.clipAxis, -1);
      gl.uniform1i(uniform.fixedNormals, 1);
      gl.uniform3fv(uniform.fixedNormal, [0, 1, 2].map((a) => (a === section.axis ? 1 : 0)));
      gl.uniform3fv(uniform.origin, meta.bounds.map(([lo], a) => lo + 0.5 * cellSize[a]));
      gl.uniform3fv(uniform.cellSize, cellSize);
      gl.uniform1f(uniform.splat, SPLAT * Math.max(...cellSize));
      gl.bindVertexArray(section.vao);
      gl.drawArrays(gl.POINTS, 0, section.count);
      points += section.count;
    }
    gl.bindVertexArray(null);
    lastFrame = performance.now() - started;
    lastDrawn = points;
    lastChunks = chunksDrawn.length;
    const levels = chunksDrawn.length ? `${Math.min(...chunksDrawn.map((c) => c.m))}-${Math.max(...chunksDrawn.map((c) => c.m))}` : "-";
    overlay.textContent = `${meta.name ? meta.name + "\n" : ""}depth ${meta.depth} (${2 ** meta.depth}³), ` +
      `${meta.voxels.toLocaleString("en")} voxels in the model\n` +
      `points drawn ${points.toLocaleString("en")} of budget ${budget.toLocaleString("en")}, levels ${levels}, ` +
      `${chunksDrawn.length} chunks${plane.axis >= 0 ? ", cut " + "xyz"[plane.axis] : ""}\nframe ${lastFrame.toFixed(1)} ms`;
    if (chunksDrawn.length && chunksDrawn !== retired.chunks) drewGeneration();
    if (chunksDrawn.length && firstDrawn) {
      api.timings.firstFrame = performance.now();
      firstDrawn();
      firstDrawn = null;
    }
  }

  // settled: the last frame asked for nothing new and nothing is on its way
  api.stats = () => ({ points: lastDrawn, chunks: lastChunks, frameMs: lastFrame, requests: api.requests,
                       triangles: mesh.state === "ready" ? mesh.triangles : 0,
                       deepest: api.deepest, loading: inFlight + queue.length, budget,
                       settled: !pending && lastRequested === 0 && inFlight + queue.length === 0 && lastChunks > 0 });
  api.setView = (azimuth, elevation, distance) => {
    camera.azimuth = azimuth; camera.elevation = elevation;
    if (distance !== undefined) camera.distance = distance;
    changed();
  };
  api.zoom = (factor) => { camera.distance *= factor; changed(); };
  // a cut-away across axis 0, 1 or 2 (-1: none) at a world coordinate, as 'implc render --cut'
  api.setCut = (axis, value) => {
    plane.axis = axis;
    if (axis >= 0) {
      const [lo, hi] = meta.bounds[axis];
      plane.fraction = Math.min(Math.max((value - lo) / (hi - lo), 0), 1);
      cutValue.value = String(Math.round(plane.fraction * 1000));
    }
    cutAxis.value = String(axis);
    changed();
  };
  const cutAxis = document.getElementById("cut-axis"), cutValue = document.getElementById("cut-value");
  cutAxis.addEventListener("change", () => { plane.axis = Number(cutAxis.value); changed(); });
  cutValue.addEventListener("input", () => { plane.fraction = Number(cutValue.value) / 1000; changed(); });

  // ---- input: pointer events cover mouse, pen and touch ----
  const pointers = new Map();
  let pinch = null;
  function pan(dx, dy) {
    const view = basis(), unitsPerPixel = camera.distance / (FOCAL * canvas.clientHeight / 2);
    camera.target = add(camera.target, add(scale(view.right, -dx * unitsPerPixel), scale(view.up, dy * unitsPerPixel)));
  }
  canvas.addEventListener("pointerdown", (e) => {
    canvas.setPointerCapture(e.pointerId);
    pointers.set(e.pointerId, { x: e.clientX, y: e.clientY, button: e.button, shift: e.shiftKey });
    pinch = null;
  });
  canvas.addEventListener("pointermove", (e) => {
    const p = pointers.get(e.pointerId);
    if (!p) return;
    const dx = e.clientX - p.x, dy = e.clientY - p.y;
    if (pointers.size === 1) {
      if (p.button === 2 || p.shift) { pan(dx, dy); } else {
        camera.azimuth -= dx * 0.4;
        camera.elevation = Math.max(-89.9, Math.min(89.9, camera.elevation + dy * 0.4));
      }
    } else if (pointers.size === 2) {
      p.x = e.clientX; p.y = e.clientY;
      const [a, b] = Array.from(pointers.values());
      const span = Math.hypot(a.x - b.x, a.y - b.y), mid = [(a.x + b.x) / 2, (a.y + b.y) / 2];
      if (pinch) {
        camera.distance *= pinch.span / Math.max(span, 1);
        pan(mid[0] - pinch.mid[0], mid[1] - pinch.mid[1]);
      }
      pinch = { span, mid };
      changed();
      return;
    }
    p.x = e.clientX; p.y = e.clientY;
    changed();
  });
  const release = (e) => { pointers.delete(e.pointerId); pinch = null; };
  canvas.addEventListener("pointerup", release);
  canvas.addEventListener("pointercancel", release);
  canvas.addEventListener("contextmenu", (e) => e.preventDefault());
  canvas.addEventListener("wheel", (e) => {
    e.preventDefault();
    camera.distance *= Math.exp(e.deltaY * 0.0015);
    changed();
  }, { passive: false });
  canvas.addEventListener("dblclick", resetCamera);
  document.getElementById("reset").addEventListener("click", resetCamera);
  window.addEventListener("keydown", (e) => { if (e.key === "r" || e.key === "R") resetCamera(); });
  window.addEventListener("resize", changed);

  // ---- a live page (implc view --watch): each new model replaces the last, the camera kept ----
  const retired = { chunks: [], mesh: null, nodes: [], sections: [] };
  let lastCut = [];
  const statusLine = document.getElementById("status");

  function dropRetired() {  // the new model is drawn: free the last one's buffers
    for (const node of retired.nodes) {
      if (node.vao) { gl.deleteVertexArray(node.vao); for (const b of node.buffers) gl.deleteBuffer(b); }
    }
    if (retired.mesh && retired.mesh.vao) {
      gl.deleteVertexArray(retired.mesh.vao);
      for (const b of retired.mesh.buffers) gl.deleteBuffer(b);
    }
    for (const entry of retired.sections) if (entry.vao) { gl.deleteBuffer(entry.buffer); gl.deleteVertexArray(entry.vao); }
    Object.assign(retired, { chunks: [], mesh: null, nodes: [], sections: [] });
  }

  function frame(newMeta) {  // where the model lies: the bounds' centre and radius, the camera's home
    const lo = newMeta.bounds.map((b) => b[0]), hi = newMeta.bounds.map((b) => b[1]);
    center = lo.map((v, a) => (v + hi[a]) / 2);
    radius = Math.hypot(...hi.map((v, a) => v - lo[a])) / 2;
    const view = params.get("view") ? params.get("view").split(",").map(Number) : newMeta.view;
    home = { azimuth: view[0], elevation: view[1], distance: radius / Math.tan(FOV / 2) * 1.05, target: center };
  }

  async function reload() {
    const newMeta = await (await fetch("meta.json")).json();
    dropRetired();
    retired.chunks = lastCut.filter((node) => node.state === "ready");
    retired.nodes = Array.from(chunks.values());
    retired.sections = Array.from(sections.values());
    if (mesh.state === "ready") retired.mesh = { ...mesh };
    chunks.clear(); sections.clear(); queue.length = 0;
    Object.assign(mesh, { state: "none", vao: null, vertices: 0, triangles: 0, buffers: [] });
    meta = newMeta;
    api.generation = meta.generation;
    frame(meta);
    if (meta.kind === "mesh") { loadMesh(); } else {
      request(0, [0, 0, 0]);
      prefetch = retired.chunks.filter((node) => node.level <= meta.max_chunk_level);
    }
    changed();
  }

  function showStatus(state) {
    api.status = state;
    statusLine.textContent = state.error ? state.error : state.building ? "building…" : "";
    statusLine.className = state.error ? "error" : state.building ? "building" : "";
  }

  async function follow() {
    let revision = -1;
    for (;;) {
      let state;
      try {
        const response = await fetch(`live.json?after=${revision}`);
        if (!response.ok) throw new Error(`HTTP ${response.status}`);
        state = await response.json();
      } catch (error) {
        showStatus({ error: "the implc view server is not answering (stopped?)", building: false });
        await new Promise((resolve) => setTimeout(resolve, 1000));
        continue;
      }
      revision = state.revision;
      showStatus(state);
      if (state.generation !== meta.generation) {
        try { await reload(); } catch (error) { api.errors.push(String(error)); }
      }
    }
  }

  // ---- start: the model's description, then its root chunk ----
  async function start() {
    meta = embed ? embed.meta : await (await fetch("meta.json")).json();
    budget = Number(params.get("budget")) || meta.budget || budget;
    api.generation = meta.generation || 0;
    frame(meta);
    Object.assign(camera, JSON.parse(JSON.stringify(home)));
    document.title = `implc view${meta.name ? " · " + meta.name : ""}`;
    if (meta.kind === "mesh") { loadMesh(); changed(); } else { request(0, [0, 0, 0]); }
    if (meta.live && !embed) follow();
  }
  start().catch((error) => { api.errors.push(String(error)); overlay.textContent = String(error); });
})();
