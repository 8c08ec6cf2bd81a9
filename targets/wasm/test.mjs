// Runs the reference script inside the wasm module under node and prints the protocol every
// target prints (see mochi-target-common::host), for the host to compare with its own run;
// then checks the viewer: the compiled model and the same artifact loaded from bytes (with f32
// weights, the same weights) step to the same bits, its triangles index its drawn vertices,
// and damaged bytes are refused with a reason. A model with a render mesh also runs the script
// through the render decode and its viewer's render mesh is checked.
//   node test.mjs MODULE.wasm NAME WEIGHTS [ARTIFACT.mochi]
import { readFileSync } from "node:fs";

const [path, name = "tiny", weights = "f32", artifact] = process.argv.slice(2);
if (!path) {
  console.error("usage: node test.mjs MODULE.wasm [NAME] [WEIGHTS] [ARTIFACT.mochi]");
  process.exit(2);
}
const { instance } = await WebAssembly.instantiate(readFileSync(path), {});
const m = instance.exports;
const frames = 1000;
let status = m.mochi_init();
if (status !== 0) {
  console.log(`status error mochi_init returned ${status}`);
  process.exit(1);
}
status = m.mochi_reference_run(frames);
if (status !== 0) {
  console.log(`status error mochi_reference_run returned ${status}`);
  process.exit(1);
}
const lines = [`model ${name} weights ${weights} frames ${frames}`];
const hex = (v, digits) => (v >>> 0).toString(16).padStart(digits, "0");
for (let i = 0; i < m.mochi_checkpoint_count(); i++) {
  lines.push(`checksum ${m.mochi_checkpoint_frame(i)} ${hex(m.mochi_checkpoint_hi(i), 8)}${hex(m.mochi_checkpoint_lo(i), 8)}`);
}
const n = m.mochi_vertex_count() * m.mochi_dim();
const positions = () => Array.from(new Uint32Array(m.memory.buffer, m.mochi_positions(), n), (b) => hex(b, 8)).join(" ");
lines.push("positions " + positions());
// Time per frame (step + full decode) of the reference run, best of 3.
let best = Infinity;
for (let round = 0; round < 3; round++) {
  const start = performance.now();
  m.mochi_reference_run(frames);
  best = Math.min(best, performance.now() - start);
}
lines.push(`microseconds_per_frame ${((1000 * best) / frames).toFixed(2)}`);
// A model with a render mesh: the script again through the render decode (the render pass of
// the protocol), and its time per frame (step + render decode).
const renderCount = m.mochi_render_count();
if (renderCount > 0) {
  if ((status = m.mochi_reference_render_run(frames)) !== 0) {
    console.log(`status error mochi_reference_render_run returned ${status}`);
    process.exit(1);
  }
  for (let i = 0; i < m.mochi_checkpoint_count(); i++) {
    lines.push(`render_checksum ${m.mochi_checkpoint_frame(i)} ${hex(m.mochi_render_checkpoint_hi(i), 8)}${hex(m.mochi_render_checkpoint_lo(i), 8)}`);
  }
  const floats = (at) => Array.from(new Uint32Array(m.memory.buffer, at, 3 * renderCount), (b) => hex(b, 8)).join(" ");
  lines.push("render_positions " + floats(m.mochi_render_positions()));
  lines.push("render_normals " + floats(m.mochi_render_normals()));
  let bestRender = Infinity;
  for (let round = 0; round < 3; round++) {
    const start = performance.now();
    m.mochi_reference_render_run(frames);
    bestRender = Math.min(bestRender, performance.now() - start);
  }
  lines.push(`render_microseconds_per_frame ${((1000 * bestRender) / frames).toFixed(2)}`);
}
// f32 weights agree with the host within a tolerance, not bit for bit: the positions every
// 10th frame (each run starts from rest, so frame f of a run of f frames is frame f of all).
if (weights === "f32") {
  for (let f = 10; f <= frames; f += 10) {
    if (m.mochi_reference_run(f) !== 0) {
      console.log(`status error mochi_reference_run(${f}) failed`);
      process.exit(1);
    }
    lines.push(`frame ${f} ${positions()}`);
  }
}
// The interactive path: a pose step moves the object and reports a non-negative status.
m.mochi_reset();
const moved = m.mochi_step_pose(0, 0.01, 0, 0.01, 0, 0);
if (moved < 0) {
  console.log(`status error mochi_step_pose returned ${moved}`);
  process.exit(1);
}
if (renderCount > 0) {
  // The viewer's render mesh after the step: unit normals, triangles within the vertices.
  const normals = new Float32Array(m.memory.buffer, m.mochi_render_normals(), 3 * renderCount);
  for (let v = 0; v < renderCount; v++) {
    const length = Math.hypot(normals[3 * v], normals[3 * v + 1], normals[3 * v + 2]);
    if (Math.abs(length - 1) > 1e-5) {
      console.log(`status error render normal ${v} of length ${length}`);
      process.exit(1);
    }
  }
  const triangles = new Uint32Array(m.memory.buffer, m.mochi_render_triangles(), 3 * m.mochi_render_triangle_count());
  if (triangles.length === 0 || triangles.some((i) => i >= renderCount)) {
    console.log("status error render triangles");
    process.exit(1);
  }
  lines.push(`viewer render ${renderCount} vertices, ${triangles.length / 3} triangles`);
}
if (m.mochi_step_pose(NaN, 0, 0, 0, 0, 0) >= 0) {
  console.log("status error a NaN pose was accepted");
  process.exit(1);
}
if (artifact) {
  const fail = (why) => {
    console.log(`status error ${why}`);
    process.exit(1);
  };
  // 30 frames of the viewer; the drawn vertices' bits after them.
  const roll = () => {
    for (let f = 1; f <= 30; f++) {
      if (m.mochi_step_pose(0, 0.002 * f, 0, 0.004 * f, 0, 0) < 0) fail(`the viewer's step ${f} was refused`);
    }
    return Uint32Array.from(new Uint32Array(m.memory.buffer, m.mochi_surface(), m.mochi_surface_count() * m.mochi_dim()));
  };
  m.mochi_init();
  const compiled = roll();
  const load = (bytes) => {
    const at = m.mochi_artifact_buffer(bytes.length);
    if (at === 0) fail(`no room for ${bytes.length} bytes`);
    new Uint8Array(m.memory.buffer, at, bytes.length).set(bytes);
    return m.mochi_load(bytes.length);
  };
  const bytes = readFileSync(artifact);
  if ((status = load(bytes)) !== 0) fail(`mochi_load returned ${status}`);
  const triangles = new Uint32Array(m.memory.buffer, m.mochi_triangles(), 3 * m.mochi_triangle_count());
  if (triangles.length === 0 || triangles.some((i) => i >= m.mochi_surface_count())) fail("triangles");
  const loaded = roll();
  if (weights === "f32" && !(loaded.length === compiled.length && loaded.every((b, i) => b === compiled[i]))) {
    fail("the loaded artifact and the compiled model stepped apart");
  }
  const damaged = Uint8Array.from(bytes);
  damaged[damaged.length >> 1] ^= 1;
  if (load(damaged) >= 0 || m.mochi_error_len() === 0) fail("damaged bytes were accepted");
  if (m.mochi_step_pose(0, 0, 0, 0, 0, 0) >= 0) fail("a refused load left a model to step");
  lines.push(`viewer loaded ${bytes.length} bytes, ${triangles.length / 3} triangles`);
}
lines.push("status ok");
console.log(lines.join("\n"));
