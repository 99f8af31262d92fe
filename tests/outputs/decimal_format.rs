//! The BVH writer's six-decimal formatter against the standard library's `format!("{v:.6}")` on
//! ten million values (issue 23): uniform values at every magnitude a BVH holds, every kind of
//! random bit pattern, and the doubles next to every half-micro tie.

use crate::common;

use common::six_decimals as reference;
use imubake::write::decimal::push_fixed6;

/// xorshift64*: a fixed, reproducible stream (no dependency on a random crate's versions).
struct Stream(u64);

impl Stream {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
}

#[test]
fn ten_million_values_are_written_as_format_writes_them() {
    let mut stream = Stream(0x0123_4567_89ab_cdef);
    let mut fast = Vec::with_capacity(64);
    let mut mismatches = Vec::new();
    let total = 10_000_000;
    for i in 0..total {
        let v = match i % 5 {
            // Angles in degrees and positions in metres or centimetres: ±10^k for k in -7..=12.
            0 | 1 => {
                let k = (stream.next() % 20) as i32 - 7;
                (stream.unit() * 2.0 - 1.0) * 10f64.powi(k)
            }
            // Any bit pattern with an exponent where the sixth decimal matters (2^-30 .. 2^45).
            2 => {
                let exponent = 1023 - 30 + stream.next() % 76;
                f64::from_bits((stream.next() & !(0x7ffu64 << 52)) | (exponent << 52))
            }
            // Any bit pattern at all (NaN, infinities, subnormals and huge values included), one
            // in fifty of these (`format!` takes microseconds for a 300-digit number); the rest
            // any bit pattern below 2⁶⁰.
            3 if i % 50 == 3 => f64::from_bits(stream.next()),
            3 => {
                let v = f64::from_bits(stream.next());
                if v.abs() < 1.2e18 {
                    v
                } else {
                    v / 1e300 / 1e300
                }
            }
            // Next to a tie k·10⁻⁶ + 5·10⁻⁷: the nearest double and a few ulps either side.
            _ => {
                let k = stream.next() % 1_000_000_000;
                let tie = (2 * k + 1) as f64 / 2_000_000.0;
                let ulps = (stream.next() % 7) as i64 - 3;
                let bits = (tie.to_bits() as i64 + ulps) as u64;
                let v = f64::from_bits(bits);
                if stream.next() & 1 == 0 { v } else { -v }
            }
        };
        fast.clear();
        push_fixed6(&mut fast, v);
        let expected = reference(v);
        if fast != expected.as_bytes() && mismatches.len() < 10 {
            mismatches.push(format!(
                "{v:e} ({:#x}): {} instead of {expected}",
                v.to_bits(),
                String::from_utf8_lossy(&fast)
            ));
        }
    }
    assert!(mismatches.is_empty(), "{mismatches:#?}");
}
