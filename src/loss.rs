//! Image losses and their adjoint images A = ∂loss/∂I (ALGORITHMS.md §7.1).

use crate::error::{Error, Result};
use crate::image::Image;

pub use crate::contract::REL_MSE_EPSILON;

pub use crate::contract::Loss;

impl Loss {
    /// The option's spelling: `l1`, `l2`, `relmse` or `relmse_max`.
    pub fn name(self) -> &'static str {
        match self {
            Loss::L1 => "l1",
            Loss::L2 => "l2",
            Loss::RelMse => "relmse",
            Loss::RelMseMax => "relmse_max",
        }
    }
}

impl std::str::FromStr for Loss {
    type Err = Error;
    fn from_str(s: &str) -> Result<Loss> {
        match s {
            "l1" => Ok(Loss::L1),
            "l2" => Ok(Loss::L2),
            "relmse" => Ok(Loss::RelMse),
            "relmse_max" => Ok(Loss::RelMseMax),
            _ => Err(Error::InvalidArgument {
                parameter: "Loss".into(),
                message: format!("'{s}' (expected relmse, relmse_max, l2 or l1)"),
            }),
        }
    }
}

/// The loss and its adjoint image, computed on the host in f64.
///
/// # Errors
/// [`Error::InvalidArgument`] if the sizes differ.
///
/// ```
/// use pathgrad::image::Image;
/// use pathgrad::loss::{loss_and_adjoint, Loss};
/// let a = Image::from_rgb(1, 1, vec![1.0, 2.0, 3.0]).unwrap();
/// let b = Image::from_rgb(1, 1, vec![1.0, 2.0, 2.0]).unwrap();
/// let (l, adj) = loss_and_adjoint(&a, &b, Loss::L2).unwrap();
/// assert!((l - 1.0 / 3.0).abs() < 1e-12);
/// assert!((adj.pixel(0, 0)[2] - 2.0 / 3.0).abs() < 1e-7);
/// ```
pub fn loss_and_adjoint(image: &Image, target: &Image, loss: Loss) -> Result<(f64, Image)> {
    if (image.width(), image.height()) != (target.width(), target.height()) {
        return Err(Error::InvalidArgument {
            parameter: "target".into(),
            message: format!(
                "is {}×{} but the render is {}×{}",
                target.width(),
                target.height(),
                image.width(),
                image.height()
            ),
        });
    }
    let n = image.as_slice().len() as f64;
    let mut total = 0.0f64;
    let adjoint: Vec<f32> = image
        .as_slice()
        .iter()
        .zip(target.as_slice())
        .map(|(&i, &t)| {
            let (i, t) = (f64::from(i), f64::from(t));
            let d = i - t;
            let (value, grad) = match loss {
                Loss::L1 => (
                    d.abs(),
                    if d > 0.0 {
                        1.0
                    } else if d < 0.0 {
                        -1.0
                    } else {
                        0.0
                    },
                ),
                Loss::L2 => (d * d, 2.0 * d),
                Loss::RelMse | Loss::RelMseMax => {
                    let eps = f64::from(REL_MSE_EPSILON);
                    let denom = if loss == Loss::RelMse { t + eps } else { t.abs().max(eps) };
                    (d * d / (denom * denom), 2.0 * d / (denom * denom))
                }
            };
            total += value;
            (grad / n) as f32
        })
        .collect();
    Ok((total / n, Image::from_rgb(image.width(), image.height(), adjoint)?))
}

/// The loss and its adjoint image computed by `shaders/loss.comp` on `ctx`'s device (the loss
/// summed in f32 with float atomics, so its last bits vary run to run).
///
/// # Errors
/// [`Error::InvalidArgument`] if the sizes differ; Vulkan failures.
pub fn loss_and_adjoint_gpu(
    ctx: &std::sync::Arc<crate::gpu::Context>,
    image: &Image,
    target: &Image,
    loss: Loss,
) -> Result<(f64, Image)> {
    use crate::contract::{BINDING_PROBE_IN, BINDING_PROBE_OUT};
    use crate::gpu::{Buffer, Kernel, pipeline::groups_for};
    if (image.width(), image.height()) != (target.width(), target.height()) {
        return Err(Error::InvalidArgument {
            parameter: "target".into(),
            message: "size differs from the render".into(),
        });
    }
    let n = image.as_slice().len();
    let mut both = image.as_slice().to_vec();
    both.extend_from_slice(target.as_slice());
    let input = Buffer::storage_with(ctx, "loss input", &both)?;
    let output = Buffer::storage(ctx, "loss output", ((n + 1) * 4) as u64)?;
    output.clear()?;
    let kernel = Kernel::new(ctx, "loss", &[BINDING_PROBE_IN, BINDING_PROBE_OUT], 8)?;
    let group = kernel.bind(&[(BINDING_PROBE_IN, &input), (BINDING_PROBE_OUT, &output)])?;
    let push = crate::contract::LossPush { count: n as u32, kind: loss.value() };
    ctx.submit_and_wait("loss", |cmd| kernel.record(cmd, &group, bytemuck::bytes_of(&push), groups_for(n as u32)))?;
    let out: Vec<f32> = output.download(n + 1)?;
    Ok((f64::from(out[0]), Image::from_rgb(image.width(), image.height(), out[1..].to_vec())?))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_two_relative_mses_differ_only_where_the_target_is_dark() {
        let image = Image::from_rgb(1, 1, vec![0.5, 0.01, 0.3]).unwrap();
        let target = Image::from_rgb(1, 1, vec![0.4, 0.0, -0.2]).unwrap();
        let (add, a) = loss_and_adjoint(&image, &target, Loss::RelMse).unwrap();
        let (max, m) = loss_and_adjoint(&image, &target, Loss::RelMseMax).unwrap();
        // Value 0: (0.1/0.401)² vs (0.1/0.4)²; value 1: (0.01/0.001)² both; value 2: 0.5/(−0.199) vs 0.5/0.2.
        let want_add = ((0.1f64 / 0.401).powi(2) + 100.0 + (0.5f64 / -0.199).powi(2)) / 3.0;
        let want_max = ((0.1f64 / 0.4).powi(2) + 100.0 + (0.5f64 / 0.2).powi(2)) / 3.0;
        assert!((add - want_add).abs() < 1e-5 * want_add, "{add} vs {want_add}");
        assert!((max - want_max).abs() < 1e-5 * want_max, "{max} vs {want_max}");
        assert_eq!(a.as_slice()[1], m.as_slice()[1]);
        for name in ["l1", "l2", "relmse", "relmse_max"] {
            assert_eq!(name.parse::<Loss>().unwrap().name(), name);
        }
    }

    /// Every adjoint equals the central difference of its loss.
    #[test]
    fn adjoints_are_derivatives_of_the_losses() {
        let image = Image::from_rgb(2, 1, vec![0.5, 0.2, 0.9, 0.05, 0.7, 0.3]).unwrap();
        let target = Image::from_rgb(2, 1, vec![0.4, 0.25, 0.9, 0.1, 0.5, 0.35]).unwrap();
        for loss in [Loss::L1, Loss::L2, Loss::RelMse, Loss::RelMseMax] {
            let (_, adj) = loss_and_adjoint(&image, &target, loss).unwrap();
            for k in 0..6 {
                if image.as_slice()[k] == target.as_slice()[k] {
                    continue;
                }
                let h = 1e-3f32;
                let shifted = |dx: f32| {
                    let mut v = image.as_slice().to_vec();
                    v[k] += dx;
                    loss_and_adjoint(&Image::from_rgb(2, 1, v).unwrap(), &target, loss).unwrap().0
                };
                let fd = (shifted(h) - shifted(-h)) / (2.0 * f64::from(h));
                let a = f64::from(adj.as_slice()[k]);
                assert!((fd - a).abs() <= 1e-3 * a.abs() + 1e-6, "{loss:?} value {k}: {a} vs {fd}");
            }
        }
    }
}
