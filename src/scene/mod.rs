//! `Scene`: plain data — triangle meshes, materials, area emitters, a pinhole camera and the
//! parameter table that holds every differentiable value.

pub mod builtin;
pub mod envmap;
pub mod flat;
pub mod gltf;
pub(crate) mod load;
pub mod medium;
pub mod mesh_io;
pub mod mitsuba;
pub mod scalar_texture;
pub mod shapes;
pub mod volume;

use glam::{Mat3, Vec2, Vec3};

use crate::bsdf::Distribution;
use crate::error::{Error, Result};
use crate::params::{ParamId, ParamTable};

pub use load::{LoadOptions, load, load_reporting, load_with};
pub use scalar_texture::ScalarTexture;

/// Index of a material in [`Scene::materials`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MaterialId(pub u32);

/// Index of a texture in [`Scene::textures`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TextureId(pub u32);

/// An RGB bitmap whose linear texels are one parameter (`width × height × 3` values, row 0 at
/// v = 0), looked up at the hit's texture coordinates as `filter` and `wrap` say (Mitsuba's
/// `filter_type` and `wrap_mode`; bilinear and repeat by default).
#[derive(Clone, Debug, PartialEq)]
pub struct Texture {
    /// Width in texels.
    pub width: u32,
    /// Height in texels.
    pub height: u32,
    /// The texels, RGB, row-major.
    pub texels: ParamId,
    /// Nearest texel instead of bilinear interpolation.
    pub nearest: bool,
    /// How texel indices outside the image wrap.
    pub wrap: Wrap,
    /// Mitsuba's `to_uv`: rows 0 and 1 of the 2D affine map applied to the hit's texture
    /// coordinates before the lookup, u' = row0 · (u, v, 1), v' = row1 · (u, v, 1)
    /// (`[Vec3::X, Vec3::Y]`: none).
    pub to_uv: [Vec3; 2],
}

/// A light without area (Mitsuba's `point`, `spot`, `directional` and `projector`): next-event
/// estimation reaches it, no ray can hit it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Light {
    /// Where and how it shines.
    pub shape: LightShape,
    /// The RGB intensity (point, spot: W/sr) or irradiance (directional; a projector's constant
    /// `irradiance`) parameter; `None` for a projector whose irradiance is its texture.
    pub intensity: Option<ParamId>,
    /// A spot's projected `texture` (multiplying its intensity) or a projector's `irradiance`
    /// bitmap, looked up as [`LightShape::Spot`] and [`LightShape::Projector`] say.
    pub texture: Option<TextureId>,
}

/// The geometry of a [`Light`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LightShape {
    /// Intensity / distance² in every direction.
    Point {
        /// Position.
        position: Vec3,
    },
    /// A point light inside a cone around `axis`: full intensity within `beam_width` degrees of
    /// it, falling linearly in angle to 0 at `cutoff` degrees (Mitsuba's `spot`).
    Spot {
        /// Position.
        position: Vec3,
        /// Unit axis of the cone.
        axis: Vec3,
        /// Cutoff angle in degrees, in (0, 90].
        cutoff: f32,
        /// Beam width in degrees, in (0, cutoff].
        beam_width: f32,
        /// The linear part of `to_world`⁻¹: a world offset from `position` into the light's frame,
        /// whose +z is `axis`. A texture is looked up at u = ½ + ½ x / (z tan(cutoff)), v = ½ +
        /// ½ y / (z tan(cutoff)) of the local offset (x, y, z) toward the lit point.
        to_local: Mat3,
    },
    /// Mitsuba's `projector`: a pinhole at `position` that projects its irradiance (a texture or
    /// a constant) through a perspective frustum, irradiance · π · scale / (z² cos θ) toward the
    /// lit point at local (x, y, z), where cos θ = `normal` · (unit direction from `position`).
    Projector {
        /// Position.
        position: Vec3,
        /// The linear part of `to_world`⁻¹.
        to_local: Mat3,
        /// `to_world` · (0, 0, 1), not normalised.
        normal: Vec3,
        /// The lookup at u = ½ + uv_scale.x · x / z, v = ½ + uv_scale.y · y / z; light only where
        /// both lie in [0, 1] and z > 0.
        uv_scale: Vec2,
        /// The parameter `scale` (one value).
        scale: ParamId,
    },
    /// Irradiance arriving along the unit `direction` (the way the light travels), everywhere.
    Directional {
        /// Direction of travel.
        direction: Vec3,
    },
}

/// A smooth BSDF's or rough dielectric's reflectance or transmittance: a parameter, a texture, or
/// (as Mitsuba, where the file does not give it) a constant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SmoothColour {
    /// The RGB parameter.
    Param(ParamId),
    /// A fixed colour.
    Constant(Vec3),
    /// A colour texture (a bitmap, checkerboard or mesh attribute; never [`Albedo::Rgb`]), looked
    /// up at the hit as a diffuse reflectance's is.
    Texture(Albedo),
}

/// How a bitmap's texel indices, or a grid volume's voxel indices, outside the image or grid wrap
/// (Mitsuba's `wrap_mode`; a bitmap's default is `Repeat`, a grid volume's `Clamp`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Wrap {
    /// Tiled.
    #[default]
    Repeat,
    /// Tiled with every other tile mirrored.
    Mirror,
    /// The edge texels extend.
    Clamp,
}

impl Wrap {
    /// Index `i` of a row of `n` texels or voxels, wrapped into [0, n).
    ///
    /// ```
    /// use pathgrad::scene::Wrap;
    /// assert_eq!([-1, 0, 3, 4].map(|i| Wrap::Repeat.index(i, 4)), [3, 0, 3, 0]);
    /// assert_eq!([-1, 0, 3, 4, 8].map(|i| Wrap::Mirror.index(i, 4)), [0, 0, 3, 3, 0]);
    /// assert_eq!([-1, 0, 3, 4].map(|i| Wrap::Clamp.index(i, 4)), [0, 0, 3, 3]);
    /// ```
    pub fn index(self, i: i32, n: i32) -> i32 {
        match self {
            Wrap::Clamp => i.clamp(0, n - 1),
            Wrap::Mirror => {
                let m = i.rem_euclid(2 * n);
                if m < n { m } else { 2 * n - 1 - m }
            }
            Wrap::Repeat => i.rem_euclid(n),
        }
    }
}

/// Where a diffuse albedo comes from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Albedo {
    /// One RGB parameter.
    Rgb(ParamId),
    /// A bitmap texture.
    Bitmap(TextureId),
    /// Mitsuba's `checkerboard`: `colors` holds six values, the first colour then the second;
    /// texture coordinates go through `to_uv` (rows of a 2D affine map) first.
    Checker {
        /// The two RGB colours (one parameter of six values, or two contiguous parameters: the
        /// first's id).
        colors: ParamId,
        /// `u' = dot(to_uv[0], (u, v, 1))`, `v' = dot(to_uv[1], (u, v, 1))`.
        to_uv: [Vec3; 2],
    },
    /// Mitsuba's `mesh_attribute`: an RGB attribute of the mesh (3 values a triangle or a
    /// vertex, one parameter) read at the hit.
    Attribute {
        /// The attribute's values.
        values: ParamId,
        /// Whose triangles or vertices they follow.
        source: AttributeSource,
    },
    /// Mitsuba's `volume` texture: field `.0` of [`Scene::volume_textures`] (a constant or a
    /// voxel grid) looked up at the hit's world-space point.
    Volume(u32),
}

/// What a mesh attribute texture (Mitsuba's `mesh_attribute`) reads: its values are one row per
/// triangle (`per_vertex` false: the hit triangle's row) or per vertex (the hit triangle's three
/// rows interpolated by the hit's barycentric coordinates) of mesh `mesh`, the one mesh whose
/// material reads it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AttributeSource {
    /// Index in [`Scene::meshes`] of the mesh the values belong to.
    pub mesh: u32,
    /// One row per vertex (else per triangle).
    pub per_vertex: bool,
}

/// A surface material. Differentiable values are parameters; the rest are constants.
#[derive(Clone, Debug, PartialEq)]
pub enum Material {
    /// Lambertian diffuse (ALGORITHMS.md §4.1).
    Diffuse {
        /// RGB albedo in [0, 1], constant or textured.
        albedo: Albedo,
    },
    /// Rough conductor (ALGORITHMS.md §4.2), isotropic or anisotropic.
    RoughConductor {
        /// Microfacet distribution.
        distribution: Distribution,
        /// Roughness alpha (α_u along the shading frame's x), 1 value, or a texture's texels
        /// ([`Scene::scalar_texture`]).
        alpha: ParamId,
        /// Roughness α_v along the shading frame's y: `alpha` itself when isotropic; 1 value or a
        /// texture's texels.
        alpha_v: ParamId,
        /// RGB specular reflectance multiplying the Fresnel term, constant or textured.
        specular: Albedo,
        /// Real part of the complex index of refraction (RGB).
        eta: Vec3,
        /// Imaginary part of the complex index of refraction (RGB); eta = 0, k = 1 gives F ≡ 1.
        k: Vec3,
        /// eta and k as parameters (Mitsuba's `NAME.eta.value`, `NAME.k.value`, RGB, whose values
        /// override `eta` and `k`): the id of eta's, which k's directly follows in the table
        /// ([`Scene::add_conductor_ior`]); `None` keeps the constants.
        eta_param: Option<ParamId>,
    },
    /// Rough plastic (Mitsuba's `roughplastic`, `crate::bsdf::rough_plastic`).
    RoughPlastic {
        /// Microfacet distribution of the coating.
        distribution: Distribution,
        /// Roughness alpha, 1 value.
        alpha: ParamId,
        /// Diffuse reflectance of the base in [0, 1], constant or textured.
        diffuse: Albedo,
        /// Specular reflectance of the coating: a parameter where the file gives it (Mitsuba
        /// traverses it only then), a texture, or the constant 1.
        specular: SmoothColour,
        /// int_ior / ext_ior.
        eta: f32,
        /// Mitsuba's `nonlinear`: the base's internal scattering darkens and saturates its colour.
        nonlinear: bool,
    },
    /// Rough dielectric (Mitsuba's `roughdielectric`, `crate::bsdf::rough_dielectric`),
    /// isotropic or anisotropic.
    RoughDielectric {
        /// Microfacet distribution.
        distribution: Distribution,
        /// Roughness alpha (α_u along the shading frame's x), 1 value or a texture's texels
        /// ([`Scene::scalar_texture`]).
        alpha: ParamId,
        /// Roughness α_v along the shading frame's y: `alpha` itself when isotropic; 1 value or a
        /// texture's texels.
        alpha_v: ParamId,
        /// RGB specular reflectance.
        reflectance: SmoothColour,
        /// RGB specular transmittance.
        transmittance: SmoothColour,
        /// int_ior / ext_ior.
        eta: f32,
        /// η as a parameter (Mitsuba's `NAME.eta`), whose value overrides `eta`; as a smooth
        /// dielectric's, only attached derivatives ([`crate::integrator::Sampling::Attached`])
        /// differentiate it. `None` keeps the constant.
        eta_param: Option<ParamId>,
    },
    /// Mitsuba's `principled` (`crate::bsdf::principled`).
    Principled {
        /// `base_color`, constant or textured.
        base_color: Albedo,
        /// `roughness`, 1 value or a texture's texels ([`Scene::scalar_texture`]).
        roughness: ParamId,
        /// `anisotropic`, as `roughness`.
        anisotropic: ParamId,
        /// metallic, spec_tint, spec_trans, sheen, sheen_tint, clearcoat, clearcoat_gloss,
        /// flatness, each as `roughness`.
        scalars: [ParamId; 8],
        /// Relative index of refraction η (`eta`, or from `specular`), a constant.
        eta: f32,
        /// The sampling rates (main specular, clearcoat, diffuse reflectance), constants.
        rates: Vec3,
    },
    /// Mitsuba's `principledthin` (`crate::bsdf::principled_thin`).
    PrincipledThin {
        /// `base_color`, constant or textured.
        base_color: Albedo,
        /// `roughness`, 1 value or a texture's texels ([`Scene::scalar_texture`]).
        roughness: ParamId,
        /// `anisotropic`, as `roughness`.
        anisotropic: ParamId,
        /// spec_trans, spec_tint, sheen, sheen_tint, flatness, diff_trans (0..2) and eta, each as
        /// `roughness`.
        scalars: [ParamId; 7],
        /// The sampling rates (specular reflectance, specular transmittance, diffuse reflectance,
        /// diffuse transmittance), constants.
        rates: [f32; 4],
    },
    /// Smooth plastic (Mitsuba's `plastic`, `crate::bsdf::plastic`).
    SmoothPlastic {
        /// Diffuse reflectance of the base in [0, 1], constant or textured.
        diffuse: Albedo,
        /// Specular reflectance of the coating, as a rough plastic's.
        specular: SmoothColour,
        /// int_ior / ext_ior.
        eta: f32,
        /// Mitsuba's `nonlinear`.
        nonlinear: bool,
    },
    /// A smooth (delta) BSDF: Mitsuba's `conductor`, `dielectric` or `thindielectric`
    /// (`crate::bsdf::specular`).
    Smooth {
        /// Which one.
        kind: crate::bsdf::specular::SmoothKind,
        /// RGB specular reflectance.
        reflectance: SmoothColour,
        /// RGB specular transmittance (dielectrics).
        transmittance: SmoothColour,
        /// Conductor: the real part of the complex index of refraction; dielectrics: η in `x`.
        eta: Vec3,
        /// Conductor: the imaginary part.
        k: Vec3,
        /// Dielectrics: η = int_ior / ext_ior as a parameter (Mitsuba's `eta`), whose value
        /// overrides `eta.x`; it acts only through the directions it refracts into, so only
        /// attached derivatives ([`crate::integrator::Sampling::Attached`]) differentiate it.
        /// Conductor: eta and k as parameters, as [`Material::RoughConductor`]'s `eta_param`
        /// (they act on the weight only: detached and attached derivatives alike).
        eta_param: Option<ParamId>,
    },
    /// `(1 − w)·child0 + w·child1` of two leaf materials (ALGORITHMS.md §4.3).
    Blend {
        /// Weight w of child 1, 1 value in [0, 1] or a texture's texels ([`Scene::scalar_texture`]).
        weight: ParamId,
        /// The two children; neither may be a blend or two-sided wrapper.
        children: [MaterialId; 2],
    },
    /// The child seen from both sides (Mitsuba's `twosided`): from the back, the shading frame is
    /// flipped so the child sees its front.
    TwoSided(MaterialId),
    /// No surface: an index-matched boundary of a medium (Mitsuba's `null`); rays pass through.
    Null,
    /// `nested` shaded in a frame that a normal map perturbs (Mitsuba's `normalmap`): the map's
    /// RGB in [0, 1], mapped to [−1, 1], is the shading normal in the frame of ∂p/∂u
    /// (`crate::cpu::surface::normal_map_frame`). The map's texels are not parameters.
    NormalMap {
        /// The BSDF in the perturbed frame: a leaf or a blend (two-sided outside the map only).
        nested: MaterialId,
        /// Index in [`Scene::normal_maps`] (RGB texels).
        map: u32,
    },
    /// `nested` shaded in a frame that a bump map perturbs (Mitsuba's `bumpmap`): ∂p/∂u and ∂p/∂v
    /// moved along the normal by `scale` times the height's gradient
    /// (`crate::cpu::surface::normal_map_frame`). The heights are not parameters.
    BumpMap {
        /// The BSDF in the perturbed frame: a leaf or a blend, not anisotropic.
        nested: MaterialId,
        /// Index in [`Scene::normal_maps`] (one height a texel: the texture's luminance).
        map: u32,
        /// Mitsuba's `scale` of the gradient.
        scale: f32,
    },
    /// `nested` where the surface is opaque and nothing where it is not (Mitsuba's `mask`): a path
    /// meeting it shades `nested` with probability `opacity` and otherwise passes straight through
    /// (a null, delta transmission that counts as a bounce, as Mitsuba's `path` and `prb` count
    /// it); shadow rays stop at it, as theirs do.
    Mask {
        /// The BSDF of the opaque part: a leaf, a blend, or a two-sided or mapped wrapper of one.
        nested: MaterialId,
        /// Opacity in [0, 1], 1 value or a texture's texels ([`Scene::scalar_texture`]).
        opacity: ParamId,
    },
}

/// A normal map's or bump map's texels (Mitsuba's `bitmap` nested in `normalmap`/`bumpmap`):
/// constants, not parameters (pathgrad does not differentiate the shading frame).
#[derive(Clone, Debug, PartialEq)]
pub struct NormalMapTexture {
    /// Width in texels.
    pub width: u32,
    /// Height in texels.
    pub height: u32,
    /// The texels, row-major, row 0 at v = 0: RGB in [0, 1] (a normal map) or one height a texel
    /// (a bump map).
    pub texels: Vec<f32>,
    /// Nearest texel instead of bilinear interpolation.
    pub nearest: bool,
    /// How texel indices outside the image wrap.
    pub wrap: Wrap,
}

/// A triangle mesh with one material, optionally emitting.
#[derive(Clone, Debug, PartialEq)]
pub struct Mesh {
    /// Name (used in parameter names and messages).
    pub name: String,
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Unit vertex normals (one per position); `None` shades with face normals.
    pub normals: Option<Vec<Vec3>>,
    /// Texture coordinates (one per position), if any.
    pub uvs: Option<Vec<Vec2>>,
    /// Triangles as vertex-index triples; the winding defines the front face (counter-clockwise seen
    /// from the front), which is the side an area emitter emits to.
    pub indices: Vec<[u32; 3]>,
    /// The material.
    pub material: MaterialId,
    /// RGB radiance parameter if the mesh is an area emitter (where it has an `emitter_texture`,
    /// a bitmap's texels or a checkerboard's `colors`).
    pub emitter: Option<ParamId>,
    /// A textured area emitter's radiance (Mitsuba's `area` with a `bitmap` or `checkerboard`
    /// `radiance`: [`Albedo::Bitmap`] or [`Albedo::Checker`], no other), looked up at the hit's
    /// texture coordinates.
    pub emitter_texture: Option<Albedo>,
    /// The medium inside the mesh (a closed surface), if any.
    pub interior: Option<medium::MediumId>,
}

/// A perspective pinhole camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Pinhole position.
    pub position: Vec3,
    /// A point the camera looks at.
    pub target: Vec3,
    /// The up direction (need not be orthogonal to the viewing direction).
    pub up: Vec3,
    /// Vertical field of view in degrees.
    pub fov_y_degrees: f32,
    /// Default image width.
    pub width: u32,
    /// Default image height.
    pub height: u32,
    /// The film's reconstruction filter.
    pub filter: PixelFilter,
    /// What projects the film onto the scene: a pinhole (`fov_y_degrees`), a thin lens around it,
    /// or an orthographic projection.
    pub lens: Lens,
    /// The part of the film the image covers (Mitsuba's `crop_*`): the whole film by default.
    pub window: FilmWindow,
}

impl Camera {
    /// The whole film's size in pixels at the image size `width × height`: the image covers
    /// [`Camera::window`] of it, with square pixels.
    pub fn film_size(&self, width: u32, height: u32) -> (f32, f32) {
        let (w, h) = self.window.extent();
        (width as f32 / w, height as f32 / h)
    }
}

/// The rectangle of the film an image covers, in fractions of the film's width and height from
/// its top-left corner (Mitsuba's `crop_offset_x/y` and `crop_width/height` over the film's
/// size). The camera's field of view spans the whole film; the image's pixels sample this
/// window only, so a cropped image is the matching block of the whole film's image (up to the
/// reconstruction filter at the window's edges, which, as at the film's, sees no samples outside).
///
/// ```
/// use pathgrad::scene::FilmWindow;
/// // Columns 16..48 and rows 8..24 of a 64×32 film.
/// let w = FilmWindow::from_pixels(64, 32, [16, 8], [32, 16]);
/// assert_eq!((w.min.x, w.min.y, w.max.x, w.max.y), (0.25, 0.25, 0.75, 0.75));
/// assert!(FilmWindow::default().is_whole());
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FilmWindow {
    /// Top-left corner, in [0, 1)².
    pub min: glam::Vec2,
    /// Bottom-right corner, in (0, 1]², greater than `min`.
    pub max: glam::Vec2,
}

impl Default for FilmWindow {
    fn default() -> Self {
        FilmWindow { min: glam::Vec2::ZERO, max: glam::Vec2::ONE }
    }
}

impl FilmWindow {
    /// The window of `size` pixels at `offset` on a film of `width × height` pixels.
    pub fn from_pixels(width: u32, height: u32, offset: [u32; 2], size: [u32; 2]) -> FilmWindow {
        let film = glam::Vec2::new(width as f32, height as f32);
        let min = glam::Vec2::new(offset[0] as f32, offset[1] as f32) / film;
        let max = glam::Vec2::new((offset[0] + size[0]) as f32, (offset[1] + size[1]) as f32) / film;
        FilmWindow { min, max }
    }

    /// Whether the window is the whole film.
    pub fn is_whole(&self) -> bool {
        *self == FilmWindow::default()
    }

    /// The window's width and height, in fractions of the film's.
    pub fn extent(&self) -> (f32, f32) {
        (self.max.x - self.min.x, self.max.y - self.min.y)
    }
}

/// A camera's projection (Mitsuba's `perspective`, `thinlens` and `orthographic` sensors).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum Lens {
    /// Rays from one point, through the film at `fov_y_degrees`.
    #[default]
    Pinhole,
    /// Rays from a point on a disk of `aperture_radius` around the position, through the point of
    /// the plane `focus_distance` ahead where the pinhole's ray meets it: in focus on that plane.
    Thin {
        /// The aperture's radius (world units).
        aperture_radius: f32,
        /// Distance from the lens to the plane in focus, along the view.
        focus_distance: f32,
    },
    /// Parallel rays along the view from a film of `2·half_height` (and the render's aspect ×
    /// `stretch` times that wide) in the plane `near_clip` ahead of the position.
    Orthographic {
        /// Half the film's height in world units.
        half_height: f32,
        /// The film's width per unit of height, over the render's aspect ratio (1 unless the
        /// sensor's `to_world` scales x and y differently).
        stretch: f32,
        /// Where rays start, ahead of the position (Mitsuba's `near_clip`).
        near_clip: f32,
    },
}

/// A film's reconstruction filter, as Mitsuba 3's `rfilter`s: a pixel's value is the filter-
/// weighted mean of the radiance over the film around the pixel's centre, ∫ f(x − c) L(x) dx /
/// ∫ f(x − c) dx over the film (Mitsuba splats samples with these weights and normalises by their
/// sum; pathgrad draws each sample's position from the filter itself, truncated to the film,
/// which has the same expectation). Separable: f(x, y) = f(x) f(y).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum PixelFilter {
    /// The pixel's own square, uniformly (`box`, radius 0.5).
    #[default]
    Box,
    /// `tent`: f(x) = max(0, 1 − |x| / radius).
    Tent {
        /// Its radius in pixels (Mitsuba's default 1).
        radius: f32,
    },
    /// `gaussian`: f(x) = max(0, exp(−x² / (2σ²)) − exp(−r² / (2σ²))) for |x| < r = 4σ.
    Gaussian {
        /// Its standard deviation σ in pixels (Mitsuba's default 0.5).
        stddev: f32,
    },
}

impl PixelFilter {
    /// The filter's constants as the kernels read them: kind, radius and (Gaussian) −1/(2σ²).
    pub fn constants(&self) -> (u32, f32, f32) {
        match *self {
            PixelFilter::Box => (crate::contract::FILTER_BOX, 0.5, 0.0),
            PixelFilter::Tent { radius } => (crate::contract::FILTER_TENT, radius, 0.0),
            PixelFilter::Gaussian { stddev } => {
                (crate::contract::FILTER_GAUSSIAN, 4.0 * stddev, -1.0 / (2.0 * stddev * stddev))
            }
        }
    }
}

/// A named camera of a scene: a Mitsuba `<sensor>` (named by its `id`, else `sensor_INDEX`) or a
/// glTF camera (named by its node).
#[derive(Clone, Debug, PartialEq)]
pub struct Sensor {
    /// The sensor's name, unique in the scene.
    pub name: String,
    /// Its camera, with its film's size.
    pub camera: Camera,
}

/// Everything a render needs.
#[derive(Clone, Debug, PartialEq)]
pub struct Scene {
    /// Where the scene came from (`builtin:NAME` or a path): used in messages.
    pub source: String,
    /// Meshes.
    pub meshes: Vec<Mesh>,
    /// Materials.
    pub materials: Vec<Material>,
    /// The camera rendered: the chosen one of `sensors` (the first unless one is selected).
    pub camera: Camera,
    /// Every camera the scene file holds, in file order (one for built-in scenes).
    pub sensors: Vec<Sensor>,
    /// The index in `sensors` that `camera` was chosen from: its paths' random-number stream
    /// ([`crate::integrator::View::current`]).
    pub sensor: usize,
    /// Bitmap textures.
    pub textures: Vec<Texture>,
    /// The texels of normal maps ([`Material::NormalMap`]).
    pub normal_maps: Vec<NormalMapTexture>,
    /// Textures on scalar parameters (roughness, blend weights), found by their texels'
    /// parameter ([`Scene::scalar_texture`]).
    pub scalar_textures: Vec<ScalarTexture>,
    /// Participating media, each inside the meshes whose `interior` it is.
    pub media: Vec<medium::Medium>,
    /// The fields of `volume` textures on surfaces ([`Albedo::Volume`]), in world space.
    pub volume_textures: Vec<medium::Field>,
    /// The environment's radiance seen by rays that leave the scene, if any: one RGB value
    /// (constant), or the texels of `env_map`.
    pub environment: Option<ParamId>,
    /// The environment map's layout when `environment` holds a map's texels.
    pub env_map: Option<envmap::EnvMap>,
    /// Lights without area.
    pub lights: Vec<Light>,
    /// Every differentiable value.
    pub params: ParamTable,
    /// Default maximum path depth (surface interactions) for this scene.
    pub max_depth: u32,
    /// Whether null-flagged BSDF samples — a `thindielectric`'s straight-through transmission, a
    /// `mask`'s pass-through — are left out of the depth that `max_depth` caps, as Mitsuba's
    /// `volpath`, `volpathmis` and `prbvolpath` count (false: every interaction counts, as in
    /// `path` and `prb`). Random numbers stay keyed by the vertex index either way.
    pub null_uncounted: bool,
    /// Mitsuba's `hide_emitters`: before the path's first counted interaction its rays pass
    /// through emitting shapes and the environment adds nothing (emitters stay visible in
    /// reflections and to next-event estimation).
    pub hide_emitters: bool,
    /// Default samples per pixel, when the scene file names one (Mitsuba's `sample_count`).
    pub default_spp: Option<u32>,
    /// Warnings found while loading (unknown properties, dropped triangles, …), also logged.
    pub warnings: Vec<String>,
    /// Triangles dropped on loading because their area overflows `f32` (coordinates too large),
    /// so that an empty result says why.
    pub overflowed_triangles: usize,
}

/// Bounds of the parameter kinds: reflectances and weights in [0, 1]; roughness between the value
/// where the microfacet distribution degenerates (ALGORITHMS.md §1, PRB blind spot) and 1;
/// radiance ≥ 0. The optimiser projects every step onto these ([`crate::optim::Adam`]).
pub mod bounds {
    /// Albedo and specular reflectance.
    pub const REFLECTANCE: (f32, f32) = (0.0, 1.0);
    /// Roughness alpha: [1e-3, 1], the range inverse rendering searches (alpha = 1 is already a
    /// very rough surface; glTF's roughness² never exceeds it).
    pub const ALPHA: (f32, f32) = (1e-3, 1.0);
    /// Blend weight.
    pub const WEIGHT: (f32, f32) = (0.0, 1.0);
    /// Emitted radiance.
    pub const RADIANCE: (f32, f32) = (0.0, f32::INFINITY);
    /// A dielectric's relative index of refraction η = int_ior / ext_ior.
    pub const IOR: (f32, f32) = (0.1, 10.0);
    /// A conductor's complex index of refraction eta + i·k, each channel of each part (Mitsuba's
    /// `eta.value`, `k.value`).
    pub const CONDUCTOR_IOR: (f32, f32) = (0.0, f32::INFINITY);
}

impl Scene {
    /// The array shape of parameter `id`, row-major, as Mitsuba's `traverse` lays its values out:
    /// `[height, width, 3]` for a bitmap's or an environment map's texels, `[z, y, x, channels]`
    /// for a medium's grid, `[len]` for everything else (`[3]` for a colour, `[1]` for a scalar).
    /// The product of the shape is always the parameter's length.
    ///
    /// ```
    /// let scene = pathgrad::scene::builtin::load("cornell-box")?;
    /// let alpha = scene.params.find("sphere.bsdf.alpha.value").unwrap();
    /// assert_eq!(scene.param_shape(alpha), [1]);
    /// # Ok::<(), pathgrad::Error>(())
    /// ```
    pub fn param_shape(&self, id: ParamId) -> Vec<usize> {
        if let Some(t) = self.textures.iter().find(|t| t.texels == id) {
            return vec![t.height as usize, t.width as usize, 3];
        }
        if let (Some(map), Some(env)) = (&self.env_map, self.environment)
            && env == id
        {
            return vec![map.height as usize, map.width as usize, 3];
        }
        for field in self.media.iter().flat_map(|m| [&m.sigma_t, &m.albedo]) {
            if let medium::Field::Grid { resolution, channels, values, .. } = field
                && *values == id
            {
                return vec![resolution.z as usize, resolution.y as usize, resolution.x as usize, *channels as usize];
            }
        }
        vec![self.params.entry(id).len as usize]
    }

    /// The sensor `selector` names: an index into [`Scene::sensors`] or a sensor's name.
    ///
    /// # Errors
    /// [`Error::Scene`] naming the scene and listing its sensors when none matches.
    pub fn sensor_index(&self, selector: &str) -> Result<usize> {
        let by_name = self.sensors.iter().position(|s| s.name == selector);
        let by_index = selector.trim().parse::<usize>().ok().filter(|&i| i < self.sensors.len());
        by_name.or(by_index).ok_or_else(|| {
            let list: Vec<String> = self.sensors.iter().enumerate().map(|(i, s)| format!("{i}: {}", s.name)).collect();
            let count = match list.len() {
                1 => "1 sensor".to_string(),
                n => format!("{n} sensors"),
            };
            Error::Scene {
                location: self.source.clone(),
                message: format!("no sensor '{selector}': the scene has {count} ({})", list.join(", ")),
            }
        })
    }

    /// An empty scene with `camera`.
    pub fn new(source: &str, camera: Camera) -> Scene {
        Scene {
            source: source.to_string(),
            meshes: Vec::new(),
            materials: Vec::new(),
            camera,
            sensors: vec![Sensor { name: "camera".into(), camera }],
            sensor: 0,
            textures: Vec::new(),
            normal_maps: Vec::new(),
            scalar_textures: Vec::new(),
            media: Vec::new(),
            volume_textures: Vec::new(),
            environment: None,
            env_map: None,
            lights: Vec::new(),
            params: ParamTable::default(),
            max_depth: 6,
            null_uncounted: false,
            hide_emitters: false,
            default_spp: None,
            warnings: Vec::new(),
            overflowed_triangles: 0,
        }
    }

    /// Adds a material and returns its id.
    pub fn add_material(&mut self, material: Material) -> MaterialId {
        self.materials.push(material);
        MaterialId(self.materials.len() as u32 - 1)
    }

    /// Adds a Lambertian material with parameter `{name}.reflectance.value`.
    ///
    /// # Errors
    /// As [`ParamTable::add`].
    pub fn add_diffuse(&mut self, name: &str, albedo: Vec3) -> Result<MaterialId> {
        let albedo = self.params.add(&format!("{name}.reflectance.value"), &albedo.to_array(), bounds::REFLECTANCE)?;
        Ok(self.add_material(Material::Diffuse { albedo: Albedo::Rgb(albedo) }))
    }

    /// Adds a rough conductor with parameters `{name}.alpha.value`,
    /// `{name}.specular_reflectance.value`, `{name}.eta.value` and `{name}.k.value` (Mitsuba's
    /// keys of a `roughconductor`).
    ///
    /// # Errors
    /// As [`ParamTable::add`].
    pub fn add_rough_conductor(
        &mut self,
        name: &str,
        distribution: Distribution,
        alpha: f32,
        specular: Vec3,
        eta: Vec3,
        k: Vec3,
    ) -> Result<MaterialId> {
        let alpha = self.params.add(&format!("{name}.alpha.value"), &[alpha], bounds::ALPHA)?;
        let specular = self.params.add(
            &format!("{name}.specular_reflectance.value"),
            &specular.to_array(),
            bounds::REFLECTANCE,
        )?;
        let specular = Albedo::Rgb(specular);
        let eta_param = Some(self.add_conductor_ior(name, eta, k)?);
        Ok(self.add_material(Material::RoughConductor {
            distribution,
            alpha,
            alpha_v: alpha,
            specular,
            eta,
            k,
            eta_param,
        }))
    }

    /// Adds a conductor's complex index of refraction as two RGB parameters, `{name}.eta.value`
    /// and, directly after it in the table, `{name}.k.value` (the layout `eta_param` of
    /// [`Material::RoughConductor`] and [`Material::Smooth`] relies on); returns eta's id.
    ///
    /// ```
    /// let mut scene = pathgrad::scene::builtin::load("cornell-box")?;
    /// let eta = scene.add_conductor_ior("gold", glam::Vec3::splat(0.2), glam::Vec3::splat(3.0))?;
    /// let k = scene.params.find("gold.k.value").unwrap();
    /// assert_eq!(scene.params.entry(k).offset, scene.params.entry(eta).offset + 3);
    /// # Ok::<(), pathgrad::Error>(())
    /// ```
    ///
    /// # Errors
    /// As [`ParamTable::add`].
    pub fn add_conductor_ior(&mut self, name: &str, eta: Vec3, k: Vec3) -> Result<ParamId> {
        let id = self.params.add(&format!("{name}.eta.value"), &eta.to_array(), bounds::CONDUCTOR_IOR)?;
        self.params.add(&format!("{name}.k.value"), &k.to_array(), bounds::CONDUCTOR_IOR)?;
        Ok(id)
    }

    /// Adds a GGX rough dielectric of relative index `eta` with parameters `{name}.alpha.value` and
    /// `{name}.specular_transmittance.value` (its reflectance is a constant 1).
    ///
    /// # Errors
    /// As [`ParamTable::add`].
    pub fn add_rough_dielectric(
        &mut self,
        name: &str,
        alpha: f32,
        transmittance: Vec3,
        eta: f32,
    ) -> Result<MaterialId> {
        let alpha = self.params.add(&format!("{name}.alpha.value"), &[alpha], bounds::ALPHA)?;
        let transmittance = self.params.add(
            &format!("{name}.specular_transmittance.value"),
            &transmittance.to_array(),
            bounds::REFLECTANCE,
        )?;
        Ok(self.add_material(Material::RoughDielectric {
            distribution: Distribution::Ggx,
            alpha,
            alpha_v: alpha,
            reflectance: SmoothColour::Constant(Vec3::ONE),
            transmittance: SmoothColour::Param(transmittance),
            eta,
            eta_param: None,
        }))
    }

    /// Adds a blend with parameter `{name}.weight.value`.
    ///
    /// # Errors
    /// As [`ParamTable::add`].
    pub fn add_blend(&mut self, name: &str, weight: f32, children: [MaterialId; 2]) -> Result<MaterialId> {
        let weight = self.params.add(&format!("{name}.weight.value"), &[weight], bounds::WEIGHT)?;
        Ok(self.add_material(Material::Blend { weight, children }))
    }

    /// Adds a mesh; with `radiance`, it becomes an area emitter with parameter
    /// `{name}.emitter.radiance.value`. Degenerate (zero-area or non-finite) triangles are dropped
    /// with a counted warning.
    ///
    /// # Errors
    /// As [`ParamTable::add`].
    pub fn add_mesh(
        &mut self,
        name: &str,
        geometry: shapes::Geometry,
        material: MaterialId,
        radiance: Option<Vec3>,
    ) -> Result<()> {
        let mut geometry = geometry;
        self.prune_triangles(name, &mut geometry);
        let emitter = match radiance {
            Some(r) => {
                Some(self.params.add(&format!("{name}.emitter.radiance.value"), &r.to_array(), bounds::RADIANCE)?)
            }
            None => None,
        };
        self.meshes.push(Mesh {
            name: name.to_string(),
            positions: geometry.positions,
            normals: geometry.normals,
            uvs: geometry.uvs,
            indices: geometry.indices,
            material,
            emitter,
            emitter_texture: None,
            interior: None,
        });
        Ok(())
    }

    /// Points the mesh attributes' [`AttributeSource::mesh`] at their meshes' new places after the
    /// meshes were reordered (mesh `old` is now `new_index[old]`).
    pub(crate) fn renumber_attribute_meshes(&mut self, new_index: &[usize]) {
        let renumber = |s: &mut AttributeSource| s.mesh = new_index[s.mesh as usize] as u32;
        for m in &mut self.materials {
            match m {
                Material::Diffuse { albedo: a }
                | Material::RoughConductor { specular: a, .. }
                | Material::RoughPlastic { diffuse: a, .. }
                | Material::SmoothPlastic { diffuse: a, .. } => {
                    if let Albedo::Attribute { source, .. } = a {
                        renumber(source);
                    }
                }
                _ => {}
            }
        }
        for t in &mut self.scalar_textures {
            if let Some(source) = &mut t.attribute {
                renumber(source);
            }
        }
    }

    /// Drops `geometry`'s degenerate (zero-area or non-finite) triangles, with their rows of the
    /// per-face attributes, warning with a count; [`Scene::add_mesh`] does this, and a loader
    /// that reads per-face attributes before adding the mesh does it first (then nothing is left
    /// to drop).
    pub(crate) fn prune_triangles(&mut self, name: &str, geometry: &mut shapes::Geometry) {
        let before = geometry.indices.len();
        let mut overflowed = 0;
        let positions = std::mem::take(&mut geometry.positions);
        geometry.retain_triangles(|t| {
            let p = t.map(|i| positions.get(i as usize).copied().unwrap_or(Vec3::NAN));
            let area = shapes::triangle_area(p[0], p[1], p[2]);
            if area.is_infinite() && p.iter().all(|v| v.is_finite()) {
                overflowed += 1;
            }
            area.is_finite() && area > 0.0
        });
        geometry.positions = positions;
        let dropped = before - geometry.indices.len();
        if overflowed > 0 {
            self.warn(format!(
                "mesh '{name}': dropped {overflowed} triangle(s) of {before} whose area overflows 32-bit floats \
                 (coordinates too large; scale the mesh down)"
            ));
            self.overflowed_triangles += overflowed;
        }
        if dropped > overflowed {
            self.warn(format!("mesh '{name}': dropped {} degenerate triangle(s) of {before}", dropped - overflowed));
        }
    }

    /// Adds a bitmap texture whose texels become the parameter `name`.
    ///
    /// # Errors
    /// [`Error::Scene`] if the texel count is not `width × height × 3` or a texel is outside [0, 1].
    pub fn add_texture(&mut self, name: &str, width: u32, height: u32, texels: &[f32]) -> Result<TextureId> {
        self.add_texture_in(name, width, height, texels, bounds::REFLECTANCE)
    }

    /// As [`Scene::add_texture`], the texels' parameter bounded by `range` (an emitter's texture:
    /// [`bounds::RADIANCE`]).
    ///
    /// # Errors
    /// As [`Scene::add_texture`].
    pub fn add_texture_in(
        &mut self,
        name: &str,
        width: u32,
        height: u32,
        texels: &[f32],
        range: (f32, f32),
    ) -> Result<TextureId> {
        check_texel_count(name, width, height, 3, texels.len())?;
        let texels = self.params.add(name, texels, range)?;
        self.textures.push(Texture {
            width,
            height,
            texels,
            nearest: false,
            wrap: Wrap::Repeat,
            to_uv: [Vec3::X, Vec3::Y],
        });
        Ok(TextureId(self.textures.len() as u32 - 1))
    }

    /// Sets the constant environment radiance, parameter `name`.
    ///
    /// # Errors
    /// As [`ParamTable::add`].
    pub fn set_environment(&mut self, name: &str, radiance: Vec3) -> Result<()> {
        self.environment = Some(self.params.add(name, &radiance.to_array(), bounds::RADIANCE)?);
        Ok(())
    }

    /// Sets an environment map: `map`'s layout with `texels` (linear RGB, row-major, `map.width ×
    /// map.height` of them), parameter `name`.
    ///
    /// # Errors
    /// As [`ParamTable::add`]; a texel count that does not match.
    pub fn set_environment_map(&mut self, name: &str, map: envmap::EnvMap, texels: &[f32]) -> Result<()> {
        if texels.len() != 3 * map.width as usize * map.height as usize || map.height < 2 || map.width == 0 {
            return Err(Error::InvalidArgument {
                parameter: name.into(),
                message: format!("{} texel values for a {}×{} map", texels.len() / 3, map.width, map.height),
            });
        }
        self.environment = Some(self.params.add(name, texels, bounds::RADIANCE)?);
        self.env_map = Some(map);
        Ok(())
    }

    /// Records a loading warning and logs it.
    pub fn warn(&mut self, message: String) {
        // Warnings of a file's loader already begin with its name (and a line), or with the
        // name and line of a file it includes (`inc.xml:6:3: …`).
        let located = message.split_once(':').is_some_and(|(file, rest)| {
            file.ends_with(".xml") && rest.split(':').next().is_some_and(|l| l.parse::<u32>().is_ok())
        });
        if message.starts_with(&self.source) || located {
            tracing::warn!("{message}");
        } else {
            tracing::warn!("{}: {message}", self.source);
        }
        self.warnings.push(message);
    }

    /// Total triangle count.
    pub fn triangle_count(&self) -> usize {
        self.meshes.iter().map(|m| m.indices.len()).sum()
    }

    /// Checks the invariants the renderer relies on.
    ///
    /// # Errors
    /// [`Error::Scene`] naming the scene and the mesh or material at fault: an empty scene, indices
    /// out of range, non-finite positions, normal/uv counts that do not match, unknown materials,
    /// nested blends, emitters of zero area, a degenerate camera.
    pub fn validate(&self) -> Result<()> {
        let err =
            |what: String, message: String| Error::Scene { location: format!("{}: {what}", self.source), message };
        if self.triangle_count() == 0 {
            let why = match self.overflowed_triangles {
                0 => String::new(),
                n => format!(
                    " ({n} were dropped because their area overflows 32-bit floats: the coordinates are too large)"
                ),
            };
            return Err(err("scene".into(), format!("has no triangles{why}")));
        }
        for (i, m) in self.materials.iter().enumerate() {
            if let Material::Blend { children, .. } = m {
                for c in children {
                    match self.materials.get(c.0 as usize) {
                        None => {
                            return Err(err(format!("material {i}"), format!("blend child {} does not exist", c.0)));
                        }
                        Some(Material::Blend { .. }) => {
                            return Err(err(format!("material {i}"), "a blend's children must not be blends".into()));
                        }
                        Some(Material::Null) => {
                            return Err(err(format!("material {i}"), "a blend's children must not be null".into()));
                        }
                        Some(Material::Mask { .. }) => {
                            return Err(err(
                                format!("material {i}"),
                                "a blend's children must not be masks (mask the blend instead)".into(),
                            ));
                        }
                        Some(Material::NormalMap { .. } | Material::BumpMap { .. }) => {
                            return Err(err(
                                format!("material {i}"),
                                "a blend's children must not be normal- or bump-mapped (map the blend instead)".into(),
                            ));
                        }
                        Some(_) => {}
                    }
                }
            }
        }
        if let Some(map) = self.env_map {
            let len = self.environment.map(|p| self.params.entry(p).len as usize);
            if map.height < 2 || len != Some(3 * map.width as usize * map.height as usize) {
                return Err(err(
                    "environment map".into(),
                    format!("its {}×{} texels do not match its parameter ({len:?} values)", map.width, map.height),
                ));
            }
        }
        for (i, l) in self.lights.iter().enumerate() {
            let bad = |m: &str| Err(err(format!("light {i}"), m.into()));
            let unit = |v: Vec3| v.is_finite() && (v.length() - 1.0).abs() < 1e-4;
            match l.shape {
                LightShape::Point { position } if !position.is_finite() => return bad("non-finite position"),
                LightShape::Spot { position, axis, cutoff, beam_width, to_local } => {
                    if !position.is_finite() || !unit(axis) || !to_local.is_finite() {
                        return bad("non-finite position or an axis that is not a unit vector");
                    }
                    if !(cutoff > 0.0 && cutoff <= 90.0 && beam_width > 0.0 && beam_width <= cutoff) {
                        return bad("a spot needs 0 < beam_width ≤ cutoff_angle ≤ 90 degrees");
                    }
                }
                LightShape::Directional { direction } if !unit(direction) => {
                    return bad("a direction that is not a unit vector");
                }
                LightShape::Projector { position, to_local, normal, uv_scale, scale } => {
                    if !(position.is_finite() && to_local.is_finite() && normal.is_finite() && uv_scale.is_finite()) {
                        return bad("a non-finite projector frame");
                    }
                    if self.params.entry(scale).len != 1 {
                        return bad("its scale is not one value");
                    }
                }
                _ => {}
            }
            match l.intensity {
                Some(p) if self.params.entry(p).len != 3 => return bad("its intensity is not one RGB value"),
                None if !matches!(l.shape, LightShape::Projector { .. }) || l.texture.is_none() => {
                    return bad("only a textured projector has no intensity");
                }
                _ => {}
            }
            if let Some(t) = l.texture {
                if t.0 as usize >= self.textures.len() {
                    return bad("a texture that does not exist");
                }
                if !matches!(l.shape, LightShape::Spot { .. } | LightShape::Projector { .. }) {
                    return bad("only a spot or a projector has a texture");
                }
            }
        }
        for (i, m) in self.materials.iter().enumerate() {
            let (nested, map, channels) = match *m {
                Material::NormalMap { nested, map } => (nested, map, 3),
                Material::BumpMap { nested, map, .. } => (nested, map, 1),
                _ => (MaterialId(0), u32::MAX, 0),
            };
            if channels > 0 {
                let bad = |message: &str| Err(err(format!("material {i}"), format!("a normal or bump map {message}")));
                match self.materials.get(nested.0 as usize) {
                    None => return bad("around a material that does not exist"),
                    Some(
                        Material::NormalMap { .. }
                        | Material::BumpMap { .. }
                        | Material::TwoSided(_)
                        | Material::Null
                        | Material::Mask { .. },
                    ) => {
                        return bad("around a normal or bump map, a two-sided wrapper, a mask or a null BSDF");
                    }
                    Some(_) => {}
                }
                match self.normal_maps.get(map as usize) {
                    Some(t)
                        if t.width > 0
                            && t.height > 0
                            && t.texels.len() == channels * (t.width * t.height) as usize => {}
                    _ => return bad("whose texture does not exist or does not match its size"),
                }
            }
            if let Material::TwoSided(c) = m
                && matches!(self.materials.get(c.0 as usize), Some(Material::Null))
            {
                return Err(err(format!("material {i}"), "a two-sided wrapper of a null BSDF".into()));
            }
            if let Material::Mask { nested, opacity } = *m {
                match self.materials.get(nested.0 as usize) {
                    None | Some(Material::Mask { .. } | Material::Null) => {
                        return Err(err(format!("material {i}"), "a mask around a missing, null or mask BSDF".into()));
                    }
                    Some(_) => {}
                }
                if self.params.entry(opacity).len != 1 && self.scalar_texture(opacity).is_none() {
                    return Err(err(
                        format!("material {i}"),
                        "a mask's opacity is neither 1 value nor a texture".into(),
                    ));
                }
            }
        }
        let attribute_len = |values: ParamId, source: AttributeSource, dim: usize, what: &str| -> Result<()> {
            let len = self.params.entry(values).len as usize;
            let expected = self
                .meshes
                .get(source.mesh as usize)
                .map(|m| dim * if source.per_vertex { m.positions.len() } else { m.indices.len() });
            if expected != Some(len) {
                return Err(err(
                    format!("{what} '{}'", self.params.entry(values).name),
                    format!("a mesh attribute of {len} values that does not match mesh {}", source.mesh),
                ));
            }
            Ok(())
        };
        // A `volume` texture is read as a diffuse's reflectance and a conductor's or rough
        // conductor's specular reflectance only (what the conformance matrix compares with
        // Mitsuba), and must exist.
        const VOLUME_SLOTS: &str = "a volume texture is read only as a diffuse's reflectance and a conductor's or \
                                    rough conductor's specular reflectance, and must exist";
        for m in &self.materials {
            use crate::bsdf::specular::SmoothKind;
            let volume = |a: Albedo| matches!(a, Albedo::Volume(_));
            let colour = |c: SmoothColour| matches!(c, SmoothColour::Texture(a) if volume(a));
            let missing = |c: SmoothColour| matches!(c, SmoothColour::Texture(Albedo::Volume(v)) if v as usize >= self.volume_textures.len());
            let refused = match *m {
                Material::Principled { base_color, .. } | Material::PrincipledThin { base_color, .. } => {
                    volume(base_color)
                }
                Material::Smooth { kind, reflectance, transmittance, .. } => {
                    (colour(reflectance) && kind != SmoothKind::Conductor)
                        || colour(transmittance)
                        || missing(reflectance)
                        || missing(transmittance)
                }
                Material::RoughDielectric { reflectance, transmittance, .. } => {
                    colour(reflectance) || colour(transmittance)
                }
                Material::RoughPlastic { specular, .. } | Material::SmoothPlastic { specular, .. } => colour(specular),
                _ => false,
            };
            if refused {
                return Err(err("a material".into(), VOLUME_SLOTS.into()));
            }
            let albedos = match *m {
                Material::Diffuse { albedo } => vec![albedo],
                Material::RoughConductor { specular, .. } => vec![specular],
                Material::RoughPlastic { diffuse, .. } | Material::SmoothPlastic { diffuse, .. } => vec![diffuse],
                _ => Vec::new(),
            };
            for a in albedos {
                if let Albedo::Attribute { values, source } = a {
                    attribute_len(values, source, 3, "colour")?;
                }
                if let Albedo::Volume(v) = a
                    && (!matches!(m, Material::Diffuse { .. } | Material::RoughConductor { .. })
                        || v as usize >= self.volume_textures.len())
                {
                    return Err(err(format!("volume texture {v}"), VOLUME_SLOTS.into()));
                }
            }
        }
        for t in &self.scalar_textures {
            if let Some(source) = t.attribute {
                attribute_len(t.texels, source, 1, "scalar texture")?;
            }
        }
        for m in &self.meshes {
            let n = m.positions.len();
            let at = || format!("mesh '{}'", m.name);
            if m.interior.is_some_and(|id| id.0 as usize >= self.media.len()) {
                return Err(err(at(), "its interior medium does not exist".into()));
            }
            if m.material.0 as usize >= self.materials.len() {
                return Err(err(at(), format!("material {} does not exist", m.material.0)));
            }
            if let Some(p) = m.positions.iter().find(|p| !p.is_finite()) {
                return Err(err(at(), format!("non-finite vertex position {p}")));
            }
            if m.normals.as_ref().is_some_and(|v| v.len() != n) || m.uvs.as_ref().is_some_and(|v| v.len() != n) {
                return Err(err(at(), "normal or uv count differs from the position count".into()));
            }
            if let Some(t) = m.indices.iter().find(|t| t.iter().any(|&i| i as usize >= n)) {
                return Err(err(at(), format!("triangle {t:?} indexes past {n} vertices")));
            }
            if m.emitter.is_some() {
                let area: f32 = m
                    .indices
                    .iter()
                    .map(|t| {
                        shapes::triangle_area(
                            m.positions[t[0] as usize],
                            m.positions[t[1] as usize],
                            m.positions[t[2] as usize],
                        )
                    })
                    .sum();
                if area <= 0.0 {
                    return Err(err(at(), "is an emitter with zero area".into()));
                }
            }
            match (m.emitter, m.emitter_texture) {
                (Some(p), None) if self.params.entry(p).len != 3 => {
                    return Err(err(at(), "its radiance is not one RGB value".into()));
                }
                (Some(p), Some(Albedo::Bitmap(t))) if self.textures.get(t.0 as usize).is_none_or(|t| t.texels != p) => {
                    return Err(err(at(), "its radiance texture does not exist or is not its radiance".into()));
                }
                (Some(p), Some(Albedo::Checker { colors, .. }))
                    if colors != p
                        || self.params.entries().get(p.0 as usize + 1).is_none_or(|next| {
                            let first = self.params.entry(p);
                            first.len != 3 || next.len != 3 || next.offset != first.offset + 3
                        }) =>
                {
                    return Err(err(at(), "its radiance checkerboard's two colours are not its radiance".into()));
                }
                (Some(_), Some(Albedo::Rgb(_) | Albedo::Attribute { .. } | Albedo::Volume(_))) => {
                    return Err(err(at(), "its radiance texture is neither a bitmap nor a checkerboard".into()));
                }
                (None, Some(_)) => return Err(err(at(), "a radiance texture without an emitter".into())),
                _ => {}
            }
        }
        let c = &self.camera;
        let forward = c.target - c.position;
        if !(c.fov_y_degrees > 0.0 && c.fov_y_degrees < 180.0)
            || forward.length_squared() == 0.0
            || forward.cross(c.up).length_squared() == 0.0
        {
            return Err(err(
                "camera".into(),
                "needs 0 < fov < 180, a target distinct from the position and an up vector not parallel to the view"
                    .into(),
            ));
        }
        let w = &c.window;
        if !(w.min.cmpge(glam::Vec2::ZERO).all() && w.max.cmple(glam::Vec2::ONE).all() && w.min.cmplt(w.max).all()) {
            return Err(err(
                "camera".into(),
                format!("the film window must lie in [0, 1]² with min < max, got {:?} to {:?}", w.min, w.max),
            ));
        }
        if c.width == 0 || c.height == 0 {
            return Err(err("camera".into(), "image size must be at least 1×1".into()));
        }
        Ok(())
    }
}

/// That a `width × height` texture of `channels` values a texel has `len` values.
///
/// # Errors
/// [`Error::Scene`] naming texture `name` otherwise (or for an empty size).
pub(crate) fn check_texel_count(name: &str, width: u32, height: u32, channels: usize, len: usize) -> Result<()> {
    let need = width as usize * height as usize * channels;
    if width == 0 || height == 0 || len != need {
        let kind = if channels == 3 { " RGB" } else { "" };
        return Err(Error::Scene {
            location: format!("texture {name}"),
            message: format!("{width}×{height}{kind} needs {need} texels, got {len}"),
        });
    }
    Ok(())
}
