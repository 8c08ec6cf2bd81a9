//! A tet mesh of a ball: the box grid of [`super::box_tets`] over the cube `[-1, 1]^3`,
//! each point moved radially so that the cube's shells of equal max-norm become spheres
//! (`p -> r |p|_inf p / |p|_2`). The boundary vertices all lie on the sphere; every tet
//! stays positively oriented (checked on build).

use super::box_tets;
use crate::energy::tet::signed_volume;
use crate::error::InputError;
use crate::mesh::{Elements, Mesh};

const BALL: &str = "<procedural ball>";

/// A ball of `radius` around `center`, `cells` grid cells across its diameter.
pub fn ball_tets(center: [f64; 3], radius: f64, cells: usize) -> Result<Mesh, InputError> {
    if !(radius.is_finite() && radius > 0.0) {
        return Err(InputError::field(
            BALL,
            "radius",
            format!("must be positive and finite, got {radius}"),
        ));
    }
    if !center.iter().all(|c| c.is_finite()) {
        return Err(InputError::field(
            BALL,
            "center",
            format!("must be finite, got {center:?}"),
        ));
    }
    if cells < 2 {
        return Err(InputError::field(
            BALL,
            "cells",
            format!("at least 2 cells across are needed, got {cells}"),
        ));
    }
    let mut mesh =
        box_tets([-1.0; 3], [1.0; 3], [cells; 3]).map_err(|e| InputError::field(BALL, "cells", e.to_string()))?;
    for p in mesh.rest.chunks_mut(3) {
        let inf = p.iter().fold(0.0f64, |m, c| m.max(c.abs()));
        let two = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        let scale = if two > 0.0 { radius * inf / two } else { 0.0 };
        for i in 0..3 {
            p[i] = center[i] + scale * p[i];
        }
    }
    let Elements::Tets(tets) = &mesh.elements else {
        unreachable!("box_tets makes tets")
    };
    let x = &mesh.rest;
    if let Some(t) = tets
        .iter()
        .find(|t| signed_volume(t.map(|v| [x[3 * v], x[3 * v + 1], x[3 * v + 2]])) <= 0.0)
    {
        return Err(InputError::field(
            BALL,
            "cells",
            format!("tet {t:?} inverts at {cells} cells across"),
        ));
    }
    Ok(mesh)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_ball_is_round_positive_and_fills_its_volume() {
        for cells in [2, 4, 6, 10] {
            let mesh = ball_tets([0.5, 1.0, -2.0], 0.1, cells).unwrap();
            let Elements::Tets(tets) = &mesh.elements else {
                panic!("tets")
            };
            let x = &mesh.rest;
            let volume: f64 = tets
                .iter()
                .map(|t| signed_volume(t.map(|v| [x[3 * v], x[3 * v + 1], x[3 * v + 2]])))
                .sum();
            let sphere = 4.0 / 3.0 * std::f64::consts::PI * 1e-3;
            // Flat faces between points on the sphere: the volume falls short, less so
            // on finer meshes.
            let shortfall = 1.0 - volume / sphere;
            assert!(
                shortfall > 0.0 && shortfall < 1.5 / (cells * cells) as f64,
                "{cells}: {shortfall}"
            );
            for v in mesh.surface_vertices() {
                let r = ((x[3 * v] - 0.5).powi(2) + (x[3 * v + 1] - 1.0).powi(2) + (x[3 * v + 2] + 2.0).powi(2)).sqrt();
                assert!((r - 0.1).abs() < 1e-12, "{cells}: surface vertex {v} at radius {r}");
            }
        }
    }

    #[test]
    fn bad_balls_name_the_field() {
        for (err, field) in [
            (ball_tets([0.0; 3], -1.0, 4), "radius"),
            (ball_tets([f64::NAN, 0.0, 0.0], 1.0, 4), "center"),
            (ball_tets([0.0; 3], 1.0, 1), "cells"),
        ] {
            let msg = err.unwrap_err().to_string();
            assert!(msg.contains(field), "{msg}");
        }
    }
}
