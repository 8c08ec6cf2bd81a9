//! Whether a decoded buffer is finite: one pass over every value, as wide as the CPU goes.
//!
//! A value is not finite when its exponent bits are all set. One pass of compares and ORs
//! over the buffer vectorises (an early-exit test would run value by value); on x86-64 the
//! same pass is compiled a second time for AVX-512F (`network/x86.rs`) and chosen at run time,
//! like the `f32` kernels ([`crate::network::fast`]).

/// Whether every value of `values` is finite.
pub(crate) fn all_finite(values: &[f32]) -> bool {
    crate::network::isa_all_finite(values).unwrap_or_else(|| no_exponent_all_set(values))
}

#[inline(always)]
fn no_exponent_all_set(values: &[f32]) -> bool {
    const EXPONENT: u32 = 0x7f80_0000;
    let any = values
        .iter()
        .fold(0u32, |any, v| any | u32::from(v.to_bits() & EXPONENT == EXPONENT));
    any == 0
}

#[cfg(all(test, feature = "std"))]
mod tests {
    use super::*;

    /// One infinity or NaN anywhere, in the vector body or the tail, is found.
    #[test]
    fn any_infinity_or_nan_anywhere_is_found() {
        let mut values = std::vec![1.5f32; 100];
        assert!(all_finite(&values));
        assert!(all_finite(&[f32::MAX, f32::MIN, -0.0, f32::MIN_POSITIVE / 2.0]));
        for bad in [f32::INFINITY, f32::NEG_INFINITY, f32::NAN] {
            for i in [0, 15, 16, 63, 64, 99] {
                values[i] = bad;
                assert!(!all_finite(&values), "{bad} at {i}");
                assert!(!no_exponent_all_set(&values), "{bad} at {i}");
                values[i] = 1.5;
            }
        }
    }
}
