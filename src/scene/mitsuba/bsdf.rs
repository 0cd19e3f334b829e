//! `<bsdf>` (diffuse, roughconductor, roughplastic, blendbsdf, twosided, mask, …) and `<texture
//! type="bitmap">`.

use super::plugins::{Category, names};
use glam::Vec3;

use super::loader::{Loader, MAX_NESTING};
use super::xml::{El, Props};
use crate::bsdf::Distribution;
use crate::bsdf::specular::SmoothKind;
use crate::error::Result;
use crate::scene::{Albedo, Material, MaterialId, NormalMapTexture, SmoothColour, Wrap, bounds};

/// Mitsuba's named indices of refraction (`int_ior`, `ext_ior` as a string).
const IORS: &[(&str, f32)] = &[
    ("vacuum", 1.0),
    ("helium", 1.000_036),
    ("hydrogen", 1.000_132),
    ("air", 1.000_277),
    ("carbon dioxide", 1.000_45),
    ("water", 1.333),
    ("acetone", 1.36),
    ("ethanol", 1.361),
    ("carbon tetrachloride", 1.461),
    ("glycerol", 1.4729),
    ("benzene", 1.501),
    ("silicone oil", 1.520_45),
    ("bromine", 1.661),
    ("water ice", 1.31),
    ("fused quartz", 1.458),
    ("pyrex", 1.47),
    ("acrylic glass", 1.49),
    ("polypropylene", 1.49),
    ("bk7", 1.5046),
    ("sodium chloride", 1.544),
    ("amber", 1.55),
    ("pet", 1.575),
    ("diamond", 2.419),
];

/// Conductor presets for `roughconductor`'s `material`: RGB (eta, k) for Au, Ag, Cu, Al, Cr and a-C,
/// the widely used RGB reductions of the measured spectra that Mitsuba tabulates (as in Mitsuba
/// 0.5's RGB mode and Tungsten), rounded to 4 decimals. Mitsuba 3 in an RGB variant integrates the
/// spectral curves itself, so colours can differ slightly: give `eta` and `k` explicitly for an
/// exact match. `none` is Mitsuba's default: eta = 0, k = 1, Fresnel ≡ 1.
const CONDUCTORS: &[(&str, [f32; 3], [f32; 3])] = &[
    ("none", [0.0, 0.0, 0.0], [1.0, 1.0, 1.0]),
    ("Au", [0.1431, 0.375, 1.4425], [3.9832, 2.3857, 1.6032]),
    ("Ag", [0.1553, 0.1167, 0.1384], [4.8283, 3.1222, 2.147]),
    ("Cu", [0.2004, 0.924, 1.1022], [3.9129, 2.4528, 2.1422]),
    ("Al", [1.6575, 0.8804, 0.5212], [9.2239, 6.2695, 4.837]),
    ("Cr", [4.3697, 2.9167, 1.6547], [5.2064, 4.2314, 3.7549]),
    // Amorphous carbon: the RGB values Mitsuba 3.9.1's `scalar_rgb` variant computes (its
    // `traverse` of a roughconductor with this preset).
    ("a-C", [2.94405, 2.22714, 1.96816], [0.887465, 0.799299, 0.81529]),
];

/// The (eta, k) of conductor preset `name`.
pub(super) fn conductor(name: &str) -> Option<(Vec3, Vec3)> {
    CONDUCTORS.iter().find(|(n, _, _)| *n == name).map(|(_, eta, k)| (Vec3::from_array(*eta), Vec3::from_array(*k)))
}

impl<'a> Loader<'a> {
    /// Builds (once) the BSDF `node` — a `<bsdf>` or a `<ref>` to one — named `name`, the path
    /// that reached it, unless the scene level named it first ([`Loader::name_of`]).
    ///
    /// # Errors
    /// Anything wrong with the BSDF or its children, reference cycles, nesting past
    /// [`MAX_NESTING`].
    pub(super) fn bsdf(&mut self, node: El<'a>, name: String, depth: usize) -> Result<MaterialId> {
        let target = self.deref(node)?;
        if !target.has_tag_name("bsdf") {
            return Err(self.x.err(node, format!("refers to a <{}>, expected a <bsdf>", target.tag_name().name())));
        }
        if let Some(&m) = self.materials.get(&target.id()) {
            let mesh = self.attribute_shape.as_ref().map(|s| s.mesh);
            if let Some(&owner) = self.attribute_owners.get(&target.id())
                && Some(owner) != mesh
            {
                return Err(self.x.err(
                    node,
                    format!(
                        "this BSDF reads the mesh attributes of shape '{}' and cannot be shared with another shape \
                         (give each shape its own BSDF)",
                        self.scene.meshes.get(owner as usize).map_or("?", |m| m.name.as_str())
                    ),
                ));
            }
            return Ok(m);
        }
        if self.in_progress.contains(&target.id()) {
            return Err(self.x.err(node, "reference cycle: this BSDF contains itself"));
        }
        if depth > MAX_NESTING {
            return Err(self.x.err(node, format!("BSDFs and textures nest more than {MAX_NESTING} deep")));
        }
        let name = self.name_of(target, name)?;
        self.in_progress.push(target.id());
        let reads = self.attribute_reads;
        let built = self.bsdf_body(target, &name, depth);
        self.in_progress.pop();
        let m = built?;
        self.materials.insert(target.id(), m);
        if self.attribute_reads > reads
            && let Some(shape) = &self.attribute_shape
        {
            self.attribute_owners.insert(target.id(), shape.mesh);
        }
        Ok(m)
    }

    fn bsdf_body(&mut self, node: El<'a>, name: &str, depth: usize) -> Result<MaterialId> {
        let p = Props::parse(&self.x, node)?;
        let m = match p.kind.as_str() {
            "diffuse" => {
                if let Some(t) = p.object("reflectance") {
                    self.finish(&p)?;
                    let albedo = self.texture(t, format!("{name}.reflectance"), depth + 1)?;
                    self.scene.add_material(Material::Diffuse { albedo })
                } else {
                    let albedo = self.color_in(&p, "reflectance", Vec3::splat(0.5), bounds::REFLECTANCE)?;
                    self.scene.add_diffuse(name, albedo).map_err(|e| self.located(node, e))?
                }
            }
            "roughconductor" => self.rough_conductor(&p, name)?,
            "roughplastic" => self.rough_plastic(&p, name, depth)?,
            "plastic" => self.smooth_plastic(&p, name, depth)?,
            "roughdielectric" => self.rough_dielectric(&p, name, depth)?,
            "principled" => self.principled(&p, name, depth)?,
            "principledthin" => self.principled_thin(&p, name, depth)?,
            "conductor" => self.smooth(&p, name, SmoothKind::Conductor, depth)?,
            "dielectric" => self.smooth(&p, name, SmoothKind::Dielectric, depth)?,
            "thindielectric" => self.smooth(&p, name, SmoothKind::ThinDielectric, depth)?,
            "null" => {
                self.finish(&p)?;
                self.scene.add_material(Material::Null)
            }
            "mask" => self.mask(&p, name, depth)?,
            "normalmap" => self.normal_map(&p, name, depth)?,
            "bumpmap" => self.bump_map(&p, name, depth)?,
            "blendbsdf" => {
                // The weight's parameter follows the children's, as it always has (a texture's too).
                let weight_texture = p.object("weight");
                let weight_value = match weight_texture {
                    None => Some(self.float_in(&p, "weight", None, bounds::WEIGHT)?),
                    Some(_) => None,
                };
                let children = p.take_nested(&["bsdf", "ref"]);
                let [c0, c1] = children[..] else {
                    return Err(self.x.err(node, format!("'blendbsdf' needs 2 nested BSDFs, got {}", children.len())));
                };
                self.finish(&p)?;
                let a = self.bsdf(c0, format!("{name}.bsdf_0"), depth + 1)?;
                let b = self.bsdf(c1, format!("{name}.bsdf_1"), depth + 1)?;
                let weight = match (weight_texture, weight_value) {
                    (Some(t), _) => self.scalar_texture(t, format!("{name}.weight"), bounds::WEIGHT)?,
                    (None, value) => {
                        let id = self.scene.params.add(
                            &format!("{name}.weight.value"),
                            &[value.unwrap_or(0.0)],
                            bounds::WEIGHT,
                        );
                        id.map_err(|e| self.located(node, e))?
                    }
                };
                let (ma, mb) = (self.material(a), self.material(b));
                match (ma, mb) {
                    (Some(Material::TwoSided(a)), Some(Material::TwoSided(b)))
                        if self.is_leaf(a) && self.is_leaf(b) =>
                    {
                        // blend(twosided(a), twosided(b)) = twosided(blend(a, b)).
                        let blend = self.scene.add_material(Material::Blend { weight, children: [a, b] });
                        self.scene.add_material(Material::TwoSided(blend))
                    }
                    _ if self.is_leaf(a) && self.is_leaf(b) => {
                        self.scene.add_material(Material::Blend { weight, children: [a, b] })
                    }
                    _ if (self.is_leaf(a) && self.is_smooth_conductor(b))
                        || (self.is_smooth_conductor(a) && self.is_leaf(b)) =>
                    {
                        self.warn_blend_with_delta(node);
                        self.scene.add_material(Material::Blend { weight, children: [a, b] })
                    }
                    _ => {
                        return Err(self.x.err(
                            node,
                            "'blendbsdf' children must both be diffuse/roughconductor/roughplastic, one of those and \
                             a smooth 'conductor', or both twosided wrappers of diffuse/roughconductor/roughplastic \
                             (pathgrad blends two leaf BSDFs)",
                        ));
                    }
                }
            }
            "twosided" => {
                let children = p.take_nested(&["bsdf", "ref"]);
                let child = match children[..] {
                    [c] => c,
                    [_, _] => {
                        return Err(self
                            .x
                            .err(node, "'twosided' with different front and back BSDFs is not supported (give one)"));
                    }
                    _ => {
                        return Err(self
                            .x
                            .err(node, format!("'twosided' needs 1 nested BSDF, got {}", children.len())));
                    }
                };
                self.finish(&p)?;
                let c = self.bsdf(child, format!("{name}.brdf_0"), depth + 1)?;
                if matches!(self.material(c), Some(Material::TwoSided(_))) {
                    return Err(self.x.err(child, "a 'twosided' BSDF cannot wrap another twosided one"));
                }
                if self.is_blend_with_delta(c) {
                    return Err(self.x.err(
                        child,
                        "a 'twosided' around a 'blendbsdf' holding a smooth 'conductor' is not supported",
                    ));
                }
                // What a normal map wraps is what transmits or not.
                let mut inner = c;
                while let Some(
                    Material::NormalMap { nested, .. }
                    | Material::BumpMap { nested, .. }
                    | Material::Mask { nested, .. },
                ) = self.material(inner)
                {
                    inner = nested;
                }
                let transmits = matches!(self.material(inner), Some(Material::Smooth { kind, .. }) if kind != SmoothKind::Conductor)
                    || matches!(self.material(inner), Some(Material::RoughDielectric { .. }))
                    || self.principled_transmits(inner)
                    || matches!(self.material(inner), Some(Material::PrincipledThin { .. }));
                if transmits {
                    return Err(self.x.err(
                        child,
                        "a 'twosided' BSDF cannot wrap one that transmits light (Mitsuba refuses it too)",
                    ));
                }
                self.scene.add_material(Material::TwoSided(c))
            }
            other => {
                return Err(self
                    .x
                    .err(node, format!("unsupported plugin '{other}' (supported: {})", names(Category::Bsdf))));
            }
        };
        self.finish(&p)?;
        Ok(m)
    }

    fn material(&self, id: MaterialId) -> Option<Material> {
        self.scene.materials.get(id.0 as usize).cloned()
    }

    /// Whether material `id` is a smooth `conductor` (a blend may hold one beside a leaf).
    fn is_smooth_conductor(&self, id: MaterialId) -> bool {
        matches!(self.material(id), Some(Material::Smooth { kind: SmoothKind::Conductor, .. }))
    }

    /// Whether material `id` is a blend holding a smooth leaf (wrappers around one are refused).
    fn is_blend_with_delta(&self, id: MaterialId) -> bool {
        match self.material(id) {
            Some(Material::Blend { children: [a, b], .. }) => {
                self.is_smooth_conductor(a) || self.is_smooth_conductor(b)
            }
            _ => false,
        }
    }

    /// Mitsuba 3.9.1's `blendbsdf` combines a sample of one child with the other child's density
    /// as one-sample MIS: `(w·f̂₁ + (1 − w)·f̂₀)/(w·p₁ + (1 − w)·p₀)`. For a smooth child, whose
    /// `p` is a discrete probability (1) and not a density, that sum mixes a probability with the
    /// other child's density: the delta lobe's light comes out weighted by
    /// `w·F/(w + (1 − w)·p₀)` instead of `F`, too dark wherever the other child's density is
    /// positive (a mirror blended half and half with black diffuse: 0.39 instead of 0.5 at
    /// normal incidence). pathgrad renders the correct expectation; it says so.
    fn warn_blend_with_delta(&mut self, node: El<'a>) {
        let w = self.x.warning(
            node,
            "'blendbsdf' with a smooth 'conductor': Mitsuba 3.9.1's blendbsdf weighs the smooth child's samples by \
             a mixture of its discrete probability and the other child's density, which renders the mirror \
             reflection too dark; pathgrad renders the correct image (not Mitsuba's)",
        );
        self.scene.warn(w);
    }

    fn is_leaf(&self, id: MaterialId) -> bool {
        matches!(
            self.material(id),
            Some(Material::Diffuse { .. } | Material::RoughConductor { .. } | Material::RoughPlastic { .. })
        )
    }

    /// A microfacet BSDF's `distribution` (Beckmann by default).
    fn distribution(&self, p: &Props<'a>) -> Result<Distribution> {
        Ok(match p.string(&self.x, "distribution")? {
            None => Distribution::Beckmann,
            Some((s, n)) => match s.as_str() {
                "beckmann" => Distribution::Beckmann,
                "ggx" => Distribution::Ggx,
                _ => {
                    return Err(self.x.err(n, format!("unsupported distribution '{s}' (supported: beckmann, ggx)")));
                }
            },
        })
    }

    /// An index of refraction `name`: a number, or one of Mitsuba's named materials (`default`
    /// when absent).
    fn ior(&self, p: &Props<'a>, name: &str, default: &str) -> Result<f32> {
        let named = |s: &str, n: El<'a>| {
            let lower = s.to_lowercase();
            IORS.iter().find(|(k, _)| *k == lower).map(|&(_, v)| v).ok_or_else(|| {
                let known: Vec<&str> = IORS.iter().map(|c| c.0).collect();
                self.x.err(
                    n,
                    format!("unknown index of refraction '{s}' for '{name}' (a number, or: {})", known.join(", ")),
                )
            })
        };
        let is_string = p.node_of(name).is_some_and(|n| n.has_tag_name("string"));
        if !is_string && let Some((v, n)) = p.float(&self.x, name)? {
            if !(v > 0.0 && v.is_finite()) {
                return Err(self.x.err(n, format!("'{name}' must be a positive number, got {v}")));
            }
            return Ok(v);
        }
        match p.string(&self.x, name)? {
            Some((s, n)) => named(&s, n),
            None => named(default, p.node),
        }
    }

    /// A plastic's `diffuse_reflectance` (texturable, 0.5: `NAME.diffuse_reflectance.value` or
    /// `.data`), `specular_reflectance` (texturable, 1: `NAME.specular_reflectance.value` or
    /// `.data` where the file gives it, as Mitsuba traverses it; [`Loader::specular_colour`]) and
    /// `int_ior`/`ext_ior` (polypropylene in air) as η, and `nonlinear`.
    fn plastic_common(&mut self, p: &Props<'a>, name: &str, depth: usize) -> Result<(Albedo, SmoothColour, f32, bool)> {
        let specular = self.specular_colour(p, name, "specular_reflectance", false, depth)?;
        let (int_ior, ext_ior) = (self.ior(p, "int_ior", "polypropylene")?, self.ior(p, "ext_ior", "air")?);
        if int_ior == ext_ior {
            return Err(self.x.err(p.node, "'int_ior' and 'ext_ior' must differ"));
        }
        let nonlinear = p.boolean(&self.x, "nonlinear", false)?;
        let diffuse = match p.object("diffuse_reflectance") {
            Some(t) => {
                let a = self.texture(t, format!("{name}.diffuse_reflectance"), depth + 1)?;
                self.refuse_volume(a, t, "diffuse_reflectance", &p.kind)?
            }
            None => {
                let rho = self.color_in(p, "diffuse_reflectance", Vec3::splat(0.5), bounds::REFLECTANCE)?;
                let id = self.scene.params.add(
                    &format!("{name}.diffuse_reflectance.value"),
                    &rho.to_array(),
                    bounds::REFLECTANCE,
                );
                Albedo::Rgb(id.map_err(|e| self.located(p.node, e))?)
            }
        };
        Ok((diffuse, specular, int_ior / ext_ior, nonlinear))
    }

    /// Mitsuba's smooth `plastic` ([`Loader::plastic_common`]'s properties).
    fn smooth_plastic(&mut self, p: &Props<'a>, name: &str, depth: usize) -> Result<MaterialId> {
        let (diffuse, specular, eta, nonlinear) = self.plastic_common(p, name, depth)?;
        Ok(self.scene.add_material(Material::SmoothPlastic { diffuse, specular, eta, nonlinear }))
    }

    /// Mitsuba's `roughplastic`: `distribution` (Beckmann), isotropic `alpha` (0.1), texturable
    /// `diffuse_reflectance` (0.5) and `specular_reflectance` (1), `int_ior`
    /// (polypropylene) and `ext_ior` (air), `nonlinear`. Parameters `NAME.alpha` (Mitsuba's key:
    /// its α is a number, not a texture) and `NAME.diffuse_reflectance.value` (or `.data`).
    fn rough_plastic(&mut self, p: &Props<'a>, name: &str, depth: usize) -> Result<MaterialId> {
        let distribution = self.distribution(p)?;
        if p.has("alpha_u") || p.has("alpha_v") {
            return Err(self.x.err(p.node, "'roughplastic' has no anisotropic roughness (Mitsuba refuses it too)"));
        }
        if let Some(t) = p.object("alpha") {
            return Err(self.x.err(t, "a textured 'alpha' of 'roughplastic' is not supported (Mitsuba's is a number)"));
        }
        let alpha = self.float_in(p, "alpha", Some(0.1), bounds::ALPHA)?;
        p.boolean(&self.x, "sample_visible", true)?;
        let (diffuse, specular, eta, nonlinear) = self.plastic_common(p, name, depth)?;
        let alpha = self.scene.params.add(&format!("{name}.alpha"), &[alpha], bounds::ALPHA);
        let alpha = alpha.map_err(|e| self.located(p.node, e))?;
        Ok(self.scene.add_material(Material::RoughPlastic { distribution, alpha, diffuse, specular, eta, nonlinear }))
    }

    /// A conductor's complex index of refraction: `material` (a preset) or `eta`/`k` (Mitsuba's
    /// default: eta 0, k 1, Fresnel ≡ 1).
    fn conductor_ior(&self, p: &Props<'a>) -> Result<(Vec3, Vec3)> {
        let x = &self.x;
        match p.string(x, "material")? {
            Some((m, n)) if m != "none" => {
                if p.has("eta") || p.has("k") {
                    return Err(x.err(n, "give either 'material' or 'eta'/'k', not both"));
                }
                conductor(&m).ok_or_else(|| {
                    let known: Vec<&str> = CONDUCTORS.iter().map(|c| c.0).collect();
                    x.err(n, format!("unknown conductor material '{m}' (supported: {})", known.join(", ")))
                })
            }
            _ => {
                let eta = self.color_in(p, "eta", Vec3::ZERO, (0.0, f32::MAX))?;
                let k = self.color_in(p, "k", Vec3::ONE, (0.0, f32::MAX))?;
                Ok((eta, k))
            }
        }
    }

    /// Mitsuba's smooth `conductor` (`specular_reflectance`, `material` or `eta`/`k`),
    /// `dielectric` and `thindielectric` (`int_ior` bk7, `ext_ior` air, `specular_reflectance`,
    /// `specular_transmittance`). Parameters as Mitsuba's: `NAME.specular_reflectance.value`
    /// always for a conductor, and for the dielectrics each colour only when the file gives it
    /// (a constant otherwise); a textured colour's texels are `NAME.KEY.data`
    /// ([`Loader::specular_colour`]).
    fn smooth(&mut self, p: &Props<'a>, name: &str, kind: SmoothKind, depth: usize) -> Result<MaterialId> {
        let conductor = kind == SmoothKind::Conductor;
        let (eta, k) =
            if conductor { self.conductor_ior(p)? } else { (Vec3::new(self.dielectric_eta(p)?, 0.0, 0.0), Vec3::ZERO) };
        let reflectance = self.specular_colour(p, name, "specular_reflectance", conductor, depth)?;
        let transmittance = if conductor {
            SmoothColour::Constant(Vec3::ZERO)
        } else {
            self.specular_colour(p, name, "specular_transmittance", false, depth)?
        };
        // Mitsuba's `eta` (int_ior / ext_ior) of both dielectrics, a parameter pathgrad
        // differentiates only with attached sampling; a conductor's eta and k (a preset's too),
        // which act on the weight only.
        let eta_param = match conductor {
            true => Some(self.scene.add_conductor_ior(name, eta, k).map_err(|e| self.located(p.node, e))?),
            false => Some(self.scene.params.add(&format!("{name}.eta"), &[eta.x], bounds::IOR)?),
        };
        Ok(self.scene.add_material(Material::Smooth { kind, reflectance, transmittance, eta, k, eta_param }))
    }

    /// A dielectric's η = `int_ior` (bk7) / `ext_ior` (air), which must differ.
    fn dielectric_eta(&self, p: &Props<'a>) -> Result<f32> {
        let (int_ior, ext_ior) = (self.ior(p, "int_ior", "bk7")?, self.ior(p, "ext_ior", "air")?);
        if int_ior == ext_ior {
            return Err(self.x.err(p.node, "'int_ior' and 'ext_ior' must differ"));
        }
        Ok(int_ior / ext_ior)
    }

    /// A microfacet BSDF's roughness as the parameters Mitsuba names: `alpha` (0.1), or both
    /// `alpha_u` and `alpha_v` (Mitsuba requires both), each its own parameter (Mitsuba's
    /// traversal names them apart whenever the file gives both, equal or not). Each may be a
    /// texture ([`Loader::scalar_property`]: texels in [0, 1], clamped to Mitsuba's floor of 10⁻⁴
    /// when looked up). `sample_visible` is read: pathgrad samples visible normals, and `false`
    /// would change only the noise. Returns (α_u, α_v): the same parameter when isotropic.
    fn microfacet_alpha(
        &mut self,
        p: &Props<'a>,
        name: &str,
    ) -> Result<(crate::params::ParamId, crate::params::ParamId)> {
        let anisotropic = p.has("alpha_u") || p.has("alpha_v");
        p.boolean(&self.x, "sample_visible", true)?;
        let texels = (0.0, 1.0);
        if !anisotropic {
            let id = self.scalar_property(p, name, "alpha", Some(0.1), bounds::ALPHA, texels)?;
            return Ok((id, id));
        }
        if p.has("alpha") {
            return Err(self.x.err(p.node, "give either 'alpha' or 'alpha_u'/'alpha_v', not both"));
        }
        if !(p.has("alpha_u") && p.has("alpha_v")) {
            return Err(self.x.err(p.node, "give both 'alpha_u' and 'alpha_v' (Mitsuba requires both)"));
        }
        let u = self.scalar_property(p, name, "alpha_u", None, bounds::ALPHA, texels)?;
        let v = self.scalar_property(p, name, "alpha_v", None, bounds::ALPHA, texels)?;
        Ok((u, v))
    }

    /// Mitsuba's `roughdielectric`: `distribution` (Beckmann), isotropic `alpha` (0.1, parameter
    /// `NAME.alpha.value`), `int_ior` (bk7) and `ext_ior` (air), and `specular_reflectance` /
    /// `specular_transmittance` (1; a parameter `NAME.KEY.value`, or a texture's `NAME.KEY.data`,
    /// only where the file gives it, as Mitsuba's traversal). η = int_ior/ext_ior is the
    /// parameter `NAME.eta` (Mitsuba's key), as a smooth dielectric's: only attached sampling
    /// differentiates it.
    fn rough_dielectric(&mut self, p: &Props<'a>, name: &str, depth: usize) -> Result<MaterialId> {
        let distribution = self.distribution(p)?;
        let (alpha, alpha_v) = self.microfacet_alpha(p, name)?;
        let eta = self.dielectric_eta(p)?;
        let reflectance = self.specular_colour(p, name, "specular_reflectance", false, depth)?;
        let transmittance = self.specular_colour(p, name, "specular_transmittance", false, depth)?;
        let eta_param = Some(self.scene.params.add(&format!("{name}.eta"), &[eta], bounds::IOR)?);
        Ok(self.scene.add_material(Material::RoughDielectric {
            distribution,
            alpha,
            alpha_v,
            reflectance,
            transmittance,
            eta,
            eta_param,
        }))
    }

    /// Mitsuba 3.9.1's `principled`: `base_color` (0.5; a colour, parameter
    /// `NAME.base_color.value`, or a `bitmap`/`checkerboard`: `.data`, `.color0/.color1.value`),
    /// `roughness` (0.5), `anisotropic`, `metallic`, `spec_tint`, `spec_trans`, `sheen`,
    /// `sheen_tint`, `clearcoat`, `clearcoat_gloss`, `flatness` (0) — each a number in [0, 1]
    /// (parameter `NAME.KEY.value`) or a one-channel texture ([`Loader::scalar_property`]) —,
    /// `eta` or `specular` (0.5; not both, as
    /// Mitsuba; constants: η moves refracted directions, whose derivative is not built) and the
    /// three sampling rates. Mitsuba's substitutions where `spec_trans` is given and nonzero: η = 1
    /// becomes 1.001, `specular` = 0 becomes 10⁻³; η = 2/(1 − √(0.08·specular)) − 1.
    fn principled(&mut self, p: &Props<'a>, name: &str, depth: usize) -> Result<MaterialId> {
        const SCALARS: [&str; 8] =
            ["metallic", "spec_tint", "spec_trans", "sheen", "sheen_tint", "clearcoat", "clearcoat_gloss", "flatness"];
        for key in ["eta", "specular"] {
            if let Some(t) = p.object(key) {
                return Err(self
                    .x
                    .err(t, format!("a textured '{key}' of 'principled' is not supported (Mitsuba's is a number)")));
            }
        }
        // Mitsuba's get_flag: a lobe exists where its property is given and not the number 0.
        let flagged = |p: &Props<'a>, key: &str| -> Result<bool> {
            if p.object(key).is_some() {
                return Ok(true);
            }
            Ok(match p.float(&self.x, key)? {
                Some((v, _)) => v != 0.0,
                None => p.has(key),
            })
        };
        let spec_trans_flag = flagged(p, "spec_trans")?;
        let eta = match (p.has("eta"), p.has("specular")) {
            (true, true) => {
                return Err(self.x.err(
                    p.node,
                    "'principled' takes either 'eta' or 'specular', not both (Mitsuba refuses both: they determine each other)",
                ));
            }
            (true, false) => {
                let eta = self.float_in(p, "eta", None, (f32::MIN_POSITIVE, f32::MAX))?;
                if spec_trans_flag && eta == 1.0 { 1.001 } else { eta }
            }
            (false, _) => {
                let specular = self.float_in(p, "specular", Some(0.5), (0.0, 1.0))?;
                let specular = if spec_trans_flag && specular == 0.0 { 1e-3 } else { specular };
                crate::bsdf::principled::eta_from_specular(specular)
            }
        };
        let rate = |key: &str| self.float_in(p, key, Some(1.0), (0.0, f32::MAX));
        let rates = Vec3::new(
            rate("main_specular_sampling_rate")?,
            rate("clearcoat_sampling_rate")?,
            rate("diffuse_reflectance_sampling_rate")?,
        );
        let (base_color, roughness, anisotropic) = self.principled_base(p, name, depth)?;
        let mut scalars = [crate::params::ParamId(0); SCALARS.len()];
        for (slot, key) in scalars.iter_mut().zip(SCALARS) {
            *slot = self.scalar_property(p, name, key, Some(0.0), bounds::WEIGHT, (0.0, 1.0))?;
        }
        Ok(self.scene.add_material(Material::Principled { base_color, roughness, anisotropic, scalars, eta, rates }))
    }

    /// What `principled` and `principledthin` read alike: `base_color` (0.5; a colour, parameter
    /// `NAME.base_color.value`, or a texture other than `volume`), `roughness` (0.5) and
    /// `anisotropic` (0), each in [0, 1] ([`Loader::scalar_property`]).
    fn principled_base(
        &mut self,
        p: &Props<'a>,
        name: &str,
        depth: usize,
    ) -> Result<(Albedo, crate::params::ParamId, crate::params::ParamId)> {
        let base_color = match p.object("base_color") {
            Some(t) => {
                let a = self.texture(t, format!("{name}.base_color"), depth + 1)?;
                self.refuse_volume(a, t, "base_color", &p.kind)?
            }
            None => {
                let c = self.color_in(p, "base_color", Vec3::splat(0.5), bounds::REFLECTANCE)?;
                let id = self.scene.params.add(&format!("{name}.base_color.value"), &c.to_array(), bounds::REFLECTANCE);
                Albedo::Rgb(id.map_err(|e| self.located(p.node, e))?)
            }
        };
        let roughness = self.scalar_property(p, name, "roughness", Some(0.5), bounds::WEIGHT, (0.0, 1.0))?;
        let anisotropic = self.scalar_property(p, name, "anisotropic", Some(0.0), bounds::WEIGHT, (0.0, 1.0))?;
        Ok((base_color, roughness, anisotropic))
    }

    /// Mitsuba 3.9.1's `principledthin`: `base_color` (0.5; a colour, parameter
    /// `NAME.base_color.value`, or a `bitmap`/`checkerboard`), `roughness` (0.5), `anisotropic`,
    /// `spec_trans`, `spec_tint`, `sheen`, `sheen_tint`, `flatness` (0; each in [0, 1]),
    /// `diff_trans` (0; in [0, 2]) and `eta` (1.5) — each a number (parameter `NAME.KEY.value`,
    /// differentiable as Mitsuba's traverse marks them all) or a one-channel texture
    /// ([`Loader::scalar_property`]) — and the four sampling rates (1; constants, as Mitsuba's are
    /// not differentiable). η bends nothing on a thin sheet: it weighs the Fresnel term and scales
    /// the transmission's roughness, so its derivative is a detached one like the others'.
    fn principled_thin(&mut self, p: &Props<'a>, name: &str, depth: usize) -> Result<MaterialId> {
        const SCALARS: [(&str, (f32, f32)); 6] = [
            ("spec_trans", bounds::WEIGHT),
            ("spec_tint", bounds::WEIGHT),
            ("sheen", bounds::WEIGHT),
            ("sheen_tint", bounds::WEIGHT),
            ("flatness", bounds::WEIGHT),
            ("diff_trans", (0.0, 2.0)),
        ];
        let rate = |key: &str| self.float_in(p, key, Some(1.0), (0.0, f32::MAX));
        let rates = [
            rate("specular_reflectance_sampling_rate")?,
            rate("specular_transmittance_sampling_rate")?,
            rate("diffuse_reflectance_sampling_rate")?,
            rate("diffuse_transmittance_sampling_rate")?,
        ];
        let (base_color, roughness, anisotropic) = self.principled_base(p, name, depth)?;
        let mut scalars = [crate::params::ParamId(0); 7];
        for (slot, (key, range)) in scalars.iter_mut().zip(SCALARS) {
            *slot = self.scalar_property(p, name, key, Some(0.0), range, range)?;
        }
        scalars[6] = self.scalar_property(p, name, "eta", Some(1.5), bounds::IOR, bounds::IOR)?;
        Ok(self.scene.add_material(Material::PrincipledThin { base_color, roughness, anisotropic, scalars, rates }))
    }

    /// Whether material `id` is a principled BSDF whose `spec_trans` is not 0 somewhere (it
    /// transmits).
    fn principled_transmits(&self, id: MaterialId) -> bool {
        matches!(self.material(id), Some(Material::Principled { scalars, .. })
            if self.scene.params.get(scalars[2]).iter().any(|v| *v != 0.0))
    }

    /// A specular colour `key` (1 by default): a texture ([`Loader::texture`]: a bitmap's texels
    /// `NAME.KEY.data`, a checkerboard's `NAME.KEY.color0/color1.value`, a mesh attribute, and on
    /// a `conductor`'s reflectance a `volume` texture's `NAME.KEY.volume.data`;
    /// [`Loader::refuse_volume`] elsewhere), the
    /// parameter `NAME.KEY.value` where the file gives a colour or `always`, else a constant
    /// (Mitsuba's dielectrics traverse only the colours given).
    fn specular_colour(
        &mut self,
        p: &Props<'a>,
        name: &str,
        key: &str,
        always: bool,
        depth: usize,
    ) -> Result<SmoothColour> {
        if let Some(t) = p.object(key) {
            let a = self.texture(t, format!("{name}.{key}"), depth + 1)?;
            // A `volume` texture only where the conformance matrix compares it with Mitsuba
            // (`texture_volume_colours`); Mitsuba's plastics refuse it (they take a colour's mean).
            let volume_ok = p.kind == "conductor";
            return Ok(SmoothColour::Texture(if volume_ok { a } else { self.refuse_volume(a, t, key, &p.kind)? }));
        }
        let value = self.color_in(p, key, Vec3::ONE, bounds::REFLECTANCE)?;
        if !(always || p.has(key)) {
            return Ok(SmoothColour::Constant(value));
        }
        let id = self.scene.params.add(&format!("{name}.{key}.value"), &value.to_array(), bounds::REFLECTANCE);
        Ok(SmoothColour::Param(id.map_err(|e| self.located(p.node, e))?))
    }

    /// Mitsuba's `roughconductor`: `distribution`, the roughness of
    /// [`Loader::microfacet_alpha`], `specular_reflectance` (1; a colour, parameter
    /// `NAME.specular_reflectance.value`, or a `bitmap`/`checkerboard`/`volume` texture as a diffuse
    /// reflectance is), `material` or `eta`/`k`.
    fn rough_conductor(&mut self, p: &Props<'a>, name: &str) -> Result<MaterialId> {
        let distribution = self.distribution(p)?;
        let (alpha, alpha_v) = self.microfacet_alpha(p, name)?;
        let specular = match p.object("specular_reflectance") {
            Some(t) => self.texture(t, format!("{name}.specular_reflectance"), 1)?,
            None => {
                let specular = self.color_in(p, "specular_reflectance", Vec3::ONE, bounds::REFLECTANCE)?;
                let specular = self.scene.params.add(
                    &format!("{name}.specular_reflectance.value"),
                    &specular.to_array(),
                    bounds::REFLECTANCE,
                );
                Albedo::Rgb(specular.map_err(|e| self.located(p.node, e))?)
            }
        };
        let (eta, k) = self.conductor_ior(p)?;
        // eta and k (a preset's too) as Mitsuba's `NAME.eta.value`, `NAME.k.value`.
        let eta_param = Some(self.scene.add_conductor_ior(name, eta, k).map_err(|e| self.located(p.node, e))?);
        let material = Material::RoughConductor { distribution, alpha, alpha_v, specular, eta, k, eta_param };
        Ok(self.scene.add_material(material))
    }

    /// Builds (once) the texture `node` — a `<texture>` or a `<ref>` to one — named `name` unless
    /// the scene level named it first ([`Loader::name_of`]); its texels become the parameter
    /// `NAME.data`.
    ///
    /// # Errors
    /// Unsupported plugins, missing or undecodable files, texels outside [0, 1].
    pub(super) fn texture(&mut self, node: El<'a>, name: String, depth: usize) -> Result<Albedo> {
        let target = self.deref(node)?;
        if !target.has_tag_name("texture") {
            return Err(self.x.err(node, format!("refers to a <{}>, expected a <texture>", target.tag_name().name())));
        }
        if let Some(&t) = self.textures.get(&target.id()) {
            return Ok(t);
        }
        if depth > MAX_NESTING {
            return Err(self.x.err(node, format!("BSDFs and textures nest more than {MAX_NESTING} deep")));
        }
        let name = self.name_of(target, name)?;
        let p = Props::parse(&self.x, target)?;
        if p.kind == "checkerboard" {
            let albedo = self.checkerboard(&p, &name, bounds::REFLECTANCE)?;
            self.textures.insert(target.id(), albedo);
            return Ok(albedo);
        }
        if p.kind == "volume" {
            let albedo = self.volume_texture(&p, &name)?;
            self.textures.insert(target.id(), albedo);
            return Ok(albedo);
        }
        if p.kind == "mesh_attribute" {
            // Not cached: each shape reads its own attribute.
            let (values, source) = self.mesh_attribute(&p, 3, bounds::REFLECTANCE)?;
            return Ok(Albedo::Attribute { values, source });
        }
        if p.kind != "bitmap" {
            return Err(self
                .x
                .err(target, format!("unsupported plugin '{}' (supported: {})", p.kind, names(Category::Texture))));
        }
        let bitmap = self.bitmap(&p, target, "reflectances must be at most 1")?;
        let to_uv = self.to_uv(&p)?;
        let t = self
            .scene
            .add_texture(&format!("{name}.data"), bitmap.width, bitmap.height, &bitmap.texels)
            .map_err(|e| self.located(target, e))?;
        let texture = &mut self.scene.textures[t.0 as usize];
        (texture.nearest, texture.wrap, texture.to_uv) = (bitmap.nearest, bitmap.wrap, to_uv);
        self.finish(&p)?;
        self.textures.insert(target.id(), Albedo::Bitmap(t));
        Ok(Albedo::Bitmap(t))
    }

    /// `a`, unless it is a `volume` texture, which pathgrad reads as a `diffuse`'s `reflectance`
    /// and a `conductor`'s or `roughconductor`'s `specular_reflectance` only (the slots the
    /// conformance matrix compares with Mitsuba;
    /// Mitsuba 3.9.1 itself refuses it on a plastic, whose sampling weight takes a colour's mean,
    /// which its `volume` texture does not implement): on `slot` of a `kind` BSDF it is refused,
    /// located at `node`.
    fn refuse_volume(&self, a: Albedo, node: El<'a>, slot: &str, kind: &str) -> Result<Albedo> {
        if matches!(a, Albedo::Volume(_)) {
            return Err(self.x.err(
                node,
                format!(
                    "a 'volume' texture is not supported as '{slot}' of '{kind}' (only as a diffuse's 'reflectance' and a conductor's or roughconductor's 'specular_reflectance')"
                ),
            ));
        }
        Ok(a)
    }

    /// A texture's `to_uv` as rows 0 and 1 of the 4×4 matrix, columns x, y and the translation:
    /// Mitsuba's 2D map of texture coordinates (identity rows without one).
    pub(super) fn to_uv(&self, p: &Props<'a>) -> Result<[Vec3; 2]> {
        Ok(match p.transform(&self.x, "to_uv")? {
            None => [Vec3::X, Vec3::Y],
            Some((t, _)) => {
                let m = t.matrix;
                [0, 1].map(|r| Vec3::new(m.col(0)[r], m.col(1)[r], m.col(3)[r]))
            }
        })
    }

    /// The `wrap_mode` of a bitmap or grid volume (`repeat`, `mirror` or `clamp`), `default` where
    /// none is given (a bitmap's is repeat, a grid volume's clamp).
    ///
    /// # Errors
    /// Another value, located at the property.
    pub(super) fn wrap_mode(&self, p: &Props<'a>, default: Wrap) -> Result<Wrap> {
        match p.string(&self.x, "wrap_mode")? {
            None => Ok(default),
            Some((v, n)) => match v.as_str() {
                "repeat" => Ok(Wrap::Repeat),
                "mirror" => Ok(Wrap::Mirror),
                "clamp" => Ok(Wrap::Clamp),
                _ => Err(self.x.err(n, format!("'wrap_mode' must be 'repeat', 'mirror' or 'clamp', got '{v}'"))),
            },
        }
    }

    /// The texels and lookup of the `bitmap` `p` (node `target`): Mitsuba's `filename`, `raw`,
    /// `filter_type`, `wrap_mode` (`format` ignored with a warning).
    ///
    /// # Errors
    /// A missing or undecodable file, bad property values, a texel outside [0, 1] (`what` says
    /// why; empty: any finite value is read).
    pub(super) fn bitmap(&mut self, p: &Props<'a>, target: El<'a>, what: &str) -> Result<NormalMapTexture> {
        let (file, file_node) = p
            .string(&self.x, "filename")?
            .ok_or_else(|| self.x.err(target, "'bitmap' needs the property 'filename'"))?;
        let raw = p.boolean(&self.x, "raw", false)?;
        let nearest = match p.string(&self.x, "filter_type")? {
            None => false,
            Some((v, _)) if v == "bilinear" => false,
            Some((v, _)) if v == "nearest" => true,
            Some((v, n)) => {
                return Err(self.x.err(n, format!("'filter_type' must be 'bilinear' or 'nearest', got '{v}'")));
            }
        };
        let wrap = self.wrap_mode(p, Wrap::Repeat)?;
        // `format` is the texels' storage: "variant" (the default) is float32, as pathgrad stores them.
        if let Some((v, n)) = p.string(&self.x, "format")?
            && v != "variant"
        {
            let w =
                self.x.warning(n, format!("property 'format' = '{v}' of 'bitmap' ignored: pathgrad uses 'variant'"));
            self.scene.warn(w);
        }
        let (width, height, texels) = self.image_file(&file, file_node, raw)?;
        let upper = if what.is_empty() { f32::MAX } else { 1.0 };
        let lower = if what.is_empty() { f32::MIN } else { 0.0 };
        if let Some((i, v)) = texels.iter().enumerate().find(|(_, v)| !(**v >= lower && **v <= upper)) {
            let texel = i / 3;
            return Err(self.x.err(
                file_node,
                format!(
                    "'{file}': texel ({}, {}) has value {v} outside [{lower}, {upper}] ({what})",
                    texel % width as usize,
                    texel / width as usize
                ),
            ));
        }
        Ok(NormalMapTexture { width, height, texels, nearest, wrap })
    }

    /// Mitsuba's `bumpmap` around its one nested BSDF: its one nested texture (a `bitmap` of any
    /// name) is read as heights (the luminance of its RGB) into
    /// [`crate::scene::Scene::normal_maps`], not the parameters; `scale` (1); the nested BSDF's
    /// parameters are named `NAME.nested_bsdf.…` (Mitsuba's traverse).
    fn bump_map(&mut self, p: &Props<'a>, name: &str, depth: usize) -> Result<MaterialId> {
        let node = p.node;
        self.refuse_non_default_map_flags(p, "bumpmap")?;
        let scale = self.float_in(p, "scale", Some(1.0), (f32::MIN, f32::MAX))?;
        let textures = p.take_nested(&["texture"]);
        let [texture] = textures[..] else {
            return Err(self.x.err(node, format!("'bumpmap' needs 1 nested <texture>, got {}", textures.len())));
        };
        let map = self.map_bitmap(texture, "a bump map", "")?;
        let heights = map
            .texels
            .chunks(3)
            .map(|c| {
                if c[0] == c[1] && c[1] == c[2] { c[0] } else { 0.212_671 * c[0] + 0.715_160 * c[1] + 0.072_169 * c[2] }
            })
            .collect();
        let map = NormalMapTexture { texels: heights, ..map };
        let nested = self.map_nested(p, name, depth, "bumpmap")?;
        let anisotropic = |id: MaterialId| match self.material(id) {
            Some(
                Material::RoughConductor { alpha, alpha_v, .. } | Material::RoughDielectric { alpha, alpha_v, .. },
            ) => alpha != alpha_v,
            Some(Material::Principled { anisotropic, .. } | Material::PrincipledThin { anisotropic, .. }) => {
                self.scene.params.get(anisotropic).iter().any(|v| *v != 0.0)
            }
            _ => false,
        };
        let children = match self.material(nested) {
            Some(Material::Blend { children, .. }) => children.to_vec(),
            _ => vec![nested],
        };
        if children.into_iter().any(anisotropic) {
            return Err(self.x.err(
                node,
                "an anisotropic BSDF inside a 'bumpmap' is not supported: Mitsuba 3.9.1 orients its tangent by \
                 mixing world and local coordinates, which only anisotropic BSDFs show (a 'normalmap' is fine)",
            ));
        }
        self.scene.normal_maps.push(map);
        let map = self.scene.normal_maps.len() as u32 - 1;
        Ok(self.scene.add_material(Material::BumpMap { nested, map, scale }))
    }

    /// Mitsuba's `mask` around the BSDF `p`'s one nested BSDF (named `NAME.nested_bsdf`, Mitsuba's
    /// traverse): `opacity` (0.5), a float (parameter `NAME.opacity.value`) or a one-channel
    /// texture ([`Loader::scalar_property`]: `NAME.opacity.data`, or a checkerboard's
    /// `.color0/.color1.value`). A mask around a mask or a `null` BSDF is refused by name, as is
    /// one inside a `blendbsdf` (mask the blend instead).
    fn mask(&mut self, p: &Props<'a>, name: &str, depth: usize) -> Result<MaterialId> {
        let opacity = self.scalar_property(p, name, "opacity", Some(0.5), bounds::WEIGHT, (0.0, 1.0))?;
        let children = p.take_nested(&["bsdf", "ref"]);
        let [child] = children[..] else {
            return Err(self.x.err(p.node, format!("'mask' needs 1 nested BSDF, got {}", children.len())));
        };
        let nested = self.bsdf(child, format!("{name}.nested_bsdf"), depth + 1)?;
        match self.material(nested) {
            Some(Material::Mask { .. }) => {
                Err(self.x.err(child, "a 'mask' around another 'mask' is not supported (multiply their opacities)"))
            }
            Some(Material::Null) => Err(self.x.err(child, "a 'mask' around a 'null' BSDF has nothing to shade")),
            _ => Ok(self.scene.add_material(Material::Mask { nested, opacity })),
        }
    }

    /// Refuses `flip_invalid_normals` and `use_shadowing_function` other than Mitsuba's default
    /// (true) on map wrapper `kind`.
    fn refuse_non_default_map_flags(&self, p: &Props<'a>, kind: &str) -> Result<()> {
        for key in ["flip_invalid_normals", "use_shadowing_function"] {
            if !p.boolean(&self.x, key, true)? {
                return Err(self.x.err(
                    p.node,
                    format!("'{key}' = false of '{kind}' is not supported (pathgrad follows Mitsuba's default)"),
                ));
            }
        }
        Ok(())
    }

    /// The texture `texture` of a map wrapper (`what`: "a normal map", "a bump map"): a `bitmap`,
    /// whose texels must lie in [0, 1] unless `range` is empty (see [`Loader::bitmap`]), or a
    /// `rawconstant` (Mitsuba's constant without colour conversion: a `vector` or a `float`), one
    /// texel read as a nearest lookup (exactly its value).
    fn map_bitmap(&mut self, texture: El<'a>, what: &str, range: &str) -> Result<NormalMapTexture> {
        let texture = self.deref(texture)?;
        let tp = Props::parse(&self.x, texture)?;
        let map = match (texture.has_tag_name("texture"), tp.kind.as_str()) {
            (true, "bitmap") => self.bitmap(&tp, texture, range)?,
            (true, "rawconstant") => {
                let value = match tp.point(&self.x, "value") {
                    Ok(Some((v, _))) => v,
                    _ => match tp.float(&self.x, "value")? {
                        Some((v, _)) => Vec3::splat(v),
                        None => return Err(self.x.err(texture, "'rawconstant' needs the property 'value'")),
                    },
                };
                if !value.is_finite() {
                    return Err(self.x.err(texture, format!("'rawconstant' value {value} is not finite")));
                }
                NormalMapTexture {
                    width: 1,
                    height: 1,
                    texels: value.to_array().to_vec(),
                    nearest: true,
                    wrap: Wrap::Repeat,
                }
            }
            _ => {
                return Err(self.x.err(
                    texture,
                    format!(
                        "{what} must be a 'bitmap' or 'rawconstant' texture, got '{}' (pathgrad reads no other)",
                        tp.kind
                    ),
                ));
            }
        };
        self.finish(&tp)?;
        Ok(map)
    }

    /// The one BSDF nested in map wrapper `kind` (`p`), named `NAME.nested_bsdf`; refuses what
    /// pathgrad cannot put inside a map.
    fn map_nested(&mut self, p: &Props<'a>, name: &str, depth: usize, kind: &str) -> Result<MaterialId> {
        let children = p.take_nested(&["bsdf", "ref"]);
        let [child] = children[..] else {
            return Err(self.x.err(p.node, format!("'{kind}' needs 1 nested BSDF, got {}", children.len())));
        };
        let nested = self.bsdf(child, format!("{name}.nested_bsdf"), depth + 1)?;
        match self.material(nested) {
            Some(Material::TwoSided(_)) => Err(self.x.err(
                child,
                format!(
                    "a '{kind}' around a 'twosided' BSDF is not supported: put 'twosided' outside the map (pathgrad \
                     applies the map in the frame the two-sided wrapper turns toward wi)"
                ),
            )),
            Some(Material::NormalMap { .. } | Material::BumpMap { .. }) => {
                Err(self.x.err(child, format!("a '{kind}' around another normal or bump map is not supported")))
            }
            Some(Material::Null) => {
                Err(self.x.err(child, format!("a '{kind}' around a 'null' BSDF has nothing to shade")))
            }
            Some(Material::Mask { .. }) => Err(self
                .x
                .err(child, format!("a '{kind}' around a 'mask' is not supported: put the 'mask' outside the map"))),
            _ if self.is_blend_with_delta(nested) => Err(self
                .x
                .err(child, format!("a '{kind}' around a 'blendbsdf' holding a smooth 'conductor' is not supported"))),
            _ => Ok(nested),
        }
    }

    /// Mitsuba's `normalmap` around the BSDF `node`'s one nested BSDF: its texture `normalmap` (a
    /// `bitmap`, usually `raw`) is read into [`crate::scene::Scene::normal_maps`], not the
    /// parameters; the nested BSDF's parameters are named `NAME.nested_bsdf.…` (Mitsuba's
    /// traverse).
    fn normal_map(&mut self, p: &Props<'a>, name: &str, depth: usize) -> Result<MaterialId> {
        let node = p.node;
        self.refuse_non_default_map_flags(p, "normalmap")?;
        let texture = p.object("normalmap").ok_or_else(|| {
            self.x.err(node, "'normalmap' needs a nested <texture name=\"normalmap\" type=\"bitmap\">")
        })?;
        let map = self.map_bitmap(
            texture,
            "a normal map",
            "a normal map's RGB holds the normal's components mapped to [0, 1]",
        )?;
        let nested = self.map_nested(p, name, depth, "normalmap")?;
        self.scene.normal_maps.push(map);
        let map = self.scene.normal_maps.len() as u32 - 1;
        Ok(self.scene.add_material(Material::NormalMap { nested, map }))
    }

    /// Mitsuba's `checkerboard` (`color0` 0.4 and `color1` 0.2 by default, each a colour in
    /// [0, 1] as Mitsuba demands of them even in an emitter — a texture there is refused by name
    /// — and `to_uv`): parameters `NAME.color0.value` and `NAME.color1.value` bounded by `range`
    /// (an emitter's: [`bounds::RADIANCE`]), added one after the other (the kernels read them as
    /// two texels).
    pub(super) fn checkerboard(&mut self, p: &Props<'a>, name: &str, range: (f32, f32)) -> Result<Albedo> {
        for slot in ["color0", "color1"] {
            if let Some(t) = p.object(slot) {
                return Err(self
                    .x
                    .err(t, format!("a textured '{slot}' of a checkerboard is not supported (a colour is)")));
            }
        }
        let color0 = self.color_in(p, "color0", Vec3::splat(0.4), bounds::REFLECTANCE)?;
        let color1 = self.color_in(p, "color1", Vec3::splat(0.2), bounds::REFLECTANCE)?;
        let to_uv = self.to_uv(p)?;
        self.finish(p)?;
        let first = self.scene.params.add(&format!("{name}.color0.value"), &color0.to_array(), range);
        let first = first.map_err(|e| self.located(p.node, e))?;
        let second = self.scene.params.add(&format!("{name}.color1.value"), &color1.to_array(), range);
        let second = second.map_err(|e| self.located(p.node, e))?;
        debug_assert_eq!(self.scene.params.entry(second).offset, self.scene.params.entry(first).offset + 3);
        Ok(Albedo::Checker { colors: first, to_uv })
    }
}
