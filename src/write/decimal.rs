//! Numbers with six decimals, written the way `format!("{v:.6}")` writes them, about ten times
//! faster: the BVH writer's motion lines are tens of millions of them.
//!
//! `{:.6}` writes the exact binary value of `v` rounded to a multiple of 10⁻⁶, ties to even
//! (0.0078125 = 2⁻⁷ → `0.007812`). With `v = m·2ᵉ` (`m` the 53-bit significand), `v·10⁶ =
//! m·10⁶·2ᵉ` is an integer times a power of two, and `m·10⁶ < 2⁷³` fits a `u128`, so the rounding
//! is exact integer arithmetic: `q = ⌊m·10⁶ / 2⁻ᵉ⌉` with the remainder deciding the tie. The
//! digits of `q` are then `q / 10⁶`, a point, and `q mod 10⁶` on six places.
//!
//! The one deliberate difference from `{:.6}`: a value that rounds to zero is `0.000000` whatever
//! its sign (`{:.6}` writes `-0.000000` for −10⁻⁹), as the BVH writer always did. Values of
//! 2⁴⁰ (≈ 1.1·10¹²) and more, and non-finite ones, are left to `format!`.

use std::fmt::Write as _;

/// Two ASCII digits of every number below 100.
const PAIRS: &[u8; 200] = b"0001020304050607080910111213141516171819\
2021222324252627282930313233343536373839\
4041424344454647484950515253545556575859\
6061626364656667686970717273747576777879\
8081828384858687888990919293949596979899";

/// Above this magnitude the rounded value no longer fits the fast path's `u64` comfortably.
const FAST_LIMIT: f64 = (1u64 << 40) as f64;

/// Appends `v` with exactly six decimals (see the module documentation).
#[inline]
pub fn push_fixed6(out: &mut Vec<u8>, v: f64) {
    // NaN fails the comparison too.
    if v.is_nan() || v.abs() >= FAST_LIMIT {
        return push_slow(out, v);
    }
    let bits = v.to_bits();
    let negative = bits >> 63 == 1;
    let exponent_bits = ((bits >> 52) & 0x7ff) as i32;
    let fraction = bits & ((1u64 << 52) - 1);
    // v = m·2^e exactly.
    let (m, e) = if exponent_bits == 0 {
        (fraction, -1074)
    } else {
        (fraction | (1u64 << 52), exponent_bits - 1075)
    };
    let scaled = m as u128 * 1_000_000;
    let q: u64 = if e >= 0 {
        // An integer below 2⁴⁰: exact.
        (scaled << e) as u64
    } else {
        let shift = (-e) as u32;
        if shift >= 128 {
            // m·10⁶ < 2⁷³ is less than half of 2¹²⁷: rounds to zero.
            0
        } else {
            let q = scaled >> shift;
            let remainder = scaled & ((1u128 << shift) - 1);
            let half = 1u128 << (shift - 1);
            (q + u128::from(remainder > half || (remainder == half && q & 1 == 1))) as u64
        }
    };
    if q == 0 {
        out.extend_from_slice(b"0.000000");
        return;
    }
    if negative {
        out.push(b'-');
    }
    push_integer(out, q / 1_000_000);
    let frac = (q % 1_000_000) as usize;
    let (a, b, c) = (frac / 10_000, frac / 100 % 100, frac % 100);
    out.extend_from_slice(&[
        b'.',
        PAIRS[2 * a],
        PAIRS[2 * a + 1],
        PAIRS[2 * b],
        PAIRS[2 * b + 1],
        PAIRS[2 * c],
        PAIRS[2 * c + 1],
    ]);
}

/// The decimal digits of `n`, no leading zeros (`0` for zero).
#[inline]
fn push_integer(out: &mut Vec<u8>, mut n: u64) {
    let mut digits = [0u8; 20];
    let mut at = digits.len();
    while n >= 100 {
        let pair = (n % 100) as usize;
        n /= 100;
        at -= 2;
        digits[at] = PAIRS[2 * pair];
        digits[at + 1] = PAIRS[2 * pair + 1];
    }
    if n >= 10 {
        at -= 2;
        digits[at] = PAIRS[2 * n as usize];
        digits[at + 1] = PAIRS[2 * n as usize + 1];
    } else {
        at -= 1;
        digits[at] = b'0' + n as u8;
    }
    out.extend_from_slice(&digits[at..]);
}

#[cold]
fn push_slow(out: &mut Vec<u8>, v: f64) {
    let mut text = String::with_capacity(32);
    let _ = write!(text, "{v:.6}");
    if text == "-0.000000" {
        text.remove(0);
    }
    out.extend_from_slice(text.as_bytes());
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What the writer always wrote: `format!` with the negative zero made positive.
    fn reference(v: f64) -> String {
        let text = format!("{v:.6}");
        if text == "-0.000000" {
            "0.000000".to_string()
        } else {
            text
        }
    }

    fn fast(v: f64) -> String {
        let mut out = Vec::new();
        push_fixed6(&mut out, v);
        String::from_utf8(out).unwrap()
    }

    #[test]
    fn binary64_edge_cases_match_format() {
        let mut cases = vec![
            0.0,
            -0.0,
            f64::MIN_POSITIVE,
            -f64::MIN_POSITIVE,
            f64::from_bits(1),
            -f64::from_bits(1),
            f64::EPSILON,
            1.0,
            -1.0,
            0.5,
            // Exact ties at the sixth decimal: 2⁻⁷ and odd multiples of it.
            0.0078125,
            -0.0078125,
            0.0234375,
            0.0390625,
            1.0078125,
            // Not ties: the nearest doubles of 5e-7, 1.5e-6, 2.5e-6 lie on either side.
            5e-7,
            -5e-7,
            1.5e-6,
            2.5e-6,
            0.9999995,
            -0.9999995,
            999_999.999_999_5,
            179.999_999_5,
            -179.999_999_5,
            360.0,
            (1u64 << 40) as f64,
            (1u64 << 40) as f64 - 0.5,
            -((1u64 << 40) as f64),
            (1u64 << 53) as f64,
            1e15,
            1e300,
            -1e300,
            f64::MAX,
            f64::MIN,
        ];
        // Every power of two from 2⁻⁶⁰ to 2⁴², and its neighbours.
        for k in -60..=42 {
            let p = 2f64.powi(k);
            for v in [
                p,
                -p,
                f64::from_bits(p.to_bits() + 1),
                f64::from_bits(p.to_bits() - 1),
            ] {
                cases.push(v);
            }
        }
        // Every half-micro tie k·10⁻⁶ + 5·10⁻⁷ that is a double, and the doubles around it.
        for k in 0..2000u64 {
            let v = (2 * k + 1) as f64 / 2_000_000.0;
            cases.extend([
                v,
                -v,
                f64::from_bits(v.to_bits() + 1),
                f64::from_bits(v.to_bits() - 1),
            ]);
        }
        for v in cases {
            assert_eq!(fast(v), reference(v), "{v:e} ({:#x})", v.to_bits());
        }
        assert_eq!(fast(-1e-9), "0.000000");
        assert_eq!(fast(0.0078125), "0.007812");
        assert_eq!(fast(-12.5), "-12.500000");
    }

    #[test]
    fn non_finite_values_are_written_as_format_writes_them() {
        assert_eq!(fast(f64::NAN), "NaN");
        assert_eq!(fast(f64::INFINITY), "inf");
        assert_eq!(fast(f64::NEG_INFINITY), "-inf");
    }

    /// A small random sample here; `tests/decimal_format.rs` checks ten million values in an
    /// optimised build.
    #[test]
    fn random_values_match_format() {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        for _ in 0..20_000 {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            let v = f64::from_bits(state);
            assert_eq!(fast(v), reference(v), "{v:e}");
        }
    }
}
