// Enumerations whose values cross the host/GPU boundary: material and leaf tags, microfacet
// distributions, strategies, losses.
//
// `include!`d by `src/contract/mod.rs` and `build.rs`. Each variant names its GLSL macro and its
// value once: Rust gets a `#[repr(u32)]` enum plus a `u32` constant of that name (for the `Pod`
// struct fields that carry the tag), and build.rs hands the same (name, value) pairs to glslc.
// Keep this file free of `use` items.

macro_rules! contract_enums {
    ($($(#[$doc:meta])* enum $name:ident { $($(#[$vdoc:meta])* $variant:ident = $glsl:ident = $value:expr,)* })*) => {
        $(
            $(#[$doc])*
            #[repr(u32)]
            #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
            pub enum $name { $($(#[$vdoc])* $variant = $value,)* }

            impl $name {
                /// Every variant, in declaration order.
                pub const ALL: &[$name] = &[$($name::$variant),*];

                /// The value the kernels see.
                pub const fn value(self) -> u32 {
                    self as u32
                }

                /// The variant with this kernel value, if any.
                pub fn from_value(value: u32) -> Option<$name> {
                    $(if value == $value { return Some($name::$variant); })*
                    None
                }
            }

            $(
                #[doc = concat!("[`", stringify!($name), "::", stringify!($variant), "`] as the kernels spell it.")]
                pub const $glsl: u32 = $value;
            )*
        )*

        /// Every enumeration value as (GLSL name, value), in declaration order.
        pub const ENUM_CONSTANTS: &[(&str, u32)] = &[$($((stringify!($glsl), $value),)*)*];
    };
}

contract_enums! {
    /// What `Material::tag` holds.
    enum MaterialTag {
        /// Lambertian diffuse.
        Diffuse = MAT_DIFFUSE = 0,
        /// Rough conductor.
        RoughConductor = MAT_ROUGH_CONDUCTOR = 1,
        /// Blend of two leaf materials.
        Blend = MAT_BLEND = 2,
        /// No surface: a medium's index-matched boundary, which paths pass through.
        Null = MAT_NULL = 3,
        /// Rough plastic (a rough dielectric coating on a Lambertian base).
        RoughPlastic = MAT_ROUGH_PLASTIC = 4,
        /// Smooth conductor (a mirror).
        Conductor = MAT_CONDUCTOR = 5,
        /// Smooth dielectric interface.
        Dielectric = MAT_DIELECTRIC = 6,
        /// Thin dielectric sheet.
        ThinDielectric = MAT_THIN_DIELECTRIC = 7,
        /// Smooth plastic (a delta coating over a Lambertian base).
        Plastic = MAT_PLASTIC = 8,
        /// Rough dielectric interface (reflects and refracts through microfacets).
        RoughDielectric = MAT_ROUGH_DIELECTRIC = 9,
        /// Mitsuba's `principled` (Burley's Disney BSDF): base colour in `p_color`, roughness in
        /// `p_alpha`, anisotropic in `p_alpha_v` (scalar slots: a parameter or `SCALAR_TEXTURE`),
        /// its other eight scalars' slots the `PRINCIPLED_SCALARS` words of the tables array from
        /// `table` on, η in `eta.x`, its three sampling rates in `k`.
        Principled = MAT_PRINCIPLED = 10,
        /// Mitsuba's `principledthin`, in principled's layout: base colour in `p_color`, roughness
        /// in `p_alpha`, anisotropic in `p_alpha_v`, the record at `table` holding the slots of
        /// (diff_trans, spec_tint, spec_trans, sheen, sheen_tint, eta, eta again, flatness) — the
        /// words of principled's (metallic, …, clearcoat, clearcoat_gloss, …) —, the sampling
        /// rates of specular reflection, specular transmission and diffuse reflection in `k` and
        /// of diffuse transmission in `eta.x`.
        PrincipledThin = MAT_PRINCIPLED_THIN = 11,
    }

    /// What `ViewCamera::lens` holds.
    enum LensKind {
        /// A pinhole.
        Pinhole = LENS_PINHOLE = 0,
        /// A thin lens (depth of field).
        Thin = LENS_THIN = 1,
        /// An orthographic projection.
        Orthographic = LENS_ORTHOGRAPHIC = 2,
    }

    /// What `DeltaLight::kind` holds.
    enum LightKind {
        /// Mitsuba's `point`: intensity / distance².
        Point = LIGHT_POINT = 0,
        /// Mitsuba's `spot`: a point light with a cone and a linear falloff in angle.
        Spot = LIGHT_SPOT = 1,
        /// Mitsuba's `directional`: irradiance from one direction, at any distance.
        Directional = LIGHT_DIRECTIONAL = 2,
        /// Mitsuba's `projector`: a pinhole that projects its irradiance texture (or constant).
        Projector = LIGHT_PROJECTOR = 3,
    }

    /// What a `FieldDesc` holds.
    enum FieldKind {
        /// One value (per channel) everywhere.
        Constant = FIELD_CONSTANT = 0,
        /// A trilinearly interpolated voxel grid over the unit cube under its transform, its
        /// indices clamped to the grid (Mitsuba's default `wrap_mode`).
        Grid = FIELD_GRID = 1,
        /// The same grid tiled over space (`wrap_mode` repeat).
        GridRepeat = FIELD_GRID_REPEAT = 2,
        /// The same grid tiled with every other tile mirrored (`wrap_mode` mirror).
        GridMirror = FIELD_GRID_MIRROR = 3,
    }

    /// A medium's phase function.
    enum PhaseKind {
        /// Uniform over the sphere.
        Isotropic = PHASE_ISOTROPIC = 0,
        /// Henyey–Greenstein.
        HenyeyGreenstein = PHASE_HG = 1,
    }

    /// The kind of a leaf BSDF in the kernels (the same values as the material tags).
    enum LeafKind {
        /// Lambertian diffuse.
        Diffuse = LEAF_DIFFUSE = 0,
        /// Rough conductor.
        RoughConductor = LEAF_ROUGH_CONDUCTOR = 1,
        /// Rough plastic.
        RoughPlastic = LEAF_ROUGH_PLASTIC = 4,
        /// Smooth conductor (kinds from here on are smooth: sampled only).
        Conductor = LEAF_CONDUCTOR = 5,
        /// Smooth dielectric.
        Dielectric = LEAF_DIELECTRIC = 6,
        /// Thin dielectric (the last purely smooth kind).
        ThinDielectric = LEAF_THIN_DIELECTRIC = 7,
        /// Smooth plastic.
        Plastic = LEAF_PLASTIC = 8,
        /// Rough dielectric.
        RoughDielectric = LEAF_ROUGH_DIELECTRIC = 9,
        /// Principled.
        Principled = LEAF_PRINCIPLED = 10,
        /// Thin principled.
        PrincipledThin = LEAF_PRINCIPLED_THIN = 11,
    }

    /// Microfacet distribution.
    enum Distribution {
        /// Beckmann.
        Beckmann = DIST_BECKMANN = 0,
        /// GGX (Trowbridge–Reitz).
        Ggx = DIST_GGX = 1,
    }

    /// A film's reconstruction filter (`ViewCamera::filter_kind`, `scene::PixelFilter`).
    enum FilterKind {
        /// The pixel's square, uniformly.
        Box = FILTER_BOX = 0,
        /// Mitsuba's `tent`.
        Tent = FILTER_TENT = 1,
        /// Mitsuba's `gaussian`.
        Gaussian = FILTER_GAUSSIAN = 2,
    }

    /// What `Globals::strategy` holds (the sampling strategy without its parameters).
    enum StrategyTag {
        /// BSDF sampling, power-heuristic MIS (plain PRB).
        Bsdf = STRATEGY_BSDF = 0,
        /// Differential path sampling with mixture MIS (ALGORITHMS.md §5).
        Diff = STRATEGY_DIFF = 1,
    }

    /// How the differential strategy weights its placements of the differential vertex
    /// (`Globals::diff_placement`, ALGORITHMS.md §5.7).
    enum PlacementMis {
        /// Balance heuristic: every contribution divided by the mixture density (\[SG24\] Eq. 24).
        Balance = PLACEMENT_BALANCE = 0,
        /// Power heuristic (exponent 2) over the placements and, with NEE, the emitter samples.
        Power = PLACEMENT_POWER = 1,
    }

    /// A loss between a rendered image I and a target Ĩ, averaged over all W·H·3 values.
    enum Loss {
        /// Mean absolute difference; its adjoint is sign(I − Ĩ)/(3WH) (0 where equal).
        L1 = LOSS_L1 = 0,
        /// Mean squared difference.
        L2 = LOSS_L2 = 1,
        /// Relative MSE with the target in the denominator: ((I − Ĩ)/(Ĩ + ε))², ε = 1e-3 (the
        /// reference's inverse-rendering scripts).
        RelMse = LOSS_REL_MSE = 2,
        /// Relative MSE with the denominator max(|Ĩ|, ε): ((I − Ĩ)/max(|Ĩ|, ε))², ε = 1e-3 (the
        /// reference's variance scripts, `variance_loss.py`). Equal to [`Loss::RelMse`] up to
        /// O(ε/Ĩ) where Ĩ ≫ ε; it differs where the target is dark.
        RelMseMax = LOSS_REL_MSE_MAX = 3,
    }
}
