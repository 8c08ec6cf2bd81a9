//! The calculus of a `D x D` deformation gradient for the two sizes the elements use (2x2 and
//! 3x3), and the fixed-size decompositions the Hessian projection needs.

use nalgebra::allocator::Allocator;
use nalgebra::{
    Const, DefaultAllocator, DimDiff, DimMin, DimSub, Matrix2, Matrix3, SMatrix, SVector, SymmetricEigen, SVD, U1,
};

/// Iteration cap of the fixed-size eigen and singular value decompositions (they need a
/// handful per eigenvalue; the cap only stops non-finite input from looping).
const MAX_ITERATIONS: usize = 1000;

/// The dimension-specific pieces of the calculus of a `D x D` deformation gradient whose
/// vectorisation has `N = D * D` entries, and the fixed-size decompositions that the
/// Hessian projection needs (nalgebra's require bounds that only concrete sizes meet).
/// Implemented for 2x2 (`N = 4`) and 3x3 (`N = 9`).
pub trait DeformationGradient<const D: usize, const N: usize>: Sized {
    /// `det F`.
    fn det(&self) -> f64;
    /// The cofactor matrix `d det F / dF` (equal to `det(F) F^-T` where `F` is invertible).
    fn cofactor(&self) -> Self;
    /// Adds `scale * d2(det F)/dF2` (over column-major `vec(F)`) to `h`.
    fn add_det_hessian(&self, scale: f64, h: &mut SMatrix<f64, N, N>);
    /// `(U, sigma, V)` with `F = U diag(sigma) V^T` and `U`, `V` rotations, so the last
    /// singular value carries the sign of `det F`; `None` if the SVD does not converge.
    fn rotation_svd(&self) -> Option<(Self, SVector<f64, D>, Self)>;
    /// Eigenvalues and eigenvectors (as columns) of `self`, symmetric; `None` if the
    /// decomposition does not converge.
    fn eigen_decomposition(&self) -> Option<(SVector<f64, D>, Self)>;
    /// Clamps the negative eigenvalues of the symmetric `h` to zero, by a numerical
    /// eigen-decomposition (`h` becomes zero, still PSD, if that does not converge).
    fn clamp_negative_eigenvalues(h: &mut SMatrix<f64, N, N>);
}

impl DeformationGradient<2, 4> for Matrix2<f64> {
    fn det(&self) -> f64 {
        self.determinant()
    }

    fn cofactor(&self) -> Self {
        Matrix2::new(self[(1, 1)], -self[(1, 0)], -self[(0, 1)], self[(0, 0)])
    }

    fn add_det_hessian(&self, scale: f64, h: &mut SMatrix<f64, 4, 4>) {
        // det = F00 F11 - F01 F10, vec(F) = (F00, F10, F01, F11): constant Hessian.
        h[(0, 3)] += scale;
        h[(3, 0)] += scale;
        h[(1, 2)] -= scale;
        h[(2, 1)] -= scale;
    }

    fn rotation_svd(&self) -> Option<(Self, SVector<f64, 2>, Self)> {
        rotation_svd(self)
    }

    fn eigen_decomposition(&self) -> Option<(SVector<f64, 2>, Self)> {
        eigen_decomposition(self)
    }

    fn clamp_negative_eigenvalues(h: &mut SMatrix<f64, 4, 4>) {
        clamp_negative_eigenvalues(h);
    }
}

impl DeformationGradient<3, 9> for Matrix3<f64> {
    fn det(&self) -> f64 {
        self.determinant()
    }

    fn cofactor(&self) -> Self {
        let (f0, f1, f2) = (self.column(0), self.column(1), self.column(2));
        Matrix3::from_columns(&[f1.cross(&f2), f2.cross(&f0), f0.cross(&f1)])
    }

    fn add_det_hessian(&self, scale: f64, h: &mut SMatrix<f64, 9, 9>) {
        // det = f0 . (f1 x f2) with columns f_a; the block of columns (a, a+1 mod 3) is
        // -[f_c]x with c the third column, its transpose is the block (a+1, a).
        for a in 0..3 {
            let b = (a + 1) % 3;
            let c = (a + 2) % 3;
            let fc = self.column(c).into_owned() * scale;
            let block = fc.cross_matrix();
            let mut ab = h.fixed_view_mut::<3, 3>(3 * a, 3 * b);
            ab -= block;
            let mut ba = h.fixed_view_mut::<3, 3>(3 * b, 3 * a);
            ba += block;
        }
    }

    fn rotation_svd(&self) -> Option<(Self, SVector<f64, 3>, Self)> {
        rotation_svd(self)
    }

    fn eigen_decomposition(&self) -> Option<(SVector<f64, 3>, Self)> {
        eigen_decomposition(self)
    }

    fn clamp_negative_eigenvalues(h: &mut SMatrix<f64, 9, 9>) {
        clamp_negative_eigenvalues(h);
    }
}

/// See [`DeformationGradient::rotation_svd`].
#[allow(clippy::type_complexity)]
fn rotation_svd<const D: usize>(
    f: &SMatrix<f64, D, D>,
) -> Option<(SMatrix<f64, D, D>, SVector<f64, D>, SMatrix<f64, D, D>)>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>> + DimSub<U1>,
    DefaultAllocator: Allocator<DimDiff<Const<D>, U1>>,
{
    let svd = SVD::<f64, Const<D>, Const<D>>::try_new(*f, true, true, f64::EPSILON, MAX_ITERATIONS)?;
    let (mut u, mut v) = (svd.u?, svd.v_t?.transpose());
    if u.determinant() < 0.0 {
        u.column_mut(D - 1).neg_mut();
    }
    if v.determinant() < 0.0 {
        v.column_mut(D - 1).neg_mut();
    }
    // Signed singular values, consistent with the sign flips above.
    let sigma = (u.transpose() * f * v).diagonal();
    Some((u, sigma, v))
}

/// See [`DeformationGradient::eigen_decomposition`].
fn eigen_decomposition<const D: usize>(m: &SMatrix<f64, D, D>) -> Option<(SVector<f64, D>, SMatrix<f64, D, D>)>
where
    Const<D>: DimSub<U1>,
    DefaultAllocator: Allocator<DimDiff<Const<D>, U1>>,
{
    let eig = SymmetricEigen::<f64, Const<D>>::try_new(*m, f64::EPSILON, MAX_ITERATIONS)?;
    Some((eig.eigenvalues, eig.eigenvectors))
}

/// See [`DeformationGradient::clamp_negative_eigenvalues`].
fn clamp_negative_eigenvalues<const N: usize>(h: &mut SMatrix<f64, N, N>)
where
    Const<N>: DimSub<U1>,
    DefaultAllocator: Allocator<DimDiff<Const<N>, U1>>,
{
    let Some((values, vectors)) = eigen_decomposition(h) else {
        h.fill(0.0);
        return;
    };
    if values.iter().all(|&l| l >= 0.0) {
        return;
    }
    let clamped = values.map(|l| l.max(0.0));
    *h = vectors * SMatrix::<f64, N, N>::from_diagonal(&clamped) * vectors.transpose();
}
