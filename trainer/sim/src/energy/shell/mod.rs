//! Cloth energies: discrete shells (Grinspun et al. 2003) with a Saint Venant-Kirchhoff
//! membrane.
//!
//! - [`ShellMembrane`]: in-plane stretching and shearing of each triangle, StVK with the
//!   plane-stress Lamé parameters, integrated over the thickness.
//! - [`ShellBending`]: one hinge per interior edge, penalising the change of the dihedral
//!   angle between the two faces.

mod bending;
mod membrane;
#[cfg(test)]
mod tests;

pub use bending::ShellBending;
pub use membrane::ShellMembrane;

use std::f64::consts::FRAC_1_SQRT_2;
use std::path::Path;

use nalgebra::{Matrix3, SMatrix, SVector, Vector3};

use super::psd::project_psd;
use super::Local;
use crate::error::InputError;
use crate::material::ElementMaterial;

/// Checks a triangle's vertex indices and rest shape, returning its rest vertices.
fn rest_triangle(
    rest: &[f64],
    num_vertices: usize,
    t: usize,
    tri: &[usize; 3],
    source: &Path,
) -> Result<[Vector3<f64>; 3], InputError> {
    for &v in tri {
        if v >= num_vertices {
            return Err(InputError::element(
                source,
                t,
                format!("triangle vertex index {v} out of range ({num_vertices} vertices)"),
            ));
        }
    }
    if tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2] {
        return Err(InputError::element(
            source,
            t,
            format!("triangle repeats a vertex: {tri:?}"),
        ));
    }
    let xs = tri.map(|v| vertex(rest, v));
    let e1 = xs[1] - xs[0];
    let e2 = xs[2] - xs[0];
    let longest = e1
        .norm_squared()
        .max(e2.norm_squared())
        .max((xs[2] - xs[1]).norm_squared());
    if e1.cross(&e2).norm() <= 1e-12 * longest {
        return Err(InputError::element(source, t, "degenerate rest triangle (zero area)"));
    }
    Ok(xs)
}

// ---------------------------------------------------------------------------------------
// Helpers shared with the rod energies.

/// Checks that `rest` holds whole 3D points with finite coordinates; returns their number.
pub(crate) fn check_positions(rest: &[f64], source: &Path) -> Result<usize, InputError> {
    if !rest.len().is_multiple_of(3) {
        return Err(InputError::field(
            source,
            "vertices",
            format!("{} coordinates is not a whole number of 3D points", rest.len()),
        ));
    }
    if let Some(k) = rest.iter().position(|c| !c.is_finite()) {
        return Err(InputError::field(
            source,
            format!("vertices[{}]", k / 3),
            format!("rest position coordinate {} is {}", k % 3, rest[k]),
        ));
    }
    Ok(rest.len() / 3)
}

/// Checks that a scalar parameter such as a thickness or radius is finite and positive.
pub(crate) fn check_positive(value: f64, field: &str, source: &Path) -> Result<(), InputError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(InputError::field(
            source,
            field,
            format!("must be positive and finite, got {value}"),
        ))
    }
}

/// Checks that there is one material, or one per `element` (`count` of them), each with a
/// positive finite Young's modulus and a Poisson ratio in (-1, 0.5).
pub(crate) fn check_materials(
    materials: &[ElementMaterial],
    count: usize,
    element: &str,
    source: &Path,
) -> Result<(), InputError> {
    if materials.len() != 1 && materials.len() != count {
        return Err(InputError::field(
            source,
            "materials",
            format!(
                "expected 1 material or one per {element} ({count}), got {}",
                materials.len()
            ),
        ));
    }
    for (k, m) in materials.iter().enumerate() {
        if !(m.youngs.is_finite() && m.youngs > 0.0) {
            return Err(InputError::field(
                source,
                format!("materials[{k}].youngs"),
                format!("Young's modulus must be positive and finite, got {}", m.youngs),
            ));
        }
        if !(m.poisson.is_finite() && m.poisson > -1.0 && m.poisson < 0.5) {
            return Err(InputError::field(
                source,
                format!("materials[{k}].poisson"),
                format!("Poisson ratio must be in (-1, 0.5), got {}", m.poisson),
            ));
        }
    }
    Ok(())
}

/// The material of element `k`: the only one, or the `k`-th.
pub(crate) fn material_of(materials: &[ElementMaterial], k: usize) -> &ElementMaterial {
    if materials.len() == 1 {
        &materials[0]
    } else {
        &materials[k]
    }
}

/// Vertex `v` of a flat 3D position vector (global, or a stencil's local positions).
pub(crate) fn vertex(x: &[f64], v: usize) -> Vector3<f64> {
    Vector3::new(x[3 * v], x[3 * v + 1], x[3 * v + 2])
}

/// Writes the 3x3 block `(a, b)` of the row-major `n x n` matrix `hess`.
pub(crate) fn write_block(hess: &mut [f64], n: usize, a: usize, b: usize, block: &Matrix3<f64>) {
    for i in 0..3 {
        for j in 0..3 {
            hess[(3 * a + i) * n + 3 * b + j] = block[(i, j)];
        }
    }
}

/// Writes into `out` the gradient and (optionally, with its projection flag) Hessian with
/// respect to a stencil's vertices of an energy given as a function of `R / 3` relative
/// vectors `r_p = sum_a coef[a][p] x_a`, from its gradient `grad` and Hessian `hess` with
/// respect to the stacked `r_p`.
pub(crate) fn scatter_relative<const P: usize, const R: usize>(
    coef: &[[f64; P]],
    grad: &SVector<f64, R>,
    hess: Option<(&SMatrix<f64, R, R>, bool)>,
    out: &mut Local,
) {
    debug_assert_eq!(R, 3 * P);
    let n = 3 * coef.len();
    for (a, row) in coef.iter().enumerate() {
        let mut g = Vector3::zeros();
        for (p, &c) in row.iter().enumerate() {
            if c != 0.0 {
                g += grad.fixed_rows::<3>(3 * p) * c;
            }
        }
        out.grad[3 * a..3 * a + 3].copy_from_slice(g.as_slice());
    }
    let Some((hess, project)) = hess else {
        return;
    };
    for (a, row_a) in coef.iter().enumerate() {
        for (b, row_b) in coef.iter().enumerate() {
            let mut block = Matrix3::zeros();
            for (p, &ca) in row_a.iter().enumerate() {
                for (q, &cb) in row_b.iter().enumerate() {
                    if ca != 0.0 && cb != 0.0 {
                        block += hess.fixed_view::<3, 3>(3 * p, 3 * q) * (ca * cb);
                    }
                }
            }
            write_block(&mut out.hess, n, a, b, &block);
        }
    }
    if project {
        project_stencil_hessian(&mut out.hess, n);
    }
}

/// Projects the row-major `n x n` Hessian `hess` of a translation-invariant stencil energy
/// (3D, `n / 3` vertices) onto the PSD cone: the same result as [`project_psd`] (symmetrise,
/// clamp eigenvalues at zero), computed without allocation and on the `n - 3` dimensional
/// complement of the rigid translations, which such a Hessian maps to zero.
pub(crate) fn project_stencil_hessian(hess: &mut [f64], n: usize) {
    // Orthonormal vectors orthogonal to (1, ..., 1) (Helmert basis): for a stencil of `v`
    // vertices, the first `v` rows of the first `v - 1` columns.
    const HELMERT: [[f64; 3]; 4] = [
        [FRAC_1_SQRT_2, 0.408_248_290_463_863, 0.288_675_134_594_812_9],
        [-FRAC_1_SQRT_2, 0.408_248_290_463_863, 0.288_675_134_594_812_9],
        [0.0, -0.816_496_580_927_726, 0.288_675_134_594_812_9],
        [0.0, 0.0, -0.866_025_403_784_438_6],
    ];
    macro_rules! clamp_on_complement {
        ($v:literal, $r:literal) => {{
            let basis = |a: usize, p: usize| HELMERT[a][p];
            let mut reduced = SMatrix::<f64, $r, $r>::zeros();
            for p in 0..$v - 1 {
                for q in 0..$v - 1 {
                    let mut block = Matrix3::zeros();
                    for a in 0..$v {
                        for b in 0..$v {
                            let w = basis(a, p) * basis(b, q);
                            if w != 0.0 {
                                block += read_block(hess, n, a, b) * w;
                            }
                        }
                    }
                    reduced.fixed_view_mut::<3, 3>(3 * p, 3 * q).copy_from(&block);
                }
            }
            let reduced = (reduced + reduced.transpose()) * 0.5;
            // Positive definite (cheap to detect) needs no projection.
            if reduced.cholesky().is_some() {
                symmetrise(hess, n);
                return;
            }
            let eig = reduced.symmetric_eigen();
            if eig.eigenvalues.iter().all(|&l| l >= 0.0) {
                symmetrise(hess, n);
                return;
            }
            let clamped = eig.eigenvalues.map(|l| l.max(0.0));
            let projected =
                eig.eigenvectors * SMatrix::<f64, $r, $r>::from_diagonal(&clamped) * eig.eigenvectors.transpose();
            for a in 0..$v {
                for b in 0..$v {
                    let mut block = Matrix3::zeros();
                    for p in 0..$v - 1 {
                        for q in 0..$v - 1 {
                            let w = basis(a, p) * basis(b, q);
                            if w != 0.0 {
                                block += projected.fixed_view::<3, 3>(3 * p, 3 * q) * w;
                            }
                        }
                    }
                    write_block(hess, n, a, b, &block);
                }
            }
        }};
    }
    match n {
        6 => clamp_on_complement!(2, 3),
        9 => clamp_on_complement!(3, 6),
        12 => clamp_on_complement!(4, 9),
        _ => project_psd(&mut hess[..n * n], n),
    }
}

/// Replaces the row-major `n x n` matrix `m` by its symmetric part.
fn symmetrise(m: &mut [f64], n: usize) {
    for i in 0..n {
        for j in 0..i {
            let mean = 0.5 * (m[i * n + j] + m[j * n + i]);
            m[i * n + j] = mean;
            m[j * n + i] = mean;
        }
    }
}

/// Reads the 3x3 block `(a, b)` of the row-major `n x n` matrix `m`.
fn read_block(m: &[f64], n: usize, a: usize, b: usize) -> Matrix3<f64> {
    Matrix3::from_fn(|i, j| m[(3 * a + i) * n + 3 * b + j])
}
