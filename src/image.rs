//! `Image`: RGB f32 images, EXR and PNG output, tone mapping and signed false-colour maps.
//!
//! An [`Image`] holds linear RGB radiance (or a gradient) as `f32`, row-major, top row first, three
//! floats per pixel. It is plain data: renderers fill it, losses read it, and this module moves it
//! to and from files.
//!
//! - **EXR** (through the `exr` crate) is the lossless format: [`Image::write_exr`] stores one part
//!   with channels `R`, `G`, `B` as 32-bit floats, ZIP-compressed scan lines, so a round trip is
//!   bit-exact (negative values and NaNs included). [`Image::write_layers_exr`] puts several images
//!   into one part under dotted channel names (`color.R`, `grad.roughness.G`, …), which compositors
//!   show as layers. [`Image::read_exr`] reads the `R`, `G`, `B` channels of the first part.
//! - **PNG** (through the `image` crate) is for looking at: [`Image::write_png`] tone-maps with an
//!   exposure and the sRGB curve; [`Image::write_signed_png`] shows signed values such as gradients
//!   in a blue–white–red map.
//!
//! Every writer is atomic and follows [`crate::output`]'s rules: a hidden temporary file in the
//! destination directory is renamed over the destination only once it is complete, so a failed or
//! interrupted write never leaves a partial output (and never clobbers a previous good one);
//! symbolic links are followed and read-only files refused. Errors name the destination path.

use std::fmt;
use std::path::Path;

use exr::image::{AnyChannel, AnyChannels, Blocks, Encoding, FlatSamples, Layer};
use exr::meta::attribute::{LineOrder, Text};
use exr::meta::header::LayerAttributes;
use exr::prelude::{Compression, SmallVec, WritableImage};
use image::ImageEncoder;

use crate::error::{Error, Result};
use crate::output::write_atomically;

/// Names of the colour channels, in storage order.
const RGB_NAMES: [&str; 3] = ["R", "G", "B"];

/// Lossless EXR encoding: ZIP over 16-line blocks, scan lines top to bottom. ZIP is lossless for
/// f32 (bit-exact round trips) and compresses rendered images well; scan lines are readable by
/// every OpenEXR reader.
const EXR_ENCODING: Encoding =
    Encoding { compression: Compression::ZIP16, blocks: Blocks::ScanLines, line_order: LineOrder::Increasing };

/// Below this linear value the sRGB transfer function is linear (IEC 61966-2-1).
const SRGB_LINEAR_THRESHOLD: f64 = 0.003_130_8;
/// Slope of the linear segment of the sRGB transfer function.
const SRGB_LINEAR_SLOPE: f64 = 12.92;
/// Scale `a + 1` of the power segment of the sRGB transfer function.
const SRGB_SCALE: f64 = 1.055;
/// Offset `a` of the power segment of the sRGB transfer function.
const SRGB_OFFSET: f64 = 0.055;
/// Exponent `γ` of the power segment (applied as `1/γ`).
const SRGB_GAMMA: f64 = 2.4;

/// The automatic scale of [`Image::write_signed_png`] is this percentile of |value|: robust to a
/// few fireflies, which would otherwise wash the rest of the map out to white.
const SIGNED_SCALE_PERCENTILE: f64 = 0.99;

/// Oklab lightness of both ends of the diverging map. Both arms share it and the chroma below, so
/// `v` and `-v` always have the same lightness and saturation; 0.5 is dark enough to read against
/// the white centre and keeps both hues inside the sRGB gamut along the whole ramp.
const DIVERGING_END_LIGHTNESS: f64 = 0.5;
/// Oklab chroma of both ends of the diverging map.
const DIVERGING_END_CHROMA: f64 = 0.16;
/// Oklab hue (degrees) of the positive end: a brick red.
const DIVERGING_POSITIVE_HUE_DEG: f64 = 27.0;
/// Oklab hue (degrees) of the negative end: a medium blue.
const DIVERGING_NEGATIVE_HUE_DEG: f64 = 260.0;

/// Oklab lightness of the dark and the light end of the sequential map of
/// [`Image::write_log_png`]: lightness rises monotonically, so order reads without the colours.
const SEQUENTIAL_LIGHTNESS: (f64, f64) = (0.18, 0.96);
/// Oklab chroma of the sequential map at its middle (it falls to a third of this at both ends,
/// which keeps the ramp inside the sRGB gamut).
const SEQUENTIAL_CHROMA: f64 = 0.13;
/// Oklab hue (degrees) of the sequential map's dark and light ends: violet through red and orange
/// to yellow.
const SEQUENTIAL_HUE_DEG: (f64, f64) = (300.0, 450.0);

/// What [`Image::non_finite`] found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NonFinite {
    /// How many values are NaN or infinite.
    pub count: usize,
    /// Column of the first.
    pub x: u32,
    /// Row of the first.
    pub y: u32,
    /// Channel of the first: `R`, `G` or `B`.
    pub channel: &'static str,
    /// The first such value.
    pub value: f32,
}

/// A linear RGB image of `f32` values: row-major, top row first, three floats per pixel.
///
/// Pixel `(x, y)` is stored at `data[3 * (y * width + x)..][..3]`, `x` to the right and `y`
/// downwards, the same order as EXR scan lines and PNG rows.
///
/// # Example
///
/// ```
/// use pathgrad::image::Image;
///
/// let mut image = Image::new(4, 2);
/// image.set_pixel(1, 0, [0.25, -0.5, 8.0]);
/// assert_eq!(image.pixel(1, 0), [0.25, -0.5, 8.0]);
/// assert_eq!(image.mean(), [0.25 / 8.0, -0.5 / 8.0, 1.0]);
///
/// let dir = std::env::temp_dir().join(format!("pathgrad-doc-image-{}", std::process::id()));
/// std::fs::create_dir_all(&dir)?;
/// image.save(dir.join("radiance.exr"))?;
/// assert_eq!(Image::read_exr(dir.join("radiance.exr"))?, image);
/// image.write_png(dir.join("radiance.png"), 0.0)?;
/// # std::fs::remove_dir_all(&dir)?;
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Clone, PartialEq)]
pub struct Image {
    width: u32,
    height: u32,
    data: Vec<f32>,
}

impl fmt::Debug for Image {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        // The pixel data can be megabytes; the size and mean say what a log or assert needs.
        f.debug_struct("Image")
            .field("width", &self.width)
            .field("height", &self.height)
            .field("mean", &self.mean())
            .finish_non_exhaustive()
    }
}

impl Image {
    /// A `width` × `height` image with every value 0.
    ///
    /// # Panics
    ///
    /// If `3 * width * height` does not fit in `usize` (or the allocation fails).
    pub fn new(width: u32, height: u32) -> Image {
        let len = float_count(width, height).expect("image size 3·width·height must fit in usize");
        Image { width, height, data: vec![0.0; len] }
    }

    /// Wraps `data` (row-major, top row first, `[r, g, b]` per pixel) as a `width` × `height`
    /// image.
    ///
    /// # Errors
    ///
    /// [`Error::InvalidArgument`] naming both sizes if `data.len() != 3 * width * height`.
    pub fn from_rgb(width: u32, height: u32, data: Vec<f32>) -> Result<Image> {
        match float_count(width, height) {
            Some(expected) if expected == data.len() => Ok(Image { width, height, data }),
            expected => Err(Error::InvalidArgument {
                parameter: "image data".into(),
                message: format!(
                    "a {width}×{height} RGB image needs {} floats, got {}",
                    expected.map_or_else(|| "more than usize::MAX".to_string(), |n| n.to_string()),
                    data.len()
                ),
            }),
        }
    }

    /// Width in pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// The `[r, g, b]` value of pixel `(x, y)`, `x` to the right and `y` downwards from the top
    /// left.
    ///
    /// # Panics
    ///
    /// If `x >= width` or `y >= height`.
    pub fn pixel(&self, x: u32, y: u32) -> [f32; 3] {
        let i = self.index(x, y);
        [self.data[i], self.data[i + 1], self.data[i + 2]]
    }

    /// Sets pixel `(x, y)` to `rgb`.
    ///
    /// # Panics
    ///
    /// If `x >= width` or `y >= height`.
    pub fn set_pixel(&mut self, x: u32, y: u32, rgb: [f32; 3]) {
        let i = self.index(x, y);
        self.data[i..i + 3].copy_from_slice(&rgb);
    }

    /// All values, row-major, top row first, `[r, g, b]` per pixel.
    pub fn as_slice(&self) -> &[f32] {
        &self.data
    }

    /// All values, mutable, in the layout of [`as_slice`](Self::as_slice).
    pub fn as_mut_slice(&mut self) -> &mut [f32] {
        &mut self.data
    }

    /// The NaN and infinite values: how many there are, and the first in storage order as
    /// `(x, y, channel name, value)`; `None` if every value is finite. Renders and loss targets
    /// are refused with this.
    ///
    /// ```
    /// use pathgrad::image::Image;
    ///
    /// let mut image = Image::new(3, 2);
    /// image.set_pixel(2, 1, [0.0, f32::INFINITY, f32::NAN]);
    /// let bad = image.non_finite().unwrap();
    /// assert_eq!((bad.count, bad.x, bad.y, bad.channel), (2, 2, 1, "G"));
    /// ```
    pub fn non_finite(&self) -> Option<NonFinite> {
        let mut bad = self.data.iter().enumerate().filter(|(_, v)| !v.is_finite());
        let (i, &value) = bad.next()?;
        let pixel = i / 3;
        let width = self.width as usize;
        Some(NonFinite {
            count: 1 + bad.count(),
            x: (pixel % width) as u32,
            y: (pixel / width) as u32,
            channel: RGB_NAMES[i % 3],
            value,
        })
    }

    /// The per-channel mean over all pixels, accumulated in `f64`.
    ///
    /// Returns `[0.0; 3]` for an image without pixels. A NaN or infinite value makes its channel's
    /// mean NaN or infinite, which is what a test of "the image is finite" wants to see.
    pub fn mean(&self) -> [f64; 3] {
        let pixels = self.data.len() / 3;
        if pixels == 0 {
            return [0.0; 3];
        }
        let mut sum = [0.0f64; 3];
        for rgb in self.data.chunks_exact(3) {
            for (s, &v) in sum.iter_mut().zip(rgb) {
                *s += f64::from(v);
            }
        }
        sum.map(|s| s / pixels as f64)
    }

    /// Writes the image to `path`, choosing the format by extension (case-insensitive): `.exr`
    /// as [`write_exr`](Self::write_exr), `.png` as [`write_png`](Self::write_png) with exposure 0.
    ///
    /// # Errors
    ///
    /// [`Error::Image`] if the extension is neither `exr` nor `png`; otherwise those of the writer.
    pub fn save(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        let extension = path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase());
        match extension.as_deref() {
            Some("exr") => self.write_exr(path),
            Some("png") => self.write_png(path, 0.0),
            Some(other) => {
                Err(image_error(path, format!("unsupported image extension '.{other}': expected .exr or .png")))
            }
            None => Err(image_error(path, "no file extension to choose the format by: expected .exr or .png")),
        }
    }

    /// Writes the image losslessly as a single-part OpenEXR file with 32-bit float channels `R`,
    /// `G`, `B`.
    ///
    /// The write is atomic (see the [module docs](self)).
    ///
    /// # Errors
    ///
    /// [`Error::Io`] if the file cannot be created or written (for example, its directory does not
    /// exist); [`Error::Image`] if the image has no pixels or the encoder fails. Both name `path`.
    pub fn write_exr(&self, path: impl AsRef<Path>) -> Result<()> {
        Image::write_layers_exr(path, &[("", self)])
    }

    /// Writes several images of the same size into one OpenEXR part, as 32-bit float channels
    /// `name.R`, `name.G`, `name.B` for each `(name, image)` (an empty name gives plain `R`, `G`,
    /// `B`, the layer compositors show by default).
    ///
    /// Gradient outputs use this: one file holding, say, `color` and `grad.roughness`. OpenEXR
    /// stores channels sorted by name, so the order of `layers` is not kept. The write is atomic
    /// (see the [module docs](self)).
    ///
    /// # Errors
    ///
    /// [`Error::Image`] naming `path` if `layers` is empty, two layers share a name, a name is not
    /// Latin-1 (OpenEXR text), the images differ in size or have no pixels, or the encoder fails;
    /// [`Error::Io`] if the file cannot be created or written.
    pub fn write_layers_exr(path: impl AsRef<Path>, layers: &[(&str, &Image)]) -> Result<()> {
        let path = path.as_ref();
        let Some(&(first_name, first)) = layers.first() else {
            return Err(image_error(path, "no layers to write"));
        };
        first.check_writable(path)?;

        let mut channels: SmallVec<[AnyChannel<FlatSamples>; 4]> = SmallVec::new();
        let mut names: Vec<&str> = Vec::with_capacity(layers.len());
        for &(name, image) in layers {
            if names.contains(&name) {
                return Err(image_error(path, format!("two layers are named '{name}'")));
            }
            names.push(name);
            if (image.width, image.height) != (first.width, first.height) {
                return Err(image_error(
                    path,
                    format!(
                        "layer '{name}' is {}×{} but layer '{first_name}' is {}×{}; all layers of \
                         one file must have the same size",
                        image.width, image.height, first.width, first.height
                    ),
                ));
            }
            for (c, suffix) in RGB_NAMES.iter().enumerate() {
                let full = if name.is_empty() { (*suffix).to_string() } else { format!("{name}.{suffix}") };
                let text = Text::new_or_none(&full).ok_or_else(|| {
                    image_error(path, format!("channel name '{full}' is not Latin-1, which OpenEXR requires"))
                })?;
                let mut channel = AnyChannel::new(text, FlatSamples::F32(image.channel(c)));
                // `new` guesses `pLinear` from the name, so `color.R` would get it and `R` would
                // not. Both hold linear-light values, which OpenEXR marks with `pLinear = 0`.
                channel.quantize_linearly = false;
                channels.push(channel);
            }
        }

        let layer = Layer::new(
            (first.width as usize, first.height as usize),
            LayerAttributes::default(),
            EXR_ENCODING,
            AnyChannels::sort(channels),
        );
        let exr_image = exr::image::Image::from_layer(layer);
        write_atomically(path, |out| {
            exr_image.write().to_buffered(out).map_err(|e| exr_error(path, Direction::Write, e))
        })
    }

    /// Reads the `R`, `G`, `B` channels of the first part of an OpenEXR file (RGB or RGBA; 16- or
    /// 32-bit float; any other channels are ignored).
    ///
    /// The image is the part's data window; its offset is not kept.
    ///
    /// # Errors
    ///
    /// [`Error::Io`] if the file cannot be opened or read; [`Error::Image`] naming the file if it
    /// is not a valid OpenEXR file, lacks one of `R`, `G`, `B` (the message lists the channels it
    /// has), stores them as integers, or subsamples them.
    pub fn read_exr(path: impl AsRef<Path>) -> Result<Image> {
        let path = path.as_ref();
        match std::fs::metadata(path) {
            Ok(meta) if meta.is_dir() => return Err(image_error(path, "is a directory, not an OpenEXR file")),
            Ok(meta) if !meta.is_file() => {
                return Err(image_error(path, "is not a regular file (a device or pipe), not an OpenEXR file"));
            }
            Ok(meta) if meta.len() == 0 => return Err(image_error(path, "is empty (0 bytes), not an OpenEXR file")),
            _ => {}
        }
        let exr_image =
            exr::prelude::read_first_flat_layer_from_file(path).map_err(|e| exr_error(path, Direction::Read, e))?;
        let layer = exr_image.layer_data;
        let (width, height) = (layer.size.x(), layer.size.y());
        let too_big = || image_error(path, format!("{width}×{height} pixels is too large"));
        let width_u32 = u32::try_from(width).map_err(|_| too_big())?;
        let height_u32 = u32::try_from(height).map_err(|_| too_big())?;
        let len = float_count(width_u32, height_u32).ok_or_else(too_big)?;
        let pixels = len / 3;

        let channels = &layer.channel_data.list;
        let mut data = vec![0.0f32; len];
        for (c, name) in RGB_NAMES.iter().enumerate() {
            let Some(channel) = channels.iter().find(|ch| ch.name == **name) else {
                let found: Vec<String> = channels.iter().map(|ch| ch.name.to_string()).collect();
                return Err(image_error(
                    path,
                    format!(
                        "no '{name}' channel; pathgrad reads RGB or RGBA images (channels found: \
                         {})",
                        if found.is_empty() { "none".to_string() } else { found.join(", ") }
                    ),
                ));
            };
            if matches!(channel.sample_data, FlatSamples::U32(_)) {
                return Err(image_error(
                    path,
                    format!("channel '{name}' holds 32-bit integers; expected 16- or 32-bit float"),
                ));
            }
            if channel.sample_data.len() != pixels {
                return Err(image_error(
                    path,
                    format!(
                        "channel '{name}' has {} samples for {width}×{height} pixels (subsampled \
                         channels are not supported)",
                        channel.sample_data.len()
                    ),
                ));
            }
            for (dst, v) in data.iter_mut().skip(c).step_by(3).zip(channel.sample_data.values_as_f32()) {
                *dst = v;
            }
        }
        Ok(Image { width: width_u32, height: height_u32, data })
    }

    /// Writes a tone-mapped 8-bit sRGB PNG: each value is multiplied by `2^exposure`, clamped to
    /// [0, 1] (NaN counts as 0), encoded with the exact sRGB transfer function (IEC 61966-2-1) and
    /// rounded to the nearest byte.
    ///
    /// The write is atomic (see the [module docs](self)).
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
    /// [module docs](self)).
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

    /// Index of the red value of pixel `(x, y)` in `data`.
    fn index(&self, x: u32, y: u32) -> usize {
        assert!(
            x < self.width && y < self.height,
            "pixel ({x}, {y}) is outside the {}×{} image",
            self.width,
            self.height
        );
        3 * (y as usize * self.width as usize + x as usize)
    }

    /// Channel `c` (0 = red) of every pixel, in pixel order.
    fn channel(&self, c: usize) -> Vec<f32> {
        self.data.iter().skip(c).step_by(3).copied().collect()
    }

    /// Refuses to write an image without pixels (neither format can hold one).
    fn check_writable(&self, path: &Path) -> Result<()> {
        if self.width == 0 || self.height == 0 {
            return Err(image_error(
                path,
                format!("cannot write a {}×{} image: it has no pixels", self.width, self.height),
            ));
        }
        Ok(())
    }
}

/// `3 · width · height`, if it fits in `usize`.
fn float_count(width: u32, height: u32) -> Option<usize> {
    (width as usize).checked_mul(height as usize)?.checked_mul(3)
}

/// The signed quantity [`Image::write_signed_png`] draws for one pixel: `r + g + b`.
fn pixel_sum(rgb: &[f32]) -> f32 {
    rgb.iter().sum()
}

/// An [`Error::Image`] for `path`.
fn image_error(path: &Path, message: impl Into<String>) -> Error {
    Error::Image { path: path.to_path_buf(), message: message.into() }
}

/// Converts an `exr` error that happened while reading or writing `path`.
fn exr_error(path: &Path, direction: Direction, error: exr::error::Error) -> Error {
    match error {
        exr::error::Error::Io(source) => Error::Io { path: path.to_path_buf(), source },
        other => image_error(
            path,
            match direction {
                Direction::Read => format!("not a readable OpenEXR file ({other})"),
                Direction::Write => format!("encoding OpenEXR failed ({other})"),
            },
        ),
    }
}

/// Which way an `exr` error happened, for its message.
#[derive(Clone, Copy)]
enum Direction {
    Read,
    Write,
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

/// The sRGB transfer function (IEC 61966-2-1), linear [0, 1] → encoded [0, 1].
fn srgb_oetf(linear: f64) -> f64 {
    if linear <= SRGB_LINEAR_THRESHOLD {
        SRGB_LINEAR_SLOPE * linear
    } else {
        SRGB_SCALE * linear.powf(1.0 / SRGB_GAMMA) - SRGB_OFFSET
    }
}

/// Clamps a linear value to [0, 1] (NaN → 0), sRGB-encodes it and rounds it to a byte.
fn linear_to_srgb8(linear: f64) -> u8 {
    // `!(x > 0)` also catches NaN.
    let clamped = if linear > 0.0 { linear.min(1.0) } else { 0.0 };
    (srgb_oetf(clamped) * 255.0).round() as u8
}

/// Oklab `[L, a, b]` of the diverging map at `t` ∈ [-1, 1]: the straight line from white to the
/// red end (`t > 0`) or the blue end (`t < 0`).
fn diverging_oklab(t: f64) -> [f64; 3] {
    let hue_deg = if t >= 0.0 { DIVERGING_POSITIVE_HUE_DEG } else { DIVERGING_NEGATIVE_HUE_DEG };
    let s = t.abs().min(1.0);
    let chroma = s * DIVERGING_END_CHROMA;
    let hue = hue_deg.to_radians();
    [1.0 - s * (1.0 - DIVERGING_END_LIGHTNESS), chroma * hue.cos(), chroma * hue.sin()]
}

/// Oklab `[L, a, b]` of the sequential map at `t` ∈ [0, 1]: lightness linear in `t`, hue turning
/// from violet to yellow, chroma largest in the middle.
fn sequential_oklab(t: f64) -> [f64; 3] {
    let t = t.clamp(0.0, 1.0);
    let (l0, l1) = SEQUENTIAL_LIGHTNESS;
    let (h0, h1) = SEQUENTIAL_HUE_DEG;
    let chroma = SEQUENTIAL_CHROMA * (1.0 - 2.0 / 3.0 * (2.0 * t - 1.0).powi(2));
    let hue = (h0 + t * (h1 - h0)).to_radians();
    [l0 + t * (l1 - l0), chroma * hue.cos(), chroma * hue.sin()]
}

/// Oklab → linear sRGB (Björn Ottosson's published matrices, "A perceptual color space for image
/// processing", 2020). Not clamped.
fn oklab_to_linear_srgb([l, a, b]: [f64; 3]) -> [f64; 3] {
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
fn diverging_srgb8(t: f64) -> [u8; 3] {
    if t.is_nan() {
        return [0; 3];
    }
    oklab_to_linear_srgb(diverging_oklab(t.clamp(-1.0, 1.0))).map(linear_to_srgb8)
}

#[cfg(test)]
mod tests {
    use std::fs;

    use super::*;

    /// A fresh temporary directory per test.
    fn temp_dir() -> tempfile::TempDir {
        tempfile::tempdir().expect("creating a temporary directory")
    }

    /// Names of the entries of `dir`.
    fn entries(dir: &Path) -> Vec<String> {
        let mut names: Vec<String> =
            fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
        names.sort();
        names
    }

    fn read_png(path: &Path) -> image::RgbImage {
        image::open(path).unwrap().into_rgb8()
    }

    /// Linear sRGB → Oklab (Ottosson 2020), to check the map's symmetry on decoded bytes.
    fn linear_srgb_to_oklab([r, g, b]: [f64; 3]) -> [f64; 3] {
        let l = 0.412_221_470_8 * r + 0.536_332_536_3 * g + 0.051_445_992_9 * b;
        let m = 0.211_903_498_2 * r + 0.680_699_545_1 * g + 0.107_396_956_6 * b;
        let s = 0.088_302_461_9 * r + 0.281_718_837_6 * g + 0.629_978_700_5 * b;
        let (l, m, s) = (l.cbrt(), m.cbrt(), s.cbrt());
        [
            0.210_454_255_3 * l + 0.793_617_785_0 * m - 0.004_072_046_8 * s,
            1.977_998_495_1 * l - 2.428_592_205_0 * m + 0.450_593_709_9 * s,
            0.025_904_037_1 * l + 0.782_771_766_2 * m - 0.808_675_766_0 * s,
        ]
    }

    /// Inverse sRGB transfer function of a byte.
    fn srgb8_to_linear(byte: u8) -> f64 {
        let e = f64::from(byte) / 255.0;
        if e <= SRGB_LINEAR_SLOPE * SRGB_LINEAR_THRESHOLD {
            e / SRGB_LINEAR_SLOPE
        } else {
            ((e + SRGB_OFFSET) / SRGB_SCALE).powf(SRGB_GAMMA)
        }
    }

    #[test]
    fn from_rgb_checks_the_length_and_names_the_sizes() {
        let err = Image::from_rgb(4, 2, vec![0.0; 23]).unwrap_err().to_string();
        assert!(err.contains("4×2") && err.contains("24") && err.contains("23"), "{err}");
        let image = Image::from_rgb(2, 1, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]).unwrap();
        assert_eq!(image.pixel(1, 0), [4.0, 5.0, 6.0]);
        assert_eq!(image.mean(), [2.5, 3.5, 4.5]);
    }

    #[test]
    fn pixels_are_row_major_top_row_first() {
        let mut image = Image::new(3, 2);
        image.set_pixel(2, 1, [7.0, 8.0, 9.0]);
        assert_eq!(&image.as_slice()[15..18], &[7.0, 8.0, 9.0]);
        assert_eq!(Image::new(0, 5).mean(), [0.0; 3]);
    }

    #[test]
    #[should_panic(expected = "outside the 3×2 image")]
    fn pixel_out_of_bounds_panics() {
        Image::new(3, 2).pixel(0, 2);
    }

    /// Values that a lossy path would change: negatives, subnormals, huge, NaN and infinities.
    fn awkward_image() -> Image {
        let specials = [-1.5, -0.0, 0.1, 1e-42, -3.0e38, f32::INFINITY, f32::NEG_INFINITY, f32::NAN, f32::MIN_POSITIVE];
        let (width, height) = (7, 5);
        let data = (0..width * height * 3)
            .map(|i| if (i as usize) < specials.len() { specials[i as usize] } else { (i as f32 * 0.37).sin() * 10.0 })
            .collect();
        Image::from_rgb(width, height, data).unwrap()
    }

    fn bits(image: &Image) -> Vec<u32> {
        image.as_slice().iter().map(|v| v.to_bits()).collect()
    }

    #[test]
    fn exr_round_trip_is_bit_exact() {
        let dir = temp_dir();
        let path = dir.path().join("a.exr");
        let image = awkward_image();
        image.write_exr(&path).unwrap();
        let back = Image::read_exr(&path).unwrap();
        assert_eq!((back.width(), back.height()), (7, 5));
        assert_eq!(bits(&back), bits(&image));
        assert_eq!(entries(dir.path()), ["a.exr"], "no temporary file is left");
    }

    #[test]
    fn exr_reads_rgba_half_files() {
        let dir = temp_dir();
        let path = dir.path().join("half.exr");
        exr::prelude::write_rgba_file(&path, 3, 2, |x, y| {
            let v = exr::prelude::f16::from_f32(x as f32 - 0.5 * y as f32);
            (v, v, -v, exr::prelude::f16::ONE)
        })
        .unwrap();
        let image = Image::read_exr(&path).unwrap();
        assert_eq!(image.pixel(2, 1), [1.5, 1.5, -1.5]);
    }

    #[test]
    fn layered_exr_uses_dotted_names_and_read_exr_explains_missing_channels() {
        let dir = temp_dir();
        let path = dir.path().join("grad.exr");
        let color = awkward_image();
        let mut grad = Image::new(7, 5);
        grad.set_pixel(3, 4, [-1.0, 2.0, -3.0]);
        Image::write_layers_exr(&path, &[("color", &color), ("grad.roughness", &grad)]).unwrap();

        let file = exr::prelude::read_first_flat_layer_from_file(&path).unwrap();
        let names: Vec<String> = file.layer_data.channel_data.list.iter().map(|c| c.name.to_string()).collect();
        assert_eq!(
            names,
            ["color.B", "color.G", "color.R", "grad.roughness.B", "grad.roughness.G", "grad.roughness.R"]
        );
        let grad_g = file.layer_data.channel_data.list.iter().find(|c| c.name == *"grad.roughness.G").unwrap();
        assert_eq!(grad_g.sample_data.values_as_f32().nth(4 * 7 + 3), Some(2.0));

        let err = Image::read_exr(&path).unwrap_err().to_string();
        assert!(err.contains("grad.exr") && err.contains("no 'R' channel") && err.contains("color.R"), "{err}");
    }

    #[test]
    fn layered_exr_rejects_bad_layer_lists() {
        let dir = temp_dir();
        let path = dir.path().join("bad.exr");
        let a = Image::new(2, 2);
        let b = Image::new(3, 2);
        let cases: [(&[(&str, &Image)], &str); 4] = [
            (&[], "no layers"),
            (&[("x", &a), ("x", &a)], "two layers are named 'x'"),
            (&[("x", &a), ("y", &b)], "3×2"),
            (&[("grad.σ", &a)], "Latin-1"),
        ];
        for (layers, expected) in cases {
            let err = Image::write_layers_exr(&path, layers).unwrap_err().to_string();
            assert!(err.contains("bad.exr") && err.contains(expected), "{err}");
        }
        assert!(entries(dir.path()).is_empty());
    }

    #[test]
    fn png_uses_the_exact_srgb_curve() {
        let dir = temp_dir();
        let path = dir.path().join("tone.png");
        let image = Image::from_rgb(
            2,
            2,
            vec![
                0.0,
                0.5,
                1.0, // exact points of the curve
                2.0,
                -1.0,
                f32::NAN, // out of range
                0.001,
                0.25,
                f32::INFINITY, // linear segment, power segment, +inf
                0.2,
                0.2,
                0.2, // grey
            ],
        )
        .unwrap();
        image.write_png(&path, 0.0).unwrap();
        let png = read_png(&path);
        assert_eq!(png.dimensions(), (2, 2));
        assert_eq!(png.get_pixel(0, 0).0, [0, 188, 255]);
        assert_eq!(png.get_pixel(1, 0).0, [255, 0, 0], ">1 clamps, negative and NaN are 0");
        // 0.001 is on the linear segment: 12.92 · 0.001 · 255 = 3.29; 0.25 → 0.5371 · 255 = 137.0.
        assert_eq!(png.get_pixel(0, 1).0, [3, 137, 255]);
        // 0.2 → 0.4845 · 255 = 123.55.
        assert_eq!(png.get_pixel(1, 1).0, [124; 3]);

        // Exposure +1 doubles: 0.25 → 0.5 → 188.
        image.write_png(&path, 1.0).unwrap();
        assert_eq!(read_png(&path).get_pixel(0, 1).0[1], 188);
        assert!(image.write_png(&path, f32::NAN).is_err());
    }

    #[test]
    fn save_picks_the_format_by_extension() {
        let dir = temp_dir();
        let image = awkward_image();
        image.save(dir.path().join("x.EXR")).unwrap();
        assert_eq!(bits(&Image::read_exr(dir.path().join("x.EXR")).unwrap()), bits(&image));
        image.save(dir.path().join("x.Png")).unwrap();
        assert_eq!(read_png(&dir.path().join("x.Png")).dimensions(), (7, 5));
        for bad in ["x.jpg", "x"] {
            let err = image.save(dir.path().join(bad)).unwrap_err().to_string();
            assert!(err.contains(bad) && err.contains(".exr or .png"), "{err}");
        }
        assert_eq!(entries(dir.path()), ["x.EXR", "x.Png"]);
    }

    #[test]
    fn diverging_map_stays_in_gamut() {
        for i in -1000..=1000 {
            let rgb = oklab_to_linear_srgb(diverging_oklab(f64::from(i) / 1000.0));
            assert!(rgb.iter().all(|&c| (-1e-6..=1.0 + 1e-6).contains(&c)), "t = {}: {rgb:?}", f64::from(i) / 1000.0);
        }
    }

    #[test]
    fn signed_png_is_symmetric_and_white_at_zero() {
        let dir = temp_dir();
        let path = dir.path().join("grad.png");
        // Pixel sums: 0, ±0.25, ±0.5, ±1, ±4 (clamped), NaN.
        let sums = [0.0, 0.25, -0.25, 0.5, -0.5, 1.0, -1.0, 4.0, -4.0, f32::NAN];
        let data = sums.iter().flat_map(|&s| [s, 0.5 * s, -0.5 * s]).collect();
        let image = Image::from_rgb(sums.len() as u32, 1, data).unwrap();
        image.write_signed_png(&path, Some(1.0)).unwrap();
        let png = read_png(&path);
        let px = |i: u32| png.get_pixel(i, 0).0;

        assert!(px(0).iter().all(|&c| c >= 250), "0 is white: {:?}", px(0));
        assert_eq!(px(9), [0, 0, 0], "NaN is black");
        assert_eq!(px(7), px(5), "beyond the scale clamps");
        assert_eq!(px(8), px(6));
        for pair in [(1, 2), (3, 4), (5, 6)] {
            let (pos, neg) = (px(pair.0), px(pair.1));
            assert!(pos[0] > pos[2] && neg[2] > neg[0], "red for +, blue for -: {pos:?} {neg:?}");
            let lab_pos = linear_srgb_to_oklab(pos.map(srgb8_to_linear));
            let lab_neg = linear_srgb_to_oklab(neg.map(srgb8_to_linear));
            let chroma = |lab: [f64; 3]| lab[1].hypot(lab[2]);
            // One 8-bit step moves Oklab L and chroma by at most ~0.01.
            assert!((lab_pos[0] - lab_neg[0]).abs() < 0.01, "{lab_pos:?} {lab_neg:?}");
            assert!((chroma(lab_pos) - chroma(lab_neg)).abs() < 0.01, "{lab_pos:?} {lab_neg:?}");
        }
        // Stronger values are darker on both arms.
        let lightness = |i| linear_srgb_to_oklab(px(i).map(srgb8_to_linear))[0];
        assert!(lightness(0) > lightness(1) && lightness(1) > lightness(3));
        assert!(lightness(3) > lightness(5));

        assert!(image.write_signed_png(&path, Some(0.0)).is_err());
        assert!(image.write_signed_png(&path, Some(f32::INFINITY)).is_err());
    }

    #[test]
    fn log_png_is_monotone_in_lightness_and_marks_nan() {
        // 1e-6 … 1 over six decades, one pixel each, plus zero, a negative value and NaN.
        let mut values: Vec<f32> = (0..=6).map(|k| 10f32.powi(k - 6)).collect();
        values.extend([0.0, -1.0, f32::NAN]);
        let image = Image::from_rgb(values.len() as u32, 1, values.iter().flat_map(|&v| [v; 3]).collect()).unwrap();
        let dir = temp_dir();
        let path = dir.path().join("log.png");
        image.write_log_png(&path, None, 6.0).unwrap();
        let png = read_png(&path);
        let lightness: Vec<f64> =
            (0..7).map(|x| linear_srgb_to_oklab(png.get_pixel(x, 0).0.map(srgb8_to_linear))[0]).collect();
        assert!(lightness.windows(2).all(|w| w[1] > w[0] + 0.05), "lightness must rise per decade: {lightness:?}");
        assert_eq!(png.get_pixel(7, 0), png.get_pixel(0, 0), "zero is drawn as the bottom of the scale");
        assert_eq!(png.get_pixel(8, 0), png.get_pixel(0, 0), "a negative value is drawn as the bottom");
        assert_eq!(png.get_pixel(9, 0).0, [255, 0, 255], "NaN is magenta");
        for t in (0..=100).map(|i| f64::from(i) / 100.0) {
            let rgb = oklab_to_linear_srgb(sequential_oklab(t));
            assert!(rgb.iter().all(|&c| (-1e-3..=1.0 + 1e-3).contains(&c)), "t = {t}: {rgb:?} is out of gamut");
        }
        assert!(image.write_log_png(&path, Some(0.0), 6.0).is_err());
        assert!(image.write_log_png(&path, None, f32::NAN).is_err());
    }

    #[test]
    fn signed_scale_is_a_robust_percentile_and_never_zero() {
        // 200 pixels with sums 1..=200: the 99th percentile by nearest rank is 198.
        let data = (1..=200).flat_map(|i| [i as f32, 0.0, 0.0]).collect();
        assert_eq!(Image::from_rgb(200, 1, data).unwrap().signed_scale(), 198.0);
        // One firefly among zeros: the percentile is 0, so the maximum is used.
        let mut sparse = Image::new(1000, 1);
        sparse.set_pixel(3, 0, [0.0, -5.0, 0.0]);
        assert_eq!(sparse.signed_scale(), 5.0);
        assert_eq!(Image::new(4, 4).signed_scale(), 1.0);
        let nan = Image::from_rgb(1, 1, vec![f32::NAN; 3]).unwrap();
        assert_eq!(nan.signed_scale(), 1.0);
        // With no scale given, the automatic one is used and the write succeeds.
        let dir = temp_dir();
        Image::new(4, 4).write_signed_png(dir.path().join("zero.png"), None).unwrap();
    }

    #[test]
    fn writes_are_atomic_and_errors_name_the_path() {
        let dir = temp_dir();
        let image = awkward_image();
        let missing = dir.path().join("no such dir");
        for name in ["a.exr", "a.png"] {
            let path = missing.join(name);
            let err = image.save(&path).unwrap_err();
            assert!(matches!(err, Error::Output { .. }) && err.to_string().contains("does not exist"), "{err:?}");
            assert!(err.to_string().contains(&*path.to_string_lossy()), "{err}");
        }
        let signed = image.write_signed_png(missing.join("s.png"), None).unwrap_err();
        assert!(signed.to_string().contains("no such dir"), "{signed}");
        assert!(!missing.exists());
        assert!(entries(dir.path()).is_empty(), "nothing is left behind");

        // A destination that is a directory is refused before anything is written.
        let target = dir.path().join("taken.exr");
        fs::create_dir(&target).unwrap();
        let err = image.write_exr(&target).unwrap_err().to_string();
        assert!(err.contains("taken.exr: is a directory"), "{err}");
        assert_eq!(entries(dir.path()), ["taken.exr"], "the temporary file is removed");
        assert!(target.is_dir());

        // An empty image cannot be written, and says so.
        let err = Image::new(0, 3).write_png(dir.path().join("e.png"), 0.0).unwrap_err();
        assert!(err.to_string().contains("0×3"), "{err}");
    }

    #[test]
    fn reading_a_non_exr_file_names_it() {
        let dir = temp_dir();
        let path = dir.path().join("not-really.exr");
        Image::new(2, 2).write_png(path.with_extension("png"), 0.0).unwrap();
        fs::rename(path.with_extension("png"), &path).unwrap();
        let err = Image::read_exr(&path).unwrap_err();
        assert!(matches!(err, Error::Image { .. }), "{err:?}");
        let message = err.to_string();
        assert!(message.contains("not-really.exr") && message.contains("not a readable OpenEXR file"), "{message}");

        let missing = dir.path().join("missing.exr");
        let err = Image::read_exr(&missing).unwrap_err();
        assert!(matches!(err, Error::Io { .. }), "{err:?}");
        assert!(err.to_string().contains("missing.exr"), "{err}");
    }
}
