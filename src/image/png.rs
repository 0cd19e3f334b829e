//! PNG files for looking at: tone-mapped radiance, signed values in a diverging map, magnitudes
//! on a log scale, all 8-bit sRGB and written atomically.

use std::path::Path;

use image::ImageEncoder;

use super::colormap::{
    SIGNED_SCALE_PERCENTILE, diverging_srgb8, linear_to_srgb8, oklab_to_linear_srgb, sequential_oklab,
};
use super::{Image, image_error, pixel_sum};
use crate::error::{Error, Result};
use crate::output::write_atomically;

impl Image {
    /// Writes a tone-mapped 8-bit sRGB PNG: each value is multiplied by `2^exposure`, clamped to
    /// [0, 1] (NaN counts as 0), encoded with the exact sRGB transfer function (IEC 61966-2-1) and
    /// rounded to the nearest byte.
    ///
    /// The write is atomic (see the [module docs](crate::image)).
    ///
    /// # Errors
    ///
    /// [`Error::InvalidArgument`] if `exposure` is not finite; [`Error::Image`] if the image has
    /// no pixels or the encoder fails; [`Error::Io`] if the file cannot be created or written.
    pub fn write_png(&self, path: impl AsRef<Path>, exposure: f32) -> Result<()> {
        let path = path.as_ref();
        if !exposure.is_finite() {
            return Err(Error::InvalidArgument {
                parameter: "exposure".into(),
                message: format!("must be finite, got {exposure}"),
            });
        }
        self.check_writable(path)?;
        let gain = f64::from(exposure).exp2();
        let bytes: Vec<u8> = self.data.iter().map(|&v| linear_to_srgb8(f64::from(v) * gain)).collect();
        write_rgb8_png(path, self.width, self.height, &bytes)
    }

    /// Writes signed values, such as a gradient, as an 8-bit PNG in a diverging blue–white–red
    /// map.
    ///
    /// Each pixel is reduced to the sum of its three channels `v` (for a gradient image, the
    /// derivative of the pixel's total radiance). `t = clamp(v / scale, -1, 1)` is then drawn on a
    /// straight line in Oklab from white (`t = 0`) to red (`t = 1`) or blue (`t = -1`). Both arms
    /// have the same lightness and chroma at `|t|`, so `v` and `-v` look equally strong and the
    /// colour changes at a perceptually even rate. NaN pixels are black, which the map never is.
    ///
    /// `scale` is the value drawn at full strength; `None` uses [`signed_scale`](Self::signed_scale).
    /// Pass one scale to several images to make them comparable. The write is atomic (see the
    /// [module docs](crate::image)).
    ///
    /// # Errors
    ///
    /// [`Error::InvalidArgument`] if `scale` is given and not finite and positive;
    /// [`Error::Image`] if the image has no pixels or the encoder fails; [`Error::Io`] if the file
    /// cannot be created or written.
    pub fn write_signed_png(&self, path: impl AsRef<Path>, scale: Option<f32>) -> Result<()> {
        let path = path.as_ref();
        let scale = match scale {
            None => self.signed_scale(),
            Some(s) if s.is_finite() && s > 0.0 => s,
            Some(s) => {
                return Err(Error::InvalidArgument {
                    parameter: "signed image scale".into(),
                    message: format!("must be finite and positive, got {s}"),
                });
            }
        };
        self.check_writable(path)?;
        let bytes: Vec<u8> = self
            .data
            .chunks_exact(3)
            .flat_map(|rgb| diverging_srgb8(f64::from(pixel_sum(rgb)) / f64::from(scale)))
            .collect();
        write_rgb8_png(path, self.width, self.height, &bytes)
    }

    /// The scale [`write_signed_png`](Self::write_signed_png) uses when given none: the 99th
    /// percentile (nearest rank) of |r + g + b| over the pixels where it is finite.
    ///
    /// Never 0: if that percentile is 0 the largest finite |r + g + b| is used, and if that is 0
    /// too (or no pixel is finite) the result is 1.
    pub fn signed_scale(&self) -> f32 {
        let mut magnitudes: Vec<f32> =
            self.data.chunks_exact(3).map(|rgb| pixel_sum(rgb).abs()).filter(|m| m.is_finite()).collect();
        if magnitudes.is_empty() {
            return 1.0;
        }
        // Nearest rank: the smallest value with at least 99 % of the values at or below it.
        let rank = (SIGNED_SCALE_PERCENTILE * magnitudes.len() as f64).ceil() as usize;
        let index = rank.clamp(1, magnitudes.len()) - 1;
        let (_, &mut percentile, _) = magnitudes.select_nth_unstable_by(index, f32::total_cmp);
        if percentile > 0.0 {
            return percentile;
        }
        let max = magnitudes.iter().copied().fold(0.0f32, f32::max);
        if max > 0.0 { max } else { 1.0 }
    }

    /// Writes non-negative values, such as a variance map, as an 8-bit PNG on a logarithmic
    /// scale: each pixel's channel mean `v` is drawn at `t = (log₁₀ v − log₁₀ max)/decades + 1`,
    /// clamped to [0, 1], on a sequential map whose Oklab lightness rises from dark violet
    /// (`t = 0`, also every `v ≤ 0`) through red and orange to pale yellow (`t = 1`). NaN pixels are
    /// magenta, which the map never is.
    ///
    /// `max` is the value drawn at full brightness; `None` uses the largest finite channel mean.
    /// Pass one `max` to several images to make them comparable. The write is atomic.
    ///
    /// # Errors
    ///
    /// [`Error::InvalidArgument`] if `max` is given and not finite and positive, or `decades` is
    /// not finite and positive; as [`write_png`](Self::write_png).
    pub fn write_log_png(&self, path: impl AsRef<Path>, max: Option<f32>, decades: f32) -> Result<()> {
        let path = path.as_ref();
        let bad = |parameter: &str, value: f32| Error::InvalidArgument {
            parameter: parameter.into(),
            message: format!("must be finite and positive, got {value}"),
        };
        if !(decades.is_finite() && decades > 0.0) {
            return Err(bad("log map decades", decades));
        }
        let max = match max {
            None => self.max_channel_mean(),
            Some(m) if m.is_finite() && m > 0.0 => m,
            Some(m) => return Err(bad("log map maximum", m)),
        };
        self.check_writable(path)?;
        let top = f64::from(max).log10();
        let bytes: Vec<u8> = self
            .data
            .chunks_exact(3)
            .flat_map(|rgb| {
                let v = f64::from(pixel_sum(rgb)) / 3.0;
                if v.is_nan() {
                    return [255, 0, 255];
                }
                let t = if v > 0.0 { ((v.log10() - top) / f64::from(decades) + 1.0).clamp(0.0, 1.0) } else { 0.0 };
                oklab_to_linear_srgb(sequential_oklab(t)).map(linear_to_srgb8)
            })
            .collect();
        write_rgb8_png(path, self.width, self.height, &bytes)
    }

    /// The largest finite channel mean (r + g + b)/3 of any pixel, or 1 if none is positive: the
    /// default maximum of [`write_log_png`](Self::write_log_png).
    pub fn max_channel_mean(&self) -> f32 {
        let max =
            self.data.chunks_exact(3).map(|rgb| pixel_sum(rgb) / 3.0).filter(|v| v.is_finite()).fold(0.0f32, f32::max);
        if max > 0.0 { max } else { 1.0 }
    }
}

/// Encodes `width` × `height` RGB bytes as a PNG at `path`, atomically.
fn write_rgb8_png(path: &Path, width: u32, height: u32, bytes: &[u8]) -> Result<()> {
    write_atomically(path, |out| {
        image::codecs::png::PngEncoder::new(out)
            .write_image(bytes, width, height, image::ExtendedColorType::Rgb8)
            .map_err(|e| match e {
                image::ImageError::IoError(source) => Error::Io { path: path.to_path_buf(), source },
                other => image_error(path, format!("writing PNG: {other}")),
            })
    })
}
