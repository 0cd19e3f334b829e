//! EXR files: one part of 32-bit float `R`, `G`, `B` channels (or dotted layers), ZIP-compressed
//! scan lines, written atomically; reading takes the first part's `R`, `G`, `B`.

use std::path::Path;

use exr::image::{AnyChannel, AnyChannels, Blocks, Encoding, FlatSamples, Layer};
use exr::meta::attribute::{LineOrder, Text};
use exr::meta::header::LayerAttributes;
use exr::prelude::{Compression, SmallVec, WritableImage};

use super::{Image, float_count, image_error};
use crate::error::{Error, Result};
use crate::output::write_atomically;

/// Names of the colour channels, in storage order.
pub(super) const RGB_NAMES: [&str; 3] = ["R", "G", "B"];

/// Lossless EXR encoding: ZIP over 16-line blocks, scan lines top to bottom. ZIP is lossless for
/// f32 (bit-exact round trips) and compresses rendered images well; scan lines are readable by
/// every OpenEXR reader.
const EXR_ENCODING: Encoding =
    Encoding { compression: Compression::ZIP16, blocks: Blocks::ScanLines, line_order: LineOrder::Increasing };

impl Image {
    /// Writes the image losslessly as a single-part OpenEXR file with 32-bit float channels `R`,
    /// `G`, `B`.
    ///
    /// The write is atomic (see the [module docs](crate::image)).
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
    /// (see the [module docs](crate::image)).
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
