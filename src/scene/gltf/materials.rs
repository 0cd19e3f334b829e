//! glTF materials and their images as pathgrad materials and texture parameters.

use ::gltf::json;
use glam::Vec3;
use json::validation::Checked;

use crate::bsdf::Distribution;
use crate::error::Result;
use crate::params::ParamId;
use crate::scene::{Albedo, Material, Scene, SmoothColour, bounds};

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
        if m.occlusion_texture.is_some() {
            ignored.push("occlusionTexture (the path tracer computes occlusion itself)");
        }
        if !matches!(m.alpha_mode, Checked::Valid(json::material::AlphaMode::Opaque)) {
            ignored.push("alphaMode (rendered as OPAQUE)");
        }
        if !ignored.is_empty() {
            self.scene.warn(format!("{at} ('{name}'): ignored {}", ignored.join(", ")));
        }

        let base = Vec3::new(factor[0], factor[1], factor[2]);
        let alpha = (roughness * roughness).max(bounds::ALPHA.0);
        // Every texture of a material reads one set of texture coordinates: the first one's.
        let mut tex_coord: Option<(u32, &str)> = None;
        let mut same_set = |this: &Self, what: &'static str, set: u32| match tex_coord {
            Some((first, by)) if first != set => Err(this.error(
                &at,
                format!(
                    "{what} reads TEXCOORD_{set} but {by} TEXCOORD_{first}: pathgrad reads one set of texture \
                     coordinates a primitive"
                ),
            )),
            _ => {
                tex_coord = Some((set, what));
                Ok(())
            }
        };
        // The base-colour texture, linear and multiplied by the factor.
        let mut base_texels = None;
        let mut mean = base;
        if let Some(info) = &pbr.base_color_texture {
            same_set(self, "baseColorTexture", info.tex_coord)?;
            let image = root.textures[info.index.value()].source.value();
            let (w, h, texels) = self.image_texels(image, base)?;
            let sum = texels.chunks_exact(3).fold(Vec3::ZERO, |s, t| s + Vec3::new(t[0], t[1], t[2]));
            mean = sum / (w as f32 * h as f32);
            base_texels = Some((w, h, texels));
        }
        // The metallic-roughness texture: roughness in G, metallic in B (stored values, no
        // transfer function), each times its factor.
        let mut metal_rough = None;
        if let Some(info) = &pbr.metallic_roughness_texture {
            same_set(self, "metallicRoughnessTexture", info.tex_coord)?;
            let image = root.textures[info.index.value()].source.value();
            let (w, h, texels) = self.image_texels_linear(image)?;
            let (rough, metal): (Vec<f32>, Vec<f32>) = texels
                .chunks_exact(3)
                .map(|t| ((t[1] * roughness).clamp(0.0, 1.0), (t[2] * metallic).clamp(0.0, 1.0)))
                .unzip();
            metal_rough = Some((w, h, rough, metal));
        }
        // The emissive texture, sRGB decoded (times the factor and strength below).
        let mut emissive = None;
        if let Some(info) = &m.emissive_texture {
            same_set(self, "emissiveTexture", info.tex_coord)?;
            let image = root.textures[info.index.value()].source.value();
            let (w, h, mut texels) = self.image_texels_linear(image)?;
            texels.iter_mut().for_each(|c| *c = srgb_to_linear(*c));
            emissive = Some((w, h, texels));
        }
        // The normal texture, its `scale` folded into the texels: n = (2·rgb − 1)·(s, s, 1),
        // stored as (n + 1)/2 (the kernels normalise the mapped normal).
        let normal_map = match &m.normal_texture {
            None => None,
            Some(info) => {
                same_set(self, "normalTexture", info.tex_coord)?;
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
        let tex_coord = tex_coord.map(|(set, _)| set);

        // α = max(r², 10⁻³) per texel of a roughness texture, else one value.
        let alpha_slot = |scene: &mut Scene, prefix: &str| -> Result<ParamId> {
            match &metal_rough {
                Some((w, h, rough, _)) => {
                    let texels: Vec<f32> = rough.iter().map(|r| (r * r).max(bounds::ALPHA.0)).collect();
                    scene.add_scalar_texture(&format!("{prefix}.alpha.data"), *w, *h, &texels, bounds::ALPHA)
                }
                None => scene.params.add(&format!("{prefix}.alpha.value"), &[alpha], bounds::ALPHA),
            }
        };
        let conductor = |scene: &mut Scene, alpha: ParamId, specular: Albedo| {
            let (eta, k) = (Vec3::ZERO, Vec3::ONE);
            scene.add_material(Material::RoughConductor {
                distribution: Distribution::Ggx,
                alpha,
                alpha_v: alpha,
                specular,
                eta,
                k,
                eta_param: None,
            })
        };
        let textured_metal = metal_rough.is_some() && metallic > 0.0 && !transmits;
        if base_texels.is_some() && (metallic > 0.0 || transmits) && !textured_metal {
            self.scene.warn(format!(
                "{at} ('{name}'): the base-colour texture tints only the diffuse part; the metallic and transmitting \
                 parts use its mean colour {mean}"
            ));
        }
        let id = if textured_metal {
            // Per texel of the metallic-roughness texture: w = F0 + (1 − F0)·m and
            // s = (m·b + F0·(1 − m))/w, b the base colour there.
            let (w, h, _, metal) = metal_rough.as_ref().expect("textured_metal");
            let (w, h) = (*w, *h);
            let colour_at = |i: usize| match &base_texels {
                None => base,
                Some((bw, bh, texels)) if (*bw, *bh) == (w, h) => Vec3::from_slice(&texels[3 * i..3 * i + 3]),
                Some((bw, bh, texels)) => {
                    let (u, v) =
                        (((i % w as usize) as f32 + 0.5) / w as f32, ((i / w as usize) as f32 + 0.5) / h as f32);
                    bilinear_repeat(texels, *bw, *bh, u, v)
                }
            };
            if base_texels.as_ref().is_some_and(|(bw, bh, _)| (*bw, *bh) != (w, h)) {
                self.scene.warn(format!(
                    "{at} ('{name}'): the base-colour and metallic-roughness textures differ in size: the metallic \
                     part's colour is the base colour resampled at the metallic-roughness texels"
                ));
            }
            let mut weights = Vec::with_capacity(metal.len());
            let mut specular = Vec::with_capacity(3 * metal.len());
            for (i, &m) in metal.iter().enumerate() {
                let wt = f0 + (1.0 - f0) * m;
                weights.push(wt);
                let s = ((m * colour_at(i) + Vec3::splat(f0 * (1.0 - m))) / wt).min(Vec3::ONE);
                specular.extend_from_slice(&s.to_array());
            }
            let diffuse = match &base_texels {
                Some((bw, bh, texels)) => {
                    let t = self.scene.add_texture(&format!("{name}.base_color.data"), *bw, *bh, texels)?;
                    self.scene.add_material(Material::Diffuse { albedo: Albedo::Bitmap(t) })
                }
                None => self.scene.add_diffuse(&format!("{name}.bsdf_0"), base)?,
            };
            let alpha = alpha_slot(&mut self.scene, &format!("{name}.bsdf_1"))?;
            let specular =
                self.scene.add_texture(&format!("{name}.bsdf_1.specular_reflectance.data"), w, h, &specular)?;
            let lobe = conductor(&mut self.scene, alpha, Albedo::Bitmap(specular));
            let weight =
                self.scene.add_scalar_texture(&format!("{name}.weight.data"), w, h, &weights, bounds::WEIGHT)?;
            self.scene.add_material(Material::Blend { weight, children: [diffuse, lobe] })
        } else if metallic >= 1.0 {
            let alpha = alpha_slot(&mut self.scene, &name)?;
            let specular = self.scene.params.add(
                &format!("{name}.specular_reflectance.value"),
                &mean.to_array(),
                bounds::REFLECTANCE,
            )?;
            conductor(&mut self.scene, alpha, Albedo::Rgb(specular))
        } else if transmits {
            if transmission_factor < 1.0 || metallic > 0.0 {
                self.scene.warn(format!(
                    "{at} ('{name}'): transmissionFactor {transmission_factor} with metallic {metallic} is rendered as \
                     a rough dielectric alone (transmission 1, metallic 0): its diffuse and metallic shares are dropped"
                ));
            }
            let alpha = alpha_slot(&mut self.scene, &name)?;
            let transmittance = self.scene.params.add(
                &format!("{name}.specular_transmittance.value"),
                &mean.to_array(),
                bounds::REFLECTANCE,
            )?;
            self.scene.add_material(Material::RoughDielectric {
                distribution: Distribution::Ggx,
                alpha,
                alpha_v: alpha,
                reflectance: SmoothColour::Constant(Vec3::ONE),
                transmittance: SmoothColour::Param(transmittance),
                eta: ior,
                eta_param: None,
            })
        } else {
            let weight = f0 + (1.0 - f0) * metallic;
            let specular = ((metallic * mean + Vec3::splat(f0 * (1.0 - metallic))) / weight).min(Vec3::ONE);
            let diffuse = match &base_texels {
                Some((w, h, texels)) => {
                    let t = self.scene.add_texture(&format!("{name}.base_color.data"), *w, *h, texels)?;
                    self.scene.add_material(Material::Diffuse { albedo: Albedo::Bitmap(t) })
                }
                None => self.scene.add_diffuse(&format!("{name}.bsdf_0"), base)?,
            };
            let alpha = alpha_slot(&mut self.scene, &format!("{name}.bsdf_1"))?;
            let specular = self.scene.params.add(
                &format!("{name}.bsdf_1.specular_reflectance.value"),
                &specular.to_array(),
                bounds::REFLECTANCE,
            )?;
            let lobe = conductor(&mut self.scene, alpha, Albedo::Rgb(specular));
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
        // An emissive texture's texels times the factor and strength (each mesh gets its own
        // parameter: `add_primitive`).
        let emission = match emissive {
            Some((w, h, texels)) if radiance.max_element() > 0.0 => {
                let texels = texels.chunks_exact(3).flat_map(|t| (Vec3::from_slice(t) * radiance).to_array()).collect();
                Some(Emission::Texture { width: w, height: h, texels })
            }
            _ => (radiance.max_element() > 0.0).then_some(Emission::Constant(radiance)),
        };
        let mapped = MappedMaterial { id, emission, tex_coord, normal_mapped: normal_map.is_some() };
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

/// The bilinear lookup, repeating, of RGB `texels` (`width × height`, row 0 at v = 0) at `(u, v)`,
/// as the kernels filter a texture.
fn bilinear_repeat(texels: &[f32], width: u32, height: u32, u: f32, v: f32) -> Vec3 {
    let (offset, weight) = crate::cpu::surface::texture_footprint(0, width, height, 0, glam::Vec2::new(u, v));
    offset.iter().zip(weight).map(|(&o, w)| Vec3::from_slice(&texels[o as usize..o as usize + 3]) * w).sum()
}
