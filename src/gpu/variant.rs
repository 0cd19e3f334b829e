//! Kernel variants: the values of the feature specialisation constants for a request on a scene.
//!
//! A kernel contains only what its request and scene use (issue "Fast kernels"): the material
//! kinds and distributions present, textures, two-sided materials, emitters and the environment,
//! next-event estimation, the strategy, and which parameter kinds are differentiated. Each bit is
//! an `F_*`/`G_*` constant of [`crate::contract`], read by `shaders/lib/features.glsl`.
//!
//! A variant's features are one `u64`: the low 32 bits are the `FEATURES` word (`F_*`, `G_*`),
//! the high 32 bits the `FEATURES2` word (`F2_*`, placed by [`word2`]).

use crate::contract::*;
use crate::integrator::{ParamKinds, RenderOptions, Strategy};
use crate::scene::flat::FlatScene;

/// A second-word bit (`F2_*`) in a variant's 64-bit features.
pub const fn word2(bit: u32) -> u64 {
    (bit as u64) << 32
}

/// The feature bits of what `flat` contains; `env_param` is the environment's parameter offset or
/// `NO_PARAM`.
pub fn scene_features(flat: &FlatScene, env_param: u32) -> u64 {
    let mut f = 0;
    // Bits of the second word (`F2_*`).
    let mut f2 = 0;
    for m in &flat.materials {
        if m.tex_mode & TEX_VOLUME != 0
            || specular_colour_slots(m).into_iter().any(|s| colour_volume(flat, s).is_some())
        {
            f2 |= F2_VOLUME_TEXTURE;
        }
        f |= match m.tag {
            MAT_DIFFUSE => F_DIFFUSE,
            MAT_ROUGH_CONDUCTOR => F_CONDUCTOR | if m.distribution == DIST_BECKMANN { F_BECKMANN } else { F_GGX },
            MAT_ROUGH_PLASTIC => F_PLASTIC | if m.distribution == DIST_BECKMANN { F_BECKMANN } else { F_GGX },
            MAT_CONDUCTOR | MAT_DIELECTRIC | MAT_THIN_DIELECTRIC => F_DELTA,
            MAT_PLASTIC => F_SMOOTH_PLASTIC,
            MAT_ROUGH_DIELECTRIC => {
                F_ROUGH_DIELECTRIC | if m.distribution == DIST_BECKMANN { F_BECKMANN } else { F_GGX }
            }
            MAT_NULL => F_MEDIA,
            // Principled lobes are GGX; its shading frame follows ∂p/∂u (anisotropic is a
            // parameter, which may leave 0).
            MAT_PRINCIPLED => F_PRINCIPLED | F_GGX | F_ANISOTROPIC,
            // A thin principled leaf (F2_PRINCIPLED_THIN), likewise.
            MAT_PRINCIPLED_THIN => {
                f2 |= F2_PRINCIPLED_THIN;
                F_GGX | F_ANISOTROPIC
            }
            _ => F_BLEND,
        };
        if m.tex_width > 0 || specular_colour_slots(m).into_iter().any(colour_textured) {
            f |= F_TEXTURE;
        }
        if (m.tag == MAT_ROUGH_CONDUCTOR || m.tag == MAT_ROUGH_DIELECTRIC) && m.p_alpha_v != m.p_alpha {
            f |= F_ANISOTROPIC;
        }
        if m.nmap_width > 0 {
            f |= F_NORMAL_MAP;
        }
        let textured = |slot: u32| slot != NO_PARAM && slot & SCALAR_TEXTURE != 0;
        let scalar_textured = match m.tag {
            MAT_ROUGH_CONDUCTOR | MAT_ROUGH_DIELECTRIC => textured(m.p_alpha) || textured(m.p_alpha_v),
            MAT_PRINCIPLED | MAT_PRINCIPLED_THIN => {
                textured(m.p_alpha)
                    || textured(m.p_alpha_v)
                    || (0..PRINCIPLED_SCALARS).any(|i| textured(flat.tables[(m.table + i) as usize].to_bits()))
            }
            MAT_BLEND => textured(m.p_weight),
            _ => false,
        } || textured(m.p_opacity);
        if scalar_textured {
            f |= F_PARAM_TEXTURE;
        }
        if m.two_sided != 0 {
            f |= F_TWO_SIDED;
        }
        if m.p_opacity != NO_PARAM {
            f |= F_MASK;
        }
    }
    if !flat.emitters.is_empty() {
        f |= F_EMITTERS;
    }
    if flat.emitters.iter().any(|e| crate::cpu::emitter::area_textured(e.p_radiance)) {
        f2 |= F2_AREA_TEXTURE;
    }
    if env_param != NO_PARAM {
        f |= F_ENV;
    }
    if !flat.env_cells.is_empty() {
        f |= F_ENV_MAP;
    }
    if !flat.lights.is_empty() {
        f |= F_LIGHTS;
    }
    if flat.lights.iter().any(crate::scene::flat::light_textured) {
        f |= F_LIGHT_TEXTURE;
    }
    if !flat.media.is_empty() {
        f |= F_MEDIA;
    }
    u64::from(f) | word2(f2)
}

/// The environment's parameter values of `scene` as (offset, count): one RGB value, or every
/// texel of a map; `(NO_PARAM, 0)` without an environment.
pub fn env_range(scene: &crate::scene::Scene) -> (u32, u32) {
    scene.environment.map_or((NO_PARAM, 0), |p| {
        let e = scene.params.entry(p);
        (e.offset, e.len)
    })
}

/// The kinds of the parameters `ids` of `scene` (flattened as `flat`).
pub fn kinds_of(scene: &crate::scene::Scene, flat: &FlatScene, ids: &[crate::params::ParamId]) -> ParamKinds {
    let env = env_range(scene);
    ids.iter().fold(ParamKinds::NONE, |k, &id| {
        let e = scene.params.entry(id);
        k.union(param_kinds(flat, env, e.offset, e.offset + e.len))
    })
}

/// The kinds of the parameter values `begin .. end`, judged by what refers to them; `env` is
/// [`env_range`].
pub fn param_kinds(flat: &FlatScene, env: (u32, u32), begin: u32, end: u32) -> ParamKinds {
    let overlaps = |offset: u32, len: u32| offset != NO_PARAM && offset < end && begin < offset.saturating_add(len);
    // A scalar slot: one value, or a texture's texels (`SCALAR_TEXTURE`).
    let overlaps_slot = |slot: u32| {
        let (offset, len) = scalar_slot_range(flat, slot);
        overlaps(offset, len)
    };
    // Reflectance, (dielectrics) transmittance and (plastics) specular reflectance, each a
    // parameter, a colour texture's texels (`SCALAR_TEXTURE`) or NO_PARAM.
    let field = |f: u32| {
        let d = &flat.fields[f as usize];
        overlaps(d.offset, d.channels * if d.kind == FIELD_CONSTANT { 1 } else { d.res_x * d.res_y * d.res_z })
    };
    // A `volume` texture's slot names its field (`colour_volume`).
    let specular_kinds = |m: &crate::contract::Material| {
        let mut k = ParamKinds::NONE;
        for slot in specular_colour_slots(m) {
            let (offset, texels) = scalar_slot_range(flat, slot);
            let read = match colour_volume(flat, slot) {
                Some(f) => field(f),
                None => overlaps(offset, 3 * texels),
            };
            if read {
                k = k.union(if colour_textured(slot) { ParamKinds::TEXTURE } else { ParamKinds::COLOR });
            }
        }
        k
    };
    let mut k = ParamKinds::NONE;
    for m in &flat.materials {
        k = k.union(specular_kinds(m));
        // A conductor's eta and k (p_weight, six values): constant colours of its weight.
        if matches!(m.tag, MAT_CONDUCTOR | MAT_ROUGH_CONDUCTOR) && overlaps(m.p_weight, 6) {
            k = k.union(ParamKinds::COLOR);
        }
        match m.tag {
            MAT_CONDUCTOR | MAT_DIELECTRIC | MAT_THIN_DIELECTRIC | MAT_ROUGH_DIELECTRIC => {
                if m.tag == MAT_ROUGH_DIELECTRIC && (overlaps_slot(m.p_alpha) || overlaps_slot(m.p_alpha_v)) {
                    k = k.union(ParamKinds::ALPHA);
                }
            }
            MAT_DIFFUSE | MAT_ROUGH_CONDUCTOR | MAT_ROUGH_PLASTIC | MAT_PLASTIC => {
                let texels = if m.tex_width > 0 { m.tex_width * m.tex_height } else { 1 };
                // A `volume` texture's p_color is its field's index.
                let read =
                    if m.tex_mode & TEX_VOLUME != 0 { field(m.p_color) } else { overlaps(m.p_color, 3 * texels) };
                if read {
                    k = k.union(if m.tex_width > 0 { ParamKinds::TEXTURE } else { ParamKinds::COLOR });
                }
                let alpha_v = m.tag == MAT_ROUGH_CONDUCTOR && overlaps_slot(m.p_alpha_v);
                if (m.tag == MAT_ROUGH_CONDUCTOR || m.tag == MAT_ROUGH_PLASTIC) && overlaps_slot(m.p_alpha) || alpha_v {
                    k = k.union(ParamKinds::ALPHA);
                }
            }
            MAT_PRINCIPLED | MAT_PRINCIPLED_THIN => {
                let texels = if m.tex_width > 0 { m.tex_width * m.tex_height } else { 1 };
                if overlaps(m.p_color, 3 * texels) {
                    k = k.union(if m.tex_width > 0 { ParamKinds::TEXTURE } else { ParamKinds::COLOR });
                }
                if overlaps_slot(m.p_alpha) {
                    k = k.union(ParamKinds::ALPHA);
                }
                // Anisotropic and the eight other scalars count as weights (of lobes).
                let record = |i: u32| flat.tables[(m.table + i) as usize].to_bits();
                if overlaps_slot(m.p_alpha_v) || (0..PRINCIPLED_SCALARS).any(|i| overlaps_slot(record(i))) {
                    k = k.union(ParamKinds::WEIGHT);
                }
            }
            _ => {
                if overlaps_slot(m.p_weight) {
                    k = k.union(ParamKinds::WEIGHT);
                }
            }
        }
        // A mask's opacity weighs its nested BSDF against passing through, as a blend's weight does.
        if overlaps_slot(m.p_opacity) {
            k = k.union(ParamKinds::WEIGHT);
        }
    }
    let light = |l: &crate::contract::DeltaLight| {
        overlaps(l.p_intensity, 3) || overlaps(l.p_scale, 1) || overlaps(l.tex, 3 * l.tex_width * l.tex_height)
    };
    // An area emitter's RGB radiance, or its texture's RGB texels (`SCALAR_TEXTURE`).
    let emitter = |e: &crate::contract::EmitterTri| {
        let (offset, texels) = scalar_slot_range(flat, e.p_radiance);
        overlaps(offset, 3 * texels)
    };
    if flat.emitters.iter().any(emitter) || flat.lights.iter().any(light) {
        k = k.union(ParamKinds::EMISSION);
    }
    if overlaps(env.0, env.1) {
        k = k.union(ParamKinds::ENVIRONMENT);
    }
    if flat.media.iter().any(|m| overlaps(m.p_scale, 1) || overlaps(m.p_g, 1) || field(m.sigma_t) || field(m.albedo)) {
        k = k.union(ParamKinds::MEDIUM);
    }
    k
}

/// The colour slots of a smooth BSDF, rough dielectric or plastic `m` (none for another
/// material): the reflectance (`p_color`) and a dielectric's transmittance (`p_alpha` smooth,
/// `p_weight` rough), a plastic's specular reflectance (`p_weight`), each a parameter offset,
/// `NO_PARAM` (a constant) or a colour texture (`SCALAR_TEXTURE`).
pub fn specular_colour_slots(m: &crate::contract::Material) -> Vec<u32> {
    match m.tag {
        MAT_CONDUCTOR => vec![m.p_color],
        MAT_DIELECTRIC | MAT_THIN_DIELECTRIC => vec![m.p_color, m.p_alpha],
        MAT_ROUGH_DIELECTRIC => vec![m.p_color, m.p_weight],
        MAT_ROUGH_PLASTIC | MAT_PLASTIC => vec![m.p_weight],
        _ => Vec::new(),
    }
}

/// Whether a colour slot of [`specular_colour_slots`] holds a texture (`SCALAR_TEXTURE`).
pub fn colour_textured(slot: u32) -> bool {
    slot != NO_PARAM && slot & SCALAR_TEXTURE != 0
}

/// The field index of a colour slot of [`specular_colour_slots`] that holds a `volume` texture
/// (its descriptor's mode has `TEX_VOLUME`, its word 0 is the field's index), looked up at the
/// world-space point (twin: `colour_volume` of shaders/lib/surface.glsl).
pub fn colour_volume(flat: &FlatScene, slot: u32) -> Option<u32> {
    if !colour_textured(slot) {
        return None;
    }
    let d = (slot & !SCALAR_TEXTURE) as usize;
    (flat.tables[d + 3].to_bits() & TEX_VOLUME != 0).then(|| flat.tables[d].to_bits())
}

/// The parameter values a scalar slot of a `Material` reads, as (offset, count): one value, or a
/// scalar texture's texels (`SCALAR_TEXTURE`: its descriptor in `flat.tables`).
pub fn scalar_slot_range(flat: &FlatScene, slot: u32) -> (u32, u32) {
    if slot == NO_PARAM || slot & SCALAR_TEXTURE == 0 {
        return (slot, 1);
    }
    let d = (slot & !SCALAR_TEXTURE) as usize;
    let word = |i: usize| flat.tables[d + i].to_bits();
    (word(0), word(1) * word(2))
}

/// The feature bits of a pass with `options` on a scene with `scene` bits, differentiating
/// `kinds` (empty for the primal kernel).
pub fn request_features(scene: u64, options: &RenderOptions, kinds: ParamKinds) -> u64 {
    let mut f = scene;
    if options.nee && scene & u64::from(F_EMITTERS | F_ENV | F_LIGHTS) != 0 {
        f |= u64::from(F_NEE);
    }
    match options.strategy {
        Strategy::Diff { .. } => f |= u64::from(F_DIFF),
        Strategy::Hero { .. } => f |= u64::from(F_DIFF) | word2(F2_HERO),
        Strategy::Bsdf => {}
    }
    f | u64::from(kinds.bits())
}

/// A short human-readable name of a variant, for logs: `nee env diffuse conductor[beckmann] ∂alpha`.
pub fn describe(features: u64) -> String {
    const NAMES: [(u64, &str); 36] = [
        (F_NEE as u64, "nee"),
        (F_ENV as u64, "env"),
        (F_EMITTERS as u64, "emitters"),
        (F_DIFF as u64, "diff"),
        (F_DIFFUSE as u64, "diffuse"),
        (F_CONDUCTOR as u64, "conductor"),
        (F_BECKMANN as u64, "beckmann"),
        (F_GGX as u64, "ggx"),
        (F_BLEND as u64, "blend"),
        (F_TEXTURE as u64, "texture"),
        (F_TWO_SIDED as u64, "two-sided"),
        (F_MEDIA as u64, "media"),
        (F_ENV_MAP as u64, "env-map"),
        (F_LIGHTS as u64, "lights"),
        (F_PLASTIC as u64, "plastic"),
        (F_DELTA as u64, "smooth"),
        (F_SMOOTH_PLASTIC as u64, "smooth-plastic"),
        (F_ROUGH_DIELECTRIC as u64, "rough-dielectric"),
        (F_ANISOTROPIC as u64, "anisotropic"),
        (F_NORMAL_MAP as u64, "normal-map"),
        (F_PARAM_TEXTURE as u64, "scalar-texture"),
        (F_MASK as u64, "mask"),
        (F_LIGHT_TEXTURE as u64, "light-texture"),
        (F_PRINCIPLED as u64, "principled"),
        (word2(F2_HERO), "hero"),
        (word2(F2_PRINCIPLED_THIN), "principledthin"),
        (word2(F2_VOLUME_TEXTURE), "volume-texture"),
        (word2(F2_HIDE_EMITTERS), "hide-emitters"),
        (word2(F2_AREA_TEXTURE), "area-texture"),
        (G_COLOR as u64, "∂color"),
        (G_TEXTURE as u64, "∂texture"),
        (G_ALPHA as u64, "∂alpha"),
        (G_WEIGHT as u64, "∂weight"),
        (G_EMISSION as u64, "∂emission"),
        (G_ENV as u64, "∂env"),
        (G_MEDIUM as u64, "∂medium"),
    ];
    let parts: Vec<&str> = NAMES.iter().filter(|(bit, _)| features & bit != 0).map(|(_, n)| *n).collect();
    parts.join(" ")
}
