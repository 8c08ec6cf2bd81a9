//! IPC's smoothing of the friction magnitude below the velocity threshold `eps_v`.
//!
//! `f0(y) = -y^3 / (3 eps_v^2) + y^2 / eps_v + eps_v / 3` for `y < eps_v`, `y` otherwise
//! (C2 at `eps_v`), with `f1 = f0'` and `f2 = f1'`. The friction force is `mu N f1(|u|) u / |u|`:
//! static below `eps_v` (growing linearly from zero), kinetic (unit direction) above.

/// `f0(y)`.
pub fn f0(y: f64, eps_v: f64) -> f64 {
    if y < eps_v {
        y * y * (1.0 / eps_v - y / (3.0 * eps_v * eps_v)) + eps_v / 3.0
    } else {
        y
    }
}

/// `f1(y) = f0'(y) = 2y / eps_v - y^2 / eps_v^2` below `eps_v`, one above.
pub fn f1(y: f64, eps_v: f64) -> f64 {
    if y < eps_v {
        y * (2.0 - y / eps_v) / eps_v
    } else {
        1.0
    }
}

/// `f2(y) = f1'(y) = 2 / eps_v - 2y / eps_v^2` below `eps_v`, zero above.
pub fn f2(y: f64, eps_v: f64) -> f64 {
    if y < eps_v {
        2.0 * (1.0 - y / eps_v) / eps_v
    } else {
        0.0
    }
}

/// `f1(y) / y`, finite at zero: `(2 - y / eps_v) / eps_v` below `eps_v`, `1 / y` above.
pub fn f1_over_x(y: f64, eps_v: f64) -> f64 {
    if y < eps_v {
        (2.0 - y / eps_v) / eps_v
    } else {
        1.0 / y
    }
}

/// `(f2(y) y - f1(y)) / y^3`: `-1 / (y eps_v^2)` below `eps_v`, `-1 / y^3` above.
pub fn f2_x_minus_f1_over_x3(y: f64, eps_v: f64) -> f64 {
    if y < eps_v {
        -1.0 / (y * eps_v * eps_v)
    } else {
        -1.0 / (y * y * y)
    }
}
