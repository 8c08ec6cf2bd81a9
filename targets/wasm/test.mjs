// Runs the reference script inside the wasm module under node and prints the protocol every
// target prints (see mochi-target-common::host), for the host to compare with its own run.
//   node test.mjs MODULE.wasm NAME WEIGHTS
import { readFileSync } from "node:fs";

const [path, name = "tiny", weights = "f32"] = process.argv.slice(2);
if (!path) {
  console.error("usage: node test.mjs MODULE.wasm [NAME] [WEIGHTS]");
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
if (m.mochi_step_pose(NaN, 0, 0, 0, 0, 0) >= 0) {
  console.log("status error a NaN pose was accepted");
  process.exit(1);
}
lines.push("status ok");
console.log(lines.join("\n"));
