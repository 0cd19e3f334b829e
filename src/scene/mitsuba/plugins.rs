//! The Mitsuba plugins the XML loader accepts, with the properties it reads: one list, from which
//! the loader's "supported: …" messages and `docs/mitsuba-plugins.md` are made, and which
//! `tests_plugins` holds against the loader (every listed plugin is accepted, every other plugin of
//! Mitsuba 3.9.1 is refused by name).

/// What kind of object a plugin makes (the XML tag).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Category {
    /// `<bsdf>`.
    Bsdf,
    /// `<emitter>`.
    Emitter,
    /// `<shape>`.
    Shape,
    /// `<texture>`.
    Texture,
    /// `<medium>`.
    Medium,
    /// `<phase>`.
    Phase,
    /// `<volume>`.
    Volume,
    /// `<sensor>`.
    Sensor,
    /// `<film>`.
    Film,
    /// `<rfilter>`.
    Rfilter,
    /// `<sampler>`.
    Sampler,
    /// `<integrator>`.
    Integrator,
}

impl Category {
    /// Every category, in the order the documentation lists them.
    pub const ALL: [Category; 12] = [
        Category::Bsdf,
        Category::Emitter,
        Category::Shape,
        Category::Texture,
        Category::Medium,
        Category::Phase,
        Category::Volume,
        Category::Sensor,
        Category::Film,
        Category::Rfilter,
        Category::Sampler,
        Category::Integrator,
    ];

    /// The XML tag.
    pub fn tag(self) -> &'static str {
        match self {
            Category::Bsdf => "bsdf",
            Category::Emitter => "emitter",
            Category::Shape => "shape",
            Category::Texture => "texture",
            Category::Medium => "medium",
            Category::Phase => "phase",
            Category::Volume => "volume",
            Category::Sensor => "sensor",
            Category::Film => "film",
            Category::Rfilter => "rfilter",
            Category::Sampler => "sampler",
            Category::Integrator => "integrator",
        }
    }
}

/// One accepted plugin.
#[derive(Clone, Copy, Debug)]
pub struct Plugin {
    /// Its kind.
    pub category: Category,
    /// Mitsuba's name (`type="…"`).
    pub name: &'static str,
    /// The properties read (Mitsuba's names), with pathgrad's parameters where they are ones.
    pub properties: &'static str,
    /// How pathgrad renders it where that is not simply Mitsuba's way.
    pub note: &'static str,
}

const fn p(category: Category, name: &'static str, properties: &'static str, note: &'static str) -> Plugin {
    Plugin { category, name, properties, note }
}

use Category::*;

/// Every accepted plugin; within a category in the order the loader's messages list them.
pub const PLUGINS: &[Plugin] = &[
    p(
        Bsdf,
        "blendbsdf",
        "`weight` (parameter `.weight.value`, or a one-channel texture: `.weight.data`), two nested BSDFs",
        "children: diffuse, roughconductor, roughplastic, or twosided wrappers of those; one of them beside a smooth \
         conductor (Mitsuba 3.9.1 renders that darker: warned)",
    ),
    p(
        Bsdf,
        "bumpmap",
        "one nested texture (a `bitmap` or `rawconstant`: heights, the luminance of its texels), `scale`, one nested BSDF (parameters `.nested_bsdf.…`)",
        "as Mitsuba (∂p/∂u, ∂p/∂v moved by the heights' gradient, flipped normals, shadow terminator); the heights are not parameters; nested BSDF not anisotropic; inside twosided, not around it; not inside blendbsdf",
    ),
    p(
        Bsdf,
        "conductor",
        "`specular_reflectance` (rgb, spectrum, bitmap, checkerboard, mesh_attribute or volume), `material` or `eta`/`k` (parameters `.eta.value`, `.k.value`, RGB, a preset's too)",
        "smooth: sampled only; gradient of the reflectance (or its texels) and of eta and k through the sampled weight",
    ),
    p(
        Bsdf,
        "dielectric",
        "`int_ior`/`ext_ior` (numbers or Mitsuba's names), `specular_reflectance`, `specular_transmittance` (each rgb, spectrum, bitmap, checkerboard or mesh_attribute)",
        "smooth; not inside blendbsdf or twosided",
    ),
    p(Bsdf, "diffuse", "`reflectance` (rgb, spectrum, bitmap, checkerboard, mesh_attribute or volume)", ""),
    p(
        Bsdf,
        "mask",
        "`opacity` (a parameter or a one-channel texture), one nested BSDF",
        "the pass-through counts as a bounce and stops shadow rays (as `path`/`prb`); volpath with a finite `max_depth` refused; not inside blendbsdf or a map",
    ),
    p(
        Bsdf,
        "normalmap",
        "texture `normalmap` (a `bitmap` or `rawconstant`), one nested BSDF (parameters `.nested_bsdf.…`)",
        "frame from ∂p/∂u as Mitsuba, with its flipped normals and shadow terminator; the map's texels are not parameters; inside twosided, not around it; not inside blendbsdf",
    ),
    p(Bsdf, "null", "—", "an index-matched boundary (media)"),
    p(
        Bsdf,
        "plastic",
        "`diffuse_reflectance` (texturable), `specular_reflectance` (rgb, spectrum, bitmap, checkerboard or mesh_attribute; differentiable through the coating's delta lobe, which Mitsuba's `prb` gives no gradient), `int_ior`/`ext_ior`, `nonlinear`",
        "",
    ),
    p(
        Bsdf,
        "principled",
        "`base_color` (rgb, spectrum, bitmap or checkerboard), `roughness`, `anisotropic`, `metallic`, `spec_tint`, `spec_trans`, `sheen`, `sheen_tint`, `clearcoat`, `clearcoat_gloss`, `flatness` (parameters or one-channel textures), `eta` or `specular`, the three `*_sampling_rate`s",
        "Mitsuba 3.9.1's lobes and sampler; `eta`/`specular` constants (not parameters); shading frame along ∂p/∂u; not inside blendbsdf; inside twosided only without `spec_trans`",
    ),
    p(
        Bsdf,
        "principledthin",
        "`base_color` (rgb, spectrum, bitmap or checkerboard), `roughness`, `anisotropic`, `spec_trans`, `spec_tint`, `sheen`, `sheen_tint`, `flatness`, `diff_trans` (0 to 2), `eta` (parameters or one-channel textures; `eta` differentiable: it bends nothing), the four `*_sampling_rate`s",
        "Mitsuba 3.9.1's lobes and sampler; shading frame along ∂p/∂u; not inside blendbsdf or twosided (Mitsuba's twosided refuses it too)",
    ),
    p(
        Bsdf,
        "roughconductor",
        "`distribution`, `alpha` or `alpha_u`/`alpha_v` (parameters or one-channel textures), `specular_reflectance` (rgb, spectrum, bitmap, checkerboard or volume), `material` or `eta`/`k` (parameters `.eta.value`, `.k.value`, RGB, a preset's too), `sample_visible`",
        "anisotropic: shading frame along ∂p/∂u",
    ),
    p(
        Bsdf,
        "roughdielectric",
        "`distribution`, `alpha` or `alpha_u`/`alpha_v` (parameters or one-channel textures), `int_ior`/`ext_ior`, `specular_reflectance`, `specular_transmittance` (each rgb, spectrum, bitmap, checkerboard or mesh_attribute), `sample_visible`",
        "anisotropic: shading frame along ∂p/∂u; not inside blendbsdf or twosided",
    ),
    p(
        Bsdf,
        "roughplastic",
        "`distribution`, `alpha` (parameter `.alpha`, a number as Mitsuba's), `diffuse_reflectance` (texturable), `specular_reflectance` (rgb, spectrum, bitmap, checkerboard or mesh_attribute), `int_ior`/`ext_ior`, `nonlinear`, `sample_visible`",
        "",
    ),
    p(
        Bsdf,
        "thindielectric",
        "`int_ior`/`ext_ior`, `specular_reflectance`, `specular_transmittance` (each rgb, spectrum, bitmap, checkerboard or mesh_attribute)",
        "smooth",
    ),
    p(Bsdf, "twosided", "one nested BSDF", "not around a transmitting BSDF (as Mitsuba)"),
    p(Emitter, "constant", "`radiance`", "the environment"),
    p(Emitter, "directional", "`irradiance`, `direction` or `to_world`", "next-event estimation only"),
    p(
        Emitter,
        "envmap",
        "`filename` (EXR, HDR, PNG), `scale`, `to_world` (a rotation)",
        "texels are parameter `.data`",
    ),
    p(Emitter, "point", "`intensity`, `position` or `to_world`", "next-event estimation only"),
    p(
        Emitter,
        "projector",
        "`irradiance` (constant or `bitmap`), `scale`, `fov`/`fov_axis`/`focal_length`, `to_world`",
        "next-event estimation only; texels are parameter `.irradiance.data`, `scale` parameter `.scale`",
    ),
    p(
        Emitter,
        "spot",
        "`intensity`, `cutoff_angle`, `beam_width`, `texture` (`bitmap`), `to_world`",
        "next-event estimation only; texels are parameter `.texture.data`",
    ),
    p(
        Emitter,
        "area",
        "`radiance` (rgb, spectrum, `bitmap` with `to_uv`, or `checkerboard` of colours in [0, 1] with `to_uv`)",
        "inside a <shape> (or referred to by one); a bitmap's texels are parameter `….radiance.data`, a checkerboard's colours `….radiance.color0.value` and `….radiance.color1.value`, read at the point's texture coordinates; sampled by area (Mitsuba samples a textured one in its texture's uv space, a bitmap by its texels ignoring `to_uv`, a checkerboard uniformly: the same expectation)",
    ),
    p(
        Shape,
        "bsplinecurve",
        "`filename` (Mitsuba's text format, at least 4 control points a curve), `to_world` (moves positions, not radii)",
        "tessellated to 0.02 px (Embree's circles normal to the tangent, Mitsuba's normals and UV, open ends); no area emitters",
    ),
    p(Shape, "cube", "`to_world`, `flip_normals`", ""),
    p(Shape, "cylinder", "`p0`, `p1`, `radius`, `to_world`, `flip_normals`", "tessellated"),
    p(Shape, "disk", "`to_world`, `flip_normals`", "tessellated"),
    p(
        Shape,
        "linearcurve",
        "`filename` (Mitsuba's text format: `x y z radius` a line, curves split by blank lines), `to_world` (moves positions, not radii)",
        "tessellated to 0.02 px (cones and joint spheres, Mitsuba's UV); no area emitters",
    ),
    p(Shape, "obj", "`filename`, `to_world`, `face_normals`, `flip_normals`", ""),
    p(Shape, "ply", "`filename`, `to_world`, `face_normals`, `flip_normals`", ""),
    p(Shape, "rectangle", "`to_world`, `flip_normals`", ""),
    p(
        Shape,
        "sdfgrid",
        "`filename` (a one-channel `.vol` grid), `normals` (`smooth` or `analytic`), `to_world`",
        "the zero set of the trilinear interpolant, tessellated to 0.02 px with Mitsuba's normals; no UV (0, 0), no area emitters; `grid` and `to_world` are not parameters",
    ),
    p(Shape, "serialized", "`filename`, `shape_index`, `to_world`, `face_normals`, `flip_normals`", ""),
    p(Shape, "sphere", "`center`, `radius`, `to_world` (a similarity), `flip_normals`", "tessellated to 0.02 px"),
    p(Shape, "shapegroup", "nested shapes", "built by its instances"),
    p(Shape, "instance", "a `<ref>` to a shapegroup, `to_world`", "flattened into meshes sharing the group's BSDFs"),
    p(
        Texture,
        "bitmap",
        "`filename`, `raw`, `filter_type`, `wrap_mode`, `to_uv`, `format`",
        "texels are parameter `.data`; on a float property (roughness, blend weight) the image must have one channel",
    ),
    p(
        Texture,
        "checkerboard",
        "`color0`, `color1`, `to_uv`",
        "colours on a colour property, `<float>`s on a float property (roughness, blend weight), where `color1` is read where `color0` would be on a colour property, as Mitsuba 3.9.1 does",
    ),
    p(
        Texture,
        "mesh_attribute",
        "`name` (`vertex_…` or `face_…`), `scale` (1 only)",
        "in the BSDF of a `ply` shape whose file has the attribute (Mitsuba's PLY naming); the values are parameter `SHAPE.NAME` (per vertex: interpolated by barycentrics), an RGB attribute on a colour property, a one-value one on a float property; a BSDF that reads one belongs to its one shape",
    ),
    p(
        Texture,
        "volume",
        "`volume` (a `gridvolume`, `constvolume`, `<float>` or `<rgb>`)",
        "as a colour: a `diffuse`'s `reflectance`, a `conductor`'s or `roughconductor`'s `specular_reflectance` (not a plastic's colours, which Mitsuba refuses, nor yet any other colour or a scalar), looked up at the world-space surface point; a grid's values are parameter `.volume.data`",
    ),
    p(Medium, "homogeneous", "`sigma_t`, `albedo`, `scale`, a phase", "inside a null or dielectric boundary"),
    p(
        Medium,
        "heterogeneous",
        "`sigma_t`, `albedo` (volumes), `scale`, a phase",
        "inside a null or dielectric boundary",
    ),
    p(Phase, "isotropic", "—", ""),
    p(Phase, "hg", "`g` (parameter)", ""),
    p(Volume, "constvolume", "`value`", ""),
    p(Volume, "gridvolume", "`filename` or data, `to_world`, `filter_type`, `wrap_mode` (clamp, repeat, mirror)", ""),
    p(
        Sensor,
        "perspective",
        "`fov`, `fov_axis`, `focal_length`, `to_world`, `near_clip`, `far_clip`",
        "does not clip (warned where it matters)",
    ),
    p(Sensor, "thinlens", "as perspective, `aperture_radius`, `focus_distance`", ""),
    p(Sensor, "orthographic", "`to_world` (its scale sizes the film), `near_clip`", ""),
    p(
        Film,
        "hdrfilm",
        "`width`, `height`, `crop_offset_x`, `crop_offset_y`, `crop_width`, `crop_height`, an rfilter",
        "`sample_border` refused",
    ),
    p(Rfilter, "box", "—", ""),
    p(Rfilter, "tent", "`radius`", ""),
    p(Rfilter, "gaussian", "`stddev`", ""),
    p(Sampler, "independent", "`sample_count`", ""),
    p(Sampler, "stratified", "`sample_count`", "drawn as independent (warned)"),
    p(Sampler, "multijitter", "`sample_count`", "drawn as independent (warned)"),
    p(Sampler, "orthogonal", "`sample_count`", "drawn as independent (warned)"),
    p(Sampler, "ldsampler", "`sample_count`", "drawn as independent (warned)"),
    p(
        Integrator,
        "path",
        "`max_depth`, `rr_depth`, `hide_emitters`",
        "every interaction counts toward `max_depth`; `hide_emitters` as Mitsuba's",
    ),
    p(Integrator, "prb", "as path", ""),
    p(Integrator, "prb_basic", "as path", ""),
    p(
        Integrator,
        "volpath",
        "as path",
        "a null-flagged BSDF sample (thindielectric transmission, mask pass-through) is no bounce",
    ),
    p(Integrator, "volpathmis", "as path", "as volpath"),
    p(Integrator, "prbvolpath", "as path", "as volpath"),
    p(
        Integrator,
        "direct",
        "`emitter_samples`, `bsdf_samples`, `shading_samples`, `hide_emitters`",
        "a path tracer of depth 2 (warned)",
    ),
    p(
        Integrator,
        "ptracer",
        "`max_depth`, `rr_depth`, `hide_emitters`, `samples_per_pass`",
        "a path tracer (warned); no media",
    ),
    p(
        Integrator,
        "prb_projective",
        "as path; `sppc`, `sppp`, `sppi`, `guiding`, `guiding_proj`, `guiding_rounds`, `project_seed`, `proj_seed_spp`",
        "as prb, no geometry gradients (warned)",
    ),
    p(Integrator, "direct_projective", "as prb_projective", "a path tracer of depth 2, no geometry gradients (warned)"),
    p(Integrator, "moment", "one nested integrator", "renders the nested one (warned)"),
    p(Integrator, "aov", "one nested integrator", "renders the nested one (warned)"),
];

/// The names of `category`'s plugins, in the list's order, joined by ", " (for messages).
pub fn names(category: Category) -> String {
    PLUGINS.iter().filter(|p| p.category == category).map(|p| p.name).collect::<Vec<_>>().join(", ")
}

/// `docs/mitsuba-plugins.md`: a table per category.
pub fn markdown() -> String {
    let mut out = String::from(
        "# Mitsuba plugins pathgrad reads\n\n\
         Generated from `src/scene/mitsuba/plugins.rs` (the loader's own list; `cargo test` fails when\n\
         this file is not what it generates: run the tests with `PATHGRAD_BLESS=1` to rewrite it).\n\
         Every other plugin of Mitsuba 3.9.1 is refused by name. Parameters are Mitsuba's `traverse` keys.\n",
    );
    for category in Category::ALL {
        out.push_str(&format!(
            "\n## `<{}>`\n\n| plugin | properties read | notes |\n| --- | --- | --- |\n",
            category.tag()
        ));
        for p in PLUGINS.iter().filter(|p| p.category == category) {
            out.push_str(&format!("| `{}` | {} | {} |\n", p.name, p.properties, p.note));
        }
    }
    out
}
