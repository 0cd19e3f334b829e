//! Loss-aware adaptive pixel sampling (ALGORITHMS.md §6; Su & Gkioulekas, Algorithm 2): pixel
//! weights from the adjoint image, the pixel each gradient sample draws, and its adjoint radiance δL.
//!
//! A gradient pass of N = W·H·spp samples gives sample k = 0..N−1 the pixel p(k) drawn from an
//! [`AliasTable`] over weights π_p ∝ Σ_c |A_pc| — two uniforms of stream `PIXEL`, counter (0, k),
//! vertex 0, block 0, under the pixel-selection key ([`pixel_select_key`]) — and traces its path
//! with counters (p(k), k), so samples that land in the same pixel are independent. Its adjoint
//! radiance is δL_{k,c} = A_{p,c}/(N·π_p) ([`AdaptiveEstimator::Importance`], unbiased; π_p is the
//! probability the table realises, [`AliasTable::pmf`]) or A_{p,c}/n_p
//! ([`AdaptiveEstimator::PixelMean`], the authors' per-pixel mean, n_p the number of samples drawn
//! in p). Either way δL depends only on the pixel, so it is folded into the adjoint image on the
//! host ([`PixelSampling::sample_adjoint`]) and the kernels read it per pixel as in a uniform pass.
//! The GLSL twin of the pixel draw is `select_pixel` in `shaders/lib/alias.glsl`.

use rayon::prelude::*;

use crate::alias::AliasTable;
use crate::error::{Error, Result};
use crate::image::Image;
use crate::integrator::RenderOptions;
use crate::rng::{PassTag, RngKey, Stream, uniform4};

/// How adaptively placed samples are weighted (ALGORITHMS.md §6, "Estimator weights").
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum AdaptiveEstimator {
    /// δL_{k,c} = A_{p,c}/(N·π_p): the unbiased importance-sampling estimator. With uniform
    /// weights it is the non-adaptive δL = A_p/spp.
    #[default]
    Importance,
    /// δL_k = A_p/n_p with n_p the number of samples drawn in pixel p: the per-pixel mean of the
    /// authors' code. Pixels that drew no sample contribute nothing, a bias of 1 − (1 − π_p)^N.
    PixelMean,
}

impl AdaptiveEstimator {
    /// The option's spelling: `importance` or `pixel_mean`.
    pub fn name(self) -> &'static str {
        match self {
            AdaptiveEstimator::Importance => "importance",
            AdaptiveEstimator::PixelMean => "pixel_mean",
        }
    }
}

impl std::str::FromStr for AdaptiveEstimator {
    type Err = Error;
    fn from_str(s: &str) -> Result<AdaptiveEstimator> {
        match s {
            "importance" => Ok(AdaptiveEstimator::Importance),
            "pixel_mean" => Ok(AdaptiveEstimator::PixelMean),
            _ => Err(Error::InvalidArgument {
                parameter: "AdaptiveEstimator".into(),
                message: format!("'{s}' (expected importance or pixel_mean)"),
            }),
        }
    }
}

/// Settings of a loss gradient with adaptive pixel sampling
/// ([`crate::backend::Backend::loss_and_gradient_adaptive`]); the gradient pass takes its samples
/// per pixel, spp_grad, from [`RenderOptions::spp`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AdaptiveOptions {
    /// Samples per pixel of pass 1, the render whose loss and adjoint image give the weights.
    pub spp_primal: u32,
    /// How the gradient samples are weighted.
    pub estimator: AdaptiveEstimator,
}

impl AdaptiveOptions {
    /// Checks ranges.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `--spp-primal` if it is 0.
    pub fn validate(&self) -> Result<()> {
        crate::integrator::check_spp_primal(self.spp_primal)
    }
}

/// The key of pixel selection: the gradient pass's key with pass tag [`PassTag::PixelSelect`]
/// (ALGORITHMS.md §2.3), so the draws are independent of every path.
pub fn pixel_select_key(gradient_key: RngKey) -> RngKey {
    RngKey([gradient_key.0[0], (gradient_key.0[1] & !0xFF) | PassTag::PixelSelect as u32])
}

/// The pixel of global sample `k` of a gradient pass keyed `gradient_key`: two uniforms of stream
/// [`Stream::Pixel`], counter (0, k), vertex 0, block 0, drawn through `table` (twin of
/// `select_pixel` in `shaders/lib/alias.glsl`).
pub fn select_pixel(table: &AliasTable, gradient_key: RngKey, k: u32) -> u32 {
    let u = uniform4(pixel_select_key(gradient_key), 0, k, 0, Stream::Pixel, 0, 0);
    table.draw(u[0], u[1])
}

/// A distribution over the pixels of a W×H image and the estimator its samples use.
///
/// ```
/// use pathgrad::adaptive::{AdaptiveEstimator, PixelSampling};
/// use pathgrad::image::Image;
/// // Weights from an adjoint image: π_p ∝ Σ_c |A_pc|.
/// let adjoint = Image::from_rgb(2, 1, vec![0.1, -0.2, 0.0, 0.0, 0.0, 0.9])?;
/// let sampling = PixelSampling::from_adjoint(&adjoint, AdaptiveEstimator::Importance)?;
/// assert!((sampling.probability(0) - 0.25).abs() < 1e-6);
/// # Ok::<(), pathgrad::Error>(())
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct PixelSampling {
    width: u32,
    height: u32,
    table: AliasTable,
    estimator: AdaptiveEstimator,
}

impl PixelSampling {
    /// Pixels drawn with probability proportional to `weights` (row-major, one per pixel).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] if there are not W·H weights, or for weights an
    /// [`AliasTable`] refuses (NaN, negative, infinite, all zero).
    pub fn new(width: u32, height: u32, weights: &[f64], estimator: AdaptiveEstimator) -> Result<PixelSampling> {
        let pixels = u64::from(width) * u64::from(height);
        if weights.len() as u64 != pixels {
            return Err(Error::InvalidArgument {
                parameter: "pixel weights".into(),
                message: format!("{} weights for a {width}×{height} image", weights.len()),
            });
        }
        Ok(PixelSampling { width, height, table: AliasTable::new(weights)?, estimator })
    }

    /// Every pixel equally likely: with [`AdaptiveEstimator::Importance`] the estimator of a
    /// uniform pass, in expectation.
    ///
    /// # Errors
    /// As [`PixelSampling::new`] (an empty image).
    pub fn uniform(width: u32, height: u32, estimator: AdaptiveEstimator) -> Result<PixelSampling> {
        PixelSampling::new(width, height, &vec![1.0; width as usize * height as usize], estimator)
    }

    /// Loss-aware weights π_p ∝ Σ_c |A_pc| of the adjoint image `adjoint` (ALGORITHMS.md §6).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming the pixel of a non-finite adjoint value, or if the adjoint
    /// image is zero everywhere (then the loss gradient is exactly zero and nothing needs sampling).
    pub fn from_adjoint(adjoint: &Image, estimator: AdaptiveEstimator) -> Result<PixelSampling> {
        let mut weights = Vec::with_capacity(adjoint.as_slice().len() / 3);
        for (p, a) in adjoint.as_slice().chunks_exact(3).enumerate() {
            if a.iter().any(|v| !v.is_finite()) {
                let (x, y) = (p as u32 % adjoint.width(), p as u32 / adjoint.width());
                return Err(Error::InvalidArgument {
                    parameter: "adjoint image".into(),
                    message: format!("pixel ({x}, {y}) is {a:?}: adaptive pixel weights need finite values"),
                });
            }
            weights.push(a.iter().map(|v| f64::from(v.abs())).sum());
        }
        if weights.iter().all(|&w| w == 0.0) {
            return Err(Error::InvalidArgument {
                parameter: "adjoint image".into(),
                message: "is zero everywhere: there is no pixel to weight (the loss gradient is 0)".into(),
            });
        }
        PixelSampling::new(adjoint.width(), adjoint.height(), &weights, estimator)
    }

    /// Image width.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Image height.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// The alias table over the pixels (row-major), as uploaded.
    pub fn table(&self) -> &AliasTable {
        &self.table
    }

    /// The estimator.
    pub fn estimator(&self) -> AdaptiveEstimator {
        self.estimator
    }

    /// The probability π_p with which a sample lands in `pixel`: the table's exact realised pmf.
    pub fn probability(&self, pixel: u32) -> f64 {
        self.table.pmf(pixel as usize)
    }

    /// N = W·H·spp, the number of samples of a gradient pass with `options`.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] if `options` renders another size, or N exceeds the 32-bit
    /// sample counter.
    pub fn sample_count(&self, options: &RenderOptions) -> Result<u32> {
        if (options.width, options.height) != (self.width, self.height) {
            return Err(Error::InvalidArgument {
                parameter: "pixel sampling".into(),
                message: format!(
                    "is for a {}×{} image but the render is {}×{}",
                    self.width, self.height, options.width, options.height
                ),
            });
        }
        let n = u64::from(self.width) * u64::from(self.height) * u64::from(options.spp);
        u32::try_from(n).map_err(|_| Error::InvalidArgument {
            parameter: "RenderOptions::spp".into(),
            message: format!(
                "{}×{} pixels × {} spp = {n} adaptive samples exceed the 32-bit sample counter",
                self.width, self.height, options.spp
            ),
        })
    }

    /// n_p: how many of the samples k = 0..`samples` of a pass keyed `gradient_key` land in each
    /// pixel (the histogram the per-pixel mean divides by).
    pub fn counts(&self, gradient_key: RngKey, samples: u32) -> Vec<u32> {
        let pixels = self.table.len();
        (0..samples)
            .into_par_iter()
            .fold(
                || vec![0u32; pixels],
                |mut counts, k| {
                    counts[select_pixel(&self.table, gradient_key, k) as usize] += 1;
                    counts
                },
            )
            .reduce(|| vec![0u32; pixels], |a, b| a.iter().zip(&b).map(|(x, y)| x + y).collect())
    }

    /// The adjoint radiance δL of a sample in each pixel, as an image: A_{p,c}/(N·π_p) or
    /// A_{p,c}/n_p (0 in pixels no sample can reach or, for the per-pixel mean, none did), for a
    /// gradient pass with `options` (its key and N = W·H·spp).
    ///
    /// # Errors
    /// As [`PixelSampling::sample_count`]; an adjoint image of another size.
    pub fn sample_adjoint(&self, options: &RenderOptions, adjoint: &Image) -> Result<Image> {
        let n = self.sample_count(options)?;
        if (adjoint.width(), adjoint.height()) != (self.width, self.height) {
            return Err(Error::InvalidArgument {
                parameter: "adjoint image".into(),
                message: format!(
                    "is {}×{} but the pixel sampling is for {}×{}",
                    adjoint.width(),
                    adjoint.height(),
                    self.width,
                    self.height
                ),
            });
        }
        let scale: Vec<f64> = match self.estimator {
            AdaptiveEstimator::Importance => (0..self.table.len())
                .map(|p| {
                    let pi = self.table.pmf(p);
                    if pi > 0.0 { 1.0 / (f64::from(n) * pi) } else { 0.0 }
                })
                .collect(),
            AdaptiveEstimator::PixelMean => self
                .counts(options.key(PassTag::Gradient), n)
                .into_iter()
                .map(|c| if c > 0 { 1.0 / f64::from(c) } else { 0.0 })
                .collect(),
        };
        let data = adjoint.as_slice().iter().enumerate().map(|(i, &a)| (f64::from(a) * scale[i / 3]) as f32).collect();
        Image::from_rgb(self.width, self.height, data)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn options(width: u32, height: u32, spp: u32) -> RenderOptions {
        let scene = crate::scene::builtin::load("cornell-box").unwrap();
        RenderOptions { width, height, spp, seed: 3, ..RenderOptions::for_scene(&scene) }
    }

    fn pattern(width: u32, height: u32) -> Image {
        let data = (0..width * height * 3).map(|i| ((i as f32) * 0.37 + 0.1).sin() * (1.0 + (i % 5) as f32)).collect();
        Image::from_rgb(width, height, data).unwrap()
    }

    /// Uniform weights give every sample δL = A_p/spp exactly when W·H divides 2²³ (the table's
    /// realised pmf is then exactly 1/(W·H)), and N·π_p·scale_p = 1 to f32 rounding otherwise: the
    /// importance estimator with uniform weights is the non-adaptive one, sample for sample in
    /// weight, and so in expectation.
    #[test]
    fn uniform_weights_reproduce_the_non_adaptive_adjoint() {
        let adjoint = pattern(32, 16);
        let opts = options(32, 16, 4);
        let uniform = PixelSampling::uniform(32, 16, AdaptiveEstimator::Importance).unwrap();
        let delta = uniform.sample_adjoint(&opts, &adjoint).unwrap();
        for (d, a) in delta.as_slice().iter().zip(adjoint.as_slice()) {
            assert_eq!(*d, a / 4.0);
        }
        let (w, h, spp) = (15, 7, 3);
        let adjoint = pattern(w, h);
        let uniform = PixelSampling::uniform(w, h, AdaptiveEstimator::Importance).unwrap();
        let delta = uniform.sample_adjoint(&options(w, h, spp), &adjoint).unwrap();
        let n = f64::from(w * h * spp);
        for (i, (d, a)) in delta.as_slice().iter().zip(adjoint.as_slice()).enumerate() {
            let weight = n * uniform.probability(i as u32 / 3) * f64::from(*d) / f64::from(*a);
            assert!((weight - 1.0).abs() < 1e-6, "value {i}: N·π·δL/A = {weight}");
        }
    }

    /// Importance weights: N·π_p·δL_p = A_p for every pixel a sample can reach, so summing δL over
    /// the expected number of samples N·π_p of each pixel gives back A (ALGORITHMS.md §6).
    #[test]
    fn importance_weights_undo_the_sampling_density() {
        let adjoint = pattern(9, 5);
        let opts = options(9, 5, 2);
        let sampling = PixelSampling::from_adjoint(&adjoint, AdaptiveEstimator::Importance).unwrap();
        let delta = sampling.sample_adjoint(&opts, &adjoint).unwrap();
        let n = f64::from(9 * 5 * 2);
        for (i, (d, a)) in delta.as_slice().iter().zip(adjoint.as_slice()).enumerate() {
            let back = n * sampling.probability(i as u32 / 3) * f64::from(*d);
            assert!((back - f64::from(*a)).abs() <= 1e-6 * f64::from(a.abs()), "value {i}: {back} vs {a}");
        }
    }

    /// Per-pixel mean: δL = A_p/n_p with n_p the histogram of the same draws the kernels make, so
    /// each drawn pixel's samples carry A_p in total; undrawn pixels carry 0.
    #[test]
    fn pixel_mean_divides_by_the_drawn_counts() {
        let adjoint = pattern(8, 8);
        let opts = options(8, 8, 1);
        let sampling = PixelSampling::from_adjoint(&adjoint, AdaptiveEstimator::PixelMean).unwrap();
        let key = opts.key(PassTag::Gradient);
        let counts = sampling.counts(key, 64);
        let mut brute = vec![0u32; 64];
        for k in 0..64 {
            brute[select_pixel(sampling.table(), key, k) as usize] += 1;
        }
        assert_eq!(counts, brute);
        assert_eq!(counts.iter().sum::<u32>(), 64);
        assert!(counts.contains(&0) && counts.iter().any(|&c| c > 1), "{counts:?}");
        let delta = sampling.sample_adjoint(&opts, &adjoint).unwrap();
        for (p, &c) in counts.iter().enumerate() {
            for ch in 0..3 {
                let (d, a) = (delta.as_slice()[3 * p + ch], adjoint.as_slice()[3 * p + ch]);
                if c == 0 {
                    assert_eq!(d, 0.0);
                } else {
                    assert!((d * c as f32 - a).abs() <= 1e-6 * a.abs(), "pixel {p}: {d} × {c} vs {a}");
                }
            }
        }
    }

    #[test]
    fn bad_inputs_are_named() {
        let nan = Image::from_rgb(2, 2, vec![0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, f32::NAN, 0.0, 1.0, 1.0, 1.0]).unwrap();
        let e = PixelSampling::from_adjoint(&nan, AdaptiveEstimator::Importance).unwrap_err().to_string();
        assert!(e.contains("pixel (0, 1)") && e.contains("NaN"), "{e}");
        let zero = Image::new(3, 2);
        let e = PixelSampling::from_adjoint(&zero, AdaptiveEstimator::Importance).unwrap_err().to_string();
        assert!(e.contains("zero everywhere"), "{e}");
        let e = PixelSampling::new(2, 2, &[1.0; 3], AdaptiveEstimator::Importance).unwrap_err().to_string();
        assert!(e.contains("3 weights for a 2×2 image"), "{e}");
        let s = PixelSampling::uniform(4, 4, AdaptiveEstimator::Importance).unwrap();
        let e = s.sample_count(&options(4, 5, 1)).unwrap_err().to_string();
        assert!(e.contains("4×4") && e.contains("4×5"), "{e}");
        let big = PixelSampling::uniform(1024, 1024, AdaptiveEstimator::Importance).unwrap();
        assert_eq!(big.sample_count(&options(1024, 1024, 4095)).unwrap(), 1024 * 1024 * 4095);
        let e = big.sample_count(&options(1024, 1024, 4096)).unwrap_err().to_string();
        assert!(e.contains("RenderOptions::spp") && e.contains("32-bit"), "{e}");
        assert_eq!("pixel_mean".parse::<AdaptiveEstimator>().unwrap(), AdaptiveEstimator::PixelMean);
        assert!("mean".parse::<AdaptiveEstimator>().unwrap_err().to_string().contains("importance or pixel_mean"));
        let e = AdaptiveOptions { spp_primal: 0, estimator: AdaptiveEstimator::Importance }.validate().unwrap_err();
        assert!(e.to_string().contains("LossGradientSetup::spp_primal"));
    }

    /// The selection key differs from the gradient key only in its pass tag, and keeps the
    /// iteration.
    #[test]
    fn pixel_select_key_swaps_the_pass_tag() {
        let g = RngKey::new(17, 5, PassTag::Gradient);
        assert_eq!(pixel_select_key(g), RngKey::new(17, 5, PassTag::PixelSelect));
    }
}
