// Integer constants shared by Rust and GLSL: binding numbers, random-number slots, feature bits, limits.
//
// This file is `include!`d by both `src/contract/mod.rs` and `build.rs`; build.rs hands the table to
// glslc as macro definitions, so no `.glsl` file spells any of these numbers. Keep it free of
// `use` items and of anything but the macro call below.

macro_rules! contract_constants {
    ($($(#[$doc:meta])* $name:ident = $value:expr;)*) => {
        $( $(#[$doc])* pub const $name: u32 = $value; )*
        /// Every constant as (name, value), in declaration order: the macro definitions of the shaders.
        pub const INT_CONSTANTS: &[(&str, u32)] = &[$((stringify!($name), $value)),*];
    };
}

contract_constants! {
    /// Invocations per workgroup of the 1-D kernels.
    WORKGROUP_SIZE = 64;

    /// Binding: per-dispatch constants (`Globals`).
    BINDING_GLOBALS = 0;
    /// Binding: BVH nodes (`BvhNode[]`).
    BINDING_NODES = 1;
    /// Binding: triangle positions in BVH leaf order (`TriPositions[]`).
    BINDING_TRIS = 2;
    /// Binding: the original triangle id of each leaf slot (`uint[]`).
    BINDING_PRIM_IDS = 3;
    /// Binding: unused since the shading data is read through device addresses
    /// (`Globals::addr_tri_vertices` and the arrays beside it).
    BINDING_SHADING = 4;
    /// Binding: materials (`Material[]`).
    BINDING_MATERIALS = 5;
    /// Binding: emissive triangles with their area CDF (`EmitterTri[]`).
    BINDING_EMITTERS = 6;
    /// Binding: the parameter table's values (`float[]`).
    BINDING_PARAMS = 7;
    /// Binding: RGB accumulation image (`float[]`, 3 per pixel).
    BINDING_ACCUM = 8;
    /// Binding: status flags written by kernels (`uint[]`).
    BINDING_STATUS = 9;
    /// Binding: the gradient, one float per parameter value (float-atomic mode).
    BINDING_GRADS = 12;
    /// Binding: the gradient in 64-bit fixed point (deterministic mode).
    BINDING_GRADS_FIXED = 13;
    /// Binding: the adjoint image δL = ∂loss/∂pixel, RGB per pixel.
    BINDING_ADJOINT = 14;
    /// Binding: the alias table of adaptive pixel sampling (`AliasEntry[]`, one per pixel).
    BINDING_ALIAS = 15;
    /// Binding: test-probe input (`uint[]`/`float[]`, probe kernels only).
    BINDING_PROBE_IN = 10;
    /// Binding: test-probe output (probe kernels only).
    BINDING_PROBE_OUT = 11;


    /// `Material::tex_mode`: nearest-texel lookup (else bilinear).
    TEX_NEAREST = 1;
    /// `Material::tex_mode`: mirrored wrapping of texel indices (Mitsuba's `mirror`).
    TEX_WRAP_MIRROR = 2;
    /// `Material::tex_mode`: clamped texel indices (Mitsuba's `clamp`); neither bit: `repeat`.
    TEX_WRAP_CLAMP = 4;
    /// `Material::tex_mode`: Mitsuba's checkerboard, a 2×1 texture whose first texel is read
    /// where the coordinates' fractional parts lie on the same side of 1/2, else its second.
    TEX_CHECKER = 8;
    /// `Material::tex_mode` (and a scalar texture's mode word): Mitsuba's `mesh_attribute` of
    /// one row per triangle, read at the hit triangle's index in its mesh (row of `dim` values).
    TEX_ATTR_FACE = 32;
    /// `Material::tex_mode` (and a scalar texture's mode word): Mitsuba's `mesh_attribute` of
    /// one row per vertex, the hit triangle's three rows weighted by its barycentric coordinates.
    TEX_ATTR_VERTEX = 64;
    /// `Material::tex_mode`: Mitsuba's `volume` texture, a field (`Material::p_color` is its
    /// index in the fields array, `Globals::addr_fields`) looked up at the hit's world-space point.
    TEX_VOLUME = 128;
    /// `Material::nmap_mode`: the map is a bump map (heights, one value a texel), not a normal
    /// map (RGB).
    NMAP_BUMP = 16;

    /// The emitter index of a triangle that does not emit (`MeshShading::emitter_base`).
    NO_EMITTER = 0xFFFF_FFFF;
    /// A parameter offset that refers to nothing (e.g. no environment).
    NO_PARAM = 0xFFFF_FFFF;
    /// A `MeshShading` offset of per-vertex or per-triangle data the mesh does not have.
    NO_ARRAY = 0xFFFF_FFFF;
    /// `MeshShading::interior` of a mesh that holds no medium, and the medium of a path
    /// in vacuum.
    NO_MEDIUM = 0xFFFF_FFFF;
    /// Bisection steps of a pixel filter's sample (`sampling::filter_sample`): 2⁻²⁴ of the
    /// filter's support, below f32's resolution of a film coordinate.
    FILTER_BISECTIONS = 24;
    /// Most null-BSDF boundaries one path segment (or shadow ray) passes before it is cut off.
    MAX_NULL_CROSSINGS = 64;
    /// `Globals::path_flags` bit: Mitsuba's `volpath` family's depth counting, in which a
    /// null-flagged BSDF sample (a `thindielectric`'s straight-through transmission, a `mask`'s
    /// pass-through) is not a bounce; without it every interaction counts (`path`, `prb`).
    PATH_NULL_UNCOUNTED = 1 << 0;
    /// `Globals::path_flags` bit: Mitsuba's `hide_emitters` — before the first counted
    /// interaction, rays pass through emitting shapes and the environment adds nothing.
    PATH_HIDE_EMITTERS = 1 << 1;
    /// Most vertices one path has (its random numbers' vertex index), whatever its counting:
    /// the cap on paths of uncounted null events (`PATH_NULL_UNCOUNTED`).
    MAX_PATH_VERTICES = 1024;
    /// Most tentative collisions one free flight or shadow segment takes before it is cut off
    /// (it then carries nothing): far beyond any majorant × length a scene has.
    MAX_TRACKING_STEPS = 32768;

    /// Status bit: an invocation exhausted lavapipe's loop budget (a loop exited early).
    STATUS_LOOP_BUDGET = 1;
    /// Status bit: the BVH traversal stack overflowed.
    STATUS_STACK_OVERFLOW = 2;

    /// Status bit: a replay ended with radiance left over (primal and replay drifted apart).
    STATUS_REPLAY_RESIDUAL = 4;
    /// Status bit: a fixed-point gradient sum overflowed.
    STATUS_FIXED_OVERFLOW = 8;

    /// Kernel variant: no gradient (the primal kernel).
    GRAD_MODE_NONE = 0;
    /// Kernel variant: reverse mode, float atomics with subgroup reduction.
    GRAD_MODE_FLOAT = 1;
    /// Kernel variant: reverse mode, 64-bit fixed-point integer atomics (bitwise reproducible).
    GRAD_MODE_FIXED = 2;
    /// Kernel variant: forward mode, per-pixel derivative of the image by one parameter.
    GRAD_MODE_FORWARD = 3;

    /// Entries of the traversal stack; the builder bounds the tree's depth to fit (src/bvh.rs).
    BVH_STACK_SIZE = 64;
    /// Most triangles in one BVH leaf (the compressed BVH's child encoding holds up to 3).
    BVH_LEAF_MAX = 3;

    /// Stream of per-vertex decisions.
    STREAM_MAIN = 0;
    /// Stream of delta-tracking steps (free flights and the null/real choice), per vertex.
    STREAM_DELTA_TRACKING = 1;
    /// Stream of ratio-tracking steps of shadow rays, per vertex.
    STREAM_RATIO_TRACKING = 2;
    /// Stream of attached sampling's Jacobian noise, per vertex (block 0: sign and magnitude).
    STREAM_JACOBIAN = 3;
    /// Stream of adaptive pixel selection (ALGORITHMS.md §2.3, §6): counter (0, k), vertex 0, block 0.
    STREAM_PIXEL = 4;
    /// Pass tag of the adaptive pixel-selection key: `key1 = (iteration << 8) | PASS_PIXEL_SELECT`.
    PASS_PIXEL_SELECT = 3;
    /// Camera vertex, block 0: pixel jitter in dims 0 and 1.
    DIM_PIXEL_JITTER = 0;
    /// Surface vertex, block 0: emitter selection.
    DIM_EMITTER_SELECT = 0;
    /// Surface vertex, block 0: position on the emitter (dims 1 and 2).
    DIM_EMITTER_POS = 1;
    /// Surface vertex, block 1: lobe selection (dim 4).
    DIM_LOBE = 4;
    /// Surface vertex, block 1: direction sample (dims 5 and 6).
    DIM_DIRECTION = 5;
    /// Surface vertex, block 1: technique choice of the differential strategy (dim 7).
    DIM_TECHNIQUE = 7;
    /// Surface vertex, block 2: signed part of the differential sampler (dim 8).
    DIM_DIFF_SIGN = 8;
    /// Surface vertex, block 2: Russian roulette (dim 9).
    DIM_ROULETTE = 9;
    /// Surface or medium vertex, block 2: the environment map's cell for next-event estimation,
    /// alias-table column and coin (dims 10 and 11).
    DIM_ENV_CELL = 10;
    /// Camera vertex, block 1: the hero parameter of the differential strategy with several
    /// targets (dim 4; ALGORITHMS.md §5.8).
    DIM_HERO = 4;
    /// Most targets of the differential strategy's hero set (`Globals::hero_count`).
    MAX_HEROES = 4;


    /// Specialisation constant id of `FEATURES` (`shaders/lib/features.glsl`).
    SPEC_FEATURES = 0;
    /// Specialisation constant id of `FEATURES2`, the second feature word: its bits are the
    /// `F2_*` constants (tested with `HAS2` in GLSL; on the host they are the high 32 bits of a
    /// variant's features, [`crate::gpu::variant::word2`]).
    SPEC_FEATURES2 = 1;
    /// Second-word feature bit: the differential strategy with several targets, one hero per path
    /// (`Globals::hero_count` > 0, ALGORITHMS.md §5.8).
    F2_HERO = 1 << 0;
    /// Second-word feature bit: thin principled leaves (Mitsuba's `principledthin`,
    /// `shaders/lib/principled_thin.glsl`), which share principled's material record and
    /// gradient gathering.
    F2_PRINCIPLED_THIN = 1 << 1;
    /// Second-word feature bit: a material's colour is a `volume` texture (`TEX_VOLUME`), read
    /// through the fields' lookup of `shaders/lib/field.glsl`.
    F2_VOLUME_TEXTURE = 1 << 2;
    /// Second-word feature bit: the scene hides its emitters from the camera (Mitsuba's
    /// `hide_emitters`, `PATH_HIDE_EMITTERS`): the path's first ray passes through emitting
    /// shapes. Every other kernel keeps the single traversal of a plain ray.
    F2_HIDE_EMITTERS = 1 << 3;
    /// Second-word feature bit: an area emitter's radiance is a texture (its `p_radiance` has
    /// `SCALAR_TEXTURE` set: a bitmap or checkerboard read at the point's texture coordinates).
    /// Kernels of scenes without one carry no texture lookup for their emitters.
    F2_AREA_TEXTURE = 1 << 4;
    /// Feature bit: next-event estimation.
    F_NEE = 1 << 0;
    /// Feature bit: a constant environment emitter.
    F_ENV = 1 << 1;
    /// Feature bit: emissive triangles.
    F_EMITTERS = 1 << 2;
    /// Feature bit: the differential strategy (ALGORITHMS.md §5).
    F_DIFF = 1 << 3;
    /// Feature bit: Lambertian leaves.
    F_DIFFUSE = 1 << 4;
    /// Feature bit: rough-conductor leaves.
    F_CONDUCTOR = 1 << 5;
    /// Feature bit: blend materials.
    F_BLEND = 1 << 6;
    /// Feature bit: textured colours.
    F_TEXTURE = 1 << 7;
    /// Feature bit: the Beckmann distribution.
    F_BECKMANN = 1 << 8;
    /// Feature bit: the GGX distribution.
    F_GGX = 1 << 9;
    /// Feature bit: two-sided materials.
    F_TWO_SIDED = 1 << 10;
    /// Feature bit: participating media and null boundaries.
    F_MEDIA = 1 << 11;
    /// Feature bit: the environment is a map (`envmap`), not a constant.
    F_ENV_MAP = 1 << 12;
    /// Feature bit: lights without area (point, spot, directional).
    F_LIGHTS = 1 << 13;
    /// Feature bit: rough-plastic leaves.
    F_PLASTIC = 1 << 14;
    /// Feature bit: smooth (delta) leaves: conductor, dielectric, thin dielectric.
    F_DELTA = 1 << 15;
    /// Feature bit: smooth-plastic leaves (a delta coating over a Lambertian base).
    F_SMOOTH_PLASTIC = 1 << 23;
    /// Feature bit: rough-dielectric leaves.
    F_ROUGH_DIELECTRIC = 1 << 24;
    /// Feature bit: anisotropic rough conductors, whose shading frame follows the surface's ∂p/∂u.
    F_ANISOTROPIC = 1 << 25;
    /// Feature bit: normal or bump maps (Mitsuba's `normalmap`, `bumpmap`), which perturb the
    /// shading frame built on ∂p/∂u.
    F_NORMAL_MAP = 1 << 26;
    /// Feature bit: textured scalar parameters (roughness, blend weight): a `Material` offset with
    /// `SCALAR_TEXTURE` set names a texture descriptor in the tables array.
    F_PARAM_TEXTURE = 1 << 27;
    /// Feature bit: masked materials (Mitsuba's `mask`): a `Material::p_opacity` other than
    /// `NO_PARAM` lets a path pass straight through with probability 1 − opacity.
    F_MASK = 1 << 28;
    /// Feature bit: lights without area that read a texture (a textured `spot`) or that are
    /// projectors (`DeltaLight::tex`, `p_scale`, `uv_scale` and the frame rows).
    F_LIGHT_TEXTURE = 1 << 29;
    /// Feature bit: principled leaves (Mitsuba's `principled`, `shaders/lib/principled.glsl`).
    F_PRINCIPLED = 1 << 30;
    /// Words of a principled material's record in the tables array (at `Material::table`): the
    /// scalar slots (a parameter offset, or `SCALAR_TEXTURE` with a texture's descriptor) of
    /// metallic, spec_tint, spec_trans, sheen, sheen_tint, clearcoat, clearcoat_gloss, flatness.
    PRINCIPLED_SCALARS = 8;
    /// An `EmitterSample::param` (a gradient term's emitter) with this bit set is not a parameter
    /// offset: its other bits are the index of a textured light or projector, whose intensity,
    /// texels and scale the term reaches.
    LIGHT_SLOT = 0x4000_0000;
    /// A `Material::p_alpha`, `p_alpha_v`, (blend) `p_weight` or `p_opacity` with this bit set is not a
    /// parameter offset: its other bits are the offset in the tables array of a one-channel
    /// texture's descriptor (`TEXTURE_DESC_LEN` words: texel offset, width, height, `TEX_*` mode,
    /// then the `to_uv` rows 0 and 1, three floats each).
    SCALAR_TEXTURE = 0x8000_0000;
    /// Words of a scalar texture's descriptor in the tables array (`SCALAR_TEXTURE`).
    TEXTURE_DESC_LEN = 10;
    /// Entries of a rough plastic's coating transmittance table (μ = k/63, k = 0..63).
    COATING_RES = 64;
    /// Floats of one coating table as the kernels read it: T, ∂T/∂α, Rᵢ, ∂Rᵢ/∂α.
    COATING_TABLE_LEN = 130;
    /// Feature bit: gradients of constant colours (albedo, specular reflectance).
    G_COLOR = 1 << 16;
    /// Feature bit: gradients of texels.
    G_TEXTURE = 1 << 17;
    /// Feature bit: gradients of roughness.
    G_ALPHA = 1 << 18;
    /// Feature bit: gradients of blend weights and mask opacities.
    G_WEIGHT = 1 << 19;
    /// Feature bit: gradients of emitted radiance (triangles).
    G_EMISSION = 1 << 20;
    /// Feature bit: gradients of the environment's radiance.
    G_ENV = 1 << 21;
    /// Feature bit: gradients of participating media (grid or constant extinction and albedo,
    /// scale, Henyey–Greenstein g).
    G_MEDIUM = 1 << 22;
    /// Feature bits that differentiate something.
    G_ANY = (1 << 16) | (1 << 17) | (1 << 18) | (1 << 19) | (1 << 20) | (1 << 21) | (1 << 22);

    /// Work items one dispatch hands out are taken from this counter (`BINDING_WORK`).
    BINDING_WORK = 16;
    /// Pixels of a square screen tile, the unit in which work items walk the image.
    TILE_SIZE = 8;
}
