//! The Mitsuba 3 XML subset: scenes users already have, loaded into a [`Scene`] with located errors.
//!
//! # What is read
//! - `<scene version="2.x|3.x">`; `<default name value>` and `$name` in any attribute value,
//!   overridden by the caller's defines (the CLI's `-D name=value`); `<ref id>` anywhere an object
//!   is expected, in either document order; `id` attributes (unique across the file).
//! - Properties `<float>`, `<integer>`, `<boolean>`, `<string>`, `<rgb>` (`"r, g, b"`, `"r g b"` or
//!   one value), `<spectrum value="c">` or of wavelength:value pairs (converted as Mitsuba's RGB
//!   variants do, module `spectrum`), `<point>`/`<vector>`, and `<transform>` with
//!   `translate`, `rotate` (axis, degrees), `scale`, `matrix` (16 row-major or 9 values) and
//!   `lookat`, each left-multiplying what came before (later elements apply after earlier ones).
//! - Shapes `obj`, `ply`, `serialized` (`shape_index`; its stored face-normals flag holds unless
//!   the scene sets `face_normals`), `rectangle`, `cube`, `disk`, `sphere`, `cylinder` (`p0`, `p1`,
//!   `radius`; tessellated like the sphere) with `to_world`, `flip_normals`
//!   and (meshes) `face_normals` (a mesh file without normals is shaded with Mitsuba's
//!   angle-weighted vertex normals, computed in world space, unless `face_normals` is set); one `<bsdf>`/`<ref>` each (default: diffuse 0.5, as Mitsuba) and
//!   optionally `<emitter type="area">` with `radiance` (a colour, a `bitmap` whose texels
//!   are `….radiance.data`, or a `checkerboard` whose colours are `….radiance.color0.value` and
//!   `….radiance.color1.value`, either with `to_uv`, read at the point's texture coordinates;
//!   sampled by area).
//! - BSDFs `diffuse` (`reflectance`: colour, `<texture type="bitmap">` (`raw`, `filter_type`
//!   bilinear/nearest, `wrap_mode` repeat/mirror/clamp),
//!   `<texture type="checkerboard">` with colour `color0`/`color1` and `to_uv`, or
//!   `<texture type="mesh_attribute">`: a PLY attribute of the shape, per face or per vertex,
//!   module `mesh_attribute`, also on float properties), or `<texture type="volume">` (a
//!   `gridvolume`/`constvolume` looked up at the world-space point, values `….volume.data`;
//!   a diffuse's reflectance, a conductor's or roughconductor's specular_reflectance)), `roughconductor`,
//!   `blendbsdf`, `twosided`; `<emitter type="constant">` at scene level (the environment).
//! - `<sensor type="perspective">` with `fov`/`focal_length`, `fov_axis`, `to_world`, a
//!   `<film type="hdrfilm">` (`width`, `height`, an `rfilter`) and a `<sampler type="independent">` (`sample_count` →
//!   [`Scene::default_spp`]), also declared at scene level and referred to by `<ref>`;
//!   `<integrator type="path|prb|prb_basic|volpath|volpathmis|prbvolpath">` `max_depth` →
//!   [`Scene::max_depth`], `direct` (depth 2), `moment`/`aov` around one of them.
//! - The scene file: `<include>` and `<path>` (module `include`), repeated `<default>`s (the first
//!   holds), a shape's `<ref>` to a scene-level area emitter.
//!
//! Any other plugin or element is an error, `file:line:col: <tag>: unsupported plugin 'X'
//! (supported: …)`; a property a supported plugin does not know is a warning in
//! [`Scene::warnings`], `file:line:col: unknown property 'p' of 'type' ignored`. Every error names
//! `file:line:col` and the element. Malformed input never panics: nesting of BSDFs and textures is
//! capped at 16, reference cycles are detected, and the XML parser's node count is capped.
//!
//! # Decisions
//! - **Parameter names** are the keys of Mitsuba 3.9.1's `mi.traverse(mi.load_file(path))`
//!   (default options), which `tests_names` compares with Mitsuba's lists for the scenes in
//!   `tests/data/mitsuba_names/` (`regenerate.py` there rewrites them). Mitsuba names a
//!   scene-level object (a child of `<scene>`) by its `id`, and every other object after the
//!   first path that reaches it, `PARENT.SLOT`: a shape's `bsdf`, `emitter` and
//!   `interior_medium`, a blend's `bsdf_0`/`bsdf_1`, a twosided's `brdf_0`, a mask's (or normal
//!   or bump map's) `nested_bsdf` and a mask's `opacity` texture, a diffuse BSDF's
//!   `reflectance` texture (and so a specular colour's texture), a medium's `sigma_t`, `albedo` and `phase_function`; an object
//!   reached again keeps its first name. So a nested object's own `id` plays no part (a blend
//!   nested in shape `ball` is `ball.bsdf` whatever its id), and a scene-level object is named by
//!   its id only if the walk of the scene reaches it before any shape or other object that refers
//!   to it. That walk takes the scene's children in document order, except that meshes (`obj`,
//!   `ply`, `serialized`, `rectangle`, `cube`) come after everything else: a BSDF declared after the rectangles
//!   that use it is still named by its id, one declared after a `sphere` or `disk` that uses it
//!   is `SHAPE.bsdf`. pathgrad builds the scene in that order (and keeps its meshes in document
//!   order). The keys end in `.reflectance.value`, `.reflectance.data` (a bitmap's texels),
//!   `.alpha.value` (`.alpha_u.value` when the file gives `alpha_u`/`alpha_v`),
//!   `.specular_reflectance.value` (`.specular_reflectance.data` or `.color0.value` textured; so
//!   `specular_transmittance`), a conductor's and rough conductor's `.eta.value` and `.k.value` (RGB,
//!   a `material` preset's too), `.weight.value`, `.radiance.value` (`SHAPE.emitter.…` or the
//!   environment's), and for media `.sigma_t.value.value`/`.sigma_t.data`, the same for
//!   `albedo`, `.scale` and `.phase_function.g` (see [`crate::scene::medium`]).
//! - **Where Mitsuba's names cannot be matched**, pathgrad keeps its own, and says so here:
//!   - A scene-level object without an id, and every scene-level texture (whose id Mitsuba's
//!     traverse ignores), is `object_<address>` in Mitsuba, a different key on every run;
//!     pathgrad calls it `_unnamed_N`, N counting such elements from 0 in document order.
//!   - Mitsuba's default load merges objects whose properties are equal (ids aside) into one,
//!     and meshes that then share a BSDF into one `object_<address>` mesh, listing the survivor
//!     once; pathgrad keeps every object, so two equal nested BSDFs are two parameters. Give
//!     objects that must stay apart different values (or load with `optimize=False`).
//!   - A rough conductor without `specular_reflectance` in the file has pathgrad's
//!     `….specular_reflectance.value` (1), which Mitsuba does not list; with `alpha_u` and
//!     `alpha_v` (equal: pathgrad is isotropic) only `alpha_u` is a parameter.
//!   - A `<volume>` or `<phase>` declared at scene level and `<ref>`'d by media is, in Mitsuba,
//!     one object named by its id; pathgrad copies it into each medium, named
//!     `MEDIUM.sigma_t.…`/`MEDIUM.phase_function.g`. A medium nothing refers to is ignored, and
//!     has no parameters. Which of two meshes first reaches an object nested in one and
//!     `<ref>`'d by the other is Mitsuba's choice (it varies between runs); pathgrad takes the
//!     document's order.
//! - **No camera, no default**: a scene without `<sensor>` is an error (Mitsuba would invent one
//!   from the scene's bounds; pathgrad asks for it explicitly). Only the first sensor is used.
//! - **Camera orientation** matches Mitsuba: local +z forward, +y up, and Mitsuba's film puts local
//!   +x on the image's left, which is what pathgrad's `forward × up = right` gives for any
//!   `to_world` with positive determinant. A mirroring `to_world` is rejected (see `sensor.rs`).
//!   `fov` is converted to pathgrad's vertical field of view with the film's aspect ratio.
//! - **Curved shapes** are tessellated so that the mesh stays within
//!   [`MAX_CHORD_ERROR_PX`] = 0.02 pixels of the true surface at the film's resolution, with
//!   between [`MIN_SEGMENTS`] and [`MAX_SEGMENTS`] segments around (the Cornell box's sphere at
//!   256² gets 174 × 87); that keeps silhouette bias at a third of a 64-spp render's noise on an
//!   edge pixel (derivation at `shapes::segments_for`). A `linearcurve` becomes its cones and
//!   joint spheres (Embree's round linear curve, which Mitsuba renders in every variant) with
//!   Mitsuba's UV; see `curves.rs`. A `bsplinecurve` becomes rings of the circles normal to its
//!   tangent that Embree intersects, stepped along each segment until the measured error is in
//!   the budget, with Mitsuba's normals and UV (open ends: a warning, as Mitsuba culls the inner
//!   wall). Control points are not parameters (geometry is fixed). An `sdfgrid` (a `.vol` file of
//!   signed distances) becomes the zero set of its trilinear interpolant, cut per voxel into
//!   cells fine enough for the same budget, with Mitsuba's `smooth` or `analytic` normals at the
//!   vertices; see `sdfgrid.rs`. Its `grid` and `to_world` are not parameters.
//! - **Depth**: `max_depth = -1` (and a scene without `<integrator>`, Mitsuba's default) becomes
//!   [`crate::integrator::UNBOUNDED_DEPTH_CAP`], which the renderer treats as unbounded. The
//!   volpath family counts depth as Mitsuba's does ([`crate::scene::Scene::null_uncounted`]: a
//!   thindielectric's transmission or a mask's pass-through is no bounce); `hide_emitters` becomes
//!   [`crate::scene::Scene::hide_emitters`]. `rr_depth` other than 5 is warned about and ignored.
//! - **Filters and samplers**: the film's `rfilter` is `box`, `tent` (`radius`) or `gaussian`
//!   (`stddev`; Mitsuba's default, also when the film names none), rendered exactly
//!   ([`crate::scene::PixelFilter`]: each sample's position is drawn from the filter around the
//!   pixel's centre, truncated to the film, which has the expectation of Mitsuba's weighted
//!   splatting); filters with negative lobes (`mitchell`, `catmullrom`, `lanczos`) and
//!   `sample_border` are refused; samplers other than `independent` are unsupported.
//! - **Bitmaps**: texel row 0 is the image's top row (Mitsuba's v = 0); PNG is sRGB-decoded
//!   unless `raw`, EXR is linear; texels must lie in [0, 1].
//! - **Blends** of two `twosided` leaves become `twosided(blend(..))` (the same BSDF), since
//!   pathgrad blends two leaf BSDFs.

mod bsdf;
mod curves;
mod include;
mod loader;
mod media;
mod mesh_attribute;
pub mod plugins;
mod scalar_texture;
mod sdfgrid;
mod sensor;
mod shapes;
mod spectrum;
mod xml;

#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_emitters;
#[cfg(test)]
mod tests_errors;
#[cfg(test)]
mod tests_include;
#[cfg(test)]
mod tests_media;
#[cfg(test)]
mod tests_mesh_attributes;
#[cfg(test)]
mod tests_names;
#[cfg(test)]
mod tests_normal_maps;
#[cfg(test)]
mod tests_plugins;
#[cfg(test)]
mod tests_scalar_textures;
#[cfg(test)]
mod tests_volume_texture;

use std::path::Path;

pub use shapes::{MAX_CHORD_ERROR_PX, MAX_SEGMENTS, MIN_SEGMENTS, segments_for, unit_disk, unit_sphere};

use crate::error::Result;
use crate::scene::{LoadOptions, Scene};

/// Loads the Mitsuba XML scene at `path`; `defines` (name, value) override its `<default>`s.
/// Relative file names (meshes, bitmaps) resolve against the file's directory and must stay inside it
/// (see [`load_with`] to allow others).
///
/// # Errors
/// [`crate::Error::Io`] if the file cannot be read; [`crate::Error::Scene`] located at
/// `file:line:col` for anything wrong or unsupported in it; [`crate::Error::InvalidArgument`] for
/// a define whose name is not an identifier.
pub fn load(path: &Path, defines: &[(String, String)]) -> Result<Scene> {
    let options = LoadOptions { defines: defines.to_vec(), ..LoadOptions::default() };
    loader::load_path(path, &options, loader::load_mesh_file)
}

/// Loads the Mitsuba XML scene at `path` with `options`: its defines; the rendered size, for which
/// the camera is set up and curved shapes are tessellated; whether files outside the scene's
/// folder may be read (by default a `filename` must lie inside it).
///
/// # Errors
/// As [`load`].
pub fn load_with(path: &Path, options: &LoadOptions) -> Result<Scene> {
    loader::load_path(path, options, loader::load_mesh_file)
}

/// Loads a Mitsuba XML scene from `text`, as if read from `file` (used in messages and to resolve
/// relative file names).
///
/// # Errors
/// As [`load`].
pub fn load_str(text: &str, file: &Path, defines: &[(String, String)]) -> Result<Scene> {
    let options = LoadOptions { defines: defines.to_vec(), ..LoadOptions::default() };
    loader::load_text_with(text, file, &options, loader::load_mesh_file)
}
