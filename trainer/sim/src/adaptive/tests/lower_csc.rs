//! The symmetric products of a matrix stored as its lower triangle, against dense ones.

use nalgebra::DMatrix;

use super::fixtures::{lower_csc, random_matrix, random_sparse_spd, rng};
use crate::adaptive::lower_csc::{symmetric_block_product, symmetric_product};
use crate::adaptive::system::hessian_times;

#[test]
fn block_and_column_products_equal_the_dense_product() {
    let mut rng = rng(5);
    let h = random_sparse_spd(40, 0.1, &mut rng);
    let lower = lower_csc(&h);
    for k in [1, 2, 5, 12] {
        let u = random_matrix(h.nrows(), k, &mut rng);
        let dense = &h * &u;
        let row_major: Vec<f64> = (0..u.nrows())
            .flat_map(|r| u.row(r).iter().copied().collect::<Vec<_>>())
            .collect();
        let mut block = vec![0.0; row_major.len()];
        symmetric_block_product(lower.as_ref(), &row_major, k, &mut block);
        let mut column = vec![0.0; u.nrows()];
        symmetric_product(lower.as_ref(), u.column(0).as_slice(), &mut column);
        let by_threads = hessian_times(lower.as_ref(), &u);
        let scale = dense.amax();
        for r in 0..u.nrows() {
            assert!(
                (column[r] - dense[(r, 0)]).abs() <= 1e-13 * scale,
                "column product, row {r}"
            );
            for j in 0..k {
                assert!(
                    (block[r * k + j] - dense[(r, j)]).abs() <= 1e-13 * scale,
                    "k {k}, ({r}, {j})"
                );
                assert!(
                    (by_threads[(r, j)] - dense[(r, j)]).abs() <= 1e-13 * scale,
                    "k {k}, ({r}, {j})"
                );
            }
        }
    }
    assert_eq!(
        hessian_times(lower.as_ref(), &DMatrix::zeros(h.nrows(), 0)).shape(),
        (h.nrows(), 0)
    );
}
