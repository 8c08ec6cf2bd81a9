//! Axis-aligned bounding boxes of contact primitives, at one configuration or swept over a
//! step. 2D boxes have `z = 0`.

/// An axis-aligned box `[min, max]` (closed).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    /// Lower corner.
    pub min: [f64; 3],
    /// Upper corner.
    pub max: [f64; 3],
}

impl Aabb {
    /// The empty box (the identity of [`Self::include`]).
    pub const EMPTY: Aabb = Aabb {
        min: [f64::INFINITY; 3],
        max: [f64::NEG_INFINITY; 3],
    };

    /// Grows the box to hold the point `p` (`p.len()` 2 or 3).
    pub fn include(&mut self, p: &[f64]) {
        for (k, &v) in p.iter().enumerate() {
            self.min[k] = self.min[k].min(v);
            self.max[k] = self.max[k].max(v);
        }
        for k in p.len()..3 {
            self.min[k] = self.min[k].min(0.0);
            self.max[k] = self.max[k].max(0.0);
        }
    }

    /// The box of the vertices `verts` of `x` (`dim` coordinates per vertex).
    pub fn of_vertices(x: &[f64], dim: usize, verts: &[usize]) -> Aabb {
        let mut b = Aabb::EMPTY;
        for &v in verts {
            b.include(&x[v * dim..(v + 1) * dim]);
        }
        b
    }

    /// The box of the vertices `verts` at both `x0` and `x1`: it holds the primitive at every
    /// time of a linear step from `x0` to `x1` (each point moves on a segment).
    pub fn swept(x0: &[f64], x1: &[f64], dim: usize, verts: &[usize]) -> Aabb {
        let mut b = Aabb::of_vertices(x0, dim, verts);
        for &v in verts {
            b.include(&x1[v * dim..(v + 1) * dim]);
        }
        b
    }

    /// The box grown by `r` on every side.
    pub fn inflated(self, r: f64) -> Aabb {
        Aabb {
            min: self.min.map(|v| v - r),
            max: self.max.map(|v| v + r),
        }
    }

    /// Whether the closed boxes share a point.
    pub fn overlaps(&self, other: &Aabb) -> bool {
        (0..3).all(|k| self.min[k] <= other.max[k] && other.min[k] <= self.max[k])
    }

    /// The largest side length.
    pub fn largest_extent(&self) -> f64 {
        (0..3).map(|k| self.max[k] - self.min[k]).fold(0.0, f64::max)
    }
}
