/* An engine's view of mochi: links libmochi_c.a, creates several instances of one model in
 * its own memory, steps them with the reference boundary-condition script and prints a
 * checksum of the decoded positions and the positions every 10th frame, which must stay
 * within 1e-5 of the rest diagonal of the host runtime's (see tests/c_program.rs); then steps the
 * same model with a render mesh and takes its render positions and normals in one call, checking
 * the normals and the refusals, and a model with a collider slot through the script with its
 * ball (`collider_checksum` lines). Output protocol: the same lines as the Cortex-M4 and wasm
 * targets. */
#include <stdio.h>
#include <string.h>

#include "mochi.h"

#define INSTANCES 3
#define FRAMES 1000
#define MAX_HANDLES 16

/* FNV-1a (64-bit) over the little-endian bytes of each float's bit pattern, as
 * mochi-target-common's Checksum. */
static uint64_t fnv(uint64_t hash, const float *values, size_t n) {
  for (size_t i = 0; i < n; i++) {
    uint32_t bits;
    memcpy(&bits, &values[i], sizeof bits);
    for (int byte = 0; byte < 4; byte++) {
      hash ^= (bits >> (8 * byte)) & 0xffu;
      hash *= 0x00000100000001b3ull;
    }
  }
  return hash;
}

static int fail(const char *what, MochiStatus status) {
  printf("status error %s returned %d\n", what, (int)status);
  return 1;
}

int main(void) {
  const MochiModel *model = mochi_model_tiny();
  MochiModelInfo info;
  MochiStatus s = mochi_model_info(model, &info);
  if (s != MochiStatus_Ok) return fail("mochi_model_info", s);
  if (info.handles > MAX_HANDLES) return fail("handle count", MochiStatus_HandleCount);

  /* Instances live in the engine's memory: here, a static array. */
  static MochiInstance bodies[INSTANCES];
  for (int i = 0; i < INSTANCES; i++) {
    s = mochi_instance_init(model, &bodies[i]);
    if (s != MochiStatus_Ok) return fail("mochi_instance_init", s);
  }
  static float positions[INSTANCES][1 << 16];
  if (info.state_len > (1 << 16)) return fail("state length", MochiStatus_BufferLength);

  /* Bad input is refused, not crashed on. */
  if (mochi_instance_step(model, &bodies[0], NULL, 1) != MochiStatus_NullPointer ||
      mochi_instance_decode(model, &bodies[0], positions[0], info.state_len - 1) != MochiStatus_BufferLength ||
      mochi_instance_step(NULL, &bodies[0], NULL, 0) != MochiStatus_NullPointer)
    return fail("bad-input checks", MochiStatus_Ok);

  /* A model of one frame time (its info's dt_max is 0) refuses another, and any model a frame
     time that is not a positive number; nothing changes. */
  MochiHandleMotion still[MAX_HANDLES];
  memset(still, 0, sizeof still);
  if (info.dt_max != 0.0f ||
      mochi_instance_step_dt(model, &bodies[0], still, info.handles, 1.0f / 90.0f) != MochiStatus_FrameTime ||
      mochi_instance_step_dt(model, &bodies[0], still, info.handles, -info.dt) != MochiStatus_FrameTime)
    return fail("frame-time checks", MochiStatus_Ok);

  printf("model tiny weights f32 frames %d\n", FRAMES);
  uint64_t hash = 0xcbf29ce484222325ull;
  MochiHandleMotion motion, rest, bc[MAX_HANDLES];
  memset(&rest, 0, sizeof rest);
  for (uint32_t frame = 1; frame <= FRAMES; frame++) {
    s = mochi_reference_motion(frame, &motion);
    if (s != MochiStatus_Ok) return fail("mochi_reference_motion", s);
    for (int i = 0; i < INSTANCES; i++) {
      /* Instances 0 and 1 follow the script; instance 2 is held at rest. */
      for (uint32_t h = 0; h < info.handles; h++) bc[h] = i < 2 ? motion : rest;
      s = mochi_instance_step(model, &bodies[i], bc, info.handles);
      if (s < 0) return fail("mochi_instance_step", s);
      s = mochi_instance_decode(model, &bodies[i], positions[i], info.state_len);
      if (s != MochiStatus_Ok) return fail("mochi_instance_decode", s);
    }
    if (memcmp(positions[0], positions[1], info.state_len * sizeof(float)) != 0)
      return fail("two instances with the same script diverged", MochiStatus_Ok);
    hash = fnv(hash, positions[0], info.state_len);
    if (frame == 1 || frame == 10 || frame == 100 || frame == FRAMES)
      printf("checksum %u %016llx\n", frame, (unsigned long long)hash);
    /* f32 weights agree with the host within a tolerance: the positions every 10th frame. */
    if (frame % 10 == 0) {
      printf("frame %u", frame);
      for (uint32_t i = 0; i < info.state_len; i++) {
        uint32_t bits;
        memcpy(&bits, &positions[0][i], sizeof bits);
        printf(" %08x", bits);
      }
      printf("\n");
    }
  }
  if (memcmp(positions[0], positions[2], info.state_len * sizeof(float)) == 0)
    return fail("the instance at rest moved with the others", MochiStatus_Ok);

  /* A collider pushes decoded vertices out (a ball around the first vertex of the instance at
     rest, in a copy); a collider that is not a shape is refused and changes nothing. */
  static float pushed[1 << 16];
  memcpy(pushed, positions[2], info.state_len * sizeof(float));
  MochiCollider ball;
  memset(&ball, 0, sizeof ball);
  ball.shape = 0;
  ball.size[0] = 0.05f * info.diagonal;
  for (uint32_t c = 0; c < info.dim; c++) ball.center[c] = pushed[c];
  uint32_t moved = 0;
  s = mochi_push_out(model, pushed, info.state_len, &ball, 1, 0.0f, &moved);
  if (s != MochiStatus_Ok || moved < 1) return fail("mochi_push_out", s);
  float gap = 0.0f;
  for (uint32_t c = 0; c < info.dim; c++) gap += (pushed[c] - ball.center[c]) * (pushed[c] - ball.center[c]);
  if (gap < 0.99f * ball.size[0] * ball.size[0]) return fail("a pushed vertex is still inside", MochiStatus_Ok);
  ball.size[0] = -1.0f;
  if (mochi_push_out(model, pushed, info.state_len, &ball, 1, 0.0f, &moved) != MochiStatus_Collider)
    return fail("a bad collider was not refused", MochiStatus_Ok);

  /* The render mesh: positions and normals in one call, through a scratch full decode. */
  const MochiModel *dressed = mochi_model_tiny_render();
  MochiModelInfo rinfo;
  s = mochi_model_info(dressed, &rinfo);
  if (s != MochiStatus_Ok || rinfo.render_len == 0 || rinfo.render_triangles == 0 || rinfo.render_uvs == 0)
    return fail("render model info", s);
  const uint32_t *triangles = NULL;
  const float *uvs = NULL;
  s = mochi_model_render_mesh(dressed, &triangles, &uvs);
  if (s != MochiStatus_Ok || triangles == NULL || uvs == NULL) return fail("mochi_model_render_mesh", s);
  static MochiInstance dressed_body;
  static float scratch[1 << 16], rpos[1 << 16], rnormals[1 << 16];
  if (rinfo.render_len > (1 << 16) || rinfo.state_len > (1 << 16)) return fail("render length", MochiStatus_BufferLength);
  s = mochi_instance_init(dressed, &dressed_body);
  if (s != MochiStatus_Ok) return fail("mochi_instance_init (render)", s);
  for (uint32_t frame = 1; frame <= 30; frame++) {
    s = mochi_reference_motion(frame, &motion);
    if (s != MochiStatus_Ok) return fail("mochi_reference_motion", s);
    for (uint32_t h = 0; h < rinfo.handles; h++) bc[h] = motion;
    s = mochi_instance_step(dressed, &dressed_body, bc, rinfo.handles);
    if (s < 0) return fail("mochi_instance_step (render)", s);
    s = mochi_instance_decode_render(dressed, &dressed_body, scratch, rinfo.state_len, rpos, rnormals,
                                     rinfo.render_len);
    if (s != MochiStatus_Ok) return fail("mochi_instance_decode_render", s);
  }
  /* Every triangle's vertices exist and every normal of a vertex in a triangle is a unit vector. */
  for (uint32_t t = 0; t < 3 * rinfo.render_triangles; t++) {
    uint32_t v = triangles[t];
    if (3 * v >= rinfo.render_len) return fail("a render triangle's vertex", MochiStatus_Ok);
    float n2 = rnormals[3 * v] * rnormals[3 * v] + rnormals[3 * v + 1] * rnormals[3 * v + 1] +
               rnormals[3 * v + 2] * rnormals[3 * v + 2];
    if (n2 < 0.9999f || n2 > 1.0001f) return fail("a render normal is not of unit length", MochiStatus_Ok);
  }
  /* Refusals: a short buffer, overlapping buffers, a null pointer; a model without a render mesh
     decodes an empty one. */
  if (mochi_instance_decode_render(dressed, &dressed_body, scratch, rinfo.state_len, rpos, rnormals,
                                   rinfo.render_len - 1) != MochiStatus_BufferLength ||
      mochi_instance_decode_render(dressed, &dressed_body, scratch, rinfo.state_len, rpos, rpos + 3,
                                   rinfo.render_len) != MochiStatus_BufferLength ||
      mochi_instance_decode_render(dressed, &dressed_body, scratch, rinfo.state_len, NULL, rnormals,
                                   rinfo.render_len) != MochiStatus_NullPointer ||
      mochi_instance_decode_render(model, &bodies[0], scratch, info.state_len, rpos, rnormals, 0) != MochiStatus_Ok ||
      info.render_len != 0)
    return fail("render refusals", MochiStatus_Ok);

  /* A model with a run-time collider slot: the reference script with its ball, the state
     given every step; the checksums of its decoded positions must be the host's. */
  const MochiModel *poke = mochi_model_tiny_poke();
  MochiModelInfo pinfo;
  s = mochi_model_info(poke, &pinfo);
  if (s != MochiStatus_Ok || pinfo.colliders != 1 || pinfo.state_len > (1 << 16)) return fail("poke model info", s);
  static MochiInstance poked;
  s = mochi_instance_init(poke, &poked);
  if (s != MochiStatus_Ok) return fail("mochi_instance_init (poke)", s);
  MochiColliderState ball_state;
  uint64_t poke_hash = 0xcbf29ce484222325ull;
  for (uint32_t frame = 1; frame <= FRAMES; frame++) {
    s = mochi_reference_poke(frame, &motion, &ball_state);
    if (s != MochiStatus_Ok) return fail("mochi_reference_poke", s);
    for (uint32_t h = 0; h < pinfo.handles; h++) bc[h] = motion;
    s = mochi_instance_step_colliders(poke, &poked, bc, pinfo.handles, &ball_state, 1, pinfo.dt);
    if (s < 0) return fail("mochi_instance_step_colliders", s);
    s = mochi_instance_decode(poke, &poked, scratch, pinfo.state_len);
    if (s != MochiStatus_Ok) return fail("mochi_instance_decode (poke)", s);
    poke_hash = fnv(poke_hash, scratch, pinfo.state_len);
    if (frame == 1 || frame == 10 || frame == 100 || frame == FRAMES)
      printf("collider_checksum %u %016llx\n", frame, (unsigned long long)poke_hash);
  }
  /* More states than slots are refused. */
  MochiColliderState two[2] = {ball_state, ball_state};
  if (mochi_instance_step_colliders(poke, &poked, bc, pinfo.handles, two, 2, pinfo.dt) != MochiStatus_Collider)
    return fail("two states for one slot were not refused", MochiStatus_Ok);

  printf("positions");
  for (uint32_t i = 0; i < info.state_len; i++) {
    uint32_t bits;
    memcpy(&bits, &positions[0][i], sizeof bits);
    printf(" %08x", bits);
  }
  printf("\nstatus ok\n");
  return 0;
}
