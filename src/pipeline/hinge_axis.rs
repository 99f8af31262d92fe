//! A hinge seen by two sensors whose worlds may differ by a turn about the vertical (one or both
//! fused without a magnetometer): the turn between their worlds, and the hinge's axis in each
//! sensor's own frame, from their orientations alone.
//!
//! A hinge (a knee, an elbow) turns its outer segment relative to the inner one about one axis,
//! fixed in both segments and so in both sensors: with `Q_i(t)` and `Q_o(t)` the sensors'
//! orientations (sensor → its own world; rig axes, +Y up, the worlds sharing the vertical) and
//! `D = R_y(δ)` the turn from the outer sensor's world into the inner one's, the axis `j_i` (inner
//! sensor's frame) and `j_o` (outer's) meet `Q_i(t) j_i = D Q_o(t) j_o` at every `t`. Over `N`
//! samples, for unit axes,
//!
//! `Σ |Q_i j_i − D Q_o j_o|² = 2N − 2 j_iᵀ B(δ) j_o`, with `B(δ) = Σ Q_iᵀ D Q_o`,
//!
//! so for each `δ` the best axes are `B(δ)`'s first singular pair (with the same sign: both the
//! same physical direction) and the residual is `2(N − σ₁(B(δ)))`; `δ` is the turn that maximises
//! `σ₁`. Since `D = cos δ (I − yyᵀ) + sin δ [y]ₓ + yyᵀ`, `B(δ) = cos δ B_c + sin δ B_s + B_y`
//! with three sums folded sample by sample. A hinge whose axis stays vertical (an elbow in a T-pose
//! turning only in the horizontal plane) cannot tell `δ`; one whose axis stays horizontal fits
//! `δ + 180°` as well (both views flip), which only a tilt of the axis tells apart here — the
//! caller decides between them ([`HingeFit::residual_deg_at`] gives each one's residual).
//!
//! This is the orientation form of the joint-axis identification of Seel, Raisch & Schauer (2014),
//! whose gyroscope form `|ω_i × j_i| = |ω_o × j_o|` needs no orientations but leaves each axis's sign
//! free. Which way is the subject's left is left to the caller: the flexion's direction.

use nalgebra::{Matrix3, UnitQuaternion, Vector3};

/// The sums of a hinge's samples ([module docs](self)).
#[derive(Debug, Clone, Default)]
pub struct HingeFit {
    cos: Matrix3<f64>,
    sin: Matrix3<f64>,
    vertical: Matrix3<f64>,
    samples: usize,
}

/// What [`HingeFit::solve`] finds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HingeAxes {
    /// `D`: the turn about +Y from the outer sensor's world into the inner one's.
    pub outer_to_inner: UnitQuaternion<f64>,
    /// The axis in the inner sensor's frame and in the outer's, unit, the same physical direction
    /// (which one, left or right, is not known here).
    pub inner: Vector3<f64>,
    pub outer: Vector3<f64>,
    /// The angle between the two sensors' views of the axis, root mean square over the samples,
    /// degrees: how well one axis explains the motion.
    pub residual_deg: f64,
}

/// Steps of the search for `δ` over a full turn (then refined between the neighbours of the best).
const DELTA_STEPS: usize = 360;

impl HingeFit {
    pub fn new() -> HingeFit {
        HingeFit::default()
    }

    /// One pair of orientations at the same instant: the inner and the outer sensor's, each in its
    /// own world (rig axes).
    pub fn push(&mut self, inner: &UnitQuaternion<f64>, outer: &UnitQuaternion<f64>) {
        let (qi, qo) = (
            inner.to_rotation_matrix().into_inner(),
            outer.to_rotation_matrix().into_inner(),
        );
        let y = Vector3::y();
        let yy = y * y.transpose();
        let qit = qi.transpose();
        self.cos += qit * (Matrix3::identity() - yy) * qo;
        self.sin += qit * y.cross_matrix() * qo;
        self.vertical += qit * yy * qo;
        self.samples += 1;
    }

    fn b(&self, delta: f64) -> Matrix3<f64> {
        self.cos * delta.cos() + self.sin * delta.sin() + self.vertical
    }

    fn sigma(&self, delta: f64) -> f64 {
        self.b(delta).singular_values().max()
    }

    /// How far off `δ` may be, degrees, were the samples `independent` independent looks (of
    /// all of them; the rest repeat them): from the least-squares cost `S(δ) = 2(N − σ₁(B(δ)))`
    /// near its minimum, `var δ = 2 (S/N) / (S'' · independent/N)` (`S''` by central differences).
    pub fn delta_uncertainty_deg(&self, d: &UnitQuaternion<f64>, independent: f64) -> f64 {
        let n = self.samples as f64;
        if n == 0.0 || independent <= 0.0 {
            return f64::INFINITY;
        }
        let delta = d.scaled_axis().y;
        let h = 1f64.to_radians();
        let cost = |x: f64| 2.0 * (n - self.sigma(x));
        let curvature = (cost(delta + h) - 2.0 * cost(delta) + cost(delta - h)) / (h * h);
        if curvature <= 0.0 {
            return f64::INFINITY;
        }
        let mean_sq = cost(delta).max(0.0) / n;
        (2.0 * mean_sq / (curvature * independent / n))
            .sqrt()
            .to_degrees()
    }

    /// The residual ([`HingeAxes::residual_deg`]) were the turn between the worlds `d`.
    pub fn residual_deg_at(&self, d: &UnitQuaternion<f64>) -> f64 {
        self.residual_deg(self.sigma(d.scaled_axis().y))
    }

    /// The residual for `B(δ)`'s first singular value `sigma`: the mean squared chord between
    /// the views is 2(1 − σ₁/N), for small angles the angle squared.
    fn residual_deg(&self, sigma: f64) -> f64 {
        let n = self.samples.max(1) as f64;
        (2.0 * (1.0 - sigma / n)).max(0.0).sqrt().to_degrees()
    }

    /// The turn between the worlds and the axes; `None` without samples.
    pub fn solve(&self) -> Option<HingeAxes> {
        if self.samples == 0 {
            return None;
        }
        let step = std::f64::consts::TAU / DELTA_STEPS as f64;
        let best = (0..DELTA_STEPS)
            .map(|k| k as f64 * step)
            .max_by(|a, b| self.sigma(*a).total_cmp(&self.sigma(*b)))?;
        // Golden-section search between the best step's neighbours (σ₁ is smooth and has one
        // maximum there).
        let ratio = (5f64.sqrt() - 1.0) / 2.0;
        let (mut lo, mut hi) = (best - step, best + step);
        for _ in 0..40 {
            let (a, b) = (hi - ratio * (hi - lo), lo + ratio * (hi - lo));
            if self.sigma(a) < self.sigma(b) {
                lo = a;
            } else {
                hi = b;
            }
        }
        let delta = (lo + hi) / 2.0;
        let svd = self.b(delta).svd(true, true);
        let (u, v_t) = (svd.u?, svd.v_t?);
        let first = svd.singular_values.imax();
        let sigma = svd.singular_values[first];
        Some(HingeAxes {
            outer_to_inner: UnitQuaternion::from_axis_angle(&Vector3::y_axis(), delta),
            inner: u.column(first).into_owned(),
            outer: v_t.row(first).transpose(),
            residual_deg: self.residual_deg(sigma),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rot(axis: Vector3<f64>, deg: f64) -> UnitQuaternion<f64> {
        UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_normalize(axis), deg.to_radians())
    }

    /// A knee walking and turning: the thigh swings and the body turns about the vertical, the
    /// shank flexes about the thigh's left. Each sensor sits on its segment at a random mount and
    /// the outer one's world is turned by 73° about the vertical: the fit finds that turn and each
    /// sensor's view of the knee's axis (the mounts' inverses applied to the bone's +X), to 1e-6,
    /// with no residual; with noise on every orientation the residual grows and the turn holds
    /// within a degree.
    #[test]
    fn the_turn_between_the_worlds_and_the_axes_are_found() {
        let (m_i, m_o) = (
            rot(Vector3::new(1.0, -2.0, 0.5), 130.0),
            rot(Vector3::new(-0.3, 1.0, 2.0), 60.0),
        );
        let d = rot(Vector3::y(), 73.0);
        let samples: Vec<_> = (0..500)
            .map(|k| {
                let t = k as f64 * 0.01;
                let body = rot(Vector3::y(), 20.0 * t);
                let thigh = body * rot(Vector3::x(), -25.0 * (3.0 * t).sin());
                let shank = thigh * rot(Vector3::x(), 30.0 * (1.0 - (3.0 * t).cos()));
                (thigh * m_i, d.inverse() * shank * m_o)
            })
            .collect();
        let mut fit = HingeFit::new();
        for (qi, qo) in &samples {
            fit.push(qi, qo);
        }
        let axes = fit.solve().unwrap();
        assert!(axes.outer_to_inner.angle_to(&d) < 1e-6, "{axes:?}");
        let sign = axes.inner.dot(&(m_i.inverse() * Vector3::x())).signum();
        assert!((axes.inner * sign - m_i.inverse() * Vector3::x()).norm() < 1e-6);
        assert!((axes.outer * sign - m_o.inverse() * Vector3::x()).norm() < 1e-6);
        assert!(axes.residual_deg < 1e-3, "{axes:?}");
        // Noise: each orientation turned by a few tenths of a degree about a wandering axis.
        let mut noisy = HingeFit::new();
        for (k, (qi, qo)) in samples.iter().enumerate() {
            let k = k as f64;
            let wobble = |s: f64| rot(Vector3::new(s.sin(), (1.7 * s).cos(), 1.0), 0.5);
            noisy.push(&(qi * wobble(k)), &(qo * wobble(k * 1.3 + 2.0)));
        }
        let axes = noisy.solve().unwrap();
        assert!(
            axes.outer_to_inner.angle_to(&d).to_degrees() < 1.0,
            "{axes:?}"
        );
        assert!(
            axes.residual_deg > 0.1 && axes.residual_deg < 2.0,
            "{axes:?}"
        );
    }

    #[test]
    fn nothing_without_samples() {
        assert!(HingeFit::new().solve().is_none());
    }
}
