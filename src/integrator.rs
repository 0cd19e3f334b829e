//! Options shared by the GPU renderer and the CPU reference: image size, samples, depth, seed.

pub use crate::contract::PlacementMis;
use crate::contract::{
    Globals, LENS_ORTHOGRAPHIC, LENS_PINHOLE, LENS_THIN, MAX_HEROES, NO_PARAM, PATH_HIDE_EMITTERS, PATH_NULL_UNCOUNTED,
    STRATEGY_BSDF, STRATEGY_DIFF, ViewCamera,
};
use crate::error::{Error, Result};
use crate::params::ParamId;
use crate::rng::{PassTag, RngKey};
use crate::scene::flat::FlatScene;
use crate::scene::{Camera, Scene};

/// Bounce cap used when `max_depth` is unbounded: a path that survives Russian roulette this long
/// is ended (its expected contribution beyond is negligible at any sane albedo).
pub const UNBOUNDED_DEPTH_CAP: u32 = 1024;

/// Most samples per pixel one render takes (2²⁰): more would run for days on any device and come
/// close to the 32-bit sample counters. For more, average renders of independent seeds.
pub const MAX_SPP: u32 = 1 << 20;

/// The largest film width or height [`RenderOptions::validate`] accepts.
pub const MAX_IMAGE_SIZE: u32 = 16_384;

/// With both an environment and area emitters, next-event estimation picks the environment with
/// this probability (Mitsuba picks among emitters uniformly; two emitter kinds give ½).
pub const ENV_SELECT_PROB: f32 = 0.5;

/// Deterministic gradients accumulate `round(value · FIXED_POINT_SCALE)` in 64-bit integers: a
/// resolution of 2⁻³² ≈ 2.3e-10 per contribution and sums up to ±2³¹ ≈ 2.1e9 before overflow,
/// which the kernels detect (sign change of an add) and report as an error.
pub const FIXED_POINT_SCALE: f32 = 4_294_967_296.0;

/// Russian roulette starts after this many bounces by default (Mitsuba's `rr_depth`).
pub const DEFAULT_RR_DEPTH: u32 = 5;

/// Probability with which the `diff` strategy makes a capable vertex the differential vertex
/// (ALGORITHMS.md §5.1; the paper's and its code's default).
pub const DEFAULT_DIFF_Q: f32 = 0.5;

/// The default amplitude of the noise attached sampling adds to its ray Jacobians
/// ([`Sampling::Attached::noise`]): none, the exact completion alone (`crate::attached`).
pub const DEFAULT_JACOBIAN_NOISE: f32 = 0.0;

/// How the sampled directions relate to the parameters (issue 34; PRB supplemental §1–2).
///
/// Detached sampling (Mitsuba's `prb`, the default) holds every sampled direction fixed while
/// differentiating: a parameter that acts only through the directions it produces — a
/// dielectric's index of refraction — has no derivative. Attached sampling lets the directions
/// move with the parameters and adds the derivative of the radiance that follows each vertex by
/// the direction leaving it, recovered from the derivative by the camera ray through the
/// product of the vertices' ray Jacobians (ALGORITHMS.md §9, `crate::attached`).
///
/// ```
/// use pathgrad::integrator::{RenderOptions, Sampling, Strategy};
/// let scene = pathgrad::scene::builtin::load("cornell-box")?;
/// let opts = RenderOptions { sampling: Sampling::attached(), ..RenderOptions::for_scene(&scene) };
/// assert!(opts.validate().is_ok());
/// // Only with plain BSDF sampling.
/// let scene = pathgrad::scene::builtin::load("blend")?;
/// let diff = Strategy::from_name(&scene, "diff", 0.5, "object.weight.value")?;
/// assert!(RenderOptions { strategy: diff, ..opts }.validate().is_err());
/// # Ok::<(), pathgrad::Error>(())
/// ```
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum Sampling {
    /// Directions held fixed (the detached derivative).
    #[default]
    Detached,
    /// Directions move with the parameters (the attached derivative).
    Attached {
        /// The amplitude a of the noise Y·I added to each vertex's completed ray Jacobian (PRB
        /// supplemental §2): |Y| uniform in [a/2, a], sign random; in [0, 1), 0 for none. Zero-mean
        /// noise keeps the estimate unbiased and adds variance; the smooth and rough vertices
        /// need none (BENCHMARKS.md "Attached derivatives"). A diffuse vertex, whose direction
        /// block is singular, always takes noise Y·R in that block alone
        /// (`crate::attached::Jac6::plus_direction_noise`), of amplitude a when a > 0, else
        /// [`crate::contract::DIFFUSE_JACOBIAN_NOISE`] (BENCHMARKS.md "Issue 34: diffuse vertices").
        noise: f32,
    },
}

impl Sampling {
    /// Attached sampling with the default regularisation ([`DEFAULT_JACOBIAN_NOISE`]).
    pub fn attached() -> Sampling {
        Sampling::Attached { noise: DEFAULT_JACOBIAN_NOISE }
    }

    /// Whether directions are attached.
    pub fn is_attached(&self) -> bool {
        matches!(self, Sampling::Attached { .. })
    }

    /// `detached` or `attached`.
    pub fn name(&self) -> &'static str {
        if self.is_attached() { "attached" } else { "detached" }
    }
}

/// Kinds of parameters, as a set: which gradients a reverse-mode pass computes
/// ([`RenderOptions::differentiate`]). A kernel is compiled with the derivative code of these
/// kinds only (issue "Fast kernels"), so asking for fewer makes gradient passes cheaper.
///
/// ```
/// use pathgrad::integrator::ParamKinds;
/// let k = ParamKinds::ALPHA.union(ParamKinds::WEIGHT);
/// assert!(k.contains(ParamKinds::ALPHA) && !k.contains(ParamKinds::COLOR));
/// assert!(ParamKinds::ALL.contains(k));
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct ParamKinds(u32);

impl ParamKinds {
    /// No parameter.
    pub const NONE: ParamKinds = ParamKinds(0);
    /// Constant colours: diffuse albedo, conductor specular reflectance, a conductor's eta and k.
    pub const COLOR: ParamKinds = ParamKinds(crate::contract::G_COLOR);
    /// Texels of textured colours.
    pub const TEXTURE: ParamKinds = ParamKinds(crate::contract::G_TEXTURE);
    /// Roughness of rough conductors.
    pub const ALPHA: ParamKinds = ParamKinds(crate::contract::G_ALPHA);
    /// Blend weights and mask opacities.
    pub const WEIGHT: ParamKinds = ParamKinds(crate::contract::G_WEIGHT);
    /// Emitted radiance of area emitters.
    pub const EMISSION: ParamKinds = ParamKinds(crate::contract::G_EMISSION);
    /// The constant environment's radiance.
    pub const ENVIRONMENT: ParamKinds = ParamKinds(crate::contract::G_ENV);
    /// Participating media: extinction and albedo (grid voxels or constants), scale, g.
    pub const MEDIUM: ParamKinds = ParamKinds(crate::contract::G_MEDIUM);
    /// Every kind.
    pub const ALL: ParamKinds = ParamKinds(crate::contract::G_ANY);

    /// Both sets.
    pub const fn union(self, other: ParamKinds) -> ParamKinds {
        ParamKinds(self.0 | other.0)
    }

    /// What both sets hold.
    pub const fn intersection(self, other: ParamKinds) -> ParamKinds {
        ParamKinds(self.0 & other.0)
    }

    /// Whether every kind of `other` is in `self`.
    pub const fn contains(self, other: ParamKinds) -> bool {
        self.0 & other.0 == other.0
    }

    /// Whether the set is empty.
    pub const fn is_empty(self) -> bool {
        self.0 == 0
    }

    /// The set as `G_*` feature bits of [`crate::contract`].
    pub const fn bits(self) -> u32 {
        self.0
    }
}

impl Default for ParamKinds {
    fn default() -> ParamKinds {
        ParamKinds::ALL
    }
}

/// How paths choose their directions (ALGORITHMS.md §3, §5). Both are unbiased for the image and for
/// the gradient of every parameter; they differ in variance.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum Strategy {
    /// Plain PRB: BSDF sampling with power-heuristic MIS against next-event estimation (Mitsuba's
    /// `prb`), the baseline.
    #[default]
    Bsdf,
    /// Differential path sampling (Su & Gkioulekas): at each vertex whose material's roughness or
    /// blend weight, or whose medium's phase-function g, *is* `target`, until one is chosen, sample
    /// the derivative of the BSDF (or phase function) by
    /// `target` with probability `q`; every contribution is divided by the mixture density of all
    /// placements (running sums w₁, w₂; Appendix-B weights for next-event estimation), or, with
    /// [`PlacementMis::Power`], weighted by the power heuristic over the placements (ALGORITHMS.md §5.7).
    Diff {
        /// The parameter whose derivative drives the differential sampler.
        target: ParamId,
        /// Probability of the differential technique at a capable vertex, in [0, 1].
        q: f32,
        /// How the placements of the differential vertex are weighted against each other.
        placement: PlacementMis,
    },
    /// Differential path sampling by several parameters, one *hero* per path (ALGORITHMS.md §5.8):
    /// each path draws its hero k with probability p_k (camera vertex, dimension `DIM_HERO`) and
    /// runs [`Strategy::Diff`]'s sampler for k, at the vertices whose roughness or blend weight is
    /// k; every contribution is divided by the mixture density over all heroes and placements,
    /// Σ_k p_k (w₁ᵏ + w₂ᵏ), so every parameter's gradient stays unbiased. Placements are weighted by
    /// the balance heuristic.
    Hero {
        /// The targets and their probabilities.
        heroes: HeroSet,
        /// Probability of the differential technique at a vertex capable for the path's hero.
        q: f32,
    },
}

/// The targets of [`Strategy::Hero`] — 2 to `MAX_HEROES` distinct parameters with a differential
/// sampler — and the probability p_k with which a path takes each as its hero (they sum to 1).
///
/// ```
/// use pathgrad::integrator::HeroSet;
/// use pathgrad::params::ParamId;
/// let set = HeroSet::new(&[ParamId(0), ParamId(3)], Some(&[1.0, 3.0]))?;
/// assert_eq!(set.targets(), &[ParamId(0), ParamId(3)]);
/// assert_eq!(set.weights(), &[0.25, 0.75]);
/// assert!(HeroSet::new(&[ParamId(0), ParamId(0)], None).is_err());
/// # Ok::<(), pathgrad::Error>(())
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HeroSet {
    targets: [ParamId; MAX_HEROES as usize],
    weights: [f32; MAX_HEROES as usize],
    len: u8,
}

impl HeroSet {
    /// The hero set of `targets` with probabilities proportional to `weights` (each finite and
    /// positive), or uniform (`None`).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `HeroSet::targets` for fewer than 2 or more than
    /// `MAX_HEROES` targets or a repeated one, `HeroSet::weights` for a count that differs from the
    /// targets' or a weight that is not finite and positive.
    pub fn new(targets: &[ParamId], weights: Option<&[f32]>) -> Result<HeroSet> {
        let bad =
            |parameter: &str, message: String| Err(Error::InvalidArgument { parameter: parameter.into(), message });
        if targets.len() < 2 || targets.len() > MAX_HEROES as usize {
            return bad(
                "HeroSet::targets",
                format!("{} targets: a hero set has 2 to {MAX_HEROES} (one target is Strategy::Diff)", targets.len()),
            );
        }
        if targets.iter().enumerate().any(|(i, t)| targets[..i].contains(t)) {
            return bad("HeroSet::targets", "a target appears twice".into());
        }
        let mut set =
            HeroSet { targets: [ParamId(0); MAX_HEROES as usize], weights: [0.0; MAX_HEROES as usize], len: 0 };
        set.targets[..targets.len()].copy_from_slice(targets);
        set.len = targets.len() as u8;
        let uniform = vec![1.0; targets.len()];
        set.with_weights(weights.unwrap_or(&uniform))
    }

    /// The same targets with probabilities proportional to `weights`.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `HeroSet::weights` for a count that differs from the
    /// targets' or a weight that is not finite and positive.
    pub fn with_weights(mut self, weights: &[f32]) -> Result<HeroSet> {
        let n = self.len as usize;
        let bad = |message: String| Err(Error::InvalidArgument { parameter: "HeroSet::weights".into(), message });
        if weights.len() != n {
            return bad(format!("{} weights for {n} targets", weights.len()));
        }
        if let Some(w) = weights.iter().find(|w| !(w.is_finite() && **w > 0.0)) {
            return bad(format!("{w} is not a finite positive weight (every target keeps its sampler)"));
        }
        let total: f64 = weights.iter().map(|&w| f64::from(w)).sum();
        for (p, &w) in self.weights.iter_mut().zip(weights) {
            *p = (f64::from(w) / total) as f32;
        }
        Ok(self)
    }

    /// The targets, in the order given.
    pub fn targets(&self) -> &[ParamId] {
        &self.targets[..self.len as usize]
    }

    /// Each target's probability of being a path's hero (normalised to sum 1).
    pub fn weights(&self) -> &[f32] {
        &self.weights[..self.len as usize]
    }
}

impl PlacementMis {
    /// The weighting named `name`: `balance` or `power`.
    ///
    /// ```
    /// use pathgrad::integrator::PlacementMis;
    /// assert_eq!(PlacementMis::from_name("power")?, PlacementMis::Power);
    /// assert!(PlacementMis::from_name("max").is_err());
    /// # Ok::<(), pathgrad::Error>(())
    /// ```
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `PlacementMis::from_name` for any other name.
    pub fn from_name(name: &str) -> Result<PlacementMis> {
        match name {
            "balance" => Ok(PlacementMis::Balance),
            "power" => Ok(PlacementMis::Power),
            other => Err(Error::InvalidArgument {
                parameter: "PlacementMis::from_name".into(),
                message: format!("unknown placement weighting '{other}' (expected balance or power)"),
            }),
        }
    }

    /// Short name: `balance` or `power`.
    pub fn name(self) -> &'static str {
        match self {
            PlacementMis::Balance => "balance",
            PlacementMis::Power => "power",
        }
    }
}

impl Strategy {
    /// The strategy named `name` (`bsdf` or `diff`); `diff` samples the derivative by the parameter
    /// `target` with probability `q`, its placements weighted by the balance heuristic (set
    /// [`Strategy::with_placement`] for the power heuristic).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `Strategy::from_name`, `Strategy::Diff::q` or the target for an unknown strategy,
    /// a q outside [0, 1], an unknown parameter, or a parameter no differential sampler covers (an
    /// anisotropic conductor's or dielectric's roughness, a normal-mapped material's).
    pub fn from_name(scene: &Scene, name: &str, q: f32, target: &str) -> Result<Strategy> {
        match name {
            "bsdf" => Ok(Strategy::Bsdf),
            "diff" => {
                if !(0.0..=1.0).contains(&q) {
                    return Err(Error::InvalidArgument {
                        parameter: "Strategy::Diff::q".into(),
                        message: format!("{q} is not in [0, 1]"),
                    });
                }
                let target = diff_target(scene, target)?;
                Ok(Strategy::Diff { target, q, placement: PlacementMis::Balance })
            }
            other => Err(Error::InvalidArgument {
                parameter: "Strategy::from_name".into(),
                message: format!("unknown strategy '{other}' (expected bsdf or diff)"),
            }),
        }
    }

    /// Differential path sampling by the parameters named `targets` (ALGORITHMS.md §5.8): one
    /// target is [`Strategy::Diff`] (today's estimator, bit for bit; `weights` must then be `None`
    /// or one weight), several are [`Strategy::Hero`] with probabilities proportional to
    /// `weights` (uniform for `None`).
    ///
    /// ```
    /// use pathgrad::integrator::Strategy;
    /// let scene = pathgrad::scene::builtin::load("blend")?;
    /// let one = Strategy::hero(&scene, &["object.weight.value"], 0.5, None)?;
    /// assert_eq!(one, Strategy::from_name(&scene, "diff", 0.5, "object.weight.value")?);
    /// // A parameter without a differential sampler cannot be a hero.
    /// let err = Strategy::hero(&scene, &["object.weight.value", "base.reflectance.value"], 0.5, None).unwrap_err();
    /// assert!(err.to_string().contains("base.reflectance.value"));
    /// # Ok::<(), pathgrad::Error>(())
    /// ```
    ///
    /// # Errors
    /// As [`Strategy::from_name`] for each target; [`Error::InvalidArgument`] naming a target of a
    /// hero set that no material has a differential sampler for, and as [`HeroSet::new`].
    pub fn hero(scene: &Scene, targets: &[&str], q: f32, weights: Option<&[f32]>) -> Result<Strategy> {
        if let [one] = targets {
            if weights.is_some_and(|w| w.len() != 1) {
                return Err(Error::InvalidArgument {
                    parameter: "HeroSet::weights".into(),
                    message: format!("{} weights for 1 target", weights.map_or(0, <[f32]>::len)),
                });
            }
            return Strategy::from_name(scene, "diff", q, one);
        }
        if !(0.0..=1.0).contains(&q) {
            return Err(Error::InvalidArgument {
                parameter: "Strategy::Diff::q".into(),
                message: format!("{q} is not in [0, 1]"),
            });
        }
        let mut ids = Vec::with_capacity(targets.len());
        for name in targets {
            let id = diff_target(scene, name)?;
            if !Strategy::has_differential_sampler(scene, id) {
                return Err(Error::InvalidArgument {
                    parameter: (*name).to_string(),
                    message: "has no differential sampler (it is no rough conductor's, dielectric's or plastic's \
                              roughness and no blend's weight), so it cannot be one of several heroes"
                        .into(),
                });
            }
            // A hero vertex is capable for one target through its α: an anisotropic roughness's
            // α_u and α_v would make one vertex capable for two.
            use crate::scene::Material;
            let anisotropic = scene.materials.iter().any(|m| match m {
                Material::RoughConductor { alpha, alpha_v, .. } | Material::RoughDielectric { alpha, alpha_v, .. } => {
                    alpha != alpha_v && (*alpha == id || *alpha_v == id)
                }
                _ => false,
            });
            if anisotropic {
                return Err(Error::InvalidArgument {
                    parameter: (*name).to_string(),
                    message: "is an anisotropic rough conductor's or dielectric's roughness, which a set of several \
                              heroes does not cover: give it alone (--diff-param)"
                        .into(),
                });
            }
            ids.push(id);
        }
        Ok(Strategy::Hero { heroes: HeroSet::new(&ids, weights)?, q })
    }

    /// The same strategy with its placements weighted by `placement` (`bsdf` has none: unchanged).
    ///
    /// ```
    /// use pathgrad::integrator::{PlacementMis, Strategy};
    /// let scene = pathgrad::scene::builtin::load("blend")?;
    /// let s = Strategy::from_name(&scene, "diff", 0.9, "object.weight.value")?.with_placement(PlacementMis::Power);
    /// assert!(matches!(s, Strategy::Diff { placement: PlacementMis::Power, .. }));
    /// # Ok::<(), pathgrad::Error>(())
    /// ```
    pub fn with_placement(self, placement: PlacementMis) -> Strategy {
        match self {
            Strategy::Diff { target, q, .. } => Strategy::Diff { target, q, placement },
            // A hero set's placements are weighted by the balance heuristic only
            // (`RenderOptions::validate` refuses nothing here: the CLI refuses `power` by name).
            other => other,
        }
    }

    /// Short name: `bsdf` or `diff`.
    pub fn name(&self) -> &'static str {
        match self {
            Strategy::Bsdf => "bsdf",
            Strategy::Diff { .. } | Strategy::Hero { .. } => "diff",
        }
    }

    /// Whether some material has a differential sampler for `target`: it is the roughness of a
    /// rough conductor, dielectric or plastic (an anisotropic conductor's or dielectric's α_u or
    /// α_v), the weight of a blend, or (some medium) the g of a
    /// Henyey–Greenstein phase function (ALGORITHMS.md §8.4). If not, `diff` samples like `bsdf` (with
    /// balance-heuristic MIS) and brings no variance reduction.
    pub fn has_differential_sampler(scene: &Scene, target: ParamId) -> bool {
        use crate::scene::Material;
        scene.materials.iter().any(|m| match m {
            Material::RoughConductor { alpha, alpha_v, .. } | Material::RoughDielectric { alpha, alpha_v, .. } => {
                *alpha == target || *alpha_v == target
            }
            Material::RoughPlastic { alpha, .. } => *alpha == target,
            Material::Blend { weight, children } => {
                *weight == target
                    && !children
                        .iter()
                        .any(|c| matches!(scene.materials.get(c.0 as usize), Some(Material::Smooth { .. })))
            }
            _ => false,
        }) || scene.media.iter().any(|m| m.phase == crate::scene::medium::Phase::HenyeyGreenstein { g: target })
    }
}

/// The parameter named `target` if a differential sampler may be driven by it.
fn diff_target(scene: &Scene, target: &str) -> Result<ParamId> {
    let target = scene.params.find(target).ok_or_else(|| Error::InvalidArgument {
        parameter: target.to_string(),
        message: "no such parameter to drive the differential sampler (see `pathgrad params SCENE`)".into(),
    })?;
    use crate::scene::Material;
    // A normal-mapped material's lobes live in the perturbed frame, whose wrapper the
    // differential sampler's densities do not include.
    let uses = |id: crate::scene::MaterialId| match scene.materials.get(id.0 as usize) {
        Some(Material::RoughConductor { alpha, alpha_v, .. } | Material::RoughDielectric { alpha, alpha_v, .. }) => {
            *alpha == target || *alpha_v == target
        }
        Some(Material::RoughPlastic { alpha, .. }) => *alpha == target,
        Some(Material::Blend { weight, .. }) => *weight == target,
        _ => false,
    };
    let mapped = scene.materials.iter().any(|m| match m {
        Material::NormalMap { nested, .. } | Material::BumpMap { nested, .. } => {
            uses(*nested)
                || matches!(scene.materials.get(nested.0 as usize), Some(Material::Blend { children, .. })
                    if children.iter().any(|c| uses(*c)))
        }
        _ => false,
    });
    let uncovered = mapped.then_some("a normal-mapped material's roughness or blend weight");
    // A mask draws its pass-through before the technique choice; the strategy's mixture
    // densities are not derived for it, so neither its opacity nor what it wraps is a target.
    fn reaches(scene: &Scene, id: crate::scene::MaterialId, uses: &dyn Fn(crate::scene::MaterialId) -> bool) -> bool {
        uses(id)
            || match scene.materials.get(id.0 as usize) {
                Some(
                    Material::TwoSided(c) | Material::NormalMap { nested: c, .. } | Material::BumpMap { nested: c, .. },
                ) => reaches(scene, *c, uses),
                Some(Material::Blend { children, .. }) => children.iter().any(|c| uses(*c)),
                _ => false,
            }
    }
    let masked = scene.materials.iter().any(|m| match m {
        Material::Mask { nested, opacity } => *opacity == target || reaches(scene, *nested, &uses),
        _ => false,
    });
    let uncovered = uncovered.or(masked.then_some("a mask's opacity or a masked material's parameter"));
    // A blend holding a smooth conductor samples a delta lobe, which the mixture's densities do
    // not include.
    let smooth =
        |c: &crate::scene::MaterialId| matches!(scene.materials.get(c.0 as usize), Some(Material::Smooth { .. }));
    let delta_blend = scene.materials.iter().any(|m| match m {
        Material::Blend { weight, children } => {
            children.iter().any(smooth) && (*weight == target || children.iter().any(|c| uses(*c)))
        }
        _ => false,
    });
    let uncovered = uncovered.or(delta_blend.then_some("a parameter of a blend holding a smooth conductor"));
    // A texture's texels each act on part of the surface: the sampler's one scalar
    // target per material does not describe them.
    let uncovered = uncovered.or(scene.scalar_texture(target).map(|_| "a texture's texels"));
    if let Some(whose) = uncovered {
        return Err(Error::InvalidArgument {
            parameter: scene.params.entry(target).name.clone(),
            message: format!(
                "is {whose}, which the differential sampler does not cover (it samples the \
                 derivative of a rough conductor's, dielectric's or plastic's lobe, a blend's weight or a \
                 medium's Henyey-Greenstein g, without a normal map or a mask): use the bsdf strategy"
            ),
        });
    }
    Ok(target)
}

/// Checks the samples per pixel of pass 1 (the loss image of a gradient step).
///
/// # Errors
/// [`Error::InvalidArgument`] naming `LossGradientSetup::spp_primal` if it is 0.
pub fn check_spp_primal(spp_primal: u32) -> Result<()> {
    if spp_primal == 0 {
        return Err(Error::InvalidArgument {
            parameter: "LossGradientSetup::spp_primal".into(),
            message: "must be at least 1".into(),
        });
    }
    Ok(())
}

/// One camera a request renders, and the random-number stream of its paths
/// ([`crate::rng::RngKey`]). A request of several views renders them all at the request's
/// [`RenderOptions::width`] × [`RenderOptions::height`], one image each, in one submission.
///
/// ```
/// use pathgrad::integrator::View;
/// let scene = pathgrad::scene::builtin::load("cornell-box")?;
/// let view = View::sensor(&scene, 0)?;
/// assert_eq!(view, View::current(&scene));
/// # Ok::<(), pathgrad::Error>(())
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct View {
    /// The pinhole camera (its film size is not used: the request's size is).
    pub camera: Camera,
    /// The stream of its paths' keys: below 2²⁴. Sensor i uses stream i.
    pub stream: u32,
}

impl View {
    /// Sensor `index` of `scene`, in stream `index`.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for an index past the scene's sensors.
    pub fn sensor(scene: &Scene, index: usize) -> Result<View> {
        let sensor = scene.sensors.get(index).ok_or_else(|| Error::InvalidArgument {
            parameter: "View::sensor".into(),
            message: format!("sensor {index} does not exist: '{}' has {}", scene.source, scene.sensors.len()),
        })?;
        if index >= 1 << 24 {
            return Err(Error::InvalidArgument {
                parameter: "View::sensor".into(),
                message: format!("sensor {index}: streams end at 2^24"),
            });
        }
        Ok(View { camera: sensor.camera, stream: index as u32 })
    }

    /// The scene's camera ([`Scene::camera`]) in the stream of the sensor it was chosen from
    /// ([`Scene::sensor`]): what single-view renders see.
    pub fn current(scene: &Scene) -> View {
        View { camera: scene.camera, stream: scene.sensor as u32 }
    }
}

/// What to render.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderOptions {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Samples per pixel.
    pub spp: u32,
    /// Maximum surface interactions per path (1: emitters only, 2: direct light); `None` unbounded
    /// (up to [`UNBOUNDED_DEPTH_CAP`]).
    pub max_depth: Option<u32>,
    /// Russian roulette starts once the vertex index minus one reaches this; `None` disables it.
    pub rr_depth: Option<u32>,
    /// Random seed (Philox key word 0).
    pub seed: u32,
    /// Next-event estimation (emitter sampling, MIS-weighted against BSDF sampling); off, paths
    /// find emitters only by hitting them.
    pub nee: bool,
    /// Direction-sampling strategy (applies to every pass rendered with these options).
    pub strategy: Strategy,
    /// The parameter kinds whose gradients reverse-mode passes compute ([`ParamKinds::ALL`] by
    /// default); the gradients of other parameters come back as 0. Forward-mode image gradients
    /// differentiate their one parameter whatever this says.
    pub differentiate: ParamKinds,
    /// Detached (default) or attached sampling of directions in reverse-mode gradient passes.
    pub sampling: Sampling,
}

impl RenderOptions {
    /// The scene's defaults: its camera's resolution and max depth, 16 spp, seed 0.
    pub fn for_scene(scene: &Scene) -> RenderOptions {
        RenderOptions {
            width: scene.camera.width,
            height: scene.camera.height,
            spp: 16,
            max_depth: Some(scene.max_depth),
            rr_depth: Some(DEFAULT_RR_DEPTH),
            seed: 0,
            nee: true,
            strategy: Strategy::Bsdf,
            differentiate: ParamKinds::ALL,
            sampling: Sampling::Detached,
        }
    }

    /// Checks ranges.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming the option.
    pub fn validate(&self) -> Result<()> {
        let bad = |p: &str, m: &str| Err(Error::InvalidArgument { parameter: p.into(), message: m.into() });
        if self.width == 0 || self.height == 0 || self.width > MAX_IMAGE_SIZE || self.height > MAX_IMAGE_SIZE {
            return bad("RenderOptions::width/height", &format!("must be between 1 and {MAX_IMAGE_SIZE}"));
        }
        if self.spp == 0 || self.spp > MAX_SPP {
            return bad(
                "RenderOptions::spp",
                &format!("must be between 1 and {MAX_SPP} (average independent seeds for more)"),
            );
        }
        match self.max_depth {
            Some(0) => return bad("RenderOptions::max_depth", "must be at least 1 (or None for unbounded)"),
            Some(d) if d > UNBOUNDED_DEPTH_CAP => {
                return bad(
                    "RenderOptions::max_depth",
                    &format!(
                        "{d} is more than {UNBOUNDED_DEPTH_CAP}, the most interactions a path can have (None, \
                         unbounded, also ends paths there)"
                    ),
                );
            }
            _ => {}
        }
        if let Strategy::Diff { q, .. } | Strategy::Hero { q, .. } = self.strategy
            && !(0.0..=1.0).contains(&q)
        {
            return bad("Strategy::Diff::q", "must be in [0, 1]");
        }
        if let Sampling::Attached { noise } = self.sampling {
            if !(0.0..1.0).contains(&noise) {
                return bad("Sampling::Attached::noise", "must be in [0, 1)");
            }
            if self.strategy != Strategy::Bsdf {
                return bad(
                    "Sampling::Attached",
                    &format!(
                        "attached sampling is built for the bsdf strategy only (this request uses {})",
                        self.strategy.name()
                    ),
                );
            }
        }
        Ok(())
    }

    /// The options of pass 1 of a gradient step (ALGORITHMS.md §3.4, §6): `spp_primal` samples per
    /// pixel with plain BSDF sampling and next-event estimation (as \[SG24\]'s Algorithm 2), the rest
    /// as `self`. Every gradient step and variance protocol renders its loss image with these.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `--spp-primal` if it is 0.
    pub fn loss_pass(&self, spp_primal: u32) -> Result<RenderOptions> {
        check_spp_primal(spp_primal)?;
        Ok(RenderOptions { spp: spp_primal, strategy: Strategy::Bsdf, nee: true, ..*self })
    }

    /// The options of `views` views stacked into one tall image, one below another (how a
    /// multi-view request holds its images, and what adaptive sampling over all views draws from).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] if the stack is too tall.
    pub fn stacked(&self, views: usize) -> Result<RenderOptions> {
        let height = u32::try_from(views).ok().and_then(|v| v.checked_mul(self.height)).ok_or_else(|| {
            Error::InvalidArgument {
                parameter: "views".into(),
                message: format!("{views} views of height {} are too many for one request", self.height),
            }
        })?;
        Ok(RenderOptions { height, ..*self })
    }

    /// The Philox key of `pass` (plain renders and loss images use [`PassTag::Primal`]; the fused
    /// gradient passes [`PassTag::Gradient`], so their paths are independent of the loss image's).
    pub fn key(&self, pass: PassTag) -> RngKey {
        RngKey::new(self.seed, 0, pass)
    }

    /// The camera constants of `view` in `pass`. The image covers the camera's
    /// [`FilmWindow`](crate::scene::FilmWindow) of a film with square pixels at the render's
    /// size: the field of view spans the whole film, whose aspect ratio is the render's
    /// `width/height` when the window is the whole film.
    pub fn view_camera(&self, view: &View, pass: PassTag) -> ViewCamera {
        let c = &view.camera;
        let forward = (c.target - c.position).normalize();
        let right = forward.cross(c.up).normalize();
        let up = right.cross(forward);
        let (film_width, film_height) = c.film_size(self.width, self.height);
        let aspect = film_width / film_height;
        let (filter_kind, filter_radius, filter_alpha) = c.filter.constants();
        // The film's half extents: per unit of depth (tangents) or, orthographic, in world units.
        let (half_x, half_y, origin, lens, aperture_radius, focus_distance) = match c.lens {
            crate::scene::Lens::Orthographic { half_height, stretch, near_clip } => (
                half_height * aspect * stretch,
                half_height,
                c.position + forward * near_clip,
                LENS_ORTHOGRAPHIC,
                0.0,
                0.0,
            ),
            lens => {
                let tan_y = (c.fov_y_degrees.to_radians() * 0.5).tan();
                let (kind, a, f) = match lens {
                    crate::scene::Lens::Thin { aperture_radius, focus_distance } => {
                        (LENS_THIN, aperture_radius, focus_distance)
                    }
                    _ => (LENS_PINHOLE, 0.0, 0.0),
                };
                (tan_y * aspect, tan_y, c.position, kind, a, f)
            }
        };
        // The window's film point (sx, sy) ∈ [−1, 1]² is the whole film's (cx + ex·sx, cy + ey·sy):
        // its centre moves the pinhole's direction through the film's centre (or the orthographic
        // film's centre), its extent scales the axes.
        let (right, up) = (right * half_x, up * half_y);
        let w = &c.window;
        let (ex, ey) = w.extent();
        let centre = right * (w.min.x + w.max.x - 1.0) + up * (1.0 - w.min.y - w.max.y);
        let (origin, through_centre) =
            if lens == LENS_ORTHOGRAPHIC { (origin + centre, forward) } else { (origin, forward + centre) };
        ViewCamera {
            origin,
            right: right * ex,
            up: up * ey,
            forward: through_centre,
            lens,
            aperture_radius,
            focus_distance,
            key1: RngKey::new(self.seed, view.stream, pass).0[1],
            filter_kind,
            filter_radius,
            filter_alpha,
        }
    }

    /// The per-dispatch constants for `scene` (flattened as `flat`) in `pass`, for one view
    /// (`view_count` is set by the renderers for a request of several).
    pub fn globals(&self, scene: &Scene, flat: &FlatScene, pass: PassTag) -> Globals {
        let (strategy, diff_q, diff_begin, diff_end, diff_placement) = match self.strategy {
            Strategy::Bsdf => (STRATEGY_BSDF, 0.0, 0, 0, PlacementMis::Balance),
            Strategy::Diff { target, q, placement } => {
                let e = scene.params.entry(target);
                (STRATEGY_DIFF, q, e.offset, e.offset + e.len, placement)
            }
            // No vertex is capable by `diff_begin .. diff_end`: the hero ranges say which are.
            Strategy::Hero { q, .. } => (STRATEGY_DIFF, q, 0, 0, PlacementMis::Balance),
        };
        let mut hero_p = [0.0f32; MAX_HEROES as usize];
        let mut hero_range = [glam::UVec2::ZERO; MAX_HEROES as usize];
        let hero_count = match self.strategy {
            Strategy::Hero { heroes, .. } => {
                for (k, (&t, &p)) in heroes.targets().iter().zip(heroes.weights()).enumerate() {
                    let e = scene.params.entry(t);
                    hero_p[k] = p;
                    hero_range[k] = glam::UVec2::new(e.offset, e.offset + e.len);
                }
                heroes.targets().len() as u32
            }
            _ => 0,
        };
        let key = self.key(pass);
        let (env_select_prob, light_select_prob) = emitter_selection(scene, flat);
        Globals {
            width: self.width,
            height: self.height,
            key0: key.0[0],
            key1: key.0[1],
            max_depth: self.max_depth.unwrap_or(UNBOUNDED_DEPTH_CAP).min(UNBOUNDED_DEPTH_CAP),
            rr_depth: self.rr_depth.unwrap_or(u32::MAX),
            path_flags: if scene.null_uncounted { PATH_NULL_UNCOUNTED } else { 0 }
                | if scene.hide_emitters { PATH_HIDE_EMITTERS } else { 0 },
            emitter_count: flat.emitters.len() as u32,
            emitter_total_area: flat.emitter_total_area,
            view_count: 1,
            env_param: scene.environment.map_or(NO_PARAM, |p| scene.params.entry(p).offset),
            env_width: scene.env_map.map_or(0, |m| m.width),
            env_height: scene.env_map.map_or(0, |m| m.height),
            env_scale: scene.env_map.map_or(1.0, |m| m.scale),
            env_rot0: scene.env_map.map_or(glam::Vec3::X, |m| m.to_local.row(0)),
            env_rot1: scene.env_map.map_or(glam::Vec3::Y, |m| m.to_local.row(1)),
            env_rot2: scene.env_map.map_or(glam::Vec3::Z, |m| m.to_local.row(2)),
            adjoint_scale: 1.0 / self.spp as f32,
            fixed_scale: FIXED_POINT_SCALE,
            forward_begin: 0,
            forward_end: 0,
            // Attached sampling estimates next events at diffuse vertices, toward all but the
            // environment (crate::attached::HitGeometry::nee_gradient); the path loops pick where.
            nee: u32::from(self.nee),
            strategy,
            diff_q,
            diff_begin,
            diff_end,
            diff_placement: diff_placement.value(),
            attached: u32::from(self.sampling.is_attached()),
            jac_noise: match self.sampling {
                Sampling::Attached { noise } => noise,
                Sampling::Detached => 0.0,
            },
            hero_count,
            hero_p0: hero_p[0],
            hero_p1: hero_p[1],
            hero_p2: hero_p[2],
            hero_p3: hero_p[3],
            hero_range0: hero_range[0],
            hero_range1: hero_range[1],
            hero_range2: hero_range[2],
            hero_range3: hero_range[3],
            node_count: flat.bvh.nodes.len() as u32,
            primal_only: 0,
            addr_nodes: glam::UVec2::ZERO,
            addr_tris: glam::UVec2::ZERO,
            addr_prim_ids: glam::UVec2::ZERO,
            addr_tri_vertices: glam::UVec2::ZERO,
            addr_meshes: glam::UVec2::ZERO,
            addr_normals: glam::UVec2::ZERO,
            addr_uvs: glam::UVec2::ZERO,
            addr_emitter_ids: glam::UVec2::ZERO,
            addr_materials: glam::UVec2::ZERO,
            addr_emitters: glam::UVec2::ZERO,
            addr_params: glam::UVec2::ZERO,
            addr_views: glam::UVec2::ZERO,
            addr_media: glam::UVec2::ZERO,
            addr_fields: glam::UVec2::ZERO,
            addr_env_cells: glam::UVec2::ZERO,
            addr_lights: glam::UVec2::ZERO,
            addr_tables: glam::UVec2::ZERO,
            addr_majorants: glam::UVec2::ZERO,
            light_count: flat.lights.len() as u32,
            light_select_prob,
            env_select_prob,
        }
    }
}

/// Next-event estimation's probabilities of sampling the environment and the lights without area
/// (the rest goes to emissive triangles). Without such lights: the environment alone, or
/// [`ENV_SELECT_PROB`] beside triangles. With them: each light, the environment and the
/// triangles as a whole are equally likely.
fn emitter_selection(scene: &Scene, flat: &FlatScene) -> (f32, f32) {
    let env = scene.environment.is_some();
    let tris = !flat.emitters.is_empty();
    let lights = flat.lights.len();
    if lights == 0 {
        return match (env, tris) {
            (false, _) => (0.0, 0.0),
            (true, false) => (1.0, 0.0),
            (true, true) => (ENV_SELECT_PROB, 0.0),
        };
    }
    let units = (lights + usize::from(env) + usize::from(tris)) as f32;
    (if env { 1.0 / units } else { 0.0 }, lights as f32 / units)
}
