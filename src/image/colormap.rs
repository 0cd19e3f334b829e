//! Colour: the sRGB transfer curve and the Oklab-based diverging (signed) and sequential
//! (magnitude) false-colour maps.

/// Below this linear value the sRGB transfer function is linear (IEC 61966-2-1).
pub(super) const SRGB_LINEAR_THRESHOLD: f64 = 0.003_130_8;
/// Slope of the linear segment of the sRGB transfer function.
pub(super) const SRGB_LINEAR_SLOPE: f64 = 12.92;
/// Scale `a + 1` of the power segment of the sRGB transfer function.
pub(super) const SRGB_SCALE: f64 = 1.055;
/// Offset `a` of the power segment of the sRGB transfer function.
pub(super) const SRGB_OFFSET: f64 = 0.055;
/// Exponent `γ` of the power segment (applied as `1/γ`).
pub(super) const SRGB_GAMMA: f64 = 2.4;

/// The automatic scale of [`Image::write_signed_png`] is this percentile of |value|: robust to a
/// few fireflies, which would otherwise wash the rest of the map out to white.
pub(super) const SIGNED_SCALE_PERCENTILE: f64 = 0.99;

/// Oklab lightness of both ends of the diverging map. Both arms share it and the chroma below, so
/// `v` and `-v` always have the same lightness and saturation; 0.5 is dark enough to read against
/// the white centre and keeps both hues inside the sRGB gamut along the whole ramp.
pub(super) const DIVERGING_END_LIGHTNESS: f64 = 0.5;
/// Oklab chroma of both ends of the diverging map.
pub(super) const DIVERGING_END_CHROMA: f64 = 0.16;
/// Oklab hue (degrees) of the positive end: a brick red.
pub(super) const DIVERGING_POSITIVE_HUE_DEG: f64 = 27.0;
/// Oklab hue (degrees) of the negative end: a medium blue.
pub(super) const DIVERGING_NEGATIVE_HUE_DEG: f64 = 260.0;

/// Oklab lightness of the dark and the light end of the sequential map of
/// [`Image::write_log_png`]: lightness rises monotonically, so order reads without the colours.
pub(super) const SEQUENTIAL_LIGHTNESS: (f64, f64) = (0.18, 0.96);
/// Oklab chroma of the sequential map at its middle (it falls to a third of this at both ends,
/// which keeps the ramp inside the sRGB gamut).
pub(super) const SEQUENTIAL_CHROMA: f64 = 0.13;
/// Oklab hue (degrees) of the sequential map's dark and light ends: violet through red and orange
/// to yellow.
pub(super) const SEQUENTIAL_HUE_DEG: (f64, f64) = (300.0, 450.0);

/// The sRGB transfer function (IEC 61966-2-1), linear [0, 1] → encoded [0, 1].
pub(super) fn srgb_oetf(linear: f64) -> f64 {
    if linear <= SRGB_LINEAR_THRESHOLD {
        SRGB_LINEAR_SLOPE * linear
    } else {
        SRGB_SCALE * linear.powf(1.0 / SRGB_GAMMA) - SRGB_OFFSET
    }
}

/// Clamps a linear value to [0, 1] (NaN → 0), sRGB-encodes it and rounds it to a byte.
pub(super) fn linear_to_srgb8(linear: f64) -> u8 {
    // `!(x > 0)` also catches NaN.
    let clamped = if linear > 0.0 { linear.min(1.0) } else { 0.0 };
    (srgb_oetf(clamped) * 255.0).round() as u8
}

/// Oklab `[L, a, b]` of the diverging map at `t` ∈ [-1, 1]: the straight line from white to the
/// red end (`t > 0`) or the blue end (`t < 0`).
pub(super) fn diverging_oklab(t: f64) -> [f64; 3] {
    let hue_deg = if t >= 0.0 { DIVERGING_POSITIVE_HUE_DEG } else { DIVERGING_NEGATIVE_HUE_DEG };
    let s = t.abs().min(1.0);
    let chroma = s * DIVERGING_END_CHROMA;
    let hue = hue_deg.to_radians();
    [1.0 - s * (1.0 - DIVERGING_END_LIGHTNESS), chroma * hue.cos(), chroma * hue.sin()]
}

/// Oklab `[L, a, b]` of the sequential map at `t` ∈ [0, 1]: lightness linear in `t`, hue turning
/// from violet to yellow, chroma largest in the middle.
pub(super) fn sequential_oklab(t: f64) -> [f64; 3] {
    let t = t.clamp(0.0, 1.0);
    let (l0, l1) = SEQUENTIAL_LIGHTNESS;
    let (h0, h1) = SEQUENTIAL_HUE_DEG;
    let chroma = SEQUENTIAL_CHROMA * (1.0 - 2.0 / 3.0 * (2.0 * t - 1.0).powi(2));
    let hue = (h0 + t * (h1 - h0)).to_radians();
    [l0 + t * (l1 - l0), chroma * hue.cos(), chroma * hue.sin()]
}

/// Oklab → linear sRGB (Björn Ottosson's published matrices, "A perceptual color space for image
/// processing", 2020). Not clamped.
pub(super) fn oklab_to_linear_srgb([l, a, b]: [f64; 3]) -> [f64; 3] {
    let l_ = l + 0.396_337_777_4 * a + 0.215_803_757_3 * b;
    let m_ = l - 0.105_561_345_8 * a - 0.063_854_172_8 * b;
    let s_ = l - 0.089_484_177_5 * a - 1.291_485_548_0 * b;
    let (l3, m3, s3) = (l_ * l_ * l_, m_ * m_ * m_, s_ * s_ * s_);
    [
        4.076_741_662_1 * l3 - 3.307_711_591_3 * m3 + 0.230_969_929_2 * s3,
        -1.268_438_004_6 * l3 + 2.609_757_401_1 * m3 - 0.341_319_396_5 * s3,
        -0.004_196_086_3 * l3 - 0.703_418_614_7 * m3 + 1.707_614_701_0 * s3,
    ]
}

/// sRGB bytes of the diverging map at `t` (clamped to [-1, 1]); NaN is black.
pub(super) fn diverging_srgb8(t: f64) -> [u8; 3] {
    if t.is_nan() {
        return [0; 3];
    }
    oklab_to_linear_srgb(diverging_oklab(t.clamp(-1.0, 1.0))).map(linear_to_srgb8)
}
