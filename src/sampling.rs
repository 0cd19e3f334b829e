//! Warps from the unit square to directions and points, shading frames, and the shared `erf` /
//! `erfinv` polynomials (twin of `shaders/lib/sampling.glsl`).
//!
//! Transcendentals that both back ends need bit-close (erf, erfinv) are polynomials written out
//! here and in GLSL, not libm calls, so CPU and GPU sample the same directions.

use std::f32::consts::{FRAC_1_PI, FRAC_PI_2, FRAC_PI_4, PI};

use glam::{Vec2, Vec3};

/// An orthonormal shading frame around a unit normal (Duff et al. 2017, branch-free except for the
/// sign of z). `to_local` maps world vectors into the frame, where the normal is +z.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    /// First tangent.
    pub t: Vec3,
    /// Second tangent.
    pub b: Vec3,
    /// The normal.
    pub n: Vec3,
}

impl Frame {
    /// The frame whose z axis is the unit vector `n`.
    pub fn from_normal(n: Vec3) -> Frame {
        let sign = if n.z >= 0.0 { 1.0 } else { -1.0 };
        let a = -1.0 / (sign + n.z);
        let b = n.x * n.y * a;
        Frame {
            t: Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
            b: Vec3::new(b, sign + n.y * n.y * a, -n.y),
            n,
        }
    }

    /// `v` in frame coordinates.
    pub fn to_local(&self, v: Vec3) -> Vec3 {
        Vec3::new(v.dot(self.t), v.dot(self.b), v.dot(self.n))
    }

    /// Frame coordinates `v` back in world space.
    pub fn to_world(&self, v: Vec3) -> Vec3 {
        self.t * v.x + self.b * v.y + self.n * v.z
    }
}

/// Shirley–Chiu concentric map of the unit square onto the unit disk.
pub fn sample_concentric_disk(u: Vec2) -> Vec2 {
    let a = 2.0 * u - Vec2::ONE;
    if a.x == 0.0 && a.y == 0.0 {
        return Vec2::ZERO;
    }
    let (r, theta) =
        if a.x.abs() > a.y.abs() { (a.x, FRAC_PI_4 * (a.y / a.x)) } else { (a.y, FRAC_PI_2 - FRAC_PI_4 * (a.x / a.y)) };
    Vec2::new(r * theta.cos(), r * theta.sin())
}

/// Cosine-weighted direction on the +z hemisphere (Malley's method over the concentric disk).
pub fn sample_cosine_hemisphere(u: Vec2) -> Vec3 {
    let d = sample_concentric_disk(u);
    Vec3::new(d.x, d.y, (1.0 - d.x * d.x - d.y * d.y).max(0.0).sqrt())
}

/// Density of [`sample_cosine_hemisphere`] in solid angle.
pub fn cosine_hemisphere_pdf(v: Vec3) -> f32 {
    v.z.max(0.0) * FRAC_1_PI
}

/// Uniform direction on the unit sphere.
pub fn sample_uniform_sphere(u: Vec2) -> Vec3 {
    let z = 1.0 - 2.0 * u.x;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * u.y;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// Density of [`sample_uniform_sphere`]: 1 / (4π).
pub const UNIFORM_SPHERE_PDF: f32 = 0.25 * FRAC_1_PI;

/// Uniform point on a triangle as barycentrics (b1, b2) of vertices 1 and 2.
pub fn sample_uniform_triangle(u: Vec2) -> Vec2 {
    let su = u.x.sqrt();
    Vec2::new(u.y * su, su * (1.0 - u.y))
}

/// ∫ from −radius to `x` of the 1D reconstruction filter `kind` (`FILTER_TENT` or
/// `FILTER_GAUSSIAN`, whose exponent factor is `alpha` = −1/(2σ²)): the tent's
/// (x + r)²/(2r) for x ≤ 0 and r − (r − x)²/(2r) beyond; Mitsuba's Gaussian
/// exp(αt²) − exp(αr²) integrates to (√π/2)·s·(erf(x/s) − erf(−r/s)) − exp(αr²)(x + r), s = σ√2.
pub fn filter_cdf(kind: u32, radius: f32, alpha: f32, x: f32) -> f32 {
    if kind == crate::contract::FILTER_TENT {
        let r = radius;
        if x <= 0.0 { (x + r) * (x + r) / (2.0 * r) } else { r - (r - x) * (r - x) / (2.0 * r) }
    } else {
        let s = (-1.0 / alpha).sqrt();
        let bias = (alpha * radius * radius).exp();
        0.5 * PI.sqrt() * s * (erf_approx(x / s) - erf_approx(-radius / s)) - bias * (x + radius)
    }
}

/// The film coordinate (in pixels, along one axis) of a sample of pixel `pixel` on a film
/// `extent` pixels long, drawn with `u` from the reconstruction filter around the pixel's centre
/// and truncated to the film, so that the mean of the samples' radiance is Mitsuba's
/// filter-weighted pixel value (`scene::PixelFilter`). The box filter is `pixel + u`; the others
/// invert [`filter_cdf`] by [`crate::contract::FILTER_BISECTIONS`] bisection steps. Twin of `filter_sample` in
/// `shaders/lib/sampling.glsl`.
pub fn filter_sample(kind: u32, radius: f32, alpha: f32, pixel: u32, extent: u32, u: f32) -> f32 {
    if kind == crate::contract::FILTER_BOX {
        return pixel as f32 + u;
    }
    let c = pixel as f32 + 0.5;
    let a = (-radius).max(-c);
    let b = radius.min(extent as f32 - c);
    let (ca, cb) = (filter_cdf(kind, radius, alpha, a), filter_cdf(kind, radius, alpha, b));
    let target = ca + u * (cb - ca);
    let (mut lo, mut hi) = (a, b);
    let mut step = 0;
    // A `while`: debug builds call core's range iterators out of line (Cargo.toml).
    while step < crate::contract::FILTER_BISECTIONS {
        let mid = 0.5 * (lo + hi);
        if filter_cdf(kind, radius, alpha, mid) < target {
            lo = mid;
        } else {
            hi = mid;
        }
        step += 1;
    }
    c + 0.5 * (lo + hi)
}

/// The error function, Abramowitz & Stegun 7.1.26 (absolute error below 1.5e-7).
pub fn erf_approx(x: f32) -> f32 {
    let ax = x.abs();
    let t = 1.0 / (1.0 + 0.327_591_1 * ax);
    let poly = t * (0.254_829_6 + t * (-0.284_496_74 + t * (1.421_413_8 + t * (-1.453_152 + t * 1.061_405_4))));
    let y = 1.0 - poly * (-ax * ax).exp();
    if x < 0.0 { -y } else { y }
}

/// The inverse error function for x in (−1, 1), Giles' single-precision polynomials (2010).
#[allow(clippy::excessive_precision, reason = "the coefficients as published, shared verbatim with GLSL")]
pub fn erfinv_approx(x: f32) -> f32 {
    let w = -((1.0 - x) * (1.0 + x)).ln();
    let p = if w < 5.0 {
        let w = w - 2.5;
        let mut p = 2.810_226_4e-8;
        p = 3.432_739_4e-7 + p * w;
        p = -3.523_387_7e-6 + p * w;
        p = -4.391_506_5e-6 + p * w;
        p = 2.185_808_7e-4 + p * w;
        p = -1.253_725e-3 + p * w;
        p = -4.177_681_6e-3 + p * w;
        p = 0.246_640_73 + p * w;
        1.501_409_4 + p * w
    } else {
        let w = w.sqrt() - 3.0;
        let mut p = -2.002_142_6e-4;
        p = 1.009_505_6e-4 + p * w;
        p = 1.349_343_2e-3 + p * w;
        p = -3.673_428_4e-3 + p * w;
        p = 5.739_507_7e-3 + p * w;
        p = -7.622_461_3e-3 + p * w;
        p = 9.438_870_5e-3 + p * w;
        p = 1.001_674_1 + p * w;
        2.832_976_8 + p * w
    };
    p * x
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(n: u32) -> impl Iterator<Item = Vec2> {
        (0..n * n).map(move |i| Vec2::new(((i % n) as f32 + 0.5) / n as f32, ((i / n) as f32 + 0.5) / n as f32))
    }

    #[test]
    fn frames_are_orthonormal() {
        for u in grid(32) {
            let n = crate::sampling::sample_cosine_hemisphere(u) * if u.x < 0.5 { 1.0 } else { -1.0 };
            let n = n.normalize();
            let f = Frame::from_normal(n);
            for (a, b) in [(f.t, f.b), (f.t, f.n), (f.b, f.n)] {
                assert!(a.dot(b).abs() < 1e-5);
            }
            assert!((f.t.length() - 1.0).abs() < 1e-5 && (f.b.length() - 1.0).abs() < 1e-5);
            let v = Vec3::new(0.3, -0.5, 0.8);
            assert!((f.to_world(f.to_local(v)) - v).length() < 1e-5);
            assert!((f.to_local(n) - Vec3::Z).length() < 1e-5);
        }
    }

    #[test]
    fn warps_land_where_they_should() {
        for u in grid(64) {
            assert!(sample_concentric_disk(u).length() <= 1.0 + 1e-6);
            let v = sample_cosine_hemisphere(u);
            assert!((v.length() - 1.0).abs() < 1e-5 && v.z >= 0.0);
            let b = sample_uniform_triangle(u);
            assert!(b.x >= 0.0 && b.y >= 0.0 && b.x + b.y <= 1.0 + 1e-6);
        }
    }

    /// Mitsuba's filters in f64: the tent, and the Gaussian windowed to zero at 4σ.
    fn filter_f64(kind: u32, radius: f64, x: f64) -> f64 {
        if kind == crate::contract::FILTER_TENT {
            (1.0 - x.abs() / radius).max(0.0)
        } else {
            let s = radius / 4.0;
            ((-x * x / (2.0 * s * s)).exp() - (-radius * radius / (2.0 * s * s)).exp()).max(0.0)
        }
    }

    /// `filter_sample` draws film coordinates with the filter's density around the pixel's centre,
    /// truncated to the film: a chi-square test over 64 bins of the support (the expected mass of
    /// each bin by Simpson's rule on the f64 filter), for a pixel inside the film and for pixels
    /// whose support the film's edges cut (the first pixel, and the last of a 3-pixel film); tent
    /// and Gaussian at Mitsuba's default and another size. The box filter is the pixel's square.
    #[test]
    fn filter_samples_follow_the_filter_truncated_to_the_film() {
        use crate::contract::{FILTER_BOX, FILTER_GAUSSIAN, FILTER_TENT};
        use crate::scene::PixelFilter;
        assert_eq!(filter_sample(FILTER_BOX, 0.5, 0.0, 7, 16, 0.25), 7.25);
        let filters = [
            PixelFilter::Gaussian { stddev: 0.5 },
            PixelFilter::Gaussian { stddev: 1.3 },
            PixelFilter::Tent { radius: 1.0 },
            PixelFilter::Tent { radius: 2.5 },
        ];
        let (n, bins) = (200_000u32, 64usize);
        for filter in filters {
            let (kind, radius, alpha) = filter.constants();
            assert!(kind == FILTER_GAUSSIAN || kind == FILTER_TENT);
            for (pixel, extent) in [(20u32, 40u32), (0, 40), (2, 3)] {
                let c = f64::from(pixel) + 0.5;
                let (a, b) = ((-f64::from(radius)).max(-c), f64::from(radius).min(f64::from(extent) - c));
                let width = (b - a) / bins as f64;
                let mass = |lo: f64| {
                    let f = |x: f64| filter_f64(kind, f64::from(radius), x);
                    width / 6.0 * (f(lo) + 4.0 * f(lo + 0.5 * width) + f(lo + width))
                };
                let masses: Vec<f64> = (0..bins).map(|i| mass(a + i as f64 * width)).collect();
                let total: f64 = masses.iter().sum();
                let expected: Vec<f64> = masses.iter().map(|m| m / total).collect();
                let mut observed = vec![0u64; bins];
                for i in 0..n {
                    let u = (f64::from(i) + 0.5) / f64::from(n);
                    // A scrambled sequence: the test is of the warp, not of a generator.
                    let u = (u + 0.618_033_988_75 * f64::from(i % 7919)).fract() as f32;
                    let x = f64::from(filter_sample(kind, radius, alpha, pixel, extent, u)) - c;
                    assert!(x >= a - 1e-4 && x <= b + 1e-4, "{filter:?} pixel {pixel}: offset {x} outside [{a}, {b}]");
                    observed[(((x - a) / width) as usize).min(bins - 1)] += 1;
                }
                let r = crate::stats::chi2_discrete(&observed, &expected);
                assert!(r.passed(1e-3), "{filter:?} pixel {pixel} of {extent}: p = {}{}", r.p_value, r.table);
            }
        }
    }

    #[test]
    fn erf_and_erfinv_match_f64_references() {
        // erf by its Taylor series / continued fraction in f64 is overkill: check the defining
        // identities instead — erfinv(erf(x)) = x and erf against a high-precision quadrature.
        for i in 0..=400 {
            let x = -3.0 + 6.0 * i as f64 / 400.0;
            // Simpson quadrature of 2/√π e^{-t²} on [0, x].
            let n = 2000;
            let h = x / n as f64;
            let f = |t: f64| (-t * t).exp();
            let mut s = f(0.0) + f(x);
            for k in 1..n {
                s += f(k as f64 * h) * if k % 2 == 1 { 4.0 } else { 2.0 };
            }
            let reference = s * h / 3.0 * 2.0 / std::f64::consts::PI.sqrt();
            let got = f64::from(erf_approx(x as f32));
            // A&S bound 1.5e-7 plus f32 rounding of ~12 operations near 1 (≤ 6e-8 each, mostly
            // cancelling): 5e-7.
            assert!((got - reference).abs() < 5e-7, "erf({x}) = {got}, expected {reference}");
        }
        for i in 1..1000 {
            let y = -1.0 + 2.0 * i as f32 / 1000.0;
            let x = erfinv_approx(y);
            assert!((erf_approx(x) - y).abs() < 1e-6 * (1.0 + 10.0 * x.abs()), "erf(erfinv({y})) = {}", erf_approx(x));
        }
    }
}
