//! Tests of the adaptive solver's linear algebra and fixed decomposition.

mod bfgs;
mod elastic_subspace;
mod fixtures;
mod lower_csc;
mod partition;
mod schur;
mod solver;
