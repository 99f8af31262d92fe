//! Numbers with six decimals, written the way `format!("{v:.6}")` writes them, about ten times
//! faster: the BVH writer's motion lines are tens of millions of them.
//!
//! `{:.6}` writes the exact binary value of `v` rounded to a multiple of 10⁻⁶, ties to even
//! (0.0078125 = 2⁻⁷ → `0.007812`). With `v = m·2ᵉ` (`m` the 53-bit significand), `v·10⁶ =
//! m·10⁶·2ᵉ` is an integer times a power of two, and `m·10⁶ < 2⁷³` fits a `u128`, so the rounding
//! is exact integer arithmetic: `q = ⌊m·10⁶ / 2⁻ᵉ⌉` with the remainder deciding the tie. The
//! digits of `q` are then `q / 10⁶`, a point, and `q mod 10⁶` on six places.
//!
//! Most values take a shorter road to the same `q`: `p = v·10⁶` rounded to a double is within
//! half an ulp of the exact product, so when `p`'s fraction is clearly away from ½ (by more
//! than [`TIE_MARGIN`], which exceeds that half ulp for `|p| < 2⁴³`), the exact product rounds to
//! the same integer as `p`. Only values within the margin of a tie take the exact road.
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

/// Below this magnitude of `v·10⁶` (|v| < 8.8·10⁶) the rounded product decides `q` unless its
/// fraction is within [`TIE_MARGIN`] of ½.
const SCALED_LIMIT: f64 = (1u64 << 43) as f64;

/// Larger than half an ulp of any double below [`SCALED_LIMIT`] (at most 2⁻¹¹), with room to
/// spare.
const TIE_MARGIN: f64 = 1.0 / 256.0;

/// Appends `v` with exactly six decimals (see the module documentation).
#[inline]
pub fn push_fixed6(out: &mut Vec<u8>, v: f64) {
    let scaled = (v * 1e6).abs();
    // NaN and infinities fail the comparison.
    if scaled < SCALED_LIMIT {
        // Truncation, then the fraction: both exact below 2⁵². (Through i64, which x86-64
        // converts in one instruction each way; u64 takes several.)
        let whole = scaled as i64;
        let fraction = scaled - whole as f64;
        if (fraction - 0.5).abs() > TIE_MARGIN {
            let q = whole as u64 + u64::from(fraction > 0.5);
            return push_micros(out, q, v.is_sign_negative());
        }
    }
    push_exact(out, v);
}

/// `q` millionths (below 2⁴³), with a minus sign when `negative` and `q` is not zero.
///
/// Built in registers and stored in one 16-byte write, then cut to length: a few short writes
/// read back as one would stall on store forwarding.
#[inline]
fn push_micros(out: &mut Vec<u8>, q: u64, negative: bool) {
    debug_assert!(q < 1 << 43);
    if q == 0 {
        out.extend_from_slice(b"0.000000");
        return;
    }
    let units = q / 1_000_000; // below 8.8·10⁶: at most seven digits
    let frac = q % 1_000_000;
    let unit_digits = digits_of_eight(units);
    // Leading zero digits are the low zero bytes; a zero part keeps one digit.
    let leading = (unit_digits.trailing_zeros() / 8).min(7);
    let mut text = (unit_digits | ASCII_ZEROS) >> (8 * leading);
    let mut len = 8 - leading;
    if negative {
        text = (text << 8) | u64::from(b'-');
        len += 1;
    }
    // '.' and the six fraction digits (the first two of eight are zeros).
    let fraction = u64::from(b'.') | (((digits_of_eight(frac) | ASCII_ZEROS) >> 16) << 8);
    let whole = u128::from(text) | (u128::from(fraction) << (8 * len));
    let at = out.len();
    out.extend_from_slice(&whole.to_le_bytes());
    out.truncate(at + len as usize + 7);
}

/// `'0'` in each of eight bytes.
const ASCII_ZEROS: u64 = 0x3030_3030_3030_3030;

/// The eight decimal digits of `x < 10⁸` (leading zeros included) as byte values 0–9, the most
/// significant in the lowest byte (first in memory), by halving the digit groups in parallel
/// lanes: 4 + 4 digits in 32-bit lanes, then 2 + 2 in 16-bit lanes, then 1 + 1 in bytes. The
/// divisions are multiply-and-shift, exact for the lanes' ranges: `⌊x·10486 / 2²⁰⌋ = ⌊x / 100⌋`
/// for `x < 10⁴`, `⌊x·103 / 2¹⁰⌋ = ⌊x / 10⌋` for `x < 100` (checked for every value in the
/// tests), and no lane's product reaches the next lane's kept bits.
#[inline]
fn digits_of_eight(x: u64) -> u64 {
    debug_assert!(x < 100_000_000);
    let fours = (x / 10_000) | ((x % 10_000) << 32);
    let hundreds = ((fours * 10_486) >> 20) & 0x0000_007f_0000_007f;
    let twos = hundreds | ((fours - hundreds * 100) << 16);
    let tens = ((twos * 103) >> 10) & 0x000f_000f_000f_000f;
    tens | ((twos - tens * 10) << 8)
}

/// [`push_fixed6`] by exact integer arithmetic on the binary value.
fn push_exact(out: &mut Vec<u8>, v: f64) {
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
    fn lane_divisions_are_exact_over_their_ranges() {
        for x in 0..10_000u64 {
            assert_eq!((x * 10_486) >> 20, x / 100, "{x}");
        }
        for x in 0..100u64 {
            assert_eq!((x * 103) >> 10, x / 10, "{x}");
        }
        for x in (0..100_000_000u64)
            .step_by(9_973)
            .chain([0, 9, 10, 99_999_999])
        {
            let text = (digits_of_eight(x) | ASCII_ZEROS).to_le_bytes();
            assert_eq!(std::str::from_utf8(&text).unwrap(), format!("{x:08}"));
        }
    }

    #[test]
    fn non_finite_values_are_written_as_format_writes_them() {
        assert_eq!(fast(f64::NAN), "NaN");
        assert_eq!(fast(f64::INFINITY), "inf");
        assert_eq!(fast(f64::NEG_INFINITY), "-inf");
    }

    /// A small random sample here; `tests/outputs/decimal_format.rs` checks ten million values in an
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
