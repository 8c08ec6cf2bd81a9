// Loads the wasm module, steps the model every animation frame with the handle pose driven by
// the mouse, and draws the mesh (edges between nearest neighbours of the rest shape) on a 2D
// canvas. With ?test=1 the same mouse handlers are fed synthetic events and the page writes a
// machine-readable line into #status (frames drawn, largest vertex displacement from rest as
// a fraction of the diagonal) for the headless-browser test.
const params = new URLSearchParams(location.search);
const testMode = params.has("test");
const testFrames = Number(params.get("frames") || 120);
const canvas = document.getElementById("view");
const ctx = canvas.getContext("2d");
const statusLine = document.getElementById("status");

const bytes = await (await fetch("mochi.wasm")).arrayBuffer();
const { instance } = await WebAssembly.instantiate(bytes, {});
const m = instance.exports;
if (m.mochi_init() !== 0) throw new Error("mochi_init failed");

const dim = m.mochi_dim();
const n = m.mochi_vertex_count();
const dt = m.mochi_dt();
const diagonal = m.mochi_diagonal();
const rest = Float32Array.from(new Float32Array(m.memory.buffer, m.mochi_rest(), n * dim));
const at = (p, i) => [p[i * dim], p[i * dim + 1], dim > 2 ? p[i * dim + 2] : 0];

// Edges: each vertex to the vertices within 1.6 times its nearest neighbour's distance.
const edges = [];
{
  const nearest = new Float32Array(n).fill(Infinity);
  const dist = (i, j) => Math.hypot(...at(rest, i).map((v, c) => v - at(rest, j)[c]));
  for (let i = 0; i < n; i++) for (let j = 0; j < n; j++) if (i !== j) nearest[i] = Math.min(nearest[i], dist(i, j));
  for (let i = 0; i < n; i++)
    for (let j = i + 1; j < n; j++) if (dist(i, j) <= 1.6 * Math.min(nearest[i], nearest[j])) edges.push([i, j]);
}

// A side view tilted a little so depth shows: screen x from world x and z, y from y and z.
const lo = [0, 1, 2].map((c) => Math.min(...Array.from({ length: n }, (_, i) => at(rest, i)[c])));
const hi = [0, 1, 2].map((c) => Math.max(...Array.from({ length: n }, (_, i) => at(rest, i)[c])));
const scale = (0.55 * canvas.width) / Math.max(hi[0] - lo[0], 1e-6);
const project = ([x, y, z]) => [
  canvas.width * 0.2 + (x - lo[0] + 0.35 * (z - lo[2])) * scale,
  canvas.height * 0.3 - (y - 0.5 * (lo[1] + hi[1]) - 0.2 * (z - lo[2])) * scale,
];

// The handle follows the mouse: vertical position -> translation along y, horizontal ->
// twist about x; smoothed, with speeds capped near the trained range.
const reach = 0.15 * diagonal;
const maxSpeed = 0.5 * diagonal; // units per second
const maxSpin = 1.0; // radians per second
let target = { y: 0, twist: 0 };
let pose = { y: 0, twist: 0 };
function onMouse(event) {
  const r = canvas.getBoundingClientRect();
  const u = (event.clientX - r.left) / r.width - 0.5;
  const v = (event.clientY - r.top) / r.height - 0.5;
  target = { y: -2 * v * reach, twist: 2 * u * 0.3 };
}
canvas.addEventListener("mousemove", onMouse);

let frames = 0;
let moved = 0;
let lastStatus = 0;
const clamp = (v, limit) => Math.max(-limit, Math.min(limit, v));
function frame() {
  pose.y += clamp(0.15 * (target.y - pose.y), maxSpeed * dt);
  pose.twist += clamp(0.15 * (target.twist - pose.twist), maxSpin * dt);
  lastStatus = m.mochi_step_pose(0, pose.y, 0, pose.twist, 0, 0);
  const x = new Float32Array(m.memory.buffer, m.mochi_positions(), n * dim);
  for (let i = 0; i < n; i++) moved = Math.max(moved, Math.hypot(...at(x, i).map((v, c) => v - at(rest, i)[c])) / diagonal);
  draw(x);
  frames++;
  statusLine.textContent = `frames=${frames} moved=${moved.toFixed(5)} status=${lastStatus}` + (testMode && frames >= testFrames ? " done" : "");
  if (!(testMode && frames >= testFrames)) schedule();
}

function drawEdges(points, colour) {
  ctx.strokeStyle = colour;
  ctx.beginPath();
  for (const [i, j] of edges) {
    const [a, b] = [project(at(points, i)), project(at(points, j))];
    ctx.moveTo(a[0], a[1]);
    ctx.lineTo(b[0], b[1]);
  }
  ctx.stroke();
}

function draw(x) {
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  drawEdges(rest, "#ccc");
  drawEdges(x, "#2b6cb0");
  ctx.fillStyle = "#c05621";
  for (let i = 0; i < n; i++) {
    const p = project(at(x, i));
    ctx.fillRect(p[0] - 1.5, p[1] - 1.5, 3, 3);
  }
}

// In test mode the mouse is synthetic: it circles the canvas, through the same handler.
function schedule() {
  if (testMode) {
    const r = canvas.getBoundingClientRect();
    const phase = (2 * Math.PI * frames) / 90;
    canvas.dispatchEvent(
      new MouseEvent("mousemove", {
        clientX: r.left + r.width * (0.5 + 0.4 * Math.sin(phase)),
        clientY: r.top + r.height * (0.5 + 0.4 * Math.cos(phase)),
      }),
    );
  }
  // A headless browser paints no frames, so the test paces itself with timers (which its
  // virtual clock advances); an open page follows the display's frames.
  if (testMode) setTimeout(frame, 1000 / 60);
  else requestAnimationFrame(frame);
}
schedule();
