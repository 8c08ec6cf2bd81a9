//! Procedural meshes: a tetrahedralised box or ball, a triangulated cloth sheet, a group of
//! straight rods.
//!
//! Bad parameters are reported as [`InputError`]s at a named field of a pseudo-file such as
//! `<procedural box>`, and every result is checked with [`Mesh::validate`].

use std::path::Path;

use nalgebra::Vector3;

use super::{Elements, Mesh};
use crate::error::InputError;

mod ball;
pub use ball::ball_tets;

/// Source name of [`box_tets`] errors.
const BOX: &str = "<procedural box>";
/// Source name of [`cloth_grid`] errors.
const CLOTH: &str = "<procedural cloth>";
/// Source name of [`rod_group`] errors.
const RODS: &str = "<procedural rods>";
/// The most vertices a procedural mesh may have (a typo in a count should be an error, not an
/// attempt to allocate all memory).
pub(crate) const MAX_VERTICES: usize = 1 << 26;

/// A conforming tet mesh of the box `lo..hi` with `cells` cubes (cuboids) per axis, each split
/// into 6 tets around its main diagonal (Kuhn / Freudenthal), so neighbouring cells' faces
/// match. All tets are positively oriented. Vertex `(i, j, k)` (grid coordinates) has index
/// `i + (cells[0] + 1) * (j + (cells[1] + 1) * k)`.
pub fn box_tets(lo: [f64; 3], hi: [f64; 3], cells: [usize; 3]) -> Result<Mesh, InputError> {
    for axis in 0..3 {
        if !(lo[axis].is_finite() && hi[axis].is_finite()) {
            return Err(InputError::field(
                BOX,
                "lo/hi",
                format!("corners must be finite, got {lo:?} and {hi:?}"),
            ));
        }
        if hi[axis] <= lo[axis] {
            return Err(InputError::field(
                BOX,
                "hi",
                format!("hi {hi:?} must exceed lo {lo:?} on every axis"),
            ));
        }
        if cells[axis] == 0 {
            return Err(InputError::field(
                BOX,
                "cells",
                format!("at least 1 cell per axis is needed, got {cells:?}"),
            ));
        }
    }
    let [nx, ny, nz] = cells;
    let vertex_count = [nx, ny, nz]
        .iter()
        .try_fold(1usize, |n, &c| n.checked_mul(c.checked_add(1)?))
        .filter(|&n| n <= MAX_VERTICES)
        .ok_or_else(|| {
            InputError::field(
                BOX,
                "cells",
                format!("{cells:?} gives more than {MAX_VERTICES} vertices"),
            )
        })?;
    let index = |i: usize, j: usize, k: usize| i + (nx + 1) * (j + (ny + 1) * k);

    let mut rest = Vec::with_capacity(3 * vertex_count);
    for k in 0..=nz {
        for j in 0..=ny {
            for i in 0..=nx {
                for (axis, step) in [i, j, k].into_iter().enumerate() {
                    let t = step as f64 / cells[axis] as f64;
                    rest.push(lo[axis] + t * (hi[axis] - lo[axis]));
                }
            }
        }
    }

    // Each permutation of the axes is a path from the cell's corner (0,0,0) to (1,1,1); its
    // tet's signed volume has the permutation's sign, so odd ones swap their last two vertices.
    const PATHS: [([usize; 3], bool); 6] = [
        ([0, 1, 2], false),
        ([1, 2, 0], false),
        ([2, 0, 1], false),
        ([0, 2, 1], true),
        ([1, 0, 2], true),
        ([2, 1, 0], true),
    ];
    let mut tets = Vec::with_capacity(6 * nx * ny * nz);
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                for (axes, odd) in PATHS {
                    let mut corner = [i, j, k];
                    let mut tet = [index(i, j, k); 4];
                    for (step, axis) in axes.into_iter().enumerate() {
                        corner[axis] += 1;
                        tet[step + 1] = index(corner[0], corner[1], corner[2]);
                    }
                    if odd {
                        tet.swap(2, 3);
                    }
                    tets.push(tet);
                }
            }
        }
    }
    let mesh = Mesh {
        dim: 3,
        rest,
        elements: Elements::Tets(tets),
        attributes: None,
    };
    mesh.validate(Path::new(BOX))?;
    Ok(mesh)
}

/// A `size[0]` by `size[1]` cloth sheet with `verts[0]` by `verts[1]` vertices, spanned from
/// `origin` along the directions `axes.0` and `axes.1` (normalised here; they need not be
/// orthogonal, only not parallel). Vertex `(i, j)` is at `origin + size[0] * i / (verts[0] - 1)
/// * u + size[1] * j / (verts[1] - 1) * v` with index `i + verts[0] * j`. Each grid cell is
/// split into two triangles along alternating diagonals (a checkerboard, so the sheet has no
/// preferred shear direction), wound counter-clockwise about `u x v`.
pub fn cloth_grid(
    size: [f64; 2],
    verts: [usize; 2],
    origin: [f64; 3],
    axes: ([f64; 3], [f64; 3]),
) -> Result<Mesh, InputError> {
    if !size.iter().all(|s| s.is_finite() && *s > 0.0) {
        return Err(InputError::field(
            CLOTH,
            "size",
            format!("sizes must be finite and positive, got {size:?}"),
        ));
    }
    if verts.iter().any(|&n| n < 2) {
        return Err(InputError::field(
            CLOTH,
            "verts",
            format!("at least 2 vertices per side are needed, got {verts:?}"),
        ));
    }
    let origin = finite_point(CLOTH, "origin", origin)?;
    let (u, v) = plane_axes(CLOTH, "axes", axes)?;
    let [nu, nv] = verts;
    let vertex_count = nu.checked_mul(nv).filter(|&n| n <= MAX_VERTICES).ok_or_else(|| {
        InputError::field(
            CLOTH,
            "verts",
            format!("{verts:?} is more than {MAX_VERTICES} vertices"),
        )
    })?;

    let mut rest = Vec::with_capacity(3 * vertex_count);
    for j in 0..nv {
        for i in 0..nu {
            let s = size[0] * i as f64 / (nu - 1) as f64;
            let t = size[1] * j as f64 / (nv - 1) as f64;
            rest.extend((origin + s * u + t * v).iter());
        }
    }
    let mut triangles = Vec::with_capacity(2 * (nu - 1) * (nv - 1));
    for j in 0..nv - 1 {
        for i in 0..nu - 1 {
            // Cell corners, counter-clockwise from (i, j).
            let a = i + nu * j;
            let b = a + 1;
            let c = b + nu;
            let d = a + nu;
            if (i + j) % 2 == 0 {
                triangles.extend([[a, b, c], [a, c, d]]);
            } else {
                triangles.extend([[a, b, d], [b, c, d]]);
            }
        }
    }
    let mesh = Mesh {
        dim: 3,
        rest,
        elements: Elements::Shell(triangles),
        attributes: None,
    };
    mesh.validate(Path::new(CLOTH))?;
    Ok(mesh)
}

/// Where the roots of a [`rod_group`] sit: a regular grid in the plane spanned by `axes`
/// (directions, normalised here, not parallel), filled row by row, `columns` roots per row,
/// `spacing` apart. Rod `r`'s root is at
/// `origin + spacing * ((r % columns) * axes.0 + (r / columns) * axes.1)`.
#[derive(Clone, Debug, PartialEq)]
pub struct RootGrid {
    /// Root of rod 0.
    pub origin: [f64; 3],
    /// Direction along a row, then from one row to the next.
    pub axes: ([f64; 3], [f64; 3]),
    /// Roots per row (at least 1).
    pub columns: usize,
    /// Distance between neighbouring roots (positive when there is more than one rod).
    pub spacing: f64,
}

/// `count` straight rods of `verts_per_rod` vertices and length `length`, each running from its
/// root (placed by `roots`) along `direction` (normalised here). Rod `r` is listed root first
/// and its vertex `k` has index `r * verts_per_rod + k`. Rods are not checked for crossing
/// each other (as they would when `direction` lies in the roots' plane).
pub fn rod_group(
    count: usize,
    verts_per_rod: usize,
    length: f64,
    roots: &RootGrid,
    direction: [f64; 3],
) -> Result<Mesh, InputError> {
    if count == 0 {
        return Err(InputError::field(RODS, "count", "at least 1 rod is needed"));
    }
    if verts_per_rod < 2 {
        return Err(InputError::field(
            RODS,
            "verts_per_rod",
            format!("a rod needs at least 2 vertices, got {verts_per_rod}"),
        ));
    }
    if !(length.is_finite() && length > 0.0) {
        return Err(InputError::field(
            RODS,
            "length",
            format!("must be finite and positive, got {length}"),
        ));
    }
    let direction = unit_vector(RODS, "direction", direction)?;
    let origin = finite_point(RODS, "roots.origin", roots.origin)?;
    let (u, v) = plane_axes(RODS, "roots.axes", roots.axes)?;
    if roots.columns == 0 {
        return Err(InputError::field(
            RODS,
            "roots.columns",
            "at least 1 root per row is needed",
        ));
    }
    if !roots.spacing.is_finite() || (count > 1 && roots.spacing <= 0.0) {
        return Err(InputError::field(
            RODS,
            "roots.spacing",
            format!("must be finite and positive, got {}", roots.spacing),
        ));
    }
    let vertex_count = count
        .checked_mul(verts_per_rod)
        .filter(|&n| n <= MAX_VERTICES)
        .ok_or_else(|| {
            InputError::field(
                RODS,
                "count",
                format!("{count} rods of {verts_per_rod} vertices is more than {MAX_VERTICES}"),
            )
        })?;

    let mut rest = Vec::with_capacity(3 * vertex_count);
    let mut rods = Vec::with_capacity(count);
    for r in 0..count {
        let column = (r % roots.columns) as f64;
        let row = (r / roots.columns) as f64;
        let root = origin + roots.spacing * (column * u + row * v);
        for k in 0..verts_per_rod {
            let along = length * k as f64 / (verts_per_rod - 1) as f64;
            rest.extend((root + along * direction).iter());
        }
        rods.push((r * verts_per_rod..(r + 1) * verts_per_rod).collect());
    }
    let mesh = Mesh {
        dim: 3,
        rest,
        elements: Elements::Rods(rods),
        attributes: None,
    };
    mesh.validate(Path::new(RODS))?;
    Ok(mesh)
}

/// `p` as a vector if all its coordinates are finite.
fn finite_point(source: &str, field: &str, p: [f64; 3]) -> Result<Vector3<f64>, InputError> {
    if p.iter().all(|c| c.is_finite()) {
        Ok(Vector3::from(p))
    } else {
        Err(InputError::field(
            source,
            field,
            format!("coordinates must be finite, got {p:?}"),
        ))
    }
}

/// `d` normalised, if it is finite and not zero.
fn unit_vector(source: &str, field: &str, d: [f64; 3]) -> Result<Vector3<f64>, InputError> {
    let d = finite_point(source, field, d)?;
    let norm = d.norm();
    if norm > 0.0 && norm.is_finite() {
        Ok(d / norm)
    } else {
        Err(InputError::field(
            source,
            field,
            format!("a direction must not be zero, got {:?}", d.as_slice()),
        ))
    }
}

/// Two unit directions spanning a plane: finite, non-zero and not parallel.
fn plane_axes(
    source: &str,
    field: &str,
    axes: ([f64; 3], [f64; 3]),
) -> Result<(Vector3<f64>, Vector3<f64>), InputError> {
    let u = unit_vector(source, field, axes.0)?;
    let v = unit_vector(source, field, axes.1)?;
    if u.cross(&v).norm() < 1e-9 {
        return Err(InputError::field(
            source,
            field,
            format!("the two axes must not be parallel, got {:?}", axes),
        ));
    }
    Ok((u, v))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::Location;
    use crate::mesh::tet_signed_volume;
    use std::collections::HashMap;

    fn field_error(result: Result<Mesh, InputError>, source: &str, field: &str) -> String {
        let err = result.expect_err("expected an error");
        assert_eq!(err.file, Path::new(source));
        assert_eq!(err.location, Location::Field(field.to_string()), "{err}");
        err.to_string()
    }

    #[test]
    fn box_tets_fill_the_box_conformingly() {
        let (lo, hi, cells) = ([-1.0, 0.0, 2.0], [1.0, 0.5, 3.5], [3, 2, 4]);
        let mesh = box_tets(lo, hi, cells).unwrap();
        assert_eq!(mesh.num_vertices(), 4 * 3 * 5);
        assert_eq!(mesh.num_elements(), 6 * 3 * 2 * 4);
        let Elements::Tets(tets) = &mesh.elements else {
            panic!("not tets")
        };
        let volumes: Vec<f64> = tets
            .iter()
            .map(|t| tet_signed_volume(&t.map(|v| mesh.point(v))))
            .collect();
        assert!(volumes.iter().all(|&v| v > 0.0));
        approx::assert_relative_eq!(volumes.iter().sum::<f64>(), 2.0 * 0.5 * 1.5, max_relative = 1e-12);
        // Every face is in one tet (boundary) or two (interior).
        let mut faces: HashMap<[usize; 3], usize> = HashMap::new();
        for t in tets {
            for skip in 0..4 {
                let mut face: Vec<usize> = (0..4).filter(|&k| k != skip).map(|k| t[k]).collect();
                face.sort_unstable();
                *faces.entry([face[0], face[1], face[2]]).or_default() += 1;
            }
        }
        assert!(faces.values().all(|&n| n == 1 || n == 2));
        // Boundary: two triangles per boundary square, as boundary_faces also finds.
        let boundary = faces.values().filter(|&&n| n == 1).count();
        assert_eq!(boundary, 4 * (3 * 2 + 2 * 4 + 4 * 3));
        assert_eq!(mesh.surface_triangles().len(), boundary);
    }

    #[test]
    fn box_surface_vertices_are_its_boundary_vertices() {
        let cells = [3, 4, 2];
        let mesh = box_tets([0.0; 3], [3.0, 4.0, 2.0], cells).unwrap();
        // Unit cells: vertex (i, j, k) is at (i, j, k); boundary iff some coordinate is extreme.
        let expected: Vec<usize> = (0..mesh.num_vertices())
            .filter(|&v| {
                let p = mesh.point(v);
                (0..3).any(|a| p[a] == 0.0 || p[a] == cells[a] as f64)
            })
            .collect();
        assert_eq!(expected.len(), 4 * 5 * 3 - 2 * 3);
        assert_eq!(mesh.surface_vertices(), expected);
    }

    #[test]
    fn box_parameter_errors() {
        let shown = field_error(box_tets([0.0; 3], [1.0; 3], [2, 0, 2]), BOX, "cells");
        assert!(
            shown.contains("<procedural box>: field `cells`: at least 1 cell per axis"),
            "{shown}"
        );
        field_error(box_tets([0.0, f64::NAN, 0.0], [1.0; 3], [1; 3]), BOX, "lo/hi");
        field_error(box_tets([0.0; 3], [1.0, 0.0, 1.0], [1; 3]), BOX, "hi");
        field_error(box_tets([0.0; 3], [1.0; 3], [usize::MAX, 2, 2]), BOX, "cells");
        // A box too thin for its cells has degenerate tets.
        let err = box_tets([0.0; 3], [1.0, 1.0, 1e-14], [1; 3]).unwrap_err();
        assert!(err.to_string().contains("tetrahedron is degenerate"), "{err}");
    }

    #[test]
    fn cloth_grid_layout_and_alternating_diagonals() {
        let mesh = cloth_grid([2.0, 1.0], [5, 3], [1.0, 2.0, 3.0], ([0.0, 0.0, 2.0], [1.0, 0.0, 0.0])).unwrap();
        assert_eq!(mesh.num_vertices(), 15);
        assert_eq!(mesh.num_elements(), 2 * 4 * 2);
        // Vertex (i, j) = origin + 0.5 i z + 0.5 j x; vertex 7 is (2, 1).
        assert_eq!(&mesh.rest[3 * 7..3 * 8], &[1.5, 2.0, 4.0]);
        let Elements::Shell(triangles) = &mesh.elements else {
            panic!("not a shell")
        };
        // Every triangle faces u x v = z x x = +y, and the areas add up to the sheet.
        let mut area = 0.0;
        for t in triangles {
            let [a, b, c] = t.map(|v| mesh.point(v));
            let normal = (b - a).cross(&(c - a));
            assert!(normal.y > 0.0 && normal.x == 0.0 && normal.z == 0.0);
            area += 0.5 * normal.norm();
        }
        approx::assert_relative_eq!(area, 2.0, max_relative = 1e-12);
        // Diagonals alternate: neighbouring cells use (a, c) then (b, d).
        assert_eq!(triangles[0], [0, 1, 6]);
        assert_eq!(triangles[2], [1, 2, 6]);
    }

    #[test]
    fn cloth_parameter_errors() {
        let axes = ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0]);
        field_error(cloth_grid([1.0, f64::NAN], [3, 3], [0.0; 3], axes), CLOTH, "size");
        field_error(cloth_grid([1.0, 0.0], [3, 3], [0.0; 3], axes), CLOTH, "size");
        let shown = field_error(cloth_grid([1.0, 1.0], [1, 3], [0.0; 3], axes), CLOTH, "verts");
        assert!(shown.contains("<procedural cloth>: field `verts`"), "{shown}");
        field_error(
            cloth_grid([1.0, 1.0], [3, 3], [f64::INFINITY, 0.0, 0.0], axes),
            CLOTH,
            "origin",
        );
        field_error(
            cloth_grid([1.0, 1.0], [3, 3], [0.0; 3], ([1.0, 0.0, 0.0], [-2.0, 0.0, 0.0])),
            CLOTH,
            "axes",
        );
        field_error(
            cloth_grid([1.0, 1.0], [3, 3], [0.0; 3], ([0.0; 3], [0.0, 1.0, 0.0])),
            CLOTH,
            "axes",
        );
    }

    fn grid() -> RootGrid {
        RootGrid {
            origin: [0.0, 1.0, 0.0],
            axes: ([1.0, 0.0, 0.0], [0.0, 0.0, 1.0]),
            columns: 2,
            spacing: 0.25,
        }
    }

    #[test]
    fn rod_group_layout() {
        let mesh = rod_group(3, 4, 1.5, &grid(), [0.0, -2.0, 0.0]).unwrap();
        assert_eq!(mesh.num_vertices(), 12);
        assert_eq!(mesh.num_elements(), 9);
        assert_eq!(
            mesh.elements,
            Elements::Rods(vec![vec![0, 1, 2, 3], vec![4, 5, 6, 7], vec![8, 9, 10, 11]])
        );
        // Roots: (0,1,0), (0.25,1,0), then the next row (0,1,0.25); tips 1.5 below.
        assert_eq!(&mesh.rest[0..3], &[0.0, 1.0, 0.0]);
        assert_eq!(&mesh.rest[12..15], &[0.25, 1.0, 0.0]);
        assert_eq!(&mesh.rest[24..27], &[0.0, 1.0, 0.25]);
        assert_eq!(&mesh.rest[33..36], &[0.0, -0.5, 0.25]);
        assert_eq!(&mesh.rest[27..30], &[0.0, 0.5, 0.25]);
    }

    #[test]
    fn rod_parameter_errors() {
        let down = [0.0, -1.0, 0.0];
        field_error(rod_group(0, 4, 1.0, &grid(), down), RODS, "count");
        field_error(rod_group(2, 1, 1.0, &grid(), down), RODS, "verts_per_rod");
        field_error(rod_group(2, 4, f64::NAN, &grid(), down), RODS, "length");
        field_error(rod_group(2, 4, -1.0, &grid(), down), RODS, "length");
        field_error(rod_group(2, 4, 1.0, &grid(), [0.0; 3]), RODS, "direction");
        let mut bad = grid();
        bad.spacing = 0.0;
        let shown = field_error(rod_group(2, 4, 1.0, &bad, down), RODS, "roots.spacing");
        assert!(shown.contains("<procedural rods>: field `roots.spacing`"), "{shown}");
        // One rod needs no spacing.
        assert!(rod_group(1, 4, 1.0, &bad, down).is_ok());
        bad = grid();
        bad.columns = 0;
        field_error(rod_group(2, 4, 1.0, &bad, down), RODS, "roots.columns");
        bad = grid();
        bad.origin[2] = f64::NAN;
        field_error(rod_group(2, 4, 1.0, &bad, down), RODS, "roots.origin");
        bad = grid();
        bad.axes.1 = bad.axes.0;
        field_error(rod_group(2, 4, 1.0, &bad, down), RODS, "roots.axes");
        field_error(rod_group(usize::MAX, 4, 1.0, &grid(), down), RODS, "count");
    }
}
