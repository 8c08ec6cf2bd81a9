//! Measures of states shared by every method and report: vertex errors against a
//! reference, as a fraction of the rest bounding-box diagonal, and kinetic energy.

/// Per vertex, the distance between `x` and `reference` (`dim` numbers per vertex, f32 or f64)
/// as a fraction of `diagonal`.
pub fn vertex_errors<'a, T: Copy + Into<f64>>(
    x: &'a [T],
    reference: &'a [f64],
    dim: usize,
    diagonal: f64,
) -> impl Iterator<Item = f64> + 'a {
    x.chunks_exact(dim).zip(reference.chunks_exact(dim)).map(move |(p, r)| {
        let squared: f64 = p.iter().zip(r).map(|(&a, &b)| (a.into() - b).powi(2)).sum();
        squared.sqrt() / diagonal
    })
}

/// The mean and the largest of [`vertex_errors`]: one frame's error in the units every report
/// uses.
pub fn mean_and_max_error<T: Copy + Into<f64>>(x: &[T], reference: &[f64], dim: usize, diagonal: f64) -> (f64, f64) {
    let (sum, max, count) = vertex_errors(x, reference, dim, diagonal)
        .fold((0.0, 0.0, 0usize), |(sum, max, count): (f64, f64, usize), e| {
            (sum + e, max.max(e), count + 1)
        });
    (sum / count.max(1) as f64, max)
}

/// Kinetic energy of the step from `prev` to `x`.
pub fn kinetic_energy(masses: &[f64], x: &[f64], prev: &[f64], dt: f64, dim: usize) -> f64 {
    masses
        .iter()
        .enumerate()
        .map(|(v, m)| {
            let s: f64 = (0..dim).map(|c| (x[v * dim + c] - prev[v * dim + c]).powi(2)).sum();
            0.5 * m * s / (dt * dt)
        })
        .sum()
}
