//! Participating media as Mitsuba 3 describes them: homogeneous and heterogeneous media inside
//! shapes, their extinction and albedo fields (constants or `.vol` grids), scale and phase function.
//!
//! Every differentiable value is a parameter named as Mitsuba's `traverse` names it: the medium's
//! prefix, `SHAPE.interior_medium` for the first shape that reaches it (a nested medium's own id
//! plays no part) or the id of one declared at scene level and reached there first (see
//! [`crate::scene::mitsuba`]), then `.sigma_t.data` for a grid, `.sigma_t.value.value` for a
//! constant or `constvolume`, the same for `albedo`, `.scale` and `.phase_function.g`
//! (`smoke.interior_medium.sigma_t.data`).
//! The extinction at a point is `scale · sigma_t(p)`; a grid fills the unit cube under its
//! volume's `to_world` and is looked up trilinearly at `p·res − 0.5` with clamping
//! ([`crate::scene::volume::Grid::lookup`]).
//!
//! **Extent, as Mitsuba 3.** A `homogeneous` medium fills its shape. A `heterogeneous` one exists
//! only inside the world-space bounding box of the unit cube under its `sigma_t` volume's
//! `to_world` (a `constvolume`'s too, and a plain `<float>`/`<rgb>` σ_t is a `constvolume` over
//! [0, 1]³), intersected with the shape: between the shape's boundary and that box a ray travels
//! in vacuum ([`Medium::extent`], ALGORITHMS.md §8).

use glam::{Mat4, UVec3, Vec3};

use crate::params::{ParamId, ParamTable};
use crate::scene::Wrap;

/// Index of a medium in [`crate::scene::Scene::media`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MediumId(pub u32);

/// A value over space.
#[derive(Clone, Debug, PartialEq)]
pub enum Field {
    /// The same value everywhere: a parameter of `channels` (1 or 3) values.
    Constant {
        /// The value.
        value: ParamId,
        /// 1 (grey) or 3 (RGB).
        channels: u32,
    },
    /// A grid of `resolution` voxels with `channels` values each, x fastest then y then z (the
    /// `.vol` order), filling the unit cube under the volume's `to_world`.
    Grid {
        /// Voxels along x, y and z.
        resolution: UVec3,
        /// 1 or 3.
        channels: u32,
        /// The voxel values.
        values: ParamId,
        /// World to the grid's unit cube (the inverse of the volume's `to_world`).
        to_local: Mat4,
        /// How voxel indices outside the grid wrap (Mitsuba's `wrap_mode`, default clamp).
        wrap: Wrap,
    },
}

impl Field {
    /// Channel `c` of the field at world point `p` with the values in `params` (a grey field
    /// gives its one value for every channel).
    pub fn eval(&self, params: &ParamTable, p: Vec3, c: u32) -> f32 {
        match self {
            Field::Constant { value, channels } => params.get(*value)[(c.min(channels - 1)) as usize],
            Field::Grid { resolution, channels, values, to_local, wrap } => crate::scene::volume::lookup(
                params.get(*values),
                *resolution,
                *channels,
                to_local.transform_point3(p),
                c.min(channels - 1),
                *wrap,
            ),
        }
    }

    /// The largest value of channel `c` anywhere (a majorant of [`Field::eval`]: trilinear
    /// interpolation never exceeds its corners).
    pub fn max(&self, params: &ParamTable, c: u32) -> f32 {
        match self {
            Field::Constant { .. } => self.eval(params, Vec3::ZERO, c),
            Field::Grid { channels, values, .. } => {
                let ch = c.min(channels - 1) as usize;
                params.get(*values).iter().skip(ch).step_by(*channels as usize).fold(0.0f32, |m, &v| m.max(v))
            }
        }
    }

    /// The number of channels.
    pub fn channels(&self) -> u32 {
        match self {
            Field::Constant { channels, .. } | Field::Grid { channels, .. } => *channels,
        }
    }
}

/// A phase function.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Phase {
    /// Uniform over the sphere: 1/(4π).
    Isotropic,
    /// Henyey–Greenstein with mean cosine `g` (one value in (−1, 1)).
    HenyeyGreenstein {
        /// The asymmetry parameter.
        g: ParamId,
    },
}

/// A participating medium inside one or more shapes (their `interior`).
#[derive(Clone, Debug, PartialEq)]
pub struct Medium {
    /// The parameter prefix: `SHAPE.interior_medium`, or the `id` of a medium Mitsuba's traverse
    /// reaches at scene level first.
    pub name: String,
    /// `heterogeneous` in the file (else `homogeneous`); both may hold grids or constants.
    pub heterogeneous: bool,
    /// Where the medium exists, as a world-space box (min, max), or `None` wherever its shape
    /// is: a heterogeneous medium's is the axis-aligned bound of the eight corners of the unit
    /// cube under its `sigma_t` volume's `to_world`, as Mitsuba's `Volume::bbox`; a homogeneous
    /// medium has none.
    pub extent: Option<(Vec3, Vec3)>,
    /// Extinction before `scale`: per unit length, ≥ 0.
    pub sigma_t: Field,
    /// Single-scattering albedo σ_s/σ_t in [0, 1].
    pub albedo: Field,
    /// Multiplies `sigma_t` (one value ≥ 0).
    pub scale: ParamId,
    /// The phase function.
    pub phase: Phase,
}

impl Medium {
    /// The extinction of channel `c` at `p`: `scale · sigma_t(p)`.
    pub fn extinction(&self, params: &ParamTable, p: Vec3, c: u32) -> f32 {
        params.get(self.scale)[0] * self.sigma_t.eval(params, p, c)
    }

    /// The majorant of delta and ratio tracking: `scale · max(sigma_t)` over every point and
    /// channel (ALGORITHMS.md §8), times 1 + [`crate::contract::MAJORANT_MARGIN`] so that it
    /// strictly exceeds every density.
    pub fn majorant(&self, params: &ParamTable) -> f32 {
        let channels = self.sigma_t.channels();
        let max = params.get(self.scale)[0] * (0..channels).map(|c| self.sigma_t.max(params, c)).fold(0.0f32, f32::max);
        max * (1.0 + crate::contract::MAJORANT_MARGIN)
    }
}

/// Voxels of a density grid per majorant-grid cell along each axis (at most
/// [`MAJORANT_GRID_MAX`] cells per axis): tracking steps by each cell's own majorant, so one dense
/// voxel sets the step length only near itself.
pub const MAJORANT_CELL_VOXELS: u32 = 8;

/// The most majorant-grid cells along one axis (a ray crosses at most the sum of the three).
pub const MAJORANT_GRID_MAX: u32 = 64;

/// A cell's majorant is this many times the largest extinction in it, unless the medium's one
/// majorant is smaller. A majorant close to the density makes null collisions rare and their
/// derivative weights 1/(σ̄ − σ_t) large: the density gradients' second moment grows as
/// ∫ 1/(σ̄ − σ_t) dt while the cost grows as ∫ σ̄ dt, so σ̄ = 2σ_max halves the cost a
/// global majorant pays in sparse cells while bounding the noise it adds.
pub const MAJORANT_CELL_SLACK: f32 = 2.0;

/// A medium's majorant grid: cells over the unit cube of its `sigma_t` grid, each holding a
/// majorant of the extinction wherever a lookup inside the cell can reach.
#[derive(Clone, Debug, PartialEq)]
pub struct MajorantGrid {
    /// Cells along x, y and z.
    pub cells: UVec3,
    /// One majorant per cell, x fastest.
    pub values: Vec<f32>,
}

impl Medium {
    /// The majorant grid of a medium whose extinction is a voxel grid of more than one cell
    /// ([`MAJORANT_CELL_VOXELS`]); `None` for a constant extinction or a small grid, which
    /// [`Medium::majorant`] bounds as tightly.
    ///
    /// A cell's value is [`MAJORANT_CELL_SLACK`] · `scale · max σ_t` over the voxels that
    /// trilinear lookups at points in the cell read (with one voxel of slack on each side for
    /// rounding at the cell's faces), times 1 + [`crate::contract::MAJORANT_MARGIN`], and at most
    /// the medium's one majorant ([`Medium::majorant`]). Points outside the unit cube (a rotated
    /// volume's box) read the clamped border voxels, which the border cells include.
    pub fn majorant_grid(&self, params: &ParamTable) -> Option<MajorantGrid> {
        let Field::Grid { resolution: res, channels, values, .. } = &self.sigma_t else { return None };
        let cells = UVec3::new(
            res.x.div_ceil(MAJORANT_CELL_VOXELS).min(MAJORANT_GRID_MAX),
            res.y.div_ceil(MAJORANT_CELL_VOXELS).min(MAJORANT_GRID_MAX),
            res.z.div_ceil(MAJORANT_CELL_VOXELS).min(MAJORANT_GRID_MAX),
        );
        if cells == UVec3::ONE {
            return None;
        }
        let voxels = params.get(*values);
        let ch = *channels as usize;
        let voxel_max: Vec<f32> = voxels.chunks_exact(ch).map(|v| v.iter().fold(0.0f32, |m, &x| m.max(x))).collect();
        let factor = params.get(self.scale)[0] * (1.0 + crate::contract::MAJORANT_MARGIN);
        let global = self.majorant(params);
        // The voxels whose trilinear support meets cell i of n along an axis of r voxels: a point
        // at local x in [i/n, (i+1)/n) reads voxels floor(x·r − 0.5) and one more.
        let span = |i: u32, n: u32, r: u32| {
            let lo = ((i as u64 * r as u64) / n as u64).saturating_sub(1);
            let hi = ((i as u64 + 1) * r as u64).div_ceil(n as u64);
            (lo as u32, (hi as u32).min(r - 1))
        };
        let mut values = Vec::with_capacity((cells.x * cells.y * cells.z) as usize);
        for cz in 0..cells.z {
            let (z0, z1) = span(cz, cells.z, res.z);
            for cy in 0..cells.y {
                let (y0, y1) = span(cy, cells.y, res.y);
                for cx in 0..cells.x {
                    let (x0, x1) = span(cx, cells.x, res.x);
                    let mut m = 0.0f32;
                    for z in z0..=z1 {
                        for y in y0..=y1 {
                            let row = ((z * res.y + y) * res.x) as usize;
                            m = voxel_max[row + x0 as usize..=row + x1 as usize].iter().fold(m, |a, &v| a.max(v));
                        }
                    }
                    values.push((MAJORANT_CELL_SLACK * m * factor).min(global));
                }
            }
        }
        Some(MajorantGrid { cells, values })
    }
}

/// The world-space axis-aligned bound of the unit cube under `to_world` (its eight corners), as
/// Mitsuba's `Volume::bbox`.
pub fn unit_cube_bounds(to_world: Mat4) -> (Vec3, Vec3) {
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    for corner in 0..8u32 {
        let c = Vec3::new((corner & 1) as f32, ((corner >> 1) & 1) as f32, ((corner >> 2) & 1) as f32);
        let p = to_world.transform_point3(c);
        lo = lo.min(p);
        hi = hi.max(p);
    }
    (lo, hi)
}

/// Bounds of medium parameters: extinction and scale ≥ 0, albedo in [0, 1], |g| < 1 (the
/// optimiser keeps g within ±0.999, where Henyey–Greenstein is still finite).
pub mod bounds {
    /// Extinction values and `scale`.
    pub const EXTINCTION: (f32, f32) = (0.0, f32::INFINITY);
    /// Albedo values.
    pub const ALBEDO: (f32, f32) = (0.0, 1.0);
    /// Henyey–Greenstein g.
    pub const HG_G: (f32, f32) = (-0.999, 0.999);
}
