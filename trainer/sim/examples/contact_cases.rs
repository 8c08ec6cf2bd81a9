//! Evaluates mochi's contact primitives on the cases of an `.npz` archive and writes the
//! results to another, for `scripts/check_ipctk.py` to compare with IPC's toolkit.
//!
//! Usage: `contact_cases IN.npz OUT.npz`. Input arrays (per pair `K` in `pp2 pp3 pe2 pe3 pt
//! ee`): `K_x` (cases x dofs) positions, `K_dhat` (cases) barrier activation distances,
//! `K_v` (cases x dofs) velocities and `K_Nfr` (cases) lagged normal forces for friction; `ee_epsx` mollifier thresholds; scalars
//! `eps_v`, `mu`, `kappa`; `bar_d`, `bar_dhat` for the scalar barrier; `fr_y` for the
//! friction smoothing; `ks_*` / `ku_in` for the barrier stiffness. For CCD (per pair `K`):
//! `ccd_K_x0`, `ccd_K_x1` (cases x dofs) the positions at the start and end of a linear step
//! and `ccd_K_xi` (cases) the minimum separations; out come `ccd_K_hit` (1 or 0) and
//! `ccd_K_toi`, additive CCD's time of impact with default parameters and `tmax = 1`. Either
//! group of inputs may be absent. Every pair's and CCD's arrays may also come under a prefix
//! (`P K_x`, `P ee_epsx`, `P ccd_K_x0`, ..., e.g. `fam_degenerate_pt_x`, the case families
//! of `scripts/ipctk_families.py`); their outputs get the same prefix.

use std::error::Error;
use std::path::Path;

use mochi_sim::contact::barrier::{
    barrier, barrier_first_derivative, barrier_force_magnitude, barrier_of_squared_distance, barrier_second_derivative,
    edge_edge_barrier,
};
use mochi_sim::contact::ccd::AdditiveCcd;
use mochi_sim::contact::distance::*;
use mochi_sim::contact::friction::*;
use mochi_sim::contact::stiffness::{initial_barrier_stiffness, update_barrier_stiffness};
use mochi_sim::energy::{Local, Want};
use mochi_sim::npz::NpzOut;
use npyz::npz::NpzArchive;
use rayon::prelude::*;

type Archive = NpzArchive<std::io::BufReader<std::fs::File>>;

fn read(npz: &mut Archive, name: &str) -> Result<(Vec<u64>, Vec<f64>), Box<dyn Error>> {
    let arr = npz.by_name(name)?.ok_or_else(|| format!("missing array {name}"))?;
    let shape = arr.shape().to_vec();
    Ok((shape, arr.into_vec::<f64>()?))
}

/// Results of one pair, row-major per array.
#[derive(Default)]
struct Columns {
    names: Vec<(String, Vec<u64>, Vec<f64>)>,
}

impl Columns {
    fn push(&mut self, name: &str, shape: &[u64], values: &[f64]) {
        match self.names.iter_mut().find(|(n, _, _)| n == name) {
            Some((_, _, v)) => v.extend_from_slice(values),
            None => self.names.push((name.to_string(), shape.to_vec(), values.to_vec())),
        }
    }
}

fn distance(key: &str, x: &[f64], want: Want, out: &mut Local) -> (f64, f64) {
    match key {
        "pp2" => (point_point_distance(x, 2, want, out), 0.0),
        "pp3" => (point_point_distance(x, 3, want, out), 0.0),
        "pe2" | "pe3" => {
            let dim = if key == "pe2" { 2 } else { 3 };
            let ty = point_edge_type(x, dim);
            (point_edge_distance_typed(x, dim, ty, want, out), ty as i64 as f64)
        }
        "pt" => {
            let ty = point_triangle_type(x);
            (point_triangle_distance_typed(x, ty, want, out), ty as i64 as f64)
        }
        "ee" => {
            let ty = edge_edge_type(x);
            (edge_edge_distance_typed(x, ty, want, out), ty as i64 as f64)
        }
        _ => unreachable!("unknown pair {key}"),
    }
}

/// Tangent basis, closest-point coordinates with their Jacobian, and relative velocity.
fn friction_frame(key: &str, x: &[f64]) -> (TangentBasis, Vec<f64>, Vec<f64>, RelativeVelocity) {
    match key {
        "pp2" | "pp3" => {
            let dim = if key == "pp2" { 2 } else { 3 };
            (
                point_point_tangent_basis(x, dim),
                vec![],
                vec![],
                RelativeVelocity::point_point(),
            )
        }
        "pe2" | "pe3" => {
            let dim = if key == "pe2" { 2 } else { 3 };
            let (alpha, jac) = point_edge_closest_point(x, dim);
            (
                point_edge_tangent_basis(x, dim),
                vec![alpha],
                jac[..3 * dim].to_vec(),
                RelativeVelocity::point_edge(alpha),
            )
        }
        "pt" => {
            let (c, jac) = point_triangle_closest_point(x);
            (
                point_triangle_tangent_basis(x),
                c.to_vec(),
                jac.concat(),
                RelativeVelocity::point_triangle(c),
            )
        }
        "ee" => {
            let (c, jac) = edge_edge_closest_point(x);
            (
                edge_edge_tangent_basis(x),
                c.to_vec(),
                jac.concat(),
                RelativeVelocity::edge_edge(c),
            )
        }
        _ => unreachable!("unknown pair {key}"),
    }
}

fn run_pair(
    npz: &mut Archive,
    prefix: &str,
    pair: &str,
    eps_v: f64,
    mu: f64,
    kappa: f64,
    cols: &mut Columns,
) -> Result<(), Box<dyn Error>> {
    // `pair` picks the functions, `key` names the arrays.
    let key = format!("{prefix}{pair}");
    let (shape, xs) = read(npz, &format!("{key}_x"))?;
    let (_, dhats) = read(npz, &format!("{key}_dhat"))?;
    let (_, vs) = read(npz, &format!("{key}_v"))?;
    let (_, lagged_forces) = read(npz, &format!("{key}_Nfr"))?;
    let epsx = if pair == "ee" {
        read(npz, &format!("{prefix}ee_epsx"))?.1
    } else {
        vec![]
    };
    let dim = if pair.ends_with('2') { 2 } else { 3 };
    let (cases, n) = (shape[0] as usize, shape[1] as usize);
    let nu = n as u64;
    let exact = Want::Hessian { project: false };
    let mut out = Local::default();
    for c in 0..cases {
        let x = &xs[c * n..(c + 1) * n];
        let (d2, ty) = distance(pair, x, exact, &mut out);
        cols.push(&format!("{key}_d"), &[], &[d2]);
        cols.push(&format!("{key}_type"), &[], &[ty]);
        cols.push(&format!("{key}_g"), &[nu], &out.grad[..n]);
        cols.push(&format!("{key}_h"), &[nu, nu], &out.hess[..n * n]);
        // Barrier b(d^2, dhat^2) (mollified for edge-edge).
        let dhat = dhats[c];
        let b = if pair == "ee" {
            edge_edge_barrier(x, epsx[c], dhat, exact, &mut out)
        } else {
            barrier_of_squared_distance(d2, n, dhat, exact, &mut out)
        };
        cols.push(&format!("{key}_b"), &[], &[b]);
        cols.push(&format!("{key}_bg"), &[nu], &out.grad[..n]);
        cols.push(&format!("{key}_bh"), &[nu, nu], &out.hess[..n * n]);
        if pair == "ee" {
            let m = edge_edge_mollifier(x, epsx[c], exact, &mut out);
            cols.push(&format!("{key}_m"), &[], &[m]);
            cols.push(&format!("{key}_mg"), &[nu], &out.grad[..n]);
            cols.push(&format!("{key}_mh"), &[nu, nu], &out.hess[..n * n]);
        }
        // Friction: lagged frame and normal force at x, potential at velocities v.
        let (basis, coords, jac, relative) = friction_frame(pair, x);
        let m = (dim - 1) as u64;
        let t: Vec<f64> = (0..dim)
            .flat_map(|i| (0..dim - 1).map(move |k| (i, k)))
            .map(|(i, k)| basis.columns[k][i])
            .collect();
        cols.push(&format!("{key}_T"), &[dim as u64, m], &t);
        if !coords.is_empty() {
            cols.push(&format!("{key}_cp"), &[coords.len() as u64], &coords);
            cols.push(&format!("{key}_cpj"), &[coords.len() as u64, nu], &jac);
        }
        let verts = n / dim;
        let gamma: Vec<f64> = (0..dim)
            .flat_map(|i| (0..verts).flat_map(move |a| (0..dim).map(move |j| (i, a, j))))
            .map(|(i, a, j)| if i == j { relative.weights[a] } else { 0.0 })
            .collect();
        cols.push(&format!("{key}_G"), &[dim as u64, nu], &gamma);
        cols.push(&format!("{key}_N"), &[], &[barrier_force_magnitude(d2, dhat, kappa)]);
        // The potential takes the lagged normal force as given (the reference's).
        let stencil = FrictionStencil {
            basis,
            relative,
            normal_force: lagged_forces[c],
            mu,
        };
        let v = &vs[c * n..(c + 1) * n];
        let f = stencil.eval(v, eps_v, exact, &mut out);
        cols.push(&format!("{key}_f"), &[], &[f]);
        cols.push(&format!("{key}_fg"), &[nu], &out.grad[..n]);
        cols.push(&format!("{key}_fh"), &[nu, nu], &out.hess[..n * n]);
        stencil.eval(v, eps_v, Want::Hessian { project: true }, &mut out);
        cols.push(&format!("{key}_fhp"), &[nu, nu], &out.hess[..n * n]);
    }
    Ok(())
}

/// Additive CCD on the motions `ccd_{key}_x0` to `ccd_{key}_x1`, if the archive has them.
fn run_ccd(npz: &mut Archive, prefix: &str, key: &str, cols: &mut Columns) -> Result<(), Box<dyn Error>> {
    if npz.by_name(&format!("{prefix}ccd_{key}_x0"))?.is_none() {
        return Ok(());
    }
    let (shape, x0s) = read(npz, &format!("{prefix}ccd_{key}_x0"))?;
    let (_, x1s) = read(npz, &format!("{prefix}ccd_{key}_x1"))?;
    let (_, xis) = read(npz, &format!("{prefix}ccd_{key}_xi"))?;
    let (cases, n) = (shape[0] as usize, shape[1] as usize);
    let dim = if key.ends_with('2') { 2 } else { 3 };
    let ccd = AdditiveCcd::default();
    // Cases in parallel: pairs sliding along each other at a tiny distance take millions of
    // advances each.
    let tois: Vec<Option<f64>> = (0..cases)
        .into_par_iter()
        .map(|c| {
            let (x0, x1, xi) = (&x0s[c * n..(c + 1) * n], &x1s[c * n..(c + 1) * n], xis[c]);
            match key {
                "pp2" | "pp3" => ccd.point_point(x0, x1, dim, xi, 1.0),
                "pe2" | "pe3" => ccd.point_edge(x0, x1, dim, xi, 1.0),
                "pt" => ccd.point_triangle(x0, x1, xi, 1.0),
                "ee" => ccd.edge_edge(x0, x1, xi, 1.0),
                _ => unreachable!("unknown pair {key}"),
            }
        })
        .collect();
    for toi in tois {
        cols.push(
            &format!("{prefix}ccd_{key}_hit"),
            &[],
            &[if toi.is_some() { 1.0 } else { 0.0 }],
        );
        cols.push(&format!("{prefix}ccd_{key}_toi"), &[], &[toi.unwrap_or(1.0)]);
    }
    Ok(())
}

const KEYS: [&str; 6] = ["pp2", "pp3", "pe2", "pe3", "pt", "ee"];

/// The prefixes under which the archive holds arrays ending in one of `suffixes` (one per
/// pair key), in order of first appearance.
fn prefixes(npz: &Archive, suffix: impl Fn(&str) -> String) -> Vec<String> {
    let mut out: Vec<String> = vec![];
    for name in npz.array_names() {
        for key in KEYS {
            let tail = suffix(key);
            if let Some(p) = name.strip_suffix(tail.as_str()) {
                if (p.is_empty() || p.ends_with('_')) && !out.iter().any(|q| q == p) {
                    out.push(p.to_string());
                }
            }
        }
    }
    out
}

fn main() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() != 3 {
        return Err("usage: contact_cases IN.npz OUT.npz".into());
    }
    let mut npz = NpzArchive::open(&args[1])?;
    let mut cols = Columns::default();
    for prefix in prefixes(&npz, |key| format!("ccd_{key}_x0")) {
        for key in KEYS {
            run_ccd(&mut npz, &prefix, key, &mut cols)?;
        }
    }
    if npz.by_name("eps_v")?.is_none() {
        return write(&cols, &args[2]);
    }
    let scalar = |npz: &mut Archive, name: &str| read(npz, name).map(|(_, v)| v[0]);
    let (eps_v, mu, kappa) = (
        scalar(&mut npz, "eps_v")?,
        scalar(&mut npz, "mu")?,
        scalar(&mut npz, "kappa")?,
    );
    for prefix in prefixes(&npz, |key| format!("{key}_x")) {
        for key in KEYS {
            if npz.by_name(&format!("{prefix}{key}_x"))?.is_some() {
                run_pair(&mut npz, &prefix, key, eps_v, mu, kappa, &mut cols)?;
            }
        }
    }
    if npz.by_name("bar_d")?.is_none() {
        return write(&cols, &args[2]);
    }
    let (_, d) = read(&mut npz, "bar_d")?;
    let (_, dhat) = read(&mut npz, "bar_dhat")?;
    for (d, dhat) in d.iter().zip(&dhat) {
        let row = [
            barrier(*d, *dhat),
            barrier_first_derivative(*d, *dhat),
            barrier_second_derivative(*d, *dhat),
        ];
        cols.push("bar", &[3], &row);
    }
    let (_, ys) = read(&mut npz, "fr_y")?;
    for y in ys {
        let row = [
            f0(y, eps_v),
            f1(y, eps_v),
            f2(y, eps_v),
            f1_over_x(y, eps_v),
            f2_x_minus_f1_over_x3(y, eps_v),
        ];
        cols.push("fr", &[5], &row);
    }
    let (kshape, kin) = read(&mut npz, "ks_in")?;
    let (gshape, ge) = read(&mut npz, "ks_ge")?;
    let (_, gb) = read(&mut npz, "ks_gb")?;
    let (k, m) = (kshape[0] as usize, gshape[1] as usize);
    for c in 0..k {
        let p = &kin[c * 4..c * 4 + 4];
        let s = initial_barrier_stiffness(p[0], p[1], p[2], &ge[c * m..(c + 1) * m], &gb[c * m..(c + 1) * m], p[3]);
        cols.push("ks", &[2], &[s.kappa, s.max]);
    }
    let (ushape, uin) = read(&mut npz, "ku_in")?;
    for c in 0..ushape[0] as usize {
        let p = &uin[c * 6..c * 6 + 6];
        cols.push(
            "ku",
            &[],
            &[update_barrier_stiffness(p[0], p[1], p[2], p[3], p[4], p[5])],
        );
    }
    write(&cols, &args[2])
}

fn write(cols: &Columns, path: &str) -> Result<(), Box<dyn Error>> {
    let mut out = NpzOut::create(Path::new(path))?;
    for (name, shape, values) in &cols.names {
        let rows = (values.len() / shape.iter().product::<u64>().max(1) as usize) as u64;
        let full: Vec<u64> = std::iter::once(rows).chain(shape.iter().copied()).collect();
        out.array(name, &full, values.iter().copied())?;
    }
    out.finish()?;
    Ok(())
}
