//! Environment maps (Mitsuba's `envmap`): the latitude-longitude lookup, and the sampling cells
//! that next-event estimation draws from (twin of the map functions in `shaders/lib/emitter.glsl`).
//!
//! Conventions are Mitsuba 3.9's, so that a map renders as it does there. In the map's frame a
//! direction d has texture coordinates u = atan2(d.x, −d.z)/2π (wrapped into [0, 1)) and
//! v = acos(d.y)/π. Texel centres are at u = (i + ½)/W in longitude, which wraps, and at
//! v = j/(H − 1) in latitude (row 0 looks along +y, row H − 1 along −y); the radiance is the bilinear
//! blend of the four texels around a direction, times `scale`.
//!
//! A *cell* is the region between four neighbouring texel centres: W × (H − 1) of them, cell
//! (i, j) spanning longitudes 2π(i + ½)/W to 2π(i + 1½)/W and latitudes πj/(H − 1) to
//! π(j + 1)/(H − 1). The radiance inside a cell is the blend of its four corners, so a cell whose
//! corners are all black is black throughout. Next-event estimation draws a cell through an
//! alias table, in proportion to its corners' mean luminance times its solid angle, then a
//! direction uniformly in solid angle within it (uniform longitude, uniform cos θ): its density is
//! the cell's realised probability ([`AliasTable::pmf`]) over the cell's solid angle, constant in
//! the cell and without the 1/sin θ of a sampler over texture space.

use glam::{Mat3, Vec2, Vec3};

use crate::alias::AliasTable;
use crate::contract::EnvCell;
use crate::error::{Error, Result};

/// An environment map's layout; its texels are the scene's environment parameter
/// ([`crate::scene::Scene::environment`]), `width × height` RGB values row by row.
///
/// ```
/// use glam::{Mat3, Vec3};
/// use pathgrad::scene::envmap::EnvMap;
/// let map = EnvMap { width: 8, height: 5, scale: 1.0, to_local: Mat3::IDENTITY };
/// // Straight up (+y) is row 0; its four texels are blended by weights that sum to 1.
/// let (texels, weights) = map.footprint(Vec3::Y);
/// assert!(texels.iter().all(|&t| t < 8 * 2));
/// assert!((weights.iter().sum::<f32>() - 1.0).abs() < 1e-6);
/// // Sampling cells: their densities integrate to 1 over the sphere.
/// let cells = map.cells(&vec![1.0; 8 * 5 * 3])?;
/// assert_eq!(cells.len(), 8 * 4);
/// # Ok::<(), pathgrad::Error>(())
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EnvMap {
    /// Texels in longitude.
    pub width: u32,
    /// Texels in latitude (at least 2).
    pub height: u32,
    /// Mitsuba's `scale`: multiplies every texel.
    pub scale: f32,
    /// The rotation from world directions to the map's frame (`to_world`'s inverse).
    pub to_local: Mat3,
}

/// Linear-sRGB luminance (Mitsuba's `luminance`).
fn luminance(rgb: Vec3) -> f32 {
    0.212_671 * rgb.x + 0.715_160 * rgb.y + 0.072_169 * rgb.z
}

/// Coefficients of atan(a)/a as a polynomial in a² on [0, 1] (fitted by least squares on
/// Chebyshev nodes; |error| of atan below 2·10⁻⁷ rad in f32).
const ATAN_POLY: [f32; 8] = [
    0.999_999_46,
    -0.333_301_07,
    0.199_485_1,
    -0.139_158_03,
    0.096_562_564,
    -0.056_063_175,
    0.021_946_61,
    -0.004_073_309_2,
];

/// atan2(y, x) by `ATAN_POLY`: the kernels compute the same polynomial (`atan2_poly` in
/// `shaders/lib/emitter.glsl`), because lavapipe's own `atan` and `acos` are approximations
/// that differ from Rust's by about 10⁻⁵, which moves a map lookup measurably where the map is
/// steep.
pub fn atan2_poly(y: f32, x: f32) -> f32 {
    let (ax, ay) = (x.abs(), y.abs());
    let (hi, lo) = (ax.max(ay), ax.min(ay));
    let a = if hi > 0.0 { lo / hi } else { 0.0 };
    let s = a * a;
    let mut p = ATAN_POLY[7];
    for k in (0..7).rev() {
        p = p * s + ATAN_POLY[k];
    }
    let mut r = p * a;
    if ay > ax {
        r = std::f32::consts::FRAC_PI_2 - r;
    }
    if x < 0.0 {
        r = std::f32::consts::PI - r;
    }
    if y < 0.0 { -r } else { r }
}

/// The map's (u, v) of `d`, a unit direction in the map's frame.
pub fn direction_uv(d: Vec3) -> Vec2 {
    let u = atan2_poly(d.x, -d.z) * (0.5 * std::f32::consts::FRAC_1_PI);
    let v = atan2_poly((d.x * d.x + d.z * d.z).sqrt(), d.y) * std::f32::consts::FRAC_1_PI;
    Vec2::new(u - u.floor(), v)
}

/// The cell (i, j) that (u, v) lies in and the bilinear weights of its corners there: x = u·W − ½
/// wraps, y = v·(H − 1) is clamped to the last cell.
fn cell_at(width: u32, height: u32, uv: Vec2) -> (u32, u32, f32, f32) {
    let x = uv.x * width as f32 - 0.5;
    let x0 = x.floor();
    let fx = x - x0;
    let i = (x0 as i64).rem_euclid(i64::from(width)) as u32;
    let y = uv.y.clamp(0.0, 1.0) * (height - 1) as f32;
    let y0 = y.floor().min((height - 2) as f32);
    (i, y0 as u32, fx, y - y0)
}

impl EnvMap {
    /// The texel indices (row-major, not parameter offsets) and bilinear weights of the radiance
    /// toward world direction `dir`.
    pub fn footprint(&self, dir: Vec3) -> ([u32; 4], [f32; 4]) {
        let (i, j, fx, fy) = cell_at(self.width, self.height, direction_uv(self.to_local * dir));
        let (w, i1) = (self.width, (i + 1) % self.width);
        (
            [j * w + i, j * w + i1, (j + 1) * w + i, (j + 1) * w + i1],
            [(1.0 - fx) * (1.0 - fy), fx * (1.0 - fy), (1.0 - fx) * fy, fx * fy],
        )
    }

    /// [`EnvMap::footprint`] and the gradients of its four weights by the world direction `dir`
    /// (attached derivatives, `crate::attached`): the weights' derivatives by the cell
    /// coordinates, times ∂u/∂d · W and ∂v/∂d · (H − 1) of the exact atan2 (the lookup's
    /// polynomial differs from it by less than 10⁻⁶). Zero on the poles' axis, where the
    /// longitude has no derivative.
    pub fn footprint_gradient(&self, dir: Vec3) -> ([u32; 4], [f32; 4], [Vec3; 4]) {
        let (texels, weights) = self.footprint(dir);
        let l = self.to_local * dir;
        let rho2 = l.x * l.x + l.z * l.z;
        if !(rho2 > 0.0) {
            return (texels, weights, [Vec3::ZERO; 4]);
        }
        let rho = rho2.sqrt();
        let grad_u = Vec3::new(-l.z, 0.0, l.x) / (rho2 * 2.0 * std::f32::consts::PI);
        let grad_v = Vec3::new(l.y * l.x / rho, -rho, l.y * l.z / rho) / ((rho2 + l.y * l.y) * std::f32::consts::PI);
        let (_, _, fx, fy) = cell_at(self.width, self.height, direction_uv(l));
        let world = self.to_local.transpose();
        let gx = world * grad_u * self.width as f32;
        let gy = world * grad_v * (self.height - 1) as f32;
        let grads = [
            -(1.0 - fy) * gx - (1.0 - fx) * gy,
            (1.0 - fy) * gx - fx * gy,
            -fy * gx + (1.0 - fx) * gy,
            fy * gx + fx * gy,
        ];
        (texels, weights, grads)
    }

    /// The index of the cell that world direction `dir` lies in.
    pub fn cell_of(&self, dir: Vec3) -> u32 {
        let (i, j, _, _) = cell_at(self.width, self.height, direction_uv(self.to_local * dir));
        j * self.width + i
    }

    /// The world direction at `u` ∈ [0, 1)² within cell `cell`: uniform in longitude and in cos θ.
    pub fn direction_in_cell(&self, cell: u32, u: Vec2) -> Vec3 {
        let (i, j) = (cell % self.width, cell / self.width);
        let phi = 2.0 * std::f32::consts::PI * (i as f32 + 0.5 + u.x) / self.width as f32;
        let (cos0, cos1) = self.cell_cos(j);
        let cos_theta = cos0 + u.y * (cos1 - cos0);
        let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
        let local = Vec3::new(phi.sin() * sin_theta, cos_theta, -phi.cos() * sin_theta);
        self.to_local.transpose() * local
    }

    /// A world direction drawn from `cells` (this map's [`EnvMap::cells`]): a cell by its alias
    /// table (`u_cell`: column and coin), then [`EnvMap::direction_in_cell`] at `u_pos`.
    pub fn sample(&self, cells: &[EnvCell], u_cell: Vec2, u_pos: Vec2) -> Vec3 {
        let count = cells.len() as u32;
        let column = ((u_cell.x * count as f32).floor() as u32).min(count - 1);
        let e = &cells[column as usize];
        let cell = if u_cell.y < e.prob { column } else { e.alias };
        self.direction_in_cell(cell, u_pos)
    }

    /// The solid-angle density with which [`EnvMap::sample`] draws world direction `dir`.
    pub fn pdf(&self, cells: &[EnvCell], dir: Vec3) -> f32 {
        cells[self.cell_of(dir) as usize].pdf
    }

    /// cos θ at the top and bottom of cell row `j`.
    fn cell_cos(&self, j: u32) -> (f32, f32) {
        let step = std::f32::consts::PI / (self.height - 1) as f32;
        ((j as f32 * step).cos(), ((j + 1) as f32 * step).cos())
    }

    /// The sampling cells for the texels `texels` (RGB, row-major). A map without light gets cells
    /// in proportion to solid angle alone: it contributes nothing, but its texels still have
    /// derivatives (which BSDF sampling finds in any case).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] if the texel count is wrong or the alias table cannot be built
    /// (a non-finite texel).
    pub fn cells(&self, texels: &[f32]) -> Result<Vec<EnvCell>> {
        let (w, h) = (self.width as usize, self.height as usize);
        if texels.len() != 3 * w * h {
            return Err(Error::InvalidArgument {
                parameter: "environment map".into(),
                message: format!("{} texel values for a {w}×{h} map (need {})", texels.len(), 3 * w * h),
            });
        }
        let lum: Vec<f64> =
            texels.chunks_exact(3).map(|c| f64::from(luminance(Vec3::new(c[0], c[1], c[2]).abs()))).collect();
        let mut solid = Vec::with_capacity(w * (h - 1));
        let mut weights = Vec::with_capacity(w * (h - 1));
        for j in 0..h - 1 {
            let (cos0, cos1) = self.cell_cos(j as u32);
            let omega = 2.0 * std::f64::consts::PI / w as f64 * f64::from(cos0 - cos1);
            for i in 0..w {
                let i1 = (i + 1) % w;
                let mean = 0.25 * (lum[j * w + i] + lum[j * w + i1] + lum[(j + 1) * w + i] + lum[(j + 1) * w + i1]);
                solid.push(omega);
                weights.push(mean * omega);
            }
        }
        let total: f64 = weights.iter().sum();
        if total == 0.0 {
            weights.clone_from(&solid);
        }
        let table = AliasTable::new(&weights).map_err(|e| Error::InvalidArgument {
            parameter: "environment map".into(),
            message: format!("cannot build its sampling table: {e}"),
        })?;
        Ok((0..weights.len())
            .map(|c| EnvCell { prob: table.prob()[c], alias: table.alias()[c], pdf: (table.pmf(c) / solid[c]) as f32 })
            .collect())
    }
}

/// The rotation from world to map frame for Mitsuba's `to_world` (its linear part `m`), which must
/// be a rotation: the sampler's densities assume directions keep their solid angle.
///
/// # Errors
/// A message if `m` scales, shears or mirrors.
pub fn to_local(m: Mat3) -> std::result::Result<Mat3, String> {
    let gram = m.transpose() * m;
    let off = (gram - Mat3::IDENTITY).to_cols_array().iter().fold(0.0f32, |a, v| a.max(v.abs()));
    if off > 1e-4 || m.determinant() < 0.0 {
        return Err("an envmap's 'to_world' must be a rotation (no scale, shear or mirroring)".into());
    }
    Ok(m.transpose())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn map(width: u32, height: u32, to_local: Mat3) -> EnvMap {
        EnvMap { width, height, scale: 1.0, to_local }
    }

    #[test]
    fn the_polynomial_atan2_is_accurate_in_every_quadrant() {
        for k in 0..10_000 {
            let t = k as f32 / 10_000.0 * 2.0 * std::f32::consts::PI;
            for r in [1e-3f32, 1.0, 7.5] {
                let (y, x) = (r * t.sin(), r * t.cos());
                // The polynomial's 1.5·10⁻⁷ plus the rounding of results up to π (ulp 2.4·10⁻⁷).
                let exact = f64::from(y).atan2(f64::from(x));
                assert!((f64::from(atan2_poly(y, x)) - exact).abs() < 5e-7, "{y} {x}");
            }
        }
        assert_eq!(atan2_poly(0.0, 0.0), 0.0);
        assert!((atan2_poly(0.0, -1.0) - std::f32::consts::PI).abs() < 1e-7);
    }

    #[test]
    fn texel_centres_follow_mitsubas_convention() {
        let m = map(8, 5, Mat3::IDENTITY);
        // +y is row 0 (v = 0), −y the last row; u = 0 looks along −z, u = ¼ along +x.
        assert_eq!(direction_uv(Vec3::Y).y, 0.0);
        assert!((direction_uv(-Vec3::Y).y - 1.0).abs() < 1e-6);
        assert!(direction_uv(-Vec3::Z).x.abs() < 1e-6);
        assert!((direction_uv(Vec3::X).x - 0.25).abs() < 1e-6);
        // The centre of texel (i, j) reads that texel alone.
        let phi = 2.0 * std::f32::consts::PI * 2.5 / 8.0;
        let theta = std::f32::consts::PI * 3.0 / 4.0;
        let d = Vec3::new(phi.sin() * theta.sin(), theta.cos(), -phi.cos() * theta.sin());
        let (texels, weights) = m.footprint(d);
        let k = (0..4).max_by(|&a, &b| weights[a].total_cmp(&weights[b])).unwrap();
        assert_eq!(texels[k], 3 * 8 + 2);
        assert!((weights[k] - 1.0).abs() < 1e-4, "{weights:?}");
    }

    #[test]
    fn longitude_wraps_between_the_last_and_first_columns() {
        let m = map(4, 3, Mat3::IDENTITY);
        // u = 0 lies halfway between the centres of columns 3 and 0.
        let (texels, weights) = m.footprint(Vec3::new(0.0, 0.0, -1.0));
        assert_eq!([texels[0] % 4, texels[1] % 4], [3, 0]);
        assert!((weights[0] - weights[1]).abs() < 1e-5);
    }

    #[test]
    fn directions_in_a_cell_lie_in_that_cell() {
        let rot = Mat3::from_rotation_y(0.7) * Mat3::from_rotation_x(-0.3);
        let m = map(16, 9, to_local(rot).unwrap());
        for cell in [0u32, 5, 15, 16, 77, 127] {
            for u in [Vec2::new(0.1, 0.2), Vec2::new(0.9, 0.95), Vec2::new(0.5, 0.5)] {
                let d = m.direction_in_cell(cell, u);
                assert!((d.length() - 1.0).abs() < 1e-5);
                assert_eq!(m.cell_of(d), cell, "cell {cell} at {u}");
            }
        }
    }

    #[test]
    fn cell_densities_integrate_to_one_and_follow_luminance() {
        let (w, h) = (6u32, 4u32);
        let texels: Vec<f32> = (0..w * h).flat_map(|t| [t as f32, 0.5 * t as f32, 1.0]).collect();
        let m = map(w, h, Mat3::IDENTITY);
        let cells = m.cells(&texels).unwrap();
        let total: f64 = (0..h - 1)
            .flat_map(|j| (0..w).map(move |i| (i, j)))
            .map(|(i, j)| {
                let (c0, c1) = m.cell_cos(j);
                f64::from(cells[(j * w + i) as usize].pdf) * 2.0 * std::f64::consts::PI / f64::from(w)
                    * f64::from(c0 - c1)
            })
            .sum();
        assert!((total - 1.0).abs() < 1e-5, "{total}");
        // A black map is sampled by solid angle.
        let black = m.cells(&vec![0.0; texels.len()]).unwrap();
        let pdf = 1.0 / (4.0 * std::f32::consts::PI);
        assert!(black.iter().all(|c| (c.pdf - pdf).abs() < 1e-4 * pdf));
    }

    #[test]
    fn chi2_the_sampler_draws_its_density() {
        use crate::rng::{PassTag, RngKey, Stream, uniform4};
        use crate::stats::{Chi2Config, chi2_directions, dump_table};
        // A sun, a black band and a smooth rest, tilted so that cells and bins do not line up;
        // the map's +y is the test's +z (the chi-square bins' pole).
        let (w, h) = (24u32, 13u32);
        let texels: Vec<f32> = (0..h)
            .flat_map(|j| (0..w).map(move |i| (i, j)))
            .flat_map(|(i, j)| {
                let sun = if (i, j) == (7, 4) { 40.0 } else { 0.0 };
                let dark = if (9..12).contains(&j) && i < 10 { 0.0 } else { 1.0 };
                let base = dark * (0.2 + 0.05 * i as f32);
                [base + sun, base + 0.5 * sun, base]
            })
            .collect();
        let rot = Mat3::from_cols(Vec3::X, Vec3::Z, -Vec3::Y) * Mat3::from_rotation_z(0.4);
        let m = map(w, h, to_local(rot).unwrap());
        let cells = m.cells(&texels).unwrap();
        let cfg = Chi2Config { cos_bins: 16, phi_bins: 32, samples: 1_000_000, significance: 0.01 };
        let r = chi2_directions(
            &cfg,
            |i| {
                let u = uniform4(RngKey::new(91, 0, PassTag::Test), i as u32, 0, 1, Stream::Main, 1, 0);
                Some(m.sample(&cells, Vec2::new(u[0], u[1]), Vec2::new(u[2], u[3])))
            },
            |d| f64::from(m.pdf(&cells, d)),
        );
        if !r.passed(cfg.significance) {
            let path = dump_table("envmap", &r);
            panic!(
                "envmap: chi2 {} with {} dof, p = {:.3e}; table in {}",
                r.statistic,
                r.dof,
                r.p_value,
                path.display()
            );
        }
    }

    #[test]
    fn scaling_or_mirroring_to_world_is_refused() {
        assert!(to_local(Mat3::from_diagonal(Vec3::new(2.0, 1.0, 1.0))).is_err());
        assert!(to_local(Mat3::from_diagonal(Vec3::new(-1.0, 1.0, 1.0))).is_err());
        assert!(to_local(Mat3::from_rotation_z(1.0)).is_ok());
    }
}
