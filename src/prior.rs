//! A smoothness prior for inverse rendering: a penalty on differences between neighbouring values of gridded parameters (volume grids, bitmap textures), with its exact gradient.
//!
//! Many voxels seen through a scattering medium from a few views are barely determined by the
//! images: the loss has flat directions, and Adam wanders along them. The prior adds
//!
//! ```text
//! P(θ) = λ · (1/N) Σ_(a,b) (θ_a − θ_b)²
//! ```
//!
//! to the objective, the sum over every pair of face-adjacent cells (voxels along x, y and z;
//! texels along u and v, without wrapping) of one channel of one optimised grid, N the number of
//! such pairs over all of them — the mean squared difference between neighbours, so λ means the
//! same at every resolution. Its gradient is `2λ/N (θ_a − θ_b)` on `a` and the negative on `b`.
//! Parameters that are not grids (scalars, colours, constant media) are not penalised.

use glam::UVec3;

use crate::error::{Error, Result};
use crate::params::{Gradients, ParamId, ParamTable};
use crate::scene::Scene;
use crate::scene::medium::Field;

/// One gridded parameter: `resolution` cells of `channels` values each, x fastest, then y, then
/// z (the layout of a `.vol` grid, and of a texture with z = 1).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GridShape {
    /// The parameter.
    pub param: ParamId,
    /// Cells along x, y and z.
    pub resolution: UVec3,
    /// Values per cell.
    pub channels: u32,
}

impl GridShape {
    /// Every gridded parameter of `scene`: the grids of its media (σ_t and albedo) and its bitmap
    /// textures.
    pub fn of_scene(scene: &Scene) -> Vec<GridShape> {
        let mut shapes = Vec::new();
        for medium in &scene.media {
            for field in [&medium.sigma_t, &medium.albedo] {
                if let Field::Grid { resolution, channels, values, .. } = field {
                    shapes.push(GridShape { param: *values, resolution: *resolution, channels: *channels });
                }
            }
        }
        for texture in &scene.textures {
            shapes.push(GridShape {
                param: texture.texels,
                resolution: UVec3::new(texture.width, texture.height, 1),
                channels: 3,
            });
        }
        // A grid shared by two media is one parameter: penalise it once.
        shapes.sort_by_key(|s| s.param.0);
        shapes.dedup();
        shapes
    }
}

/// The smoothness prior over some gridded parameters (see the module's documentation).
///
/// ```
/// use pathgrad::prior::Smoothness;
///
/// let scene = pathgrad::scene::builtin::load("cornell-box")?;
/// // The Cornell box has no gridded parameter: nothing to smooth, and the prior says so.
/// let everything: Vec<_> = (0..scene.params.entries().len() as u32).map(pathgrad::params::ParamId).collect();
/// assert!(Smoothness::new(&scene, &everything, 0.1).is_err());
/// # Ok::<(), pathgrad::Error>(())
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct Smoothness {
    weight: f64,
    grids: Vec<GridShape>,
    pairs: u64,
}

impl Smoothness {
    /// The prior of weight `weight` (λ) over those of `params` that are gridded in `scene`.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `smoothness` if `weight` is negative or not finite, or if
    /// none of `params` is a grid of more than one cell.
    pub fn new(scene: &Scene, params: &[ParamId], weight: f64) -> Result<Smoothness> {
        let invalid = |message: String| Error::InvalidArgument { parameter: "smoothness".into(), message };
        if !(weight >= 0.0 && weight.is_finite()) {
            return Err(invalid(format!("the weight {weight} must be a finite number ≥ 0")));
        }
        let grids: Vec<GridShape> =
            GridShape::of_scene(scene).into_iter().filter(|g| params.contains(&g.param)).collect();
        let pairs = grids.iter().map(pair_count).sum();
        if pairs == 0 {
            return Err(invalid(
                "none of the optimised parameters is a grid of more than one cell (a volume grid or a bitmap \
                 texture): there is nothing to smooth"
                    .into(),
            ));
        }
        Ok(Smoothness { weight, grids, pairs })
    }

    /// The weight λ.
    pub fn weight(&self) -> f64 {
        self.weight
    }

    /// The gridded parameters it penalises.
    pub fn grids(&self) -> &[GridShape] {
        &self.grids
    }

    /// P(θ) at the values in `table`.
    pub fn value(&self, table: &ParamTable) -> f64 {
        let mut sum = 0.0;
        self.visit(table, |d, _, _| sum += d * d);
        self.weight * sum / self.pairs as f64
    }

    /// `gradients` plus ∂P/∂θ at the values in `table` (the same layout).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] if `gradients` has another layout than `table`.
    pub fn add_gradient(&self, table: &ParamTable, gradients: &Gradients) -> Result<Gradients> {
        gradients.check_layout(table)?;
        let mut prior = vec![0.0f64; table.values().len()];
        let scale = 2.0 * self.weight / self.pairs as f64;
        self.visit(table, |d, a, b| {
            prior[a] += scale * d;
            prior[b] -= scale * d;
        });
        let values = gradients.values().iter().zip(&prior).map(|(&g, &p)| (f64::from(g) + p) as f32).collect();
        Ok(Gradients::new(table, values))
    }

    /// Calls `f(θ_a − θ_b, a, b)` for every neighbouring pair, a and b indices into the table's
    /// values.
    fn visit(&self, table: &ParamTable, mut f: impl FnMut(f64, usize, usize)) {
        for grid in &self.grids {
            let e = table.entry(grid.param);
            let values = table.get(grid.param);
            let r = grid.resolution;
            let c = grid.channels as usize;
            let cell = |x: u32, y: u32, z: u32| ((z * r.y + y) * r.x + x) as usize * c;
            for z in 0..r.z {
                for y in 0..r.y {
                    for x in 0..r.x {
                        let a = cell(x, y, z);
                        let neighbours = [
                            (x + 1 < r.x).then(|| cell(x + 1, y, z)),
                            (y + 1 < r.y).then(|| cell(x, y + 1, z)),
                            (z + 1 < r.z).then(|| cell(x, y, z + 1)),
                        ];
                        for b in neighbours.into_iter().flatten() {
                            for ch in 0..c {
                                let d = f64::from(values[a + ch]) - f64::from(values[b + ch]);
                                f(d, e.offset as usize + a + ch, e.offset as usize + b + ch);
                            }
                        }
                    }
                }
            }
        }
    }
}

/// The number of neighbouring value pairs of one grid.
fn pair_count(g: &GridShape) -> u64 {
    let r = g.resolution.as_u64vec3();
    let along = |n: u64, a: u64, b: u64| n.saturating_sub(1) * a * b;
    (along(r.x, r.y, r.z) + along(r.y, r.x, r.z) + along(r.z, r.x, r.y)) * u64::from(g.channels)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Texture;

    /// A scene with one 3×2 RGB texture as its only gridded parameter, and a scalar.
    fn scene() -> (Scene, ParamId, ParamId) {
        let mut scene = crate::scene::builtin::load("cornell-box").unwrap();
        let texels: Vec<f32> = (0..18).map(|i| 0.1 + 0.8 * (i as f32 * 0.37).fract()).collect();
        let id = scene.params.add("tex.data", &texels, (0.0, 1.0)).unwrap();
        scene.textures.push(Texture {
            width: 3,
            height: 2,
            texels: id,
            nearest: false,
            wrap: crate::scene::Wrap::Repeat,
            to_uv: [glam::Vec3::X, glam::Vec3::Y],
        });
        let scalar = scene.params.find("red.reflectance.value").unwrap();
        (scene, id, scalar)
    }

    #[test]
    fn the_value_is_the_mean_squared_neighbour_difference() {
        let (scene, id, _) = scene();
        let prior = Smoothness::new(&scene, &[id], 0.5).unwrap();
        let v = scene.params.get(id);
        let px = |x: usize, y: usize, c: usize| f64::from(v[(y * 3 + x) * 3 + c]);
        let mut sum = 0.0;
        for c in 0..3 {
            for y in 0..2 {
                for x in 0..2 {
                    sum += (px(x, y, c) - px(x + 1, y, c)).powi(2);
                }
            }
            for x in 0..3 {
                sum += (px(x, 0, c) - px(x, 1, c)).powi(2);
            }
        }
        // 4 horizontal and 3 vertical pairs a channel.
        assert_eq!(prior.pairs, 21);
        assert!((prior.value(&scene.params) - 0.5 * sum / 21.0).abs() < 1e-12);
    }

    #[test]
    fn the_gradient_matches_finite_differences() {
        let (scene, id, scalar) = scene();
        let prior = Smoothness::new(&scene, &[id, scalar], 2.0).unwrap();
        let zero = Gradients::new(&scene.params, vec![0.0; scene.params.values().len()]);
        let g = prior.add_gradient(&scene.params, &zero).unwrap();
        let e = scene.params.entry(id).clone();
        for i in 0..e.len as usize {
            let at = |delta: f32| {
                let mut t = scene.params.clone();
                let mut v = t.get(id).to_vec();
                v[i] += delta;
                t.set(&e.name, &v).unwrap();
                prior.value(&t)
            };
            let h = 1e-3;
            let fd = (at(h) - at(-h)) / (2.0 * f64::from(h));
            let analytic = f64::from(g.values()[e.offset as usize + i]);
            assert!((fd - analytic).abs() < 1e-4 * analytic.abs().max(1.0), "value {i}: {analytic} vs fd {fd}");
        }
        // The scalar is not a grid: its gradient is left alone.
        let s = scene.params.entry(scalar);
        assert!(g.values()[s.offset as usize..(s.offset + s.len) as usize].iter().all(|&v| v == 0.0));
    }

    #[test]
    fn bad_weights_and_ungridded_parameters_are_refused() {
        let (scene, id, scalar) = scene();
        for w in [-1.0, f64::NAN, f64::INFINITY] {
            let e = Smoothness::new(&scene, &[id], w).unwrap_err().to_string();
            assert!(e.contains("smoothness"), "{e}");
        }
        let e = Smoothness::new(&scene, &[scalar], 1.0).unwrap_err().to_string();
        assert!(e.contains("nothing to smooth"), "{e}");
    }

    #[test]
    fn a_constant_grid_costs_nothing() {
        let (mut scene, id, _) = scene();
        scene.params.set("tex.data", &[0.25; 18]).unwrap();
        let prior = Smoothness::new(&scene, &[id], 3.0).unwrap();
        assert_eq!(prior.value(&scene.params), 0.0);
    }
}
