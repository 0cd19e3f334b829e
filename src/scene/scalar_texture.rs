//! Textures on scalar parameters (roughness, blend weight): one-channel texels (or a mesh attribute) that are one parameter.

use glam::Vec3;

use super::Wrap;
use crate::error::Result;
use crate::params::ParamId;

/// A one-channel texture on a scalar slot (Mitsuba's `bitmap` or `checkerboard` given as a
/// roughness `alpha`/`alpha_u`/`alpha_v` or a `blendbsdf` `weight`): its texels are the parameter
/// `texels` (`width × height` values row by row, row 0 at v = 0; a checkerboard's two colours as
/// two texels), looked up at the hit's texture coordinates through `to_uv`. A material whose
/// scalar parameter is `texels` reads it through this texture ([`crate::scene::Scene::scalar_texture`]).
#[derive(Clone, Debug, PartialEq)]
pub struct ScalarTexture {
    /// The texels' parameter.
    pub texels: ParamId,
    /// Width in texels (2 for a checkerboard).
    pub width: u32,
    /// Height in texels (1 for a checkerboard).
    pub height: u32,
    /// Nearest texel instead of bilinear interpolation.
    pub nearest: bool,
    /// How texel indices outside the image wrap.
    pub wrap: Wrap,
    /// Mitsuba's checkerboard: texel 0 where the fractional parts of (u, v) lie on the same side
    /// of 1/2, else texel 1.
    pub checker: bool,
    /// `u' = dot(to_uv[0], (u, v, 1))`, `v' = dot(to_uv[1], (u, v, 1))`.
    pub to_uv: [Vec3; 2],
    /// Mitsuba's `mesh_attribute`: the texels are a one-value attribute of a mesh, read at the
    /// hit triangle (or interpolated between its vertices) instead of at texture coordinates
    /// (`width` is then the number of values, `height` 1; lookups read neither).
    pub attribute: Option<super::AttributeSource>,
}

impl super::Scene {
    /// The scalar texture whose texels are parameter `id`, if `id` is one.
    pub fn scalar_texture(&self, id: ParamId) -> Option<&ScalarTexture> {
        self.scalar_textures.iter().find(|t| t.texels == id)
    }

    /// Adds a one-channel texture (bilinear, repeating, texture coordinates as they are) whose
    /// `width × height` texels, row 0 at v = 0, become the parameter `name` within `range`; a
    /// material's scalar slot (roughness, blend weight) refers to the returned parameter.
    ///
    /// # Errors
    /// [`crate::error::Error::Scene`] naming the texture if the texel count is not `width × height`; as
    /// [`crate::params::ParamTable::add`] for the values.
    pub fn add_scalar_texture(
        &mut self,
        name: &str,
        width: u32,
        height: u32,
        texels: &[f32],
        range: (f32, f32),
    ) -> Result<ParamId> {
        super::check_texel_count(name, width, height, 1, texels.len())?;
        let id = self.params.add(name, texels, range)?;
        self.scalar_textures.push(ScalarTexture {
            texels: id,
            width,
            height,
            nearest: false,
            wrap: Wrap::Repeat,
            checker: false,
            to_uv: [Vec3::X, Vec3::Y],
            attribute: None,
        });
        Ok(id)
    }
}
