// Loads the wasm module and the models listed in models.json (written beside the page by
// scripts/run-wasm.sh), steps the chosen model every frame with its handles following the
// mouse, and draws the surface the artifact carries (its drawn vertices and triangles) with
// WebGL2 (render.js). The time per frame shown is the model's own: one latent step plus the
// decode of the drawn vertices (mochi_step_pose), measured with performance.now() and
// averaged over the last frames.
//
// With Shift held, the mouse moves a ball (a run-time collider, mochi_set_collider) through
// the body instead, on the vertical plane through its centre; the drawn vertices inside the
// ball are pushed out to its surface after each step (the runtime's correction), and a model
// trained with collider slots also reads it.
//
// With ?test=1 the mouse is synthetic (the same handler gets generated events) and #status
// holds a machine-readable line for the headless-browser check (scripts/check-page.py):
//   model=NAME frames=N moved=D status=S drawn=P ms=T pushed=K
// (frames since the model was chosen, largest drawn-vertex displacement from rest as a
// fraction of the diagonal, the last step's status, non-background pixels of the last
// read-back frame, mean milliseconds per frame, most drawn vertices the ball pushed out in one
// step; the synthetic mouse sweeps the ball through the body from frame 60 on).
import { SurfaceView } from "./render.js";

const params = new URLSearchParams(location.search);
const testMode = params.has("test");
const canvas = document.getElementById("view");
const picker = document.getElementById("model");
const about = document.getElementById("about");
const timing = document.getElementById("timing");
const statusLine = document.getElementById("status");

const { instance } = await WebAssembly.instantiate(await (await fetch("mochi.wasm")).arrayBuffer(), {});
const m = instance.exports;
const view = new SurfaceView(canvas);

// The model compiled into the module, then the artifacts the page fetches.
const manifest = await fetch("models.json")
  .then((r) => (r.ok ? r.json() : {}))
  .catch(() => ({}));
const compiled = manifest.compiled ?? { name: "compiled", weights: "f32" };
const models = [
  { name: compiled.name, label: `${compiled.name} (compiled into the module, ${compiled.weights} weights)` },
  ...(manifest.models ?? []).map((e) => ({ ...e, label: `${e.name} (${(e.bytes / 1e6).toFixed(1)} MB artifact)` })),
];
for (const model of models) picker.add(new Option(model.label, model.name));

// How the mouse moves the handles: each model learned its own handle motions (its scene's
// [handles.motion]), so the mouse drives those and no others. [kind, axis]: "move" translates
// along the axis, "twist" turns about it. Solids (tiny, beam): up and down moves the clamped
// end, left and right twists it; cloth-line: left and right swings the pinned corners across
// the sheet (the one direction it was trained on).
const MOUSE = {
  solid: { horizontal: ["twist", 0], vertical: ["move", 1] },
  cloth: { horizontal: ["move", 2], vertical: ["move", 1] },
  "cloth-line": { horizontal: ["move", 2] },
  strands: { horizontal: ["move", 0], vertical: ["move", 2] },
};
const mouseOf = (name) => MOUSE[name] ?? (name.startsWith("cloth") ? MOUSE["cloth-line"] : MOUSE.solid);
const COLOURS = [[0.36, 0.55, 0.82], [0.83, 0.47, 0.3], [0.45, 0.68, 0.42], [0.7, 0.45, 0.75]];

// The model on screen; null while one loads.
let active = null;
const artifacts = new Map();
const TIMED_FRAMES = 60;

async function choose(name) {
  active = null;
  const index = Math.max(models.findIndex((e) => e.name === name), 0);
  const model = models[index];
  statusLine.textContent = `model=${model.name} loading`;
  let status;
  if (model.file === undefined) {
    status = m.mochi_init();
  } else {
    if (!artifacts.has(model.file)) {
      const response = await fetch(model.file);
      if (!response.ok) throw new Error(`${model.file}: HTTP ${response.status}`);
      artifacts.set(model.file, new Uint8Array(await response.arrayBuffer()));
    }
    const bytes = artifacts.get(model.file);
    const at = m.mochi_artifact_buffer(bytes.length);
    if (at === 0) throw new Error(`${model.file}: ${bytes.length} bytes is more than the page takes`);
    new Uint8Array(m.memory.buffer, at, bytes.length).set(bytes);
    status = m.mochi_load(bytes.length);
  }
  if (status < 0) {
    const text = new TextDecoder().decode(new Uint8Array(m.memory.buffer, m.mochi_error_text(), m.mochi_error_len()));
    throw new Error(`${model.name}: ${text || `status ${status}`}`);
  }
  const dim = m.mochi_dim();
  // A model with a render mesh draws it (its positions and normals from the module); any other
  // its simulation mesh's drawn vertices.
  const render = m.mochi_render_count() > 0;
  const count = render ? m.mochi_render_count() : m.mochi_surface_count();
  const triangles = render
    ? Uint32Array.from(new Uint32Array(m.memory.buffer, m.mochi_render_triangles(), 3 * m.mochi_render_triangle_count()))
    : Uint32Array.from(new Uint32Array(m.memory.buffer, m.mochi_triangles(), 3 * m.mochi_triangle_count()));
  const rest = (render ? renderPositions(count) : surface(dim, count)).slice();
  view.setMesh(triangles, rest, COLOURS[index % COLOURS.length]);
  about.textContent =
    `${model.name}: ${m.mochi_vertex_count().toLocaleString()} vertices, ` +
    (render ? `render mesh of ${count.toLocaleString()} vertices, ` : `${count.toLocaleString()} drawn, `) +
    `${(triangles.length / 3).toLocaleString()} triangles, ${m.mochi_handle_count()} handle(s), ` +
    (m.mochi_dt_max() > 0
      ? `steps at the page's frame rate (trained ${(1 / m.mochi_dt_max()).toFixed(0)}-${(1 / m.mochi_dt_min()).toFixed(0)} Hz)`
      : `${(1 / m.mochi_dt()).toFixed(0)} steps per second of simulated time`);
  active = {
    name: model.name,
    dim,
    render,
    count,
    rest,
    diagonal: m.mochi_diagonal(),
    dt: m.mochi_dt(),
    // A model trained over a range of frame times steps by the page's own frame time (kept
    // inside that range); any other by its one `dt`.
    dtRange: [m.mochi_dt_min(), m.mochi_dt_max()],
    last: null,
    mouse: mouseOf(model.name),
    pose: { t: [0, 0, 0], r: [0, 0, 0] },
    target: { t: [0, 0, 0], r: [0, 0, 0] },
    frames: 0,
    moved: 0,
    ball: null,
    pushed: 0,
    status: 0,
    drawn: 0,
    times: [],
  };
}

// The render mesh's positions and normals after the last step, 3 floats per render vertex.
function renderPositions(count) {
  return new Float32Array(m.memory.buffer, m.mochi_render_positions(), 3 * count);
}
function renderNormals(count) {
  return new Float32Array(m.memory.buffer, m.mochi_render_normals(), 3 * count);
}

// The drawn vertices' positions, 3 floats each (z = 0 for a 2D model).
function surface(dim, count) {
  const x = new Float32Array(m.memory.buffer, m.mochi_surface(), dim * count);
  if (dim === 3) return x;
  const out = new Float32Array(3 * count);
  for (let i = 0; i < count; i++) out.set(x.subarray(dim * i, dim * i + dim), 3 * i);
  return out;
}

// Mouse over the canvas without a button: the handles follow it (smoothed, speeds capped near
// the trained ranges). Dragging turns the camera; the wheel zooms.
function onMove(event) {
  if (event.buttons !== 0) {
    view.orbit(event.movementX, event.movementY);
    return;
  }
  if (!active) return;
  const r = canvas.getBoundingClientRect();
  const along = { horizontal: (event.clientX - r.left) / r.width - 0.5, vertical: 0.5 - (event.clientY - r.top) / r.height };
  if (event.shiftKey) {
    // The ball, a tenth of the diagonal across, over the body's rest box.
    const c = view.centre;
    const reach = 0.6 * active.diagonal;
    active.ball = {
      centre: [c[0] + 2 * along.horizontal * reach, c[1] + 2 * along.vertical * reach, c[2]],
      radius: 0.1 * active.diagonal,
    };
    return;
  }
  const target = { t: [0, 0, 0], r: [0, 0, 0] };
  for (const [direction, [kind, axis]] of Object.entries(active.mouse)) {
    if (kind === "move") target.t[axis] = 2 * along[direction] * 0.15 * active.diagonal;
    else target.r[axis] = 2 * along[direction] * 0.3;
  }
  active.target = target;
}
canvas.addEventListener("mousemove", onMove);
canvas.addEventListener("wheel", (event) => {
  event.preventDefault();
  view.zoom(Math.exp(0.001 * event.deltaY));
});
picker.addEventListener("change", () => choose(picker.value).catch(fail));

function fail(error) {
  active = null;
  statusLine.textContent = `error ${error.message}`;
}

const clamp = (v, limit) => Math.max(-limit, Math.min(limit, v));

function frame() {
  const a = active;
  if (a) {
    const now = performance.now();
    let dt = a.dt;
    if (a.dtRange[1] > 0 && a.last !== null) {
      dt = Math.min(a.dtRange[1], Math.max(a.dtRange[0], (now - a.last) / 1000));
    }
    a.last = now;
    const maxMove = 0.5 * a.diagonal * dt;
    const maxTurn = 1.0 * dt;
    for (let c = 0; c < 3; c++) {
      a.pose.t[c] += clamp(0.15 * (a.target.t[c] - a.pose.t[c]), maxMove);
      a.pose.r[c] += clamp(0.15 * (a.target.r[c] - a.pose.r[c]), maxTurn);
    }
    const start = performance.now();
    if (a.ball) m.mochi_set_collider(a.ball.radius, ...a.ball.centre);
    else m.mochi_set_collider(0, 0, 0, 0);
    a.status = m.mochi_step_pose_dt(dt, ...a.pose.t, ...a.pose.r);
    a.times.push(performance.now() - start);
    a.pushed = Math.max(a.pushed, m.mochi_pushed());
    view.setBall(a.ball);
    if (a.times.length > TIMED_FRAMES) a.times.shift();
    const x = a.render ? renderPositions(a.count) : surface(a.dim, a.count);
    view.draw(x, a.render ? renderNormals(a.count) : null);
    a.frames++;
    for (let i = 0; i < x.length; i += 3) {
      const d = Math.hypot(x[i] - a.rest[i], x[i + 1] - a.rest[i + 1], x[i + 2] - a.rest[i + 2]);
      a.moved = Math.max(a.moved, d / a.diagonal);
    }
    const ms = a.times.reduce((s, t) => s + t, 0) / a.times.length;
    timing.textContent = `time per frame: ${ms.toFixed(3)} ms (latent step + decode of the ${a.render ? "render mesh" : "drawn vertices"}, mean of the last ${a.times.length} frames)`;
    if (testMode) {
      if (a.frames % 10 === 0) a.drawn = view.drawnPixels();
      statusLine.textContent = `model=${a.name} frames=${a.frames} moved=${a.moved.toFixed(5)} status=${a.status} drawn=${a.drawn} ms=${ms.toFixed(4)} pushed=${a.pushed}`;
    } else {
      statusLine.textContent = a.status < 0 ? `step refused (status ${a.status})` : "";
    }
  }
  schedule();
}

// In test mode the mouse is synthetic: it circles the canvas, through the same handler, and
// the page paces itself with timers; an open page follows the display's frames.
function schedule() {
  if (testMode) {
    const r = canvas.getBoundingClientRect();
    const frames = active?.frames ?? 0;
    const phase = (2 * Math.PI * frames) / 90;
    canvas.dispatchEvent(
      new MouseEvent("mousemove", {
        clientX: r.left + r.width * (0.5 + 0.4 * Math.sin(phase)),
        clientY: r.top + r.height * (0.5 + 0.4 * Math.cos(phase)),
      }),
    );
    // From frame 60 the ball sweeps left and right through the body's middle.
    if (frames >= 60) {
      canvas.dispatchEvent(
        new MouseEvent("mousemove", {
          shiftKey: true,
          clientX: r.left + r.width * (0.5 + 0.3 * Math.sin(phase)),
          clientY: r.top + 0.5 * r.height,
        }),
      );
    }
    setTimeout(frame, 1000 / 60);
  } else {
    requestAnimationFrame(frame);
  }
}

const wanted = params.get("model") ?? manifest.default;
picker.value = models.some((e) => e.name === wanted) ? wanted : models[0].name;
await choose(picker.value).catch(fail);
schedule();
