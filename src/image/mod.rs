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

mod colormap;
mod exr;
mod png;
#[cfg(test)]
mod tests;

use std::fmt;
use std::path::Path;

use crate::error::{Error, Result};
use exr::RGB_NAMES;

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

    /// `images` (one width) one below another, the first at the top: the layout in which a
    /// multi-view request holds its views' pixels.
    ///
    /// ```
    /// use pathgrad::image::Image;
    /// let a = Image::from_rgb(1, 1, vec![1.0, 2.0, 3.0])?;
    /// let b = Image::from_rgb(1, 1, vec![4.0, 5.0, 6.0])?;
    /// let both = Image::stack(&[a.clone(), b])?;
    /// assert_eq!((both.width(), both.height()), (1, 2));
    /// assert_eq!(both.split(2)?[0], a);
    /// # Ok::<(), pathgrad::Error>(())
    /// ```
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for no images, different widths or a stack too tall.
    pub fn stack(images: &[Image]) -> Result<Image> {
        let Some(first) = images.first() else {
            return Err(Error::InvalidArgument { parameter: "images".into(), message: "nothing to stack".into() });
        };
        if let Some(other) = images.iter().find(|i| i.width != first.width) {
            return Err(Error::InvalidArgument {
                parameter: "images".into(),
                message: format!("widths differ ({} and {})", first.width, other.width),
            });
        }
        let height = images.iter().try_fold(0u32, |h, i| h.checked_add(i.height)).ok_or_else(|| {
            Error::InvalidArgument { parameter: "images".into(), message: "the stack is too tall".into() }
        })?;
        Image::from_rgb(first.width, height, images.iter().flat_map(|i| i.data.iter().copied()).collect())
    }

    /// The image cut into `count` images of equal height, top first (the inverse of
    /// [`Image::stack`]).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] if the height is not a multiple of `count`.
    pub fn split(&self, count: u32) -> Result<Vec<Image>> {
        if count == 0 || !self.height.is_multiple_of(count) {
            return Err(Error::InvalidArgument {
                parameter: "count".into(),
                message: format!("{count} does not divide the height {}", self.height),
            });
        }
        let height = self.height / count;
        let chunk = (self.width * height * 3) as usize;
        self.data
            .chunks(chunk.max(1))
            .take(count as usize)
            .map(|c| Image::from_rgb(self.width, height, c.to_vec()))
            .collect()
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

    /// The values, in the layout of [`as_slice`](Self::as_slice), without a copy.
    ///
    /// ```
    /// let image = pathgrad::image::Image::from_rgb(1, 1, vec![0.5, 1.0, 2.0])?;
    /// assert_eq!(image.into_rgb(), [0.5, 1.0, 2.0]);
    /// # Ok::<(), pathgrad::Error>(())
    /// ```
    pub fn into_rgb(self) -> Vec<f32> {
        self.data
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

    /// Index of the red value of pixel `(x, y)` in `data`.
    pub(crate) fn index(&self, x: u32, y: u32) -> usize {
        assert!(
            x < self.width && y < self.height,
            "pixel ({x}, {y}) is outside the {}×{} image",
            self.width,
            self.height
        );
        3 * (y as usize * self.width as usize + x as usize)
    }

    /// Channel `c` (0 = red) of every pixel, in pixel order.
    pub(crate) fn channel(&self, c: usize) -> Vec<f32> {
        self.data.iter().skip(c).step_by(3).copied().collect()
    }

    /// Refuses to write an image without pixels (neither format can hold one).
    pub(crate) fn check_writable(&self, path: &Path) -> Result<()> {
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
pub(crate) fn float_count(width: u32, height: u32) -> Option<usize> {
    (width as usize).checked_mul(height as usize)?.checked_mul(3)
}

/// The signed quantity [`Image::write_signed_png`] draws for one pixel: `r + g + b`.
pub(crate) fn pixel_sum(rgb: &[f32]) -> f32 {
    rgb.iter().sum()
}

/// An [`Error::Image`] for `path`.
pub(crate) fn image_error(path: &Path, message: impl Into<String>) -> Error {
    Error::Image { path: path.to_path_buf(), message: message.into() }
}
