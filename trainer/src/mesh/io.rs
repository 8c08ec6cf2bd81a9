//! Mesh file readers (filled in).
