//! Textures on scalar properties (a roughness, a `blendbsdf` weight): `bitmap` and `checkerboard`
//! with one channel, their texels one parameter.

use super::loader::Loader;
use super::plugins::{Category, names};
use super::xml::{El, Props};
use crate::error::Result;
use crate::params::ParamId;
use crate::scene::ScalarTexture;

impl<'a> Loader<'a> {
    /// The scalar property `key` of `p` (BSDF `name`): a `<float>` (`default` when absent), or a
    /// nested `<texture>` ([`Loader::scalar_texture`]). A constant is the parameter
    /// `NAME.KEY.value`; values must lie in `range`, texels in `texel_range`.
    ///
    /// # Errors
    /// A value out of range, a missing property without default, a bad texture.
    pub(super) fn scalar_property(
        &mut self,
        p: &Props<'a>,
        name: &str,
        key: &str,
        default: Option<f32>,
        range: (f32, f32),
        texel_range: (f32, f32),
    ) -> Result<ParamId> {
        if let Some(t) = p.object(key) {
            return self.scalar_texture(t, format!("{name}.{key}"), texel_range);
        }
        let value = self.float_in(p, key, default, range)?;
        let id = self.scene.params.add(&format!("{name}.{key}.value"), &[value], range);
        id.map_err(|e| self.located(p.node, e))
    }

    /// Builds (once) the texture `node` — a `<texture>` or a `<ref>` to one — on a scalar property
    /// named `name` (unless the scene level named it first): a `bitmap` whose image has one channel
    /// (grey: every texel's R = G = B), its texels the parameter `NAME.data`, or a `checkerboard`
    /// of two `<float>` colours (`color0` 0.4, `color1` 0.2, `to_uv`), the parameters
    /// `NAME.color1.value` and `NAME.color0.value` — Mitsuba's `traverse` names; `color1` is read
    /// where the halves of (u, v) agree, as Mitsuba 3.9.1's float lookup of a checkerboard does
    /// (its colour lookup reads `color0` there). Texels must lie in `range`.
    ///
    /// # Errors
    /// Other plugins, an RGB image, values out of range, a missing or undecodable file.
    pub(super) fn scalar_texture(&mut self, node: El<'a>, name: String, range: (f32, f32)) -> Result<ParamId> {
        let target = self.deref(node)?;
        if !target.has_tag_name("texture") {
            return Err(self.x.err(node, format!("refers to a <{}>, expected a <texture>", target.tag_name().name())));
        }
        if let Some(&id) = self.scalar_textures.get(&target.id()) {
            return Ok(id);
        }
        let name = self.name_of(target, name)?;
        let p = Props::parse(&self.x, target)?;
        let texture = match p.kind.as_str() {
            "mesh_attribute" => {
                // Not cached: each shape reads its own attribute.
                let (texels, source) = self.mesh_attribute(&p, 1, range)?;
                if let Some(t) = self.scene.scalar_texture(texels) {
                    return Ok(t.texels);
                }
                // width × height is the number of values (the kernels read neither).
                let values = self.scene.params.entry(texels).len;
                self.scene.scalar_textures.push(ScalarTexture {
                    texels,
                    width: values,
                    height: 1,
                    nearest: true,
                    wrap: crate::scene::Wrap::Repeat,
                    checker: false,
                    to_uv: [glam::Vec3::X, glam::Vec3::Y],
                    attribute: Some(source),
                });
                return Ok(texels);
            }
            "checkerboard" => {
                let color0 = self.float_in(&p, "color0", Some(0.4), range)?;
                let color1 = self.float_in(&p, "color1", Some(0.2), range)?;
                let to_uv = self.to_uv(&p)?;
                self.finish(&p)?;
                // Mitsuba 3.9.1's checkerboard, looked up as a float (its `eval_1`), reads
                // `color1` where its colour lookup reads `color0` and the other way round: the
                // parameters are added `color1` first, so texel 0 (read where the halves agree)
                // is `color1`, as Mitsuba renders it.
                let first = self.scene.params.add(&format!("{name}.color1.value"), &[color1], range);
                let first = first.map_err(|e| self.located(target, e))?;
                let second = self.scene.params.add(&format!("{name}.color0.value"), &[color0], range);
                let second = second.map_err(|e| self.located(target, e))?;
                // The kernels read the two colours as two neighbouring texels.
                debug_assert_eq!(self.scene.params.entry(second).offset, self.scene.params.entry(first).offset + 1);
                ScalarTexture {
                    texels: first,
                    width: 2,
                    height: 1,
                    nearest: true,
                    wrap: crate::scene::Wrap::Repeat,
                    checker: true,
                    to_uv,
                    attribute: None,
                }
            }
            "bitmap" => {
                let bitmap = self.bitmap(&p, target, "")?;
                let (file, file_node) = p.string(&self.x, "filename")?.unwrap_or_else(|| (String::new(), target));
                let mut texels = Vec::with_capacity(bitmap.texels.len() / 3);
                for (i, c) in bitmap.texels.chunks(3).enumerate() {
                    if !(c[0] == c[1] && c[1] == c[2]) {
                        return Err(self.x.err(
                            file_node,
                            format!(
                                "'{file}': texel ({}, {}) is not grey ({}, {}, {}): a texture on the float property \
                                 '{}' must have one channel (pathgrad does not reduce RGB to its luminance)",
                                i % bitmap.width as usize,
                                i / bitmap.width as usize,
                                c[0],
                                c[1],
                                c[2],
                                name.rsplit('.').next().unwrap_or(&name)
                            ),
                        ));
                    }
                    if !(c[0] >= range.0 && c[0] <= range.1) {
                        return Err(self.x.err(
                            file_node,
                            format!(
                                "'{file}': texel ({}, {}) has value {} outside [{}, {}]",
                                i % bitmap.width as usize,
                                i / bitmap.width as usize,
                                c[0],
                                range.0,
                                range.1
                            ),
                        ));
                    }
                    texels.push(c[0]);
                }
                let to_uv = self.to_uv(&p)?;
                self.finish(&p)?;
                let id = self.scene.params.add(&format!("{name}.data"), &texels, range);
                ScalarTexture {
                    texels: id.map_err(|e| self.located(target, e))?,
                    width: bitmap.width,
                    height: bitmap.height,
                    nearest: bitmap.nearest,
                    wrap: bitmap.wrap,
                    checker: false,
                    to_uv,
                    attribute: None,
                }
            }
            other => {
                return Err(self.x.err(
                    target,
                    format!(
                        "unsupported plugin '{other}' on a float property (supported: bitmap, checkerboard, mesh_attribute; all \
                         textures: {})",
                        names(Category::Texture)
                    ),
                ));
            }
        };
        let id = texture.texels;
        self.scene.scalar_textures.push(texture);
        self.scalar_textures.insert(target.id(), id);
        Ok(id)
    }
}
