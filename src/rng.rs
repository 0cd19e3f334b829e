//! Counter-based random numbers: Philox4x32-10 keyed and laid out as ALGORITHMS.md §2 (twin of
//! `shaders/lib/rng.glsl`).
//!
//! A uniform is a pure function of (seed, pass, pixel, sample, vertex, stream, dimension): the adjoint
//! replay and the CPU reference recompute exactly what the primal GPU pass drew, with no state.

/// Philox's per-round multipliers (Salmon et al. 2011).
const PHILOX_M0: u32 = 0xD251_1F53;
const PHILOX_M1: u32 = 0xCD9E_8D57;
/// Weyl-sequence key increments (golden ratio and √3 − 1, as 32-bit fractions).
const PHILOX_W0: u32 = 0x9E37_79B9;
const PHILOX_W1: u32 = 0xBB67_AE85;

/// Philox4x32 with 10 rounds: encrypts the 128-bit `counter` under the 64-bit `key`.
///
/// ```
/// // The first Random123 known-answer vector.
/// let out = pathgrad::rng::philox4x32_10([0; 4], [0; 2]);
/// assert_eq!(out, [0x6627e8d5, 0xe169c58d, 0xbc57ac4c, 0x9b00dbd8]);
/// ```
pub fn philox4x32_10(counter: [u32; 4], key: [u32; 2]) -> [u32; 4] {
    let mut c = counter;
    let mut k = key;
    // A `while`, not `for round in 0..10`: at opt-level 1 (debug builds) rustc links core's
    // generic `Range::next` from a dependency built at opt-level 0 rather than inlining it, and
    // this loop runs for every uniform the CPU reference draws (BENCHMARKS.md, "Eleventh session").
    let mut round = 0;
    while round < 10 {
        if round > 0 {
            k[0] = k[0].wrapping_add(PHILOX_W0);
            k[1] = k[1].wrapping_add(PHILOX_W1);
        }
        let p0 = u64::from(PHILOX_M0) * u64::from(c[0]);
        let p1 = u64::from(PHILOX_M1) * u64::from(c[2]);
        let (hi0, lo0) = ((p0 >> 32) as u32, p0 as u32);
        let (hi1, lo1) = ((p1 >> 32) as u32, p1 as u32);
        c = [hi1 ^ c[1] ^ k[0], lo1, hi0 ^ c[3] ^ k[1], lo0];
        round += 1;
    }
    c
}

/// Converts 32 random bits to a float in the open interval (0, 1): the top 24 bits with the lowest
/// forced to 1, times 2⁻²⁴. Exact in f32, never 0 or 1, mean exactly ½ (ALGORITHMS.md §2.3).
#[inline]
pub fn u32_to_unit_f32(x: u32) -> f32 {
    ((x >> 8) | 1) as f32 * (1.0 / 16_777_216.0)
}

/// Which pass a key belongs to (ALGORITHMS.md §2.3, `pass_tag`).
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PassTag {
    /// The loss image (pass 1 of a gradient step) and plain renders.
    Primal = 1,
    /// The gradient passes (fused primal + replay).
    Gradient = 2,
    /// Adaptive pixel selection.
    PixelSelect = crate::contract::PASS_PIXEL_SELECT,
    /// Reference (target) renders.
    Reference = 4,
    /// Tests and tools.
    Test = 5,
}

/// Random-number streams within a vertex (ALGORITHMS.md §2.3).
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stream {
    /// Per-vertex decisions of surface vertices.
    Main = 0,
    /// Delta-tracking steps.
    DeltaTracking = crate::contract::STREAM_DELTA_TRACKING,
    /// Ratio-tracking steps of NEE.
    RatioTracking = crate::contract::STREAM_RATIO_TRACKING,
    /// Attached-derivative regularisation noise.
    Jacobian = crate::contract::STREAM_JACOBIAN,
    /// Pixel selection (adaptive sampling, ALGORITHMS.md §6).
    Pixel = crate::contract::STREAM_PIXEL,
}

/// The Philox key of one pass: `key0 = seed`, `key1 = (stream << 8) | pass_tag`. The 24-bit
/// stream separates the paths of a request's views: a view of sensor i uses stream i
/// ([`crate::integrator::View`]), so each sensor's paths are the same whichever views are
/// rendered with it, and independent of every other sensor's.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RngKey(pub [u32; 2]);

impl RngKey {
    /// The key for `seed`, `stream` (below 2²⁴) and `pass`.
    pub fn new(seed: u32, stream: u32, pass: PassTag) -> Self {
        RngKey([seed, (stream << 8) | pass as u32])
    }
}

/// Four uniforms of one block: dimensions `4*block .. 4*block+4` of (pixel, sample, vertex, stream, step).
///
/// ```
/// use pathgrad::rng::{uniform4, PassTag, RngKey, Stream};
/// let key = RngKey::new(7, 0, PassTag::Primal);
/// let u = uniform4(key, 10, 0, 1, Stream::Main, 1, 0);
/// assert!(u.iter().all(|&x| x > 0.0 && x < 1.0));
/// ```
#[inline]
pub fn uniform4(key: RngKey, pixel: u32, sample: u32, vertex: u32, stream: Stream, block: u32, step: u32) -> [f32; 4] {
    let c2 = (vertex & 0xFFFF) | ((stream as u32) << 16) | (block << 24);
    let x = philox4x32_10([pixel, sample, c2, step], key.0);
    [u32_to_unit_f32(x[0]), u32_to_unit_f32(x[1]), u32_to_unit_f32(x[2]), u32_to_unit_f32(x[3])]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The three Random123 known-answer vectors (ALGORITHMS.md §2.2).
    #[test]
    fn philox_known_answers() {
        assert_eq!(philox4x32_10([0; 4], [0; 2]), [0x6627e8d5, 0xe169c58d, 0xbc57ac4c, 0x9b00dbd8]);
        assert_eq!(philox4x32_10([u32::MAX; 4], [u32::MAX; 2]), [0x408f276d, 0x41c83b0e, 0xa20bc7c6, 0x6d5451fd]);
        assert_eq!(
            philox4x32_10([0x243f6a88, 0x85a308d3, 0x13198a2e, 0x03707344], [0xa4093822, 0x299f31d0]),
            [0xd16cfe09, 0x94fdcceb, 0x5001e420, 0x24126ea1]
        );
    }

    /// Over the whole 2²⁴ grid of top bits the conversion has min > 0, max < 1 and mean exactly ½.
    #[test]
    fn float_conversion_is_open_and_centred() {
        let mut sum = 0.0f64;
        let (mut lo, mut hi) = (1.0f32, 0.0f32);
        for top in 0u32..(1 << 24) {
            let u = u32_to_unit_f32(top << 8);
            sum += f64::from(u);
            lo = lo.min(u);
            hi = hi.max(u);
        }
        assert!(lo > 0.0 && hi < 1.0, "range [{lo}, {hi}]");
        assert_eq!(sum / f64::from(1u32 << 24), 0.5);
    }

    /// Uniformity (chi-square over 64 bins) and neighbour correlation along each counter field.
    #[test]
    fn uniform_and_uncorrelated_along_every_field() {
        let key = RngKey::new(1234, 0, PassTag::Test);
        let n = 1 << 16;
        type Draw = fn(RngKey, u32) -> f32;
        let fields: [(&str, Draw); 4] = [
            ("pixel", |k, i| uniform4(k, i, 0, 1, Stream::Main, 0, 0)[0]),
            ("sample", |k, i| uniform4(k, 3, i, 1, Stream::Main, 0, 0)[0]),
            ("vertex", |k, i| uniform4(k, 3, 5, i & 0xFFFF, Stream::Main, (i >> 16) & 0xFF, 0)[1]),
            ("step", |k, i| uniform4(k, 3, 5, 2, Stream::DeltaTracking, 0, i)[2]),
        ];
        for (name, draw) in fields {
            let xs: Vec<f64> = (0..n).map(|i| f64::from(draw(key, i))).collect();
            let mut bins = [0u32; 64];
            for &x in &xs {
                bins[(x * 64.0) as usize] += 1;
            }
            let expected = f64::from(n) / 64.0;
            let chi2: f64 = bins.iter().map(|&b| (f64::from(b) - expected).powi(2) / expected).sum();
            // 63 degrees of freedom: the 0.9999 quantile is about 116.
            assert!(chi2 < 116.0, "{name}: chi2 = {chi2}");
            let mean = xs.iter().sum::<f64>() / f64::from(n);
            let cov = xs.windows(2).map(|w| (w[0] - mean) * (w[1] - mean)).sum::<f64>() / f64::from(n - 1);
            let corr = cov / (1.0 / 12.0);
            // The lag-1 sample correlation of independent uniforms has standard deviation 1/√n.
            assert!(corr.abs() < 4.0 / f64::from(n).sqrt(), "{name}: lag-1 correlation {corr}");
        }
    }
}
