//! Property tests: no reader panics on any input, and the SOU line check is exactly the paper's
//! regular expression (checked against the `regex` crate, an independent implementation).

use imubake::read::{ReadOptions, detect_bytes, imubake_csv, sou};
use proptest::prelude::*;
use std::path::Path;

const PAPER_REGEX: &str = r"^[0-9]+,[a-zA-Z0-9]+(,[ \-0-9\.]+){6}$";

fn sou_like_line() -> impl Strategy<Value = String> {
    // Mostly near-valid lines over the characters that matter, so both outcomes occur often.
    proptest::string::string_regex(r"[0-9]{0,3}(,[A-Za-z0-9_ ]{0,3}){0,1}(,[ \-0-9\.a]{0,4}){0,8}")
        .expect("valid strategy regex")
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn sou_check_equals_the_paper_regex(line in sou_like_line()) {
        let re = regex::Regex::new(PAPER_REGEX).unwrap();
        prop_assert_eq!(sou::format_problem(line.as_bytes()).is_none(), re.is_match(&line), "{:?}", line);
    }

    #[test]
    fn sou_reader_never_panics(bytes in proptest::collection::vec(any::<u8>(), 0..2048)) {
        let _ = sou::read_from(&bytes[..], Path::new("fuzz.log"), &ReadOptions::default());
        let _ = detect_bytes(&bytes);
    }

    #[test]
    fn csv_reader_never_panics(bytes in proptest::collection::vec(any::<u8>(), 0..2048)) {
        let _ = imubake_csv::read_from(&bytes[..], Path::new("fuzz.csv"), &ReadOptions::default());
    }

    /// Arbitrary edits of valid logs: every outcome is a take or an error, and a take's tracks
    /// keep their invariants (strictly increasing finite times starting at 0, unit quaternions).
    #[test]
    fn mutated_logs_give_takes_that_hold_invariants(
        which in 0usize..2,
        edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>(), 0u8..3), 0..40),
        skip_seconds in prop_oneof![Just(0.0), 0.0f64..0.2],
    ) {
        let base: &[u8] = if which == 0 {
            b"1000,N0,10,1,2,20,3,4\n1040,N0,11,1,2,21,3,4\n1020,N1,1,2,3,4,5,6\n1060,N1,1,2,3,4,5,6\n1100,N0,350,89.9,-179,0,0,0\n"
        } else {
            b"# world: nwu\ntime_s,sensor,qw,qx,qy,qz,gx_dps,gy_dps,gz_dps,ax_g,ay_g,az_g\n0.0,a,1,0,0,0,1,2,3,0,0,1\n0.01,b,0,1,0,0,1,2,3,0,0,1\n0.02,a,0.5,0.5,0.5,0.5,1,2,3,0,0,1\n0.015,a,1,0,0,0,0,0,0,0,0,1\n"
        };
        let mut bytes = base.to_vec();
        for (index, byte, op) in edits {
            if bytes.is_empty() { bytes.push(byte); continue; }
            let i = index.index(bytes.len());
            match op {
                0 => bytes[i] = byte,
                1 => bytes.insert(i, byte),
                _ => { bytes.remove(i); }
            }
        }
        let options = ReadOptions { skip_seconds, ..ReadOptions::default() };
        let result = if which == 0 {
            sou::read_from(&bytes[..], Path::new("m.log"), &options)
        } else {
            imubake_csv::read_from(&bytes[..], Path::new("m.csv"), &options)
        };
        if let Ok(take) = result {
            let mut earliest = f64::INFINITY;
            for s in take.sensors() {
                let times = s.primary_times_s();
                prop_assert!(times.windows(2).all(|w| w[0] < w[1]));
                prop_assert!(times.iter().all(|t| t.is_finite() && *t >= 0.0));
                earliest = earliest.min(s.first_time_s());
                if let Some(o) = s.orientation() {
                    for q in o.to_quaternions().values() {
                        prop_assert!((q.into_inner().norm() - 1.0).abs() < 1e-9);
                    }
                }
            }
            prop_assert_eq!(earliest, 0.0);
        }
    }
}

#[test]
fn paper_regex_examples_by_hand() {
    let re = regex::Regex::new(PAPER_REGEX).unwrap();
    for (line, ok) in [
        ("1000,N0,1,2,3,4,5,6", true),
        ("1000,N0, -1.5,2,3,4,5,6", true),
        ("1000,N0,1--2,2,3,4,5,6", true),
        ("1000,N0,1,2,3,4,5", false),
        ("1000,N0,1,2,3,4,5,6,7", false),
        ("1000,N_0,1,2,3,4,5,6", false),
        ("-1000,N0,1,2,3,4,5,6", false),
        ("1000,N0,1e3,2,3,4,5,6", false),
        ("1000,N0,,2,3,4,5,6", false),
    ] {
        assert_eq!(re.is_match(line), ok, "{line}");
        assert_eq!(sou::format_problem(line.as_bytes()).is_none(), ok, "{line}");
    }
}
