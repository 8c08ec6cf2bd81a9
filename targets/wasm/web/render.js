// A triangle mesh drawn as a lit surface with WebGL2: vertex normals recomputed from the
// positions every frame (area-weighted face normals; a render mesh's come from the module), a key and a fill light, both sides lit
// (cloth shows its back), under an orbit camera around the rest shape.

const VERTEX_SHADER = `#version 300 es
in vec3 position;
in vec3 normal;
uniform mat4 view;
uniform mat4 projection;
out vec3 viewNormal;
out vec3 viewPosition;
void main() {
  vec4 p = view * vec4(position, 1.0);
  viewPosition = p.xyz;
  viewNormal = mat3(view) * normal;
  gl_Position = projection * p;
  gl_PointSize = 5.0;
}`;

const FRAGMENT_SHADER = `#version 300 es
precision highp float;
in vec3 viewNormal;
in vec3 viewPosition;
uniform vec3 colour;
out vec4 fragment;
void main() {
  vec3 toEye = normalize(-viewPosition);
  // Points (a model without triangles) have no normal: lit as if facing the eye.
  vec3 n = dot(viewNormal, viewNormal) > 0.0 ? normalize(viewNormal) : toEye;
  if (dot(n, toEye) < 0.0) n = -n;
  // View space: a light at the eye (what faces the camera is never dark), a key light from
  // above and to the right of it, and a sky above.
  vec3 key = normalize(vec3(0.5, 0.7, 0.5));
  float facing = max(dot(n, toEye), 0.0);
  float diffuse = max(dot(n, key), 0.0);
  float sky = 0.5 + 0.5 * n.y;
  float specular = pow(max(dot(n, normalize(key + toEye)), 0.0), 40.0);
  vec3 c = colour * (0.12 + 0.1 * sky + 0.45 * facing + 0.4 * diffuse) + vec3(0.2 * specular);
  fragment = vec4(c, 1.0);
}`;

/** Background colour (RGB bytes); pixels of any other colour are the drawn surface. */
export const BACKGROUND = [246, 245, 242];

function compile(gl, type, source) {
  const shader = gl.createShader(type);
  gl.shaderSource(shader, source);
  gl.compileShader(shader);
  if (!gl.getShaderParameter(shader, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(shader));
  return shader;
}

function perspective(fovY, aspect, near, far) {
  const f = 1 / Math.tan(fovY / 2);
  const m = new Float32Array(16);
  m[0] = f / aspect;
  m[5] = f;
  m[10] = (far + near) / (near - far);
  m[11] = -1;
  m[14] = (2 * far * near) / (near - far);
  return m;
}

const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const unit = (a) => {
  const l = Math.hypot(...a) || 1;
  return a.map((v) => v / l);
};

function lookAt(eye, target, up) {
  const z = unit(sub(eye, target));
  const x = unit(cross(up, z));
  const y = cross(z, x);
  return new Float32Array([x[0], y[0], z[0], 0, x[1], y[1], z[1], 0, x[2], y[2], z[2], 0, -dot(x, eye), -dot(y, eye), -dot(z, eye), 1]);
}

export class SurfaceView {
  constructor(canvas) {
    const gl = canvas.getContext("webgl2", { antialias: true });
    if (!gl) throw new Error("this browser has no WebGL2");
    this.gl = gl;
    this.canvas = canvas;
    const program = gl.createProgram();
    gl.attachShader(program, compile(gl, gl.VERTEX_SHADER, VERTEX_SHADER));
    gl.attachShader(program, compile(gl, gl.FRAGMENT_SHADER, FRAGMENT_SHADER));
    gl.linkProgram(program);
    if (!gl.getProgramParameter(program, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(program));
    this.program = program;
    this.uniforms = Object.fromEntries(["view", "projection", "colour"].map((n) => [n, gl.getUniformLocation(program, n)]));
    this.vao = gl.createVertexArray();
    gl.bindVertexArray(this.vao);
    this.positionBuffer = gl.createBuffer();
    this.normalBuffer = gl.createBuffer();
    this.indexBuffer = gl.createBuffer();
    for (const [name, buffer] of [["position", this.positionBuffer], ["normal", this.normalBuffer]]) {
      const at = gl.getAttribLocation(program, name);
      gl.bindBuffer(gl.ARRAY_BUFFER, buffer);
      gl.enableVertexAttribArray(at);
      gl.vertexAttribPointer(at, 3, gl.FLOAT, false, 0, 0);
    }
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, this.indexBuffer);
    // The page's collider: a unit sphere's mesh, placed and scaled each frame.
    this.ballVao = gl.createVertexArray();
    gl.bindVertexArray(this.ballVao);
    this.ballPositions = gl.createBuffer();
    this.ballNormals = gl.createBuffer();
    for (const [name, buffer] of [["position", this.ballPositions], ["normal", this.ballNormals]]) {
      const at = gl.getAttribLocation(program, name);
      gl.bindBuffer(gl.ARRAY_BUFFER, buffer);
      gl.enableVertexAttribArray(at);
      gl.vertexAttribPointer(at, 3, gl.FLOAT, false, 0, 0);
    }
    this.sphere = unitSphere(24, 16);
    this.ballIndices = gl.createBuffer();
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, this.ballIndices);
    gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, this.sphere.triangles, gl.STATIC_DRAW);
    gl.bindBuffer(gl.ARRAY_BUFFER, this.ballNormals);
    gl.bufferData(gl.ARRAY_BUFFER, this.sphere.points, gl.STATIC_DRAW);
    this.ball = null;
    gl.bindVertexArray(this.vao);
    gl.enable(gl.DEPTH_TEST);
    this.camera = { yaw: -0.55, pitch: 0.3, zoom: 1 };
    this.colour = [0.36, 0.55, 0.82];
    this.triangles = new Uint32Array(0);
  }

  /** A new mesh: `triangles` index `rest` (3 floats per vertex); the camera frames the rest shape. */
  setMesh(triangles, rest, colour) {
    const gl = this.gl;
    this.triangles = triangles;
    this.count = rest.length / 3;
    this.normals = new Float32Array(rest.length);
    this.colour = colour;
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, this.indexBuffer);
    gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, triangles, gl.STATIC_DRAW);
    const lo = [Infinity, Infinity, Infinity];
    const hi = [-Infinity, -Infinity, -Infinity];
    for (let i = 0; i < rest.length; i++) {
      lo[i % 3] = Math.min(lo[i % 3], rest[i]);
      hi[i % 3] = Math.max(hi[i % 3], rest[i]);
    }
    this.centre = [0, 1, 2].map((c) => 0.5 * (lo[c] + hi[c]));
    this.radius = Math.max(0.5 * Math.hypot(...sub(hi, lo)), 1e-6);
  }

  /** Shows the collider as a sphere at `centre` of `radius`, or hides it (`null`). */
  setBall(ball) {
    this.ball = ball;
  }

  /** Turns the camera by a drag of (dx, dy) pixels. */
  orbit(dx, dy) {
    this.camera.yaw -= 0.008 * dx;
    this.camera.pitch = Math.max(-1.5, Math.min(1.5, this.camera.pitch + 0.008 * dy));
  }

  /** Moves the camera closer (factor < 1) or away. */
  zoom(factor) {
    this.camera.zoom = Math.max(0.2, Math.min(5, this.camera.zoom * factor));
  }

  /** Area-weighted vertex normals of the mesh at `positions` (3 floats per vertex). */
  updateNormals(positions) {
    const n = this.normals;
    n.fill(0);
    const t = this.triangles;
    for (let i = 0; i < t.length; i += 3) {
      const a = 3 * t[i], b = 3 * t[i + 1], c = 3 * t[i + 2];
      const ux = positions[b] - positions[a], uy = positions[b + 1] - positions[a + 1], uz = positions[b + 2] - positions[a + 2];
      const vx = positions[c] - positions[a], vy = positions[c + 1] - positions[a + 1], vz = positions[c + 2] - positions[a + 2];
      const nx = uy * vz - uz * vy, ny = uz * vx - ux * vz, nz = ux * vy - uy * vx;
      for (const v of [a, b, c]) {
        n[v] += nx;
        n[v + 1] += ny;
        n[v + 2] += nz;
      }
    }
  }

  /** Draws the mesh at `positions` (3 floats per vertex), with `normals` where the module
   * gives them (a render mesh), else normals computed here. */
  draw(positions, normals = null) {
    const gl = this.gl;
    const { width, height } = this.canvas;
    if (normals) this.normals.set(normals);
    else this.updateNormals(positions);
    gl.viewport(0, 0, width, height);
    gl.clearColor(...BACKGROUND.map((v) => v / 255), 1);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    gl.useProgram(this.program);
    const fov = 0.6;
    const distance = (1.15 * this.radius * this.camera.zoom) / Math.sin(fov / 2);
    const { yaw, pitch } = this.camera;
    const eye = [
      this.centre[0] + distance * Math.cos(pitch) * Math.sin(yaw),
      this.centre[1] + distance * Math.sin(pitch),
      this.centre[2] + distance * Math.cos(pitch) * Math.cos(yaw),
    ];
    gl.uniformMatrix4fv(this.uniforms.view, false, lookAt(eye, this.centre, [0, 1, 0]));
    const near = Math.max(distance - 3 * this.radius, 1e-3 * distance);
    gl.uniformMatrix4fv(this.uniforms.projection, false, perspective(fov, width / height, near, distance + 3 * this.radius));
    gl.uniform3fv(this.uniforms.colour, this.colour);
    gl.bindVertexArray(this.vao);
    gl.bindBuffer(gl.ARRAY_BUFFER, this.positionBuffer);
    gl.bufferData(gl.ARRAY_BUFFER, positions, gl.DYNAMIC_DRAW);
    gl.bindBuffer(gl.ARRAY_BUFFER, this.normalBuffer);
    gl.bufferData(gl.ARRAY_BUFFER, this.normals, gl.DYNAMIC_DRAW);
    if (this.triangles.length > 0) {
      gl.drawElements(gl.TRIANGLES, this.triangles.length, gl.UNSIGNED_INT, 0);
    } else {
      gl.drawArrays(gl.POINTS, 0, this.count);
    }
    if (this.ball) {
      const { centre, radius } = this.ball;
      const unit = this.sphere.points;
      const placed = new Float32Array(unit.length);
      for (let i = 0; i < unit.length; i++) placed[i] = centre[i % 3] + radius * unit[i];
      gl.uniform3fv(this.uniforms.colour, [0.6, 0.6, 0.6]);
      gl.bindVertexArray(this.ballVao);
      gl.bindBuffer(gl.ARRAY_BUFFER, this.ballPositions);
      gl.bufferData(gl.ARRAY_BUFFER, placed, gl.DYNAMIC_DRAW);
      gl.drawElements(gl.TRIANGLES, this.sphere.triangles.length, gl.UNSIGNED_INT, 0);
      gl.bindVertexArray(this.vao);
    }
  }

  /** Pixels of the last frame that are not background (read back; call right after draw). */
  drawnPixels() {
    const gl = this.gl;
    const { width, height } = this.canvas;
    const pixels = new Uint8Array(4 * width * height);
    gl.readPixels(0, 0, width, height, gl.RGBA, gl.UNSIGNED_BYTE, pixels);
    let drawn = 0;
    for (let i = 0; i < pixels.length; i += 4) {
      if (pixels[i] !== BACKGROUND[0] || pixels[i + 1] !== BACKGROUND[1] || pixels[i + 2] !== BACKGROUND[2]) drawn++;
    }
    return drawn;
  }
}

/** A unit sphere of `slices` x `stacks` quads: its points (also its normals) and triangles. */
function unitSphere(slices, stacks) {
  const points = [];
  for (let j = 0; j <= stacks; j++) {
    const theta = (Math.PI * j) / stacks;
    for (let i = 0; i <= slices; i++) {
      const phi = (2 * Math.PI * i) / slices;
      points.push(Math.sin(theta) * Math.cos(phi), Math.cos(theta), Math.sin(theta) * Math.sin(phi));
    }
  }
  const triangles = [];
  for (let j = 0; j < stacks; j++) {
    for (let i = 0; i < slices; i++) {
      const a = j * (slices + 1) + i, b = a + slices + 1;
      triangles.push(a, b, a + 1, a + 1, b, b + 1);
    }
  }
  return { points: new Float32Array(points), triangles: new Uint32Array(triangles) };
}
