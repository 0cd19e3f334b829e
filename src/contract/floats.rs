// Float constants shared by Rust and GLSL: epsilons, clamps and the constants of π and e.
//
// `include!`d by `src/contract/mod.rs` and `build.rs`. build.rs writes each value as the shortest
// decimal that reads back to the same f32 (it checks that reading the literal as a double and
// rounding, as glslang does, gives the same bits) and hands it to glslc as a macro; the contract
// probe (`tests/it/twins.rs`) reads every value back from a kernel and compares bits. Values are
// f32 constant expressions; keep this file free of `use` items.

macro_rules! contract_floats {
    ($($(#[$doc:meta])* $name:ident = $value:expr;)*) => {
        $( $(#[$doc])* pub const $name: f32 = $value; )*
        /// Every float constant as (name, value), in declaration order.
        pub const FLOAT_CONSTANTS: &[(&str, f32)] = &[$((stringify!($name), $value)),*];
    };
}

contract_floats! {
    /// The largest finite f32: the far end of an unbounded ray.
    FLOAT_MAX = f32::MAX;
    /// π.
    PI = std::f32::consts::PI;
    /// 1/π.
    INV_PI = std::f32::consts::FRAC_1_PI;
    /// π/2.
    PI_OVER_2 = std::f32::consts::FRAC_PI_2;
    /// π/4.
    PI_OVER_4 = std::f32::consts::FRAC_PI_4;
    /// e, rounded to f32.
    EULER_E = std::f32::consts::E;
    /// The f32 rounding error of e, so that 1 + e·x is formed without cancellation near x = −1/e.
    EULER_E_LO = (std::f64::consts::E - std::f32::consts::E as f64) as f32;

    /// The smallest roughness a textured α takes (Mitsuba's microfacet distribution clamps α to
    /// this; a texel may be 0): below it the lookup is clamped and its derivative is 0.
    ALPHA_TEXTURE_FLOOR = 1e-4;

    /// Offset of spawned rays, relative to the largest coordinate (at least 1): they must not re-hit
    /// the triangle they start on.
    RAY_OFFSET = 1e-4;
    /// Shadow rays stop this fraction short of the emitter point so the emitter never occludes itself.
    SHADOW_EPSILON = 1e-4;
    /// A medium's majorant is `scale · max σ_t` times 1 + this: no density reaches it, so no
    /// delta- or ratio-tracking weight (σ̄ − σ_t)/… is exactly 0 and no derivative through one is
    /// lost (issue 13, "exactness where a zero appears"); it costs 0.4 % more tentative collisions.
    MAJORANT_MARGIN = 0.00390625;
    /// Direction components smaller than this are replaced by it (keeping the sign), so the slab
    /// test's reciprocal is finite and `0 · ∞` never produces NaN.
    MIN_DIR_COMPONENT = 1e-20;
    /// The far end of a ray's span through a quantised BVH box is scaled by this before the box
    /// test: the box's planes are reached through a grid transform whose few ulps of rounding must
    /// not miss a triangle lying on a face (flat boxes are common: axis-aligned walls).
    BVH_FAR_SCALE = 1.0 + 1.0 / 1_048_576.0;
    /// A replay may leave this much radiance, relative to the path's (plus a floor): the primal sums
    /// its terms and the replay subtracts the same terms in the same order (ALGORITHMS.md §3.3).
    REPLAY_RESIDUAL_TOLERANCE = 1e-5;
    /// ε of the relative MSE's denominator (`Loss::RelMse`, `Loss::RelMseMax`).
    REL_MSE_EPSILON = 1e-3;

    /// D is set to 0 where D·cos θh falls below this: the value underflows and its derivative is noise.
    D_UNDERFLOW = 1e-20;
    /// Below this |sin θ| the azimuth of the stretched incident direction is taken as 0.
    AZIMUTH_EPSILON = 1e-7;
    /// The Beckmann slope sampler clamps its uniforms into [ε, 1 − ε] (logarithms and erfinv stay finite).
    BECKMANN_U_CLAMP = 1e-6;
    /// Above this cos θi the Beckmann visible slopes are sampled as the plain (Gaussian) slopes: the
    /// Newton inversion degenerates as tan θi → 0 while the two distributions coincide.
    BECKMANN_NORMAL_INCIDENCE = 0.99999;

    /// Below this distance p = √(2(1 + e·x)) from the branch point the Lambert-W series alone is used
    /// (its truncation error is ~0.026 p⁶ < 3e-8, while Halley's residual loses precision as p → 0).
    LAMBERT_SERIES_ONLY = 0.1;
    /// Above this x, W0 starts from x(1 − x) instead of the branch-point series.
    LAMBERT_W0_SMALL = -0.25;
    /// Above this x, W−1 starts from the asymptotic expansion instead of the series.
    LAMBERT_WM1_SMALL = -0.15;
    /// Half vectors with cos θh below this have differential density 0 (ALGORITHMS.md §4.2).
    DIFF_COS_EPSILON = 1e-9;

    /// Attached sampling: the amplitude of the direction noise that regularises a diffuse vertex's
    /// Jacobian (`crate::attached::Jac6::plus_direction_noise`) when the request sets none.
    DIFFUSE_JACOBIAN_NOISE = 1.0;
}
