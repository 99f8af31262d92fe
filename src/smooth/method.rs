//! Smoothing methods and their options: `--smooth METHOD[:key=value,...]` and the config file's
//! `smoothing` section.

use serde::Serialize;
use std::fmt;

/// A smoothing method that looks ahead in time (Gaussian, FFT) asked to run causally.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("`{method}` looks ahead in time and cannot run causally; use butterworth (causal) or none")]
pub struct NotCausal {
    pub method: Method,
}
use std::str::FromStr;

/// A smoothing method with its options. Times are seconds, frequencies Hz.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "method", rename_all = "lowercase")]
pub enum Method {
    None,
    /// Butterworth low-pass; zero-phase (forward-backward, as scipy's `sosfiltfilt`) unless
    /// `causal`.
    Butterworth {
        order: usize,
        cutoff_hz: f64,
        causal: bool,
    },
    /// Gaussian kernel, as scipy's `gaussian_filter1d` (mode `reflect`, truncate 4).
    Gaussian {
        sigma_s: f64,
    },
    /// Paper 002's frequency-domain filter: bins at least `threshold` × the largest keep their
    /// value, the others are scaled by `suppress`; `cutoff_hz` zeroes the bins above it.
    Fft {
        threshold: Option<f64>,
        suppress: f64,
        cutoff_hz: Option<f64>,
    },
}

/// The default for `convert` and `watch`: zero-phase 4th-order Butterworth at 14 Hz. Measured on
/// closed loops (README, "Smoothing"): with 3° of noise it cuts the mean per-bone error by 37–38 %,
/// on clean takes it adds 0.09–0.13°; lower cutoffs remove more noise but bend real motion more
/// (6 Hz adds 0.7° on the pymo walk).
pub const DEFAULT: Method = Method::Butterworth {
    order: 4,
    cutoff_hz: 14.0,
    causal: false,
};

impl Default for Method {
    fn default() -> Self {
        DEFAULT
    }
}

impl fmt::Display for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Method::None => write!(f, "none"),
            Method::Butterworth {
                order,
                cutoff_hz,
                causal,
            } => write!(
                f,
                "butterworth:order={order},cutoff={cutoff_hz}{}",
                if *causal { ",causal" } else { "" }
            ),
            Method::Gaussian { sigma_s } => write!(f, "gaussian:sigma={sigma_s}"),
            Method::Fft {
                threshold,
                suppress,
                cutoff_hz,
            } => {
                write!(f, "fft:suppress={suppress}")?;
                if let Some(t) = threshold {
                    write!(f, ",threshold={t}")?;
                }
                if let Some(c) = cutoff_hz {
                    write!(f, ",cutoff={c}")?;
                }
                Ok(())
            }
        }
    }
}

fn number(key: &str, value: Option<&str>) -> Result<f64, String> {
    let v = value.ok_or_else(|| format!("`{key}` needs a value, e.g. {key}=6"))?;
    match v.trim().parse::<f64>() {
        Ok(x) if x.is_finite() => Ok(x),
        _ => Err(format!("`{key}={v}`: not a number")),
    }
}

impl FromStr for Method {
    type Err = String;

    /// `none`, `butterworth[:order=4,cutoff=14[,causal]]`, `gaussian[:sigma=0.02]` (seconds),
    /// `fft[:threshold=0.5,suppress=0.3]`, `fft:cutoff=6` (a plain low-pass), or both.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let (name, args) = s.trim().split_once(':').unwrap_or((s.trim(), ""));
        let pairs: Vec<(&str, Option<&str>)> = args
            .split(',')
            .map(str::trim)
            .filter(|a| !a.is_empty())
            .map(|a| match a.split_once('=') {
                Some((k, v)) => (k.trim(), Some(v.trim())),
                None => (a, None),
            })
            .collect();
        let unknown = |k: &str, allowed: &str| {
            Err(format!(
                "`{s}`: unknown option `{k}` for {name}; expected {allowed}"
            ))
        };
        let method = match name.to_ascii_lowercase().as_str() {
            "none" => {
                if let Some((k, _)) = pairs.first() {
                    return unknown(k, "no options");
                }
                Method::None
            }
            "butterworth" | "butter" => {
                let (mut order, mut cutoff_hz, mut causal) = (4usize, 14.0, false);
                for (k, v) in pairs {
                    match k {
                        "order" => {
                            let o = number(k, v)?;
                            if o.fract() != 0.0 || !(1.0..=10.0).contains(&o) {
                                return Err(format!(
                                    "`{s}`: order must be a whole number from 1 to 10"
                                ));
                            }
                            order = o as usize;
                        }
                        "cutoff" | "cutoff_hz" => cutoff_hz = number(k, v)?,
                        "causal" => causal = true,
                        "zero_phase" | "zerophase" => causal = false,
                        _ => return unknown(k, "order, cutoff (Hz), causal"),
                    }
                }
                Method::Butterworth {
                    order,
                    cutoff_hz,
                    causal,
                }
            }
            "gaussian" | "gauss" => {
                let mut sigma_s = 0.02;
                for (k, v) in pairs {
                    match k {
                        "sigma" | "sigma_s" => sigma_s = number(k, v)?,
                        _ => return unknown(k, "sigma (seconds)"),
                    }
                }
                Method::Gaussian { sigma_s }
            }
            "fft" => {
                let (mut threshold, mut suppress, mut cutoff_hz) = (None, 0.3, None);
                let mut threshold_given = false;
                for (k, v) in pairs {
                    match k {
                        "threshold" => {
                            threshold = Some(number(k, v)?);
                            threshold_given = true;
                        }
                        "suppress" => suppress = number(k, v)?,
                        "cutoff" | "cutoff_hz" => cutoff_hz = Some(number(k, v)?),
                        _ => return unknown(k, "threshold, suppress, cutoff (Hz)"),
                    }
                }
                // The paper's rule (threshold 0.5) unless only a plain low-pass was asked for.
                if !threshold_given && cutoff_hz.is_none() {
                    threshold = Some(0.5);
                }
                Method::Fft {
                    threshold,
                    suppress,
                    cutoff_hz,
                }
            }
            _ => {
                return Err(format!(
                    "unknown smoothing method `{name}`; expected none, butterworth, gaussian or fft"
                ));
            }
        };
        method.validate().map_err(|e| format!("`{s}`: {e}"))?;
        Ok(method)
    }
}

impl Method {
    /// Whether the method uses only the past (a stream can run it): none, or causal Butterworth.
    pub fn is_causal(&self) -> bool {
        matches!(
            self,
            Method::None | Method::Butterworth { causal: true, .. }
        )
    }

    /// The causal form of the method: Butterworth runs causal; the Gaussian and FFT filters,
    /// which look ahead, have none.
    pub fn to_causal(&self) -> Result<Method, NotCausal> {
        match self {
            Method::None => Ok(Method::None),
            Method::Butterworth {
                order, cutoff_hz, ..
            } => Ok(Method::Butterworth {
                order: *order,
                cutoff_hz: *cutoff_hz,
                causal: true,
            }),
            Method::Gaussian { .. } | Method::Fft { .. } => Err(NotCausal {
                method: self.clone(),
            }),
        }
    }

    /// Checks the options' ranges (those that do not depend on the sample rate).
    pub fn validate(&self) -> Result<(), String> {
        match self {
            Method::None => Ok(()),
            Method::Butterworth {
                order, cutoff_hz, ..
            } => {
                if !(1..=10).contains(order) {
                    Err("order must be from 1 to 10".into())
                } else if cutoff_hz.is_nan() || *cutoff_hz <= 0.0 {
                    Err("cutoff must be above 0 Hz".into())
                } else {
                    Ok(())
                }
            }
            Method::Gaussian { sigma_s } => {
                if *sigma_s >= 0.0 {
                    Ok(())
                } else {
                    Err("sigma must be 0 s or more".into())
                }
            }
            Method::Fft {
                threshold,
                suppress,
                cutoff_hz,
            } => {
                if threshold.is_some_and(|t| !(0.0..=1.0).contains(&t)) {
                    Err("threshold must be from 0 to 1".into())
                } else if !(0.0..=1.0).contains(suppress) {
                    Err("suppress must be from 0 to 1".into())
                } else if cutoff_hz.is_some_and(|c| c.is_nan() || c <= 0.0) {
                    Err("cutoff must be above 0 Hz".into())
                } else {
                    Ok(())
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_methods_and_options() {
        assert_eq!("none".parse::<Method>().unwrap(), Method::None);
        assert_eq!(
            "butterworth:order=3,cutoff=5,causal"
                .parse::<Method>()
                .unwrap(),
            Method::Butterworth {
                order: 3,
                cutoff_hz: 5.0,
                causal: true
            }
        );
        assert_eq!("butterworth".parse::<Method>().unwrap(), DEFAULT);
        assert_eq!(
            "gaussian:sigma=0.05".parse::<Method>().unwrap(),
            Method::Gaussian { sigma_s: 0.05 }
        );
        assert_eq!(
            "fft".parse::<Method>().unwrap(),
            Method::Fft {
                threshold: Some(0.5),
                suppress: 0.3,
                cutoff_hz: None
            }
        );
        assert_eq!(
            "fft:cutoff=8".parse::<Method>().unwrap(),
            Method::Fft {
                threshold: None,
                suppress: 0.3,
                cutoff_hz: Some(8.0)
            }
        );
        for bad in [
            "median",
            "butterworth:order=0",
            "butterworth:order=2.5",
            "butterworth:cutoff=-1",
            "butterworth:speed=3",
            "gaussian:sigma=x",
            "fft:threshold=2",
            "none:order=2",
        ] {
            assert!(bad.parse::<Method>().is_err(), "{bad}");
        }
        // Display round-trips.
        for m in [
            "butterworth:order=2,cutoff=7.5,causal",
            "gaussian:sigma=0.1",
            "fft:suppress=0.2,threshold=0.4,cutoff=9",
        ] {
            let parsed: Method = m.parse().unwrap();
            assert_eq!(parsed.to_string().parse::<Method>().unwrap(), parsed);
        }
    }
}
