//! Raw readings fused sample by sample, as a live stream delivers them: the online filters'
//! cores stepped by the same rule as [`super::fuse`] steps them over a whole track
//! (`steps_for`: each step's `dt` from the samples' times, short gaps filled at the nominal rate;
//! the first step from the first readings' attitude).
//!
//! What a whole track knows in advance a stream learns from its first [`WARM_SAMPLES`] readings,
//! which come out together once they are in: the nominal period (their median step, where `fuse`
//! takes the whole track's), the units check, and whether the magnetometer carries a field. A
//! regularly sampled sensor therefore fuses to the same orientations either way (tested).

use super::{Ahrs, Fusion, FusionError, init, median};
use crate::take::ImuSample;
use nalgebra::{UnitQuaternion, Vector3};

/// Readings a stream collects before its filter starts.
pub const WARM_SAMPLES: usize = 16;

/// One sensor's raw readings fused as they come (see the module docs).
pub struct StreamFuser {
    sensor: String,
    fusion: Fusion,
    warm: Vec<(f64, ImuSample, Option<Vector3<f64>>)>,
    core: Option<Box<dyn Ahrs + Send>>,
    period_s: f64,
    nine_d: bool,
    last: Option<(f64, ImuSample)>,
    /// Readings interpolated into gaps so far.
    pub filled: usize,
    /// Readings fused so far, and how many of them the filter rejected the magnetometer's and
    /// the accelerometer's correction for.
    pub readings: usize,
    pub magnetic_rejected: usize,
    pub acceleration_rejected: usize,
    /// What the fusion has had to say (a long gap, a magnetometer that reads nothing).
    pub warnings: Vec<String>,
}

impl StreamFuser {
    /// A fuser for `sensor` with `fusion`'s online form (the offline fusion needs the whole
    /// take: online VQF with its parameters stands in, as `convert --causal` does).
    pub fn new(sensor: &str, fusion: &Fusion) -> StreamFuser {
        StreamFuser {
            sensor: sensor.to_string(),
            fusion: fusion.online(),
            warm: Vec::with_capacity(WARM_SAMPLES),
            core: None,
            period_s: 0.01,
            nine_d: false,
            last: None,
            filled: 0,
            readings: 0,
            magnetic_rejected: 0,
            acceleration_rejected: 0,
            warnings: Vec::new(),
        }
    }

    /// The gyroscope bias the filter estimates now, rad/s.
    pub fn gyro_bias(&self) -> Option<Vector3<f64>> {
        self.core.as_ref().and_then(|c| c.gyro_bias())
    }

    /// A reading at `t` seconds (times increase); the orientations `q_enu_sensor` it lets out
    /// go to `out` with their times.
    pub fn push(
        &mut self,
        t: f64,
        imu: ImuSample,
        mag: Option<Vector3<f64>>,
        out: &mut Vec<(f64, UnitQuaternion<f64>)>,
    ) -> Result<(), FusionError> {
        if self.core.is_some() {
            self.step(t, imu, mag, out);
            return Ok(());
        }
        self.warm.push((t, imu, mag));
        if self.warm.len() >= WARM_SAMPLES {
            self.start(out)?;
        }
        Ok(())
    }

    /// The end of the stream: a fuser still warming up starts with what it has.
    pub fn finish(&mut self, out: &mut Vec<(f64, UnitQuaternion<f64>)>) -> Result<(), FusionError> {
        if self.core.is_none() && !self.warm.is_empty() {
            self.start(out)?;
        }
        Ok(())
    }

    /// Whether the filter uses the magnetometer (known once started).
    pub fn nine_d(&self) -> bool {
        self.nine_d
    }

    fn start(&mut self, out: &mut Vec<(f64, UnitQuaternion<f64>)>) -> Result<(), FusionError> {
        let warm = std::mem::take(&mut self.warm);
        let values: Vec<ImuSample> = warm.iter().map(|w| w.1).collect();
        let times: Vec<f64> = warm.iter().map(|w| w.0).collect();
        let track =
            crate::take::Track::new(times.clone(), values).map_err(|_| FusionError::NoStart {
                sensor: self.sensor.clone(),
            })?;
        self.warnings
            .extend(super::check_units(&self.sensor, &track)?);
        let dts: Vec<f64> = times.windows(2).map(|w| w[1] - w[0]).collect();
        self.period_s = if dts.is_empty() { 0.01 } else { median(dts) };
        let mags: Vec<Vector3<f64>> = warm.iter().filter_map(|w| w.2).collect();
        let works = mags
            .first()
            .is_some_and(|first| first.norm() > 0.0 && mags.iter().any(|m| m != first));
        if !mags.is_empty() && !works {
            self.warnings.push(format!(
                "sensor `{}`: the magnetometer reads nothing (zero or one value in its first readings); \
                 fused without it (6D)",
                self.sensor
            ));
        }
        self.nine_d = works && !self.fusion.six_d;
        let (_, first, first_mag) = warm[0];
        let mag0 = first_mag.filter(|_| self.nine_d);
        let q0 = init::attitude(&first.accel_m_s2, mag0.as_ref()).ok_or_else(|| {
            FusionError::NoStart {
                sensor: self.sensor.clone(),
            }
        })?;
        self.core = Some(self.fusion.core(q0, self.period_s, self.nine_d));
        for (t, imu, mag) in warm {
            self.step(t, imu, mag, out);
        }
        Ok(())
    }

    /// One reading through the filter, after the readings filled into a gap before it.
    fn step(
        &mut self,
        t: f64,
        imu: ImuSample,
        mag: Option<Vector3<f64>>,
        out: &mut Vec<(f64, UnitQuaternion<f64>)>,
    ) {
        let mag = mag.filter(|_| self.nine_d);
        let core = self.core.as_mut().expect("started");
        let prev = self.last.as_ref().map(|(t, s)| (*t, s));
        let gap = super::steps_for(prev, t, &imu, self.period_s, |gyr, acc, dt, _| {
            core.update(&gyr, &acc, mag.as_ref(), dt);
        });
        self.filled += gap.filled;
        if let Some(dt) = gap.long_s {
            self.warnings
                .push(super::long_gap_warning(&self.sensor, dt, t));
        }
        self.last = Some((t, imu));
        let rejected = core.rejected();
        self.readings += 1;
        self.magnetic_rejected += usize::from(rejected.magnetic);
        self.acceleration_rejected += usize::from(rejected.acceleration);
        out.push((t, core.orientation()));
    }
}

/// A whole track fused as a stream would fuse it ([`StreamFuser`]): what `convert --causal`
/// does, so a take converted in causal mode gives the frames a live session of it gave.
pub fn fuse_as_stream(
    sensor: &str,
    inertial: &crate::take::Track<ImuSample>,
    magnetometer: Option<&crate::take::Track<Vector3<f64>>>,
    fusion: &Fusion,
) -> Result<super::Fused, FusionError> {
    let mut fuser = StreamFuser::new(sensor, fusion);
    let mut out = Vec::with_capacity(inertial.len());
    let mut index = 0;
    for (t, imu) in inertial.iter() {
        // The latest magnetometer reading at or before t (as `fuse` pairs them).
        let mag = magnetometer.and_then(|m| {
            let times = m.times_s();
            while index + 1 < times.len() && times[index + 1] <= t {
                index += 1;
            }
            (times[index] <= t || index == 0).then(|| m.values()[index])
        });
        fuser.push(t, *imu, mag, &mut out)?;
    }
    fuser.finish(&mut out)?;
    let n = fuser.readings.max(1) as f64;
    let bias = fuser.gyro_bias();
    let (times, values): (Vec<f64>, Vec<UnitQuaternion<f64>>) = out.into_iter().unzip();
    Ok(super::Fused {
        track: crate::take::Track::new(times, values).map_err(|_| FusionError::NoStart {
            sensor: sensor.to_string(),
        })?,
        stats: super::FusionStats {
            algorithm: fuser.fusion.filter.name(),
            variant: if fuser.nine_d() { "9d" } else { "6d" },
            filled_samples: fuser.filled,
            gyro_bias_dps: bias.map(|b| [b.x.to_degrees(), b.y.to_degrees(), b.z.to_degrees()]),
            magnetic_rejected: fuser.magnetic_rejected as f64 / n,
            acceleration_rejected: fuser.acceleration_rejected as f64 / n,
            rest_s: None,
            disturbed_s: None,
            expected_error_deg: None,
            corrections: Vec::new(),
            series: Vec::new(),
        },
        warnings: std::mem::take(&mut fuser.warnings),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::take::Track;

    /// Readings of a sensor turning about a tilted axis at 128 Hz (a period exact in binary, so
    /// both medians are the same number) with the field of a place in the northern hemisphere,
    /// a gap of 5 missing samples and one of 80 (beyond filling).
    const DT: f64 = 1.0 / 128.0;

    fn readings() -> (Vec<f64>, Vec<ImuSample>, Vec<Vector3<f64>>) {
        let mut times = Vec::new();
        let (mut imu, mut mag) = (Vec::new(), Vec::new());
        let mut q = UnitQuaternion::from_euler_angles(0.2, -0.1, 0.4);
        let w = Vector3::new(0.3, -0.8, 0.5);
        let field = Vector3::new(0.0, 20.0, -40.0);
        for i in 0..1500 {
            if (300..305).contains(&i) || (900..980).contains(&i) {
                q = UnitQuaternion::from_scaled_axis(q * w * DT) * q;
                continue;
            }
            times.push(i as f64 * DT);
            let gravity = Vector3::new(0.0, 0.0, 9.81);
            imu.push(ImuSample {
                gyro_rad_s: w,
                accel_m_s2: q.inverse() * gravity,
            });
            mag.push(q.inverse() * field);
            q = UnitQuaternion::from_scaled_axis(q * w * DT) * q;
        }
        (times, imu, mag)
    }

    #[test]
    fn a_stream_fuses_as_the_whole_track_does() {
        let (times, imu, mag) = readings();
        for spec in ["vqf", "madgwick", "mahony:kp=0.5", "vqf:6d"] {
            let fusion: Fusion = spec.parse().unwrap();
            let whole = super::super::fuse(
                "s",
                &Track::new(times.clone(), imu.clone()).unwrap(),
                Some(&Track::new(times.clone(), mag.clone()).unwrap()),
                &fusion,
            )
            .unwrap();
            let mut fuser = StreamFuser::new("s", &fusion);
            let mut out = Vec::new();
            for ((t, s), m) in times.iter().zip(&imu).zip(&mag) {
                fuser.push(*t, *s, Some(*m), &mut out).unwrap();
            }
            fuser.finish(&mut out).unwrap();
            assert_eq!(out.len(), times.len());
            assert_eq!(fuser.filled, whole.stats.filled_samples, "{spec}");
            let worst = out
                .iter()
                .zip(whole.track.values())
                .map(|((_, a), b)| a.angle_to(b))
                .fold(0.0, f64::max);
            assert!(worst < 1e-12, "{spec}: {worst}");
        }
    }

    #[test]
    fn readings_in_the_wrong_units_are_refused() {
        let (times, imu, _) = readings();
        let mut fuser = StreamFuser::new("s", &Fusion::online_default());
        let mut out = Vec::new();
        let mut result = Ok(());
        for (t, s) in times.iter().zip(&imu).take(WARM_SAMPLES) {
            let g = ImuSample {
                gyro_rad_s: s.gyro_rad_s,
                accel_m_s2: s.accel_m_s2 / 9.81,
            };
            result = fuser.push(*t, g, None, &mut out);
        }
        assert!(matches!(result, Err(FusionError::AccelUnits { .. })));
    }
}
