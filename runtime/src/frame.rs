//! Boundary conditions: handle motions, the handle vertices they place, and the frame
//! (rotation, origins, and the starts of bend-encoded strands) in which the model's states are
//! encoded.

use nalgebra::{Matrix2, Matrix3, Rotation3, Vector3};

use crate::model::{Chain, Handle, Model, MAX_HANDLES, SIGNAL_PER_HANDLE};

/// A handle's rigid pose relative to its reference placement: translation of the pivot and a
/// rotation vector (axis times angle in radians) about it.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct HandlePose {
    /// Translation of the pivot.
    pub translation: [f32; 3],
    /// Rotation vector about the pivot.
    pub rotation: [f32; 3],
}

/// What the model needs of one handle each frame: its velocities over the step that ends at
/// this frame and its pose (the order of the trainer's boundary-condition signal).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct HandleMotion {
    /// Linear velocity of the pivot (units / s).
    pub linear_velocity: [f32; 3],
    /// Angular velocity (rad / s, world axes).
    pub angular_velocity: [f32; 3],
    /// Translation of the pivot.
    pub translation: [f32; 3],
    /// Rotation vector about the pivot.
    pub rotation: [f32; 3],
}

impl HandleMotion {
    /// A handle at its reference placement, at rest.
    pub const REST: HandleMotion = HandleMotion {
        linear_velocity: [0.0; 3],
        angular_velocity: [0.0; 3],
        translation: [0.0; 3],
        rotation: [0.0; 3],
    };

    /// The motion that moves a handle from `previous` to `current` in `dt` seconds (for
    /// engines that only track poses).
    pub fn from_poses(previous: &HandlePose, current: &HandlePose, dt: f32) -> HandleMotion {
        let v = |a: [f32; 3]| Vector3::from(a);
        let linear = (v(current.translation) - v(previous.translation)) / dt;
        let step = rotation(&current.rotation) * rotation(&previous.rotation).inverse();
        let angular = Vector3::from(rotation_vector(step.matrix())) / dt;
        HandleMotion {
            linear_velocity: linear.into(),
            angular_velocity: angular.into(),
            translation: current.translation,
            rotation: current.rotation,
        }
    }

    /// The motion whose signal is `s` (the order of [`HandleMotion::signal`]).
    pub fn from_signal(s: &[f32; SIGNAL_PER_HANDLE]) -> HandleMotion {
        let part = |i: usize| [s[3 * i], s[3 * i + 1], s[3 * i + 2]];
        HandleMotion {
            linear_velocity: part(0),
            angular_velocity: part(1),
            translation: part(2),
            rotation: part(3),
        }
    }

    /// Whether every number is finite.
    pub fn is_finite(&self) -> bool {
        self.signal().iter().all(|v| v.is_finite())
    }

    /// The [`SIGNAL_PER_HANDLE`] numbers the integrator reads.
    pub fn signal(&self) -> [f32; SIGNAL_PER_HANDLE] {
        let mut s = [0.0; SIGNAL_PER_HANDLE];
        for (i, part) in [
            self.linear_velocity,
            self.angular_velocity,
            self.translation,
            self.rotation,
        ]
        .iter()
        .enumerate()
        {
            s[3 * i..3 * i + 3].copy_from_slice(part);
        }
        s
    }
}

/// The rotation of a rotation vector (Rodrigues' formula), with `libm`'s sine and cosine
/// rather than the platform's, so that every target computes the same bits.
pub(crate) fn rotation(rotation_vector: &[f32; 3]) -> Rotation3<f32> {
    let [x, y, z] = *rotation_vector;
    let angle = libm::sqrtf(x * x + y * y + z * z);
    if angle <= f32::EPSILON {
        return Rotation3::identity();
    }
    let (sin, cos) = (libm::sinf(angle), libm::cosf(angle));
    let (x, y, z) = (x / angle, y / angle, z / angle);
    let c = 1.0 - cos;
    Rotation3::from_matrix_unchecked(Matrix3::new(
        cos + x * x * c,
        x * y * c - z * sin,
        x * z * c + y * sin,
        y * x * c + z * sin,
        cos + y * y * c,
        y * z * c - x * sin,
        z * x * c - y * sin,
        z * y * c + x * sin,
        cos + z * z * c,
    ))
}

/// The rotation vector (axis times angle, the angle in `[0, pi]`) of the rotation matrix `m`,
/// the inverse of [`rotation`]; in `libm` arithmetic like it, so every target computes the
/// same bits (nalgebra's `scaled_axis` takes the platform's trigonometry where `std` is on).
pub(crate) fn rotation_vector(m: &Matrix3<f32>) -> [f32; 3] {
    // 2 sin(angle) times the axis, and cos(angle).
    let v = [m[(2, 1)] - m[(1, 2)], m[(0, 2)] - m[(2, 0)], m[(1, 0)] - m[(0, 1)]];
    let twice_sin = libm::sqrtf(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    let cos = (0.5 * (m[(0, 0)] + m[(1, 1)] + m[(2, 2)] - 1.0)).clamp(-1.0, 1.0);
    let angle = libm::atan2f(0.5 * twice_sin, cos);
    if angle <= f32::EPSILON {
        // Small angles: the skew part is the rotation vector to first order.
        return v.map(|c| 0.5 * c);
    }
    if cos > -0.5 {
        let scale = angle / twice_sin;
        return v.map(|c| c * scale);
    }
    // Near a half turn the skew part vanishes: the axis from the symmetric part,
    // m + m^T = 2 cos I + 2 (1 - cos) a a^T, its largest component first.
    let d = 1.0 - cos;
    let i = (0..3).fold(0, |best, k| if m[(k, k)] > m[(best, best)] { k } else { best });
    let mut axis = [0.0f32; 3];
    axis[i] = libm::sqrtf(((m[(i, i)] - cos) / d).max(0.0));
    for k in (0..3).filter(|&k| k != i) {
        axis[k] = (m[(i, k)] + m[(k, i)]) / (2.0 * d * axis[i]);
    }
    // The sign that agrees with the skew part.
    let dot = axis[0] * v[0] + axis[1] * v[1] + axis[2] * v[2];
    let sign = if dot < 0.0 { -1.0 } else { 1.0 };
    axis.map(|c| sign * angle * c)
}

/// The world placement of a model's handles and its encoding frame for one frame of handle
/// poses (read from the signal: translation at 6..9, rotation vector at 9..12 per handle).
pub struct Placement<'m, 'a> {
    model: &'m Model<'a>,
    rotations: [Matrix3<f32>; MAX_HANDLES],
    translations: [Vector3<f32>; MAX_HANDLES],
    /// Frame rotation `R` (upper-left 2x2 in 2D).
    pub frame: Matrix3<f32>,
    centroid: Vector3<f32>,
}

impl<'m, 'a> Placement<'m, 'a> {
    /// Places the handles of `model` at the poses in `signal` (`bc_len` numbers).
    pub fn new(model: &'m Model<'a>, signal: &[f32]) -> Self {
        let mut rotations = [Matrix3::identity(); MAX_HANDLES];
        let mut translations = [Vector3::zeros(); MAX_HANDLES];
        for (h, s) in signal.chunks_exact(SIGNAL_PER_HANDLE).take(MAX_HANDLES).enumerate() {
            translations[h] = Vector3::new(s[6], s[7], s[8]);
            rotations[h] = *rotation(&[s[9], s[10], s[11]]).matrix();
        }
        let mut placement = Placement {
            model,
            rotations,
            translations,
            frame: Matrix3::identity(),
            centroid: Vector3::zeros(),
        };
        let slots = model.handle_vertices().len();
        if slots > 0 {
            let mut sum = Vector3::zeros();
            placement.each_target(|_, p| sum += p);
            placement.centroid = sum / slots as f32;
        }
        if model.rotates {
            placement.frame = match model.handles.len() {
                1 => rotations[0],
                _ => placement.best_fit_rotation(),
            };
            if model.dim() == 2 {
                placement.frame = planar(&placement.frame);
            }
        }
        placement
    }

    /// Handle and index within it of handle slot `slot`.
    fn locate(&self, slot: usize) -> Option<(usize, &Handle, usize)> {
        let mut first = 0;
        for (h, handle) in self.model.handles.iter().enumerate() {
            let len = handle.vertices.len as usize;
            if slot < first + len {
                return Some((h, handle, slot - first));
            }
            first += len;
        }
        None
    }

    /// Reference (identity-pose) position of handle slot `slot`.
    fn reference(&self, slot: usize) -> Vector3<f32> {
        self.locate(slot)
            .map_or(Vector3::zeros(), |(_, handle, i)| self.reference_in(handle, i))
    }

    /// Reference position of vertex `i` of `handle`.
    fn reference_in(&self, handle: &Handle, i: usize) -> Vector3<f32> {
        self.model
            .handle_reference_of(handle)
            .get(3 * i..3 * i + 3)
            .map_or(Vector3::zeros(), |p| Vector3::new(p[0], p[1], p[2]))
    }

    /// World position of handle slot `slot` (z = 0 in 2D).
    pub fn target(&self, slot: usize) -> Vector3<f32> {
        self.locate(slot)
            .map_or(Vector3::zeros(), |(h, handle, i)| self.target_in(h, handle, i))
    }

    /// [`Placement::target`] of every handle slot in order, as `visit(slot, position)`: one
    /// handle after another, without searching for each slot's handle.
    pub fn each_target(&self, mut visit: impl FnMut(usize, Vector3<f32>)) {
        let mut slot = 0;
        for (h, handle) in self.model.handles.iter().enumerate() {
            for i in 0..handle.vertices.len as usize {
                visit(slot, self.target_in(h, handle, i));
                slot += 1;
            }
        }
    }

    /// World position of vertex `i` of `handle`, handle number `h` (z = 0 in 2D).
    fn target_in(&self, h: usize, handle: &Handle, i: usize) -> Vector3<f32> {
        let (Some(translation), Some(rotation)) = (self.translations.get(h), self.rotations.get(h)) else {
            return Vector3::zeros();
        };
        let pivot = Vector3::from(handle.pivot);
        let p = pivot + translation + rotation * (self.reference_in(handle, i) - pivot);
        if self.model.dim() == 2 {
            Vector3::new(p.x, p.y, 0.0)
        } else {
            p
        }
    }

    /// The centroid of the handle targets: the encoding origin of a body without strand roots.
    pub fn centroid(&self) -> Vector3<f32> {
        self.centroid
    }

    /// Origin `o` of an encoded vertex whose origin index is `origin`.
    pub fn origin(&self, origin: u32) -> Vector3<f32> {
        match self.model.root_slots().get(origin as usize) {
            Some(&slot) => self.target(slot as usize),
            None => self.centroid,
        }
    }

    /// Where the bend-encoded strand `chain` starts in this placement: its second prescribed
    /// vertex and the axes of its first bend (see [`Chain`]).
    pub fn chain_start(&self, chain: &Chain) -> ChainWalk {
        let point = |slot: u32| -> [f32; 3] { self.target(slot as usize).into() };
        let anchor = point(chain.parent[1]);
        let d = normalized(sub(anchor, point(chain.parent[0])));
        let r = &self.frame;
        let n = chain.rest_normal;
        let turned: [f32; 3] = core::array::from_fn(|i| r[(i, 0)] * n[0] + r[(i, 1)] * n[1] + r[(i, 2)] * n[2]);
        let along = dot(&d, &turned);
        let projected: [f32; 3] = core::array::from_fn(|i| turned[i] - d[i] * along);
        let norm = libm::sqrtf(dot(&projected, &projected));
        let u = if norm > 1e-6 {
            projected.map(|v| v / norm)
        } else {
            normal_to(&d)
        };
        ChainWalk {
            position: anchor,
            axes: [d, u, cross(&d, &u)].map(|axis| axis.map(flush_tiny)),
        }
    }

    /// The proper rotation that best maps the reference handle points onto their targets
    /// (Kabsch; the handles of one model may rotate differently).
    fn best_fit_rotation(&self) -> Matrix3<f32> {
        let slots = self.model.handle_vertices().len();
        let mean_ref = (0..slots).fold(Vector3::zeros(), |acc, s| acc + self.reference(s)) / slots.max(1) as f32;
        let mut cov = Matrix3::zeros();
        for s in 0..slots {
            cov += (self.reference(s) - mean_ref) * (self.target(s) - self.centroid).transpose();
        }
        if self.model.dim() == 2 {
            let angle = libm::atan2f(cov[(0, 1)] - cov[(1, 0)], cov[(0, 0)] + cov[(1, 1)]);
            let r = Matrix2::new(
                libm::cosf(angle),
                -libm::sinf(angle),
                libm::sinf(angle),
                libm::cosf(angle),
            );
            return Matrix3::new(r[(0, 0)], r[(0, 1)], 0.0, r[(1, 0)], r[(1, 1)], 0.0, 0.0, 0.0, 1.0);
        }
        let svd = cov.svd(true, true);
        let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
            return Matrix3::identity();
        };
        let mut r = v_t.transpose() * u.transpose();
        if r.determinant() < 0.0 {
            let mut flip = Matrix3::identity();
            flip[(2, 2)] = -1.0;
            r = v_t.transpose() * flip * u.transpose();
        }
        r
    }
}

/// The in-plane part of a rotation, for 2D models.
fn planar(r: &Matrix3<f32>) -> Matrix3<f32> {
    Matrix3::new(r[(0, 0)], r[(0, 1)], 0.0, r[(1, 0)], r[(1, 1)], 0.0, 0.0, 0.0, 1.0)
}

/// A walk along a bend-encoded strand (see [`Chain`]): the last vertex placed and the axes
/// `[d, u, w]` of the next bend.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ChainWalk {
    /// Position of the last vertex placed (at the start, the strand's second prescribed
    /// vertex).
    pub position: [f32; 3],
    /// Direction of the last edge, then the two normals (`d x u = w`).
    pub axes: [[f32; 3]; 3],
}

impl ChainWalk {
    /// Places the next vertex from its two encoded numbers `q` and the rest length of the edge
    /// that ends at it: turns the axes by the Cayley map of `g = (u q[0] + w q[1]) / length`
    /// (`y + 2 / (1 + |g|^2) (g x y + g x (g x y))`) and steps `length` along the new `d`.
    /// `q`, `g`, `g x y` and the turned axes are [`flush_tiny`]'d. Returns the vertex's
    /// position.
    pub fn step(&mut self, q: [f32; 2], length: f32) -> [f32; 3] {
        let q = q.map(flush_tiny);
        let [_, u, w] = self.axes;
        let g: [f32; 3] = core::array::from_fn(|i| flush_tiny((u[i] * q[0] + w[i] * q[1]) / length));
        let c = 2.0 / (1.0 + dot(&g, &g));
        for y in &mut self.axes {
            let h = cross(&g, y).map(flush_tiny);
            let k = cross(&g, &h);
            *y = core::array::from_fn(|i| flush_tiny(y[i] + (h[i] + k[i]) * c));
        }
        let d = self.axes[0];
        self.position = core::array::from_fn(|i| self.position[i] + d[i] * length);
        self.position
    }
}

/// Magnitudes below this (`2^-50`) are zero in a strand walk.
pub(crate) const TINY: f32 = 1.0 / (1u64 << 50) as f32;

/// `v`, or zero where `|v| < 2^-50` (NaN stays NaN): the strand walk flushes its inputs and
/// the factors of its products, so that every operand is zero or at least `2^-50` and no
/// product or difference of two falls below `f32`'s normal range. A strand that moves in a
/// plane has out-of-plane bends and axis components that decay towards zero frame after
/// frame; x86 computes with such subnormal numbers in microcode, tens of times slower (a
/// swinging `rods` model spent two thirds of its frame there). The rule is arithmetic, not
/// an FPU mode, so every target flushes the same values and keeps the same bits; at `2^-50`
/// of a unit axis or a bend it is far below `f32`'s resolution of the positions.
#[inline(always)]
pub(crate) fn flush_tiny(v: f32) -> f32 {
    if libm::fabsf(v) < TINY {
        0.0
    } else {
        v
    }
}

// Plain `f32` vector arithmetic in a fixed order (no fused multiply-add), the same on every
// target.

fn dot(a: &[f32; 3], b: &[f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: &[f32; 3], b: &[f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn normalized(v: [f32; 3]) -> [f32; 3] {
    let norm = libm::sqrtf(dot(&v, &v));
    v.map(|c| c / norm)
}

/// A unit vector perpendicular to the unit vector `d`: the coordinate axis least aligned with
/// `d` (the first on ties), with its `d` component removed.
fn normal_to(d: &[f32; 3]) -> [f32; 3] {
    let mut axis = 0;
    for i in 1..3 {
        if libm::fabsf(d[i]) < libm::fabsf(d[axis]) {
            axis = i;
        }
    }
    let mut e = [0.0; 3];
    e[axis] = 1.0;
    normalized(core::array::from_fn(|i| e[i] - d[i] * d[axis]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::Span;

    #[test]
    fn a_handle_past_the_room_is_placed_at_zero_not_panicked_on() {
        let one = Handle {
            vertices: Span { start: 0, len: 1 },
            reference: Span { start: 0, len: 3 },
            pivot: [1.0, 2.0, 3.0],
        };
        let handles = [one; MAX_HANDLES + 1];
        let floats = [5.0, 6.0, 7.0];
        let model = Model {
            dim: 3,
            floats: &floats,
            handles: &handles,
            ..Model::EMPTY
        };
        let place = Placement::new(&model, &[]);
        assert_eq!(place.target(MAX_HANDLES - 1), Vector3::new(5.0, 6.0, 7.0));
        assert_eq!(place.target(MAX_HANDLES), Vector3::zeros());
    }

    /// `rotation_vector` inverts `rotation` for angles from zero to a half turn, about axes
    /// in every direction (the near-half-turn branch included).
    #[test]
    fn rotation_vector_is_the_inverse_of_rotation() {
        let mut checked = 0;
        for i in 0..40 {
            let t = i as f32 * 0.61;
            let axis = Vector3::new(libm::sinf(t), libm::cosf(1.7 * t), libm::sinf(2.3 * t + 0.4)).normalize();
            for angle in [0.0, 1e-4, 0.3, 1.5, 2.5, 3.0, 3.1, 3.135] {
                let r = (axis * angle).into();
                let back = rotation_vector(rotation(&r).matrix());
                let gap = (Vector3::from(back) - Vector3::from(r)).norm();
                assert!(
                    gap <= 1e-3 * angle.max(1e-2),
                    "axis {axis:?} angle {angle}: {back:?} vs {r:?}"
                );
                checked += 1;
            }
        }
        assert_eq!(checked, 320);
    }
}
