//! glTF materials and their images as pathgrad materials and texture parameters.

use ::gltf::json;
use glam::Vec3;
use json::validation::Checked;

use crate::bsdf::Distribution;
use crate::error::Result;
use crate::scene::{Albedo, Material, bounds};

use super::*;

impl Loader<'_> {
    /// The pathgrad material of glTF material `index` (`None`: the default material), mapped once.
    pub(super) fn material(&mut self, index: Option<usize>) -> Result<MappedMaterial> {
        let root = self.root;
        let slot = index.unwrap_or(root.materials.len());
        if let Some(mapped) = &self.materials[slot] {
            return Ok(mapped.clone());
        }
        let default = json::Material::default();
        let (m, name, at) = match index {
            Some(i) => (&root.materials[i], self.material_names[i].clone(), format!("materials[{i}]")),
            None => (&default, "default_material".to_string(), "default material".to_string()),
        };
        let pbr = &m.pbr_metallic_roughness;
        let factor = pbr.base_color_factor.0;
        let (metallic, roughness) = (pbr.metallic_factor.0, pbr.roughness_factor.0);
        let in_unit = |v: f32| (0.0..=1.0).contains(&v);
        if !factor.iter().all(|&v| in_unit(v)) {
            return Err(self.error(&at, format!("baseColorFactor {factor:?} must lie in [0, 1]")));
        }
        if !in_unit(metallic) || !in_unit(roughness) {
            return Err(self
                .error(&at, format!("metallicFactor {metallic} and roughnessFactor {roughness} must lie in [0, 1]")));
        }
        let ext = m.extensions.as_ref();
        let ior = ext.and_then(|e| e.ior.as_ref()).map_or(1.5, |i| i.ior.0);
        if !(ior >= 1.0 && ior.is_finite()) {
            return Err(self.error(&at, format!("KHR_materials_ior: ior {ior} must be ≥ 1 (0 is not supported)")));
        }
        // The dielectric's reflectance at normal incidence (0.04 at glTF's default ior 1.5).
        let f0 = ((ior - 1.0) / (ior + 1.0)).powi(2);
        let transmission = ext.and_then(|e| e.transmission.as_ref());
        let transmission_factor = transmission.map_or(0.0, |t| t.transmission_factor.0);
        if !in_unit(transmission_factor) {
            return Err(self.error(&at, format!("transmissionFactor {transmission_factor} must lie in [0, 1]")));
        }
        let transmits = transmission_factor > 0.0 && metallic < 1.0;
        if transmits && ior == 1.0 {
            return Err(self.error(&at, "a transmitting material needs an ior other than 1 (it would not refract)"));
        }
        let mut ignored = Vec::new();
        if transmission.is_some_and(|t| t.transmission_texture.is_some()) {
            ignored.push("transmissionTexture");
        }
        if pbr.metallic_roughness_texture.is_some() {
            ignored.push("metallicRoughnessTexture");
        }
        if m.occlusion_texture.is_some() {
            ignored.push("occlusionTexture");
        }
        if m.emissive_texture.is_some() {
            ignored.push("emissiveTexture");
        }
        if !matches!(m.alpha_mode, Checked::Valid(json::material::AlphaMode::Opaque)) {
            ignored.push("alphaMode (rendered as OPAQUE)");
        }
        if !ignored.is_empty() {
            self.scene.warn(format!("{at} ('{name}'): ignored {}", ignored.join(", ")));
        }

        let base = Vec3::new(factor[0], factor[1], factor[2]);
        let alpha = (roughness * roughness).max(bounds::ALPHA.0);
        // The base-colour texture, linear and multiplied by the factor.
        let mut texture = None;
        let mut mean = base;
        let mut tex_coord = None;
        if let Some(info) = &pbr.base_color_texture {
            let image = root.textures[info.index.value()].source.value();
            let (w, h, texels) = self.image_texels(image, base)?;
            let sum = texels.chunks_exact(3).fold(Vec3::ZERO, |s, t| s + Vec3::new(t[0], t[1], t[2]));
            mean = sum / (w as f32 * h as f32);
            if metallic > 0.0 || transmits {
                self.scene.warn(format!(
                    "{at} ('{name}'): the base-colour texture tints only the diffuse part; the metallic and \
                     transmitting parts use its mean colour {mean}"
                ));
            }
            if metallic < 1.0 && !transmits {
                texture = Some(self.scene.add_texture(&format!("{name}.base_color.data"), w, h, &texels)?);
            }
            tex_coord = Some(info.tex_coord);
        }
        // The normal texture, its `scale` folded into the texels: n = (2·rgb − 1)·(s, s, 1),
        // stored as (n + 1)/2 (the kernels normalise the mapped normal).
        let normal_map = match &m.normal_texture {
            None => None,
            Some(info) => {
                if let Some(set) = tex_coord.filter(|&set| set != info.tex_coord) {
                    return Err(self.error(
                        &at,
                        format!(
                            "normalTexture reads TEXCOORD_{} but baseColorTexture TEXCOORD_{set}: pathgrad reads one \
                             set of texture coordinates a primitive",
                            info.tex_coord
                        ),
                    ));
                }
                tex_coord = Some(info.tex_coord);
                let scale = info.scale;
                if !scale.is_finite() {
                    return Err(self.error(&at, format!("normalTexture scale {scale} must be finite")));
                }
                let image = root.textures[info.index.value()].source.value();
                let (width, height, mut texels) = self.image_texels_linear(image)?;
                for t in texels.chunks_exact_mut(3) {
                    for c in &mut t[..2] {
                        *c = ((2.0 * *c - 1.0) * scale + 1.0) * 0.5;
                    }
                }
                let map = crate::scene::NormalMapTexture {
                    width,
                    height,
                    texels,
                    nearest: false,
                    wrap: crate::scene::Wrap::Repeat,
                };
                self.scene.normal_maps.push(map);
                Some(self.scene.normal_maps.len() as u32 - 1)
            }
        };
        let id = if metallic >= 1.0 {
            self.scene.add_rough_conductor(&name, Distribution::Ggx, alpha, mean, Vec3::ZERO, Vec3::ONE)?
        } else if transmits {
            if transmission_factor < 1.0 || metallic > 0.0 {
                self.scene.warn(format!(
                    "{at} ('{name}'): transmissionFactor {transmission_factor} with metallic {metallic} is rendered as \
                     a rough dielectric alone (transmission 1, metallic 0): its diffuse and metallic shares are dropped"
                ));
            }
            self.scene.add_rough_dielectric(&name, alpha, mean, ior)?
        } else {
            let weight = f0 + (1.0 - f0) * metallic;
            let specular = ((metallic * mean + Vec3::splat(f0 * (1.0 - metallic))) / weight).min(Vec3::ONE);
            let diffuse = match texture {
                Some(t) => self.scene.add_material(Material::Diffuse { albedo: Albedo::Bitmap(t) }),
                None => self.scene.add_diffuse(&format!("{name}.bsdf_0"), base)?,
            };
            let lobe = self.scene.add_rough_conductor(
                &format!("{name}.bsdf_1"),
                Distribution::Ggx,
                alpha,
                specular,
                Vec3::ZERO,
                Vec3::ONE,
            )?;
            self.scene.add_blend(&name, weight, [diffuse, lobe])?
        };
        let id = match normal_map {
            Some(map) => self.scene.add_material(Material::NormalMap { nested: id, map }),
            None => id,
        };
        // A dielectric is seen from both sides already (and a two-sided one would hide its inside).
        let id = if m.double_sided && !transmits { self.scene.add_material(Material::TwoSided(id)) } else { id };

        let strength =
            m.extensions.as_ref().and_then(|e| e.emissive_strength.as_ref()).map_or(1.0, |s| s.emissive_strength.0);
        let radiance = Vec3::from(m.emissive_factor.0) * strength;
        if !(radiance.is_finite() && radiance.min_element() >= 0.0) {
            return Err(self.error(
                &at,
                format!("emitted radiance {radiance} (emissiveFactor × emissiveStrength) must be finite and ≥ 0"),
            ));
        }
        let mapped = MappedMaterial {
            id,
            radiance: (radiance.max_element() > 0.0).then_some(radiance),
            tex_coord,
            normal_mapped: normal_map.is_some(),
        };
        self.materials[slot] = Some(mapped.clone());
        Ok(mapped)
    }

    /// Image `index` decoded to linear RGB texels (sRGB decoded, times `factor`), row 0 at the top.
    pub(super) fn image_texels(&mut self, index: usize, factor: Vec3) -> Result<(u32, u32, Vec<f32>)> {
        let (width, height, mut texels) = self.image_texels_linear(index)?;
        for t in texels.chunks_exact_mut(3) {
            for c in 0..3 {
                t[c] = (srgb_to_linear(t[c]) * factor[c]).clamp(0.0, 1.0);
            }
        }
        Ok((width, height, texels))
    }

    /// Image `index`'s RGB as stored (values / 255 for 8-bit images; no transfer function), row 0
    /// at the top (v = 0).
    pub(super) fn image_texels_linear(&mut self, index: usize) -> Result<(u32, u32, Vec<f32>)> {
        let root = self.root;
        let image = &root.images[index];
        let at = format!("images[{index}]");
        let bytes = match (&image.buffer_view, &image.uri) {
            (Some(view), _) => self.view(view.value(), &at)?.0.to_vec(),
            (None, Some(uri)) => self.read_uri(&at, uri)?,
            (None, None) => return Err(self.error(at, "has neither a uri nor a bufferView")),
        };
        let decoded =
            crate::scene::load::decode_image(&bytes).map_err(|e| self.error(&at, format!("cannot decode: {e}")))?;
        let rgb = decoded.to_rgb32f();
        Ok((rgb.width(), rgb.height(), rgb.into_raw()))
    }
}
