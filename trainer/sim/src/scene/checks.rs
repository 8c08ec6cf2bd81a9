//! Range checks of a scene's numbers, run when it is loaded ([`Scene::validate`]): every
//! physical number must be finite and inside the interval of its kind, or loading fails
//! with an error naming the scene file and the field's path (`material.youngs`,
//! `mesh.parts[1].radius`, `handles[0].select.side.tolerance`).
//!
//! The intervals are wide: many decades beyond any real body in SI units, so that no
//! sensible scene (in metres, kilograms and seconds, or in units of similar scale) meets
//! them, but narrow enough that the energies, their gradients and Hessians stay far inside
//! `f64` (largest 1.8e308, smallest normal 2.2e-308). A body's lengths lie in
//! [`MIN_SIZE`]..[`MAX_LENGTH`] (so its volumes lie in about 1e-27..1e27 m^3) and its moduli,
//! densities and stiffnesses in [`MIN_MATERIAL`]..[`MAX_MATERIAL`]: an energy `E V strain^2`,
//! a Hessian entry `E L` or a mass `rho V` then stays between about 1e-60 and 1e65, even for
//! strains of 1e3. Without these bounds a modulus of 1.5e308 passes as finite and makes
//! every Hessian entry infinite.

use super::{BoxSpec, ColliderSpec, HandleSpec, MeshSpec, ObstacleMesh, Scene, Selection, MAX_COLLIDERS};
use crate::energy::external::Obstacle;
use crate::material::ElementMaterial;

/// Smallest Young's modulus (Pa), density (kg/m^3) and collision stiffness: 1e-30, thirty
/// decades below 1 so that no real material (the softest gels have about 10 Pa, aerogels
/// about 1 kg/m^3) is refused, while masses and stiffnesses of the smallest bodies stay
/// normal `f64` numbers.
pub const MIN_MATERIAL: f64 = 1e-30;
/// Largest Young's modulus (Pa), density (kg/m^3) and collision stiffness: 1e30, eighteen
/// decades above diamond (1.2e12 Pa) and osmium (2.3e4 kg/m^3); times the largest volume and
/// squared strain (1e6) a scene holds the elastic energy stays below about 1e65, far from
/// overflow.
pub const MAX_MATERIAL: f64 = 1e30;
/// Smallest size of a body or obstacle feature (ball radius, box extent, cloth side, rod
/// length and radius, cloth thickness, barrier distance; m): 1e-9, a nanometre. Below it
/// the elements' volumes (a size cubed, over the cells) fall toward `f64`'s underflow and
/// the mesh degenerates.
pub const MIN_SIZE: f64 = 1e-9;
/// Largest size and largest coordinate magnitude (m): 1e9, a million kilometres; squared
/// distances and volumes stay far inside `f64`.
pub const MAX_LENGTH: f64 = 1e9;
/// Largest magnitude of a force (N), acceleration (m/s^2), velocity (m/s), angular velocity
/// (rad/s) or direction component: 1e30, so that their norms and products with masses and
/// time steps cannot overflow.
pub const MAX_MAGNITUDE: f64 = 1e30;
/// Largest angle (rad) of an obstacle's rotation vector: one full turn, 2 pi. Every rotation
/// has a rotation vector of angle at most pi; a larger one is most likely degrees written as
/// radians, and a huge one (1e300) overflows its norm.
pub const MAX_ROTATION: f64 = std::f64::consts::TAU;

/// An allowed interval of one kind of scene number and the unit its messages show.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Range {
    low: f64,
    /// Whether `low` itself is excluded.
    low_open: bool,
    high: f64,
    /// Whether `high` itself is excluded.
    high_open: bool,
    unit: &'static str,
}

impl Range {
    const fn closed(low: f64, high: f64, unit: &'static str) -> Range {
        Range {
            low,
            low_open: false,
            high,
            high_open: false,
            unit,
        }
    }

    const fn above(low: f64, high: f64, unit: &'static str) -> Range {
        Range {
            low_open: true,
            ..Range::closed(low, high, unit)
        }
    }

    fn contains(&self, v: f64) -> bool {
        let above = if self.low_open { v > self.low } else { v >= self.low };
        let below = if self.high_open { v < self.high } else { v <= self.high };
        v.is_finite() && above && below
    }
}

/// Young's modulus (Pa).
const MODULUS: Range = Range::closed(MIN_MATERIAL, MAX_MATERIAL, " Pa");
/// Mass density (kg/m^3).
const DENSITY: Range = Range::closed(MIN_MATERIAL, MAX_MATERIAL, " kg/m^3");
/// Poisson ratio: (-1, 0.5), the range of a stable isotropic material.
const POISSON: Range = Range {
    high_open: true,
    ..Range::above(-1.0, 0.5, "")
};
/// Collision stiffness (acceleration per squared penetration).
const STIFFNESS: Range = Range::closed(MIN_MATERIAL, MAX_MATERIAL, "");
/// Sizes (m).
const SIZE: Range = Range::closed(MIN_SIZE, MAX_LENGTH, " m");
/// Distances that may be zero (collision margin, spacing of a single rod; m).
const DISTANCE: Range = Range::closed(0.0, MAX_LENGTH, " m");
/// Coordinates of points (m).
const COORDINATE: Range = Range::closed(-MAX_LENGTH, MAX_LENGTH, " m");
/// Positive scale factors of a mesh file.
const FACTOR: Range = Range::closed(MIN_SIZE, MAX_LENGTH, "");
/// Per-axis factors that may be zero or negative (a handle's reference scale).
const SIGNED_FACTOR: Range = Range::closed(-MAX_LENGTH, MAX_LENGTH, "");
/// Components of forces, accelerations, velocities and directions.
const COMPONENT: Range = Range::closed(-MAX_MAGNITUDE, MAX_MAGNITUDE, "");
/// Non-negative rates and coefficients (speeds, friction).
const RATE: Range = Range::closed(0.0, MAX_MAGNITUDE, "");
/// Positive rates and tolerances (friction smoothing velocity, Newton's tolerance).
const POSITIVE: Range = Range::above(0.0, MAX_MAGNITUDE, "");
/// Time step (s).
const TIME_STEP: Range = Range::above(0.0, MAX_LENGTH, " s");
/// Keyframe times (s).
const TIME: Range = Range::closed(-MAX_LENGTH, MAX_LENGTH, " s");
/// A side selection's tolerance, relative to the mesh's extent (1 already takes every vertex).
const SIDE_TOLERANCE: Range = Range::closed(0.0, 1.0, "");

/// A field path and what is wrong with it.
pub(crate) type Bad = (String, String);

/// A number as messages show it: exponent notation for very large and small magnitudes.
fn show(v: f64) -> String {
    if v != 0.0 && v.is_finite() && !(1e-3..1e4).contains(&v.abs()) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

/// `value` in `range`, or the field `field` and a message naming the range.
pub(crate) fn check(field: impl Into<String>, value: f64, range: Range) -> Result<(), Bad> {
    if range.contains(value) {
        return Ok(());
    }
    let open = if range.low_open { "(" } else { "[" };
    let close = if range.high_open { ")" } else { "]" };
    let (low, high) = (show(range.low), show(range.high));
    let got = show(value);
    Err((
        field.into(),
        format!(
            "must be a finite number in {open}{low}, {high}{close}{}, got {got}",
            range.unit
        ),
    ))
}

/// Every entry of `values` in `range`; the error names the entry (`gravity[1]`).
pub(crate) fn check_each(field: &str, values: &[f64], range: Range) -> Result<(), Bad> {
    for (i, v) in values.iter().enumerate() {
        check(format!("{field}[{i}]"), *v, range)?;
    }
    Ok(())
}

/// A material's modulus, Poisson ratio and density; the error names the field under
/// `field` (`material`, `material.regions[2]`).
pub(crate) fn check_material(field: &str, m: &ElementMaterial) -> Result<(), Bad> {
    check(format!("{field}.youngs"), m.youngs, MODULUS)?;
    check(format!("{field}.poisson"), m.poisson, POISSON)?;
    check(format!("{field}.density"), m.density, DENSITY)
}

/// The numbers of the mesh `spec` (at `field`: `mesh`, `mesh.parts[1]`).
fn check_mesh(field: &str, spec: &MeshSpec) -> Result<(), Bad> {
    match spec {
        MeshSpec::Box { min, max, .. } => check_box(field, &BoxSpec { min: *min, max: *max }, true),
        MeshSpec::Ball { center, radius, .. } => {
            check_each(&format!("{field}.center"), center, COORDINATE)?;
            check(format!("{field}.radius"), *radius, SIZE)
        }
        MeshSpec::ClothGrid { size, origin, axes, .. } => {
            check_each(&format!("{field}.size"), size, SIZE)?;
            check_each(&format!("{field}.origin"), origin, COORDINATE)?;
            for (i, a) in axes.iter().enumerate() {
                check_each(&format!("{field}.axes[{i}]"), a, COMPONENT)?;
            }
            Ok(())
        }
        MeshSpec::Rods {
            count,
            length,
            spacing,
            direction,
            origin,
            ..
        } => {
            check(format!("{field}.length"), *length, SIZE)?;
            let spacing_range = if *count > 1 { SIZE } else { DISTANCE };
            check(format!("{field}.spacing"), *spacing, spacing_range)?;
            check_each(&format!("{field}.direction"), direction, COMPONENT)?;
            check_each(&format!("{field}.origin"), origin, COORDINATE)
        }
        MeshSpec::File { scale, .. } => match scale {
            Some(s) => check_each(&format!("{field}.scale"), s, FACTOR),
            None => Ok(()),
        },
        MeshSpec::Parts { parts } => {
            for (k, p) in parts.iter().enumerate() {
                check_mesh(&format!("{field}.parts[{k}]"), p)?;
            }
            Ok(())
        }
    }
}

/// A box's corners; a `body` box also needs every extent to be a size.
fn check_box(field: &str, b: &BoxSpec, body: bool) -> Result<(), Bad> {
    check_each(&format!("{field}.min"), &b.min, COORDINATE)?;
    check_each(&format!("{field}.max"), &b.max, COORDINATE)?;
    if body {
        for i in 0..3 {
            let (_, message) = match check(String::new(), b.max[i] - b.min[i], SIZE) {
                Ok(()) => continue,
                Err(bad) => bad,
            };
            return Err((format!("{field}.max[{i}]"), format!("minus `min[{i}]`: {message}")));
        }
    }
    Ok(())
}

/// A selection's numbers (at `field`: `handles[0].select`).
fn check_selection(field: &str, s: &Selection) -> Result<(), Bad> {
    match s {
        Selection::Box(b) => check_box(&format!("{field}.box"), b, false),
        Selection::Nearest(points) => {
            for (k, p) in points.iter().enumerate() {
                check_each(&format!("{field}.nearest[{k}]"), p, COORDINATE)?;
            }
            Ok(())
        }
        Selection::Side { tolerance, .. } => check(format!("{field}.side.tolerance"), *tolerance, SIDE_TOLERANCE),
        Selection::Indices(_) | Selection::RodRoots(_) => Ok(()),
    }
}

/// A handle's numbers (at `handles[k]`).
fn check_handle(field: &str, h: &HandleSpec) -> Result<(), Bad> {
    check_selection(&format!("{field}.select"), &h.select)?;
    if let Some(s) = &h.reference_scale {
        check_each(&format!("{field}.reference_scale"), s, SIGNED_FACTOR)?;
    }
    if let Some(p) = &h.pivot {
        check_each(&format!("{field}.pivot"), p, COORDINATE)?;
    }
    if let Some(m) = &h.motion {
        let f = |name: &str| format!("{field}.motion.{name}");
        check_each(&f("speed"), &m.speed, RATE)?;
        check_each(&f("angular_speed"), &m.angular_speed, RATE)?;
        for (k, d) in m.directions.iter().enumerate() {
            check_each(&format!("{}[{k}]", f("directions")), d, COMPONENT)?;
        }
        for (k, a) in m.rotation_axes.iter().enumerate() {
            check_each(&format!("{}[{k}]", f("rotation_axes")), a, COMPONENT)?;
        }
    }
    for (j, s) in h.script.iter().enumerate() {
        check_each(&format!("{field}.script[{j}].velocity"), &s.velocity, COMPONENT)?;
        check_each(
            &format!("{field}.script[{j}].angular_velocity"),
            &s.angular_velocity,
            COMPONENT,
        )?;
    }
    Ok(())
}

/// An analytic obstacle's numbers (at `obstacles[k]`).
fn check_obstacle(field: &str, o: &Obstacle) -> Result<(), Bad> {
    let f = |name: &str| format!("{field}.{name}");
    match o {
        Obstacle::Plane { point, normal } => {
            check_each(&f("point"), point, COORDINATE)?;
            check_each(&f("normal"), normal, COMPONENT)
        }
        Obstacle::Sphere { center, radius } => {
            check_each(&f("center"), center, COORDINATE)?;
            check(f("radius"), *radius, SIZE)
        }
        Obstacle::Capsule { a, b, radius } => {
            check_each(&f("a"), a, COORDINATE)?;
            check_each(&f("b"), b, COORDINATE)?;
            check(f("radius"), *radius, SIZE)
        }
    }
}

/// The angle (norm, rad) of a rotation vector, if it is finite and at most [`MAX_ROTATION`];
/// otherwise the field `field` and why.
fn check_rotation(field: String, r: &[f64; 3]) -> Result<(), Bad> {
    // The norm scaled by the largest component, which cannot overflow.
    let largest = r.iter().fold(0.0f64, |m, c| m.max(c.abs()));
    let angle = if largest > 0.0 {
        largest * r.iter().map(|c| (c / largest).powi(2)).sum::<f64>().sqrt()
    } else {
        0.0
    };
    if !angle.is_finite() || angle > MAX_ROTATION {
        return Err((
            field,
            format!(
                "the rotation vector's angle (its norm, in radians) must be finite and at most \
                 2 pi = {MAX_ROTATION:.4} rad, got {}",
                show(angle)
            ),
        ));
    }
    Ok(())
}

/// A collider's numbers (at `colliders[k]`): its sizes, rotation, motion and placement.
fn check_collider(field: &str, c: &ColliderSpec) -> Result<(), Bad> {
    let f = |name: &str| format!("{field}.{name}");
    c.shape().map_err(|(name, msg)| (f(name), msg))?;
    if let Some(r) = c.radius {
        check(f("radius"), r, SIZE)?;
    }
    if let Some(l) = c.length {
        check(f("length"), l, DISTANCE)?;
    }
    if let Some(h) = &c.half_extents {
        check_each(&f("half_extents"), h, SIZE)?;
    }
    if let Some(r) = &c.rotation {
        check_rotation(f("rotation"), r)?;
    }
    if let Some(m) = &c.motion {
        let g = |name: &str| format!("{field}.motion.{name}");
        m.validate().map_err(|(name, msg)| (g(name), msg))?;
        check_each(&g("speed"), &m.speed, RATE)?;
        if let Some(r) = &m.region {
            check_box(&g("region"), r, false)?;
        }
        for (k, d) in m.directions.iter().enumerate() {
            check_each(&format!("{}[{k}]", g("directions")), d, COMPONENT)?;
        }
        check(g("clearance"), m.clearance, DISTANCE)?;
    }
    if let Some(p) = &c.placement {
        if c.motion.is_some() {
            return Err((
                f("placement"),
                "a collider either moves (`motion`) or rests where each sequence puts it \
                 (`placement`), not both"
                    .into(),
            ));
        }
        let g = |name: &str| format!("{field}.placement.{name}");
        p.validate().map_err(|(name, msg)| (g(name), msg))?;
        check_box(&g("center"), &p.center, false)?;
    }
    Ok(())
}

/// An obstacle mesh's numbers (at `contact.obstacles[k]`): corners, scale, offset, keyframes
/// and the rotation vector, whose angle (its norm) is at most [`MAX_ROTATION`].
fn check_obstacle_mesh(field: &str, o: &ObstacleMesh) -> Result<(), Bad> {
    let f = |name: &str| format!("{field}.{name}");
    for (k, frame) in o.keyframes().iter().enumerate() {
        check(format!("{}[{k}][0]", f("keyframes")), frame[0], TIME)?;
        for (i, c) in frame.iter().enumerate().skip(1) {
            check(format!("{}[{k}][{i}]", f("keyframes")), *c, COORDINATE)?;
        }
    }
    match o {
        ObstacleMesh::Box { min, max, rotation, .. } => {
            check_box(field, &BoxSpec { min: *min, max: *max }, true)?;
            if let Some(r) = rotation {
                check_rotation(f("rotation"), r)?;
            }
            Ok(())
        }
        ObstacleMesh::File { scale, offset, .. } => {
            check(f("scale"), *scale, FACTOR)?;
            check_each(&f("offset"), offset, COORDINATE)
        }
    }
}

impl Scene {
    /// Checks values that TOML types cannot: ranges, finiteness, required fields. Every
    /// physical number is checked against the interval of its kind (see the bounds in this
    /// module: [`MAX_MATERIAL`], [`MIN_SIZE`], [`MAX_LENGTH`], [`MAX_MAGNITUDE`],
    /// [`MAX_ROTATION`]); errors name the scene file and the field's path.
    pub fn validate(&self) -> Result<(), crate::error::InputError> {
        self.check_fields().map_err(|(f, msg)| self.field_error(f, msg))
    }

    fn check_fields(&self) -> Result<(), Bad> {
        let bad = |f: &str, msg: &str| Err((f.to_string(), msg.to_string()));
        check("dt", self.dt, TIME_STEP)?;
        check_each("gravity", &self.gravity, COMPONENT)?;
        check("newton.tolerance", self.newton.tolerance, POSITIVE)?;
        if self.newton.max_iterations == 0 {
            return bad("newton.max_iterations", "must be at least 1");
        }
        if let Some(invalid) = self.solver.invalid() {
            return Err(invalid);
        }
        check_mesh("mesh", &self.mesh)?;
        let m = &self.material;
        let base = ElementMaterial {
            youngs: m.youngs,
            poisson: m.poisson,
            density: m.density,
        };
        check_material("material", &base)?;
        super::regions::check_selectors(m)?;
        for (k, r) in m.regions.iter().enumerate() {
            let field = format!("material.regions[{k}]");
            if let Some(b) = &r.bounds {
                check_box(&format!("{field}.box"), b, false)?;
            }
            let e = ElementMaterial {
                youngs: r.youngs.unwrap_or(m.youngs),
                poisson: r.poisson.unwrap_or(m.poisson),
                density: r.density.unwrap_or(m.density),
            };
            check_material(&field, &e)?;
        }
        if let Some(t) = m.thickness {
            check("material.thickness", t, SIZE)?;
        }
        if let Some(r) = m.radius {
            check("material.radius", r, SIZE)?;
        }
        if self.mesh.any(&|s| matches!(s, MeshSpec::ClothGrid { .. })) && m.thickness.is_none() {
            return bad("material.thickness", "cloth needs a positive thickness");
        }
        if self.mesh.any(&|s| matches!(s, MeshSpec::Rods { .. })) && m.radius.is_none() {
            return bad("material.radius", "rods need a positive radius");
        }
        check("collision.stiffness", self.collision.stiffness, STIFFNESS)?;
        check("collision.margin", self.collision.margin, DISTANCE)?;
        if let Some(c) = &self.contact {
            c.validate()?;
            check("contact.dhat", c.dhat, SIZE)?;
            check("contact.friction", c.friction, RATE)?;
            check("contact.epsv", c.epsv, POSITIVE)?;
            for (k, o) in c.obstacles.iter().enumerate() {
                check_obstacle_mesh(&format!("contact.obstacles[{k}]"), o)?;
            }
        }
        if self.colliders.len() > MAX_COLLIDERS {
            return Err((
                "colliders".into(),
                format!("at most {MAX_COLLIDERS} colliders, got {}", self.colliders.len()),
            ));
        }
        if !self.colliders.is_empty() && self.contact.is_none() {
            return bad(
                "colliders",
                "colliders act through IPC contact: add a `[contact]` table (its `dhat` serves them)",
            );
        }
        for (k, c) in self.colliders.iter().enumerate() {
            check_collider(&format!("colliders[{k}]"), c)?;
        }
        if let Some(v) = &self.initial_velocity {
            check_each("initial_velocity", v, COMPONENT)?;
        }
        for (k, o) in self.obstacles.iter().enumerate() {
            let field = format!("obstacles[{k}]");
            check_obstacle(&field, o)?;
            o.validate().map_err(|msg| (field, msg))?;
        }
        for (k, h) in self.handles.iter().enumerate() {
            let field = format!("handles[{k}]");
            check_handle(&field, h)?;
            if let Some(motion) = &h.motion {
                motion
                    .validate()
                    .map_err(|(f, msg)| (format!("{field}.motion.{f}"), msg))?;
            }
        }
        for (k, l) in self.loads.iter().enumerate() {
            check_selection(&format!("loads[{k}].select"), &l.select)?;
            check_each(&format!("loads[{k}].force"), &l.force, COMPONENT)?;
        }
        let d = &self.dataset;
        if d.train == 0 || d.frames == 0 || !(d.beyond.is_finite() && d.beyond >= 1.0) {
            return bad("dataset", "needs train >= 1, frames >= 1 and beyond >= 1");
        }
        if d.test_frames == Some(0) {
            return bad("dataset.test_frames", "must be at least 1");
        }
        if let Some([lo, hi]) = d.frame_rates {
            // Up to 10,000 frames per second: beyond, a step is shorter than any host's frame.
            let rate = |v: f64| v.is_finite() && v > 0.0 && v <= 1e4;
            if !(rate(lo) && rate(hi) && lo <= hi) {
                return bad(
                    "dataset.frame_rates",
                    "must be [lowest, highest] frames per second, 0 < lowest <= highest <= 10000",
                );
            }
        }
        Ok(())
    }
}
