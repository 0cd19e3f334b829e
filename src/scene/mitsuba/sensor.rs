//! `<sensor type="perspective">` with its `<film>` and `<sampler>`, and `<integrator>`: the camera
//! and the render defaults.
//!
//! Mitsuba's camera looks along +z of its `to_world` frame with +y up, and its film maps local +x
//! to the *left* edge of the image (`perspective_projection` scales x by −½). pathgrad's camera
//! puts `forward × up` on the right, so with `forward = M·z`, `up = M·y` the two agree exactly
//! when `det M > 0` (then `M·z × M·y = −M·x`, the image's right). A mirroring `to_world`
//! (`det M < 0`) would need a mirrored image, which pathgrad's camera cannot express: it is
//! rejected rather than rendered mirrored.

use super::plugins::{Category, names};
use glam::{Mat4, Vec3};

use super::loader::Loader;
use super::xml::{El, Props, Transform};
use crate::error::Result;
use crate::integrator::{DEFAULT_RR_DEPTH, UNBOUNDED_DEPTH_CAP};
use crate::scene::{Camera, Lens, PixelFilter};

/// Mitsuba's default film size.
const DEFAULT_FILM: (u32, u32) = (768, 576);
/// Mitsuba's `gaussian` rfilter's default standard deviation, in pixels.
const DEFAULT_GAUSSIAN_STDDEV: f32 = 0.5;
/// The largest filter radius read, in pixels.
const MAX_FILTER_RADIUS: f32 = 64.0;
/// Largest film side pathgrad renders (as `RenderOptions::validate`).
const MAX_FILM: i64 = 16_384;
/// Mitsuba's default `sample_count` of the `independent` sampler.
const DEFAULT_SAMPLE_COUNT: i64 = 4;
/// Mitsuba's default focal length in millimetres (35 mm film equivalent, diagonal field of view).
const DEFAULT_FOCAL_LENGTH_MM: f32 = 50.0;
/// Diagonal of 35 mm film (36 × 24 mm), in millimetres.
const FILM_DIAGONAL_MM: f32 = 43.266_615;
/// Relative tolerance for "the sensor's `to_world` is a rotation, uniform scale and translation":
/// looser than f32 rounding of a product of a few matrices (~1e-6), tighter than any deliberate
/// non-uniform scale.
const SIMILARITY_TOLERANCE: f32 = 1e-4;

/// Which image axis Mitsuba's `fov` spans.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum FovAxis {
    /// Horizontal (Mitsuba's default).
    X,
    /// Vertical.
    Y,
    /// Diagonal.
    Diagonal,
    /// The shorter image side.
    Smaller,
    /// The longer image side.
    Larger,
}

/// pathgrad's vertical field of view (degrees) for Mitsuba's `fov` along `axis` on a
/// `width × height` film: `tan(fov_y/2) = tan(fov/2)·h/s` where `s` is the film extent along the
/// axis (`w`, `h` or `√(w²+h²)`). `smaller`/`larger` pick `y`/`x` as Mitsuba does (`x` on a
/// square film).
pub(super) fn vertical_fov(fov: f32, axis: FovAxis, width: u32, height: u32) -> f32 {
    let (w, h) = (f64::from(width), f64::from(height));
    let axis = match axis {
        FovAxis::Smaller if w > h => FovAxis::Y,
        FovAxis::Smaller => FovAxis::X,
        FovAxis::Larger if w > h => FovAxis::X,
        FovAxis::Larger => FovAxis::Y,
        a => a,
    };
    let extent = match axis {
        FovAxis::Y => return fov,
        FovAxis::X => w,
        _ => w.hypot(h),
    };
    let tan_y = (f64::from(fov) * 0.5).to_radians().tan() * h / extent;
    (2.0 * tan_y.atan().to_degrees()) as f32
}

/// The pinhole field of view an orthographic camera carries (unused by its lens).
const DEFAULT_ORTHOGRAPHIC_FOV: f32 = 45.0;

/// Mitsuba 3's `perspective` clip distances when the scene names none.
const MITSUBA_NEAR_CLIP: f32 = 0.01;
const MITSUBA_FAR_CLIP: f32 = 10_000.0;

/// What a `<film>` gives the sensor.
struct Film {
    /// The film's size in pixels (what the field of view spans).
    width: u32,
    height: u32,
    /// The crop window's top-left pixel and size (the image's size; the film's when not cropped).
    offset: [u32; 2],
    crop: [u32; 2],
    filter: PixelFilter,
}

impl Film {
    /// The camera of this film: the image is its crop window.
    fn camera(&self, position: Vec3, target: Vec3, up: Vec3, fov_y_degrees: f32, lens: Lens) -> Camera {
        Camera {
            position,
            target,
            up,
            fov_y_degrees,
            width: self.crop[0],
            height: self.crop[1],
            filter: self.filter,
            lens,
            window: crate::scene::FilmWindow::from_pixels(self.width, self.height, self.offset, self.crop),
        }
    }
}

impl<'a> Loader<'a> {
    /// Reads the sensor into `scene.camera` (and `default_spp`).
    pub(super) fn sensor(&mut self, node: El<'a>) -> Result<()> {
        let p = Props::parse(&self.x, node)?;
        if !matches!(p.kind.as_str(), "perspective" | "thinlens" | "orthographic") {
            return Err(self
                .x
                .err(node, format!("unsupported plugin '{}' (supported: {})", p.kind, names(Category::Sensor))));
        }
        let films = p.take_nested(&["film"]);
        // Mitsuba's hdrfilm reconstructs with a Gaussian (σ = 0.5) unless told otherwise.
        let film = match films[..] {
            [] => Film {
                width: DEFAULT_FILM.0,
                height: DEFAULT_FILM.1,
                offset: [0, 0],
                crop: [DEFAULT_FILM.0, DEFAULT_FILM.1],
                filter: PixelFilter::Gaussian { stddev: DEFAULT_GAUSSIAN_STDDEV },
            },
            [f] => self.film(f)?,
            [_, second, ..] => return Err(self.x.err(second, "a sensor has at most one <film>")),
        };
        let (width, height) = (film.width, film.height);
        // A sampler nested here or declared at scene level and referred to (`<ref id="…"/>`).
        let samplers = p.take_nested(&["sampler", "ref"]);
        let samplers = samplers.into_iter().map(|s| self.deref(s)).collect::<Result<Vec<_>>>()?;
        if let Some(other) = samplers.iter().find(|s| !s.has_tag_name("sampler")) {
            return Err(self.x.err(*other, "a sensor refers only to a <sampler> (a <film> must be nested in it)"));
        }
        match samplers[..] {
            [] => {}
            [s] => self.sampler(s)?,
            [_, second, ..] => return Err(self.x.err(second, "a sensor has at most one <sampler>")),
        }
        if p.kind == "orthographic" {
            return self.orthographic(&p, &film);
        }
        let lens = if p.kind == "thinlens" {
            let aperture_radius = match p.float(&self.x, "aperture_radius")? {
                Some((r, _)) if r > 0.0 && r.is_finite() => r,
                Some((r, n)) => return Err(self.x.err(n, format!("'aperture_radius' must be positive, got {r}"))),
                None => return Err(self.x.err(node, "'thinlens' needs the property 'aperture_radius'")),
            };
            let far = p.float(&self.x, "far_clip")?.map_or(MITSUBA_FAR_CLIP, |(v, _)| v);
            let focus_distance = match p.float(&self.x, "focus_distance")? {
                Some((d, _)) if d > 0.0 && d.is_finite() => d,
                Some((d, n)) => return Err(self.x.err(n, format!("'focus_distance' must be positive, got {d}"))),
                // Mitsuba's default: the far clip distance.
                None => far,
            };
            Lens::Thin { aperture_radius, focus_distance }
        } else {
            // A pinhole has no focus: Mitsuba's `perspective` reads no `focus_distance` either
            // (scenes written for `thinlens` keep it), so it changes nothing and is accepted silently.
            p.float(&self.x, "focus_distance")?;
            Lens::Pinhole
        };
        let fov_y = self.fov_y(&p, width, height)?;
        let mut clips = Vec::new();
        for (clip, default) in [("near_clip", MITSUBA_NEAR_CLIP), ("far_clip", MITSUBA_FAR_CLIP)] {
            let (depth, warning) = match p.float(&self.x, clip)? {
                Some((depth, n)) => (
                    depth,
                    self.x.warning(
                        n,
                        format!("property '{clip}' of 'perspective' ignored: pathgrad's camera does not clip"),
                    ),
                ),
                // Mitsuba clips at its defaults too; geometry that close (or that far) is rare.
                None => (
                    default,
                    self.x.warning(
                        node,
                        format!(
                            "Mitsuba's default {clip} ({default}) clips geometry that pathgrad's camera, which does \
                             not clip, renders"
                        ),
                    ),
                ),
            };
            clips.push((clip == "near_clip", depth, warning));
        }
        let transform = p.transform(&self.x, "to_world")?;
        self.finish(&p)?;
        let (position, target, up) = match transform {
            None => (Vec3::ZERO, Vec3::Z, Vec3::Y),
            Some((t, n)) => camera_frame(&t).map_err(|m| self.x.err(n, m))?,
        };
        self.scene.camera = film.camera(position, target, up, fov_y, lens);
        // Whether they clip anything is known once the shapes are built.
        let at = self.scene.warnings.len();
        for (near, depth, warning) in clips {
            self.clips.push(super::loader::PendingClip { camera: self.scene.camera, near, depth, warning, at });
        }
        Ok(())
    }

    /// Mitsuba's `orthographic` sensor: parallel rays along `to_world`'s z from the film, which
    /// spans x ∈ [−1, 1] and y ∈ [−1/aspect, 1/aspect] of `to_world`'s frame (so its x and y
    /// scales size it) on the plane `near_clip` ahead; pathgrad starts rays there as Mitsuba does,
    /// and renders beyond `far_clip` (with a warning where that matters).
    /// The vertical field of view (degrees) that `p`'s Mitsuba `fov` and `fov_axis`, or its
    /// `focal_length` (35 mm film, 50 mm by default), give a `width × height` image.
    ///
    /// # Errors
    /// An unknown `fov_axis`, both `fov` and `focal_length`, values out of range.
    pub(super) fn fov_y(&self, p: &Props<'a>, width: u32, height: u32) -> Result<f32> {
        let axis = match p.string(&self.x, "fov_axis")? {
            None => FovAxis::X,
            Some((s, n)) => match s.to_ascii_lowercase().as_str() {
                "x" => FovAxis::X,
                "y" => FovAxis::Y,
                "diagonal" => FovAxis::Diagonal,
                "smaller" => FovAxis::Smaller,
                "larger" => FovAxis::Larger,
                _ => {
                    return Err(self
                        .x
                        .err(n, format!("unknown fov_axis '{s}' (supported: x, y, diagonal, smaller, larger)")));
                }
            },
        };
        let fov = p.float(&self.x, "fov")?;
        let focal = p.string(&self.x, "focal_length")?;
        Ok(match (fov, focal) {
            (Some(_), Some((_, n))) => {
                return Err(self.x.err(n, "give either 'fov' or 'focal_length', not both"));
            }
            (Some((f, n)), None) => {
                if !(f > 0.0 && f < 180.0) {
                    return Err(self.x.err(n, format!("'fov' must lie in (0, 180) degrees, got {f}")));
                }
                vertical_fov(f, axis, width, height)
            }
            (None, focal) => {
                let mm = match focal {
                    None => DEFAULT_FOCAL_LENGTH_MM,
                    Some((s, n)) => {
                        let digits = s.trim().trim_end_matches("mm");
                        match digits.trim().parse::<f32>() {
                            Ok(v) if v.is_finite() && v > 0.0 => v,
                            _ => {
                                return Err(self.x.err(
                                    n,
                                    format!("'focal_length' must be a positive length like '50mm', got '{s}'"),
                                ));
                            }
                        }
                    }
                };
                let diagonal_fov = 2.0 * (FILM_DIAGONAL_MM / (2.0 * mm)).atan().to_degrees();
                vertical_fov(diagonal_fov, FovAxis::Diagonal, width, height)
            }
        })
    }

    fn orthographic(&mut self, p: &Props<'a>, film: &Film) -> Result<()> {
        let near = p.float(&self.x, "near_clip")?.map_or(MITSUBA_NEAR_CLIP, |(v, _)| v);
        let far = p.float(&self.x, "far_clip")?;
        let transform = p.transform(&self.x, "to_world")?;
        self.finish(p)?;
        let (position, target, up, scale) = match transform {
            None => (Vec3::ZERO, Vec3::Z, Vec3::Y, Vec3::ONE),
            Some((t, n)) => scaled_camera_frame(&t).map_err(|m| self.x.err(n, m))?,
        };
        let aspect = film.width as f32 / film.height as f32;
        let lens =
            Lens::Orthographic { half_height: scale.y / aspect, stretch: scale.x / scale.y, near_clip: near * scale.z };
        // fov_y_degrees is the pinhole's: unused by this lens, a valid value for the checks.
        self.scene.camera = film.camera(position, target, up, DEFAULT_ORTHOGRAPHIC_FOV, lens);
        if let Some((depth, n)) = far {
            let warning =
                self.x.warning(n, "property 'far_clip' of 'orthographic' ignored: pathgrad's camera does not clip far");
            let at = self.scene.warnings.len();
            self.clips.push(super::loader::PendingClip { camera: self.scene.camera, near: false, depth, warning, at });
        }
        Ok(())
    }

    /// A `<film>`: its size, crop window and reconstruction filter (Mitsuba's default: a Gaussian
    /// of σ 0.5).
    fn film(&mut self, node: El<'a>) -> Result<Film> {
        let p = Props::parse(&self.x, node)?;
        if p.kind != "hdrfilm" {
            return Err(self.x.err(node, format!("unsupported plugin '{}' (supported: hdrfilm)", p.kind)));
        }
        let mut size = [DEFAULT_FILM.0, DEFAULT_FILM.1];
        for (s, name) in size.iter_mut().zip(["width", "height"]) {
            if let Some((v, n)) = p.integer(&self.x, name)? {
                if !(1..=MAX_FILM).contains(&v) {
                    return Err(self.x.err(n, format!("'{name}' must lie in [1, {MAX_FILM}], got {v}")));
                }
                *s = v as u32;
            }
        }
        // Mitsuba's crop window: the image covers only these pixels of the film.
        let mut offset = [0u32; 2];
        for (o, name) in offset.iter_mut().zip(["crop_offset_x", "crop_offset_y"]) {
            if let Some((v, n)) = p.integer(&self.x, name)? {
                if !(0..MAX_FILM).contains(&v) {
                    return Err(self.x.err(n, format!("'{name}' must lie in [0, {MAX_FILM}), got {v}")));
                }
                *o = v as u32;
            }
        }
        let mut crop = [size[0].saturating_sub(offset[0]), size[1].saturating_sub(offset[1])];
        for (axis, name) in ["crop_width", "crop_height"].into_iter().enumerate() {
            if let Some((v, n)) = p.integer(&self.x, name)? {
                if !(1..=MAX_FILM).contains(&v) {
                    return Err(self.x.err(n, format!("'{name}' must lie in [1, {MAX_FILM}], got {v}")));
                }
                crop[axis] = v as u32;
            }
        }
        for (axis, (name, size_name)) in
            [("crop_offset_x", "width"), ("crop_offset_y", "height")].into_iter().enumerate()
        {
            if crop[axis] == 0 || offset[axis] + crop[axis] > size[axis] {
                let crop_name = ["crop_width", "crop_height"][axis];
                let n = p.node_of(crop_name).or(p.node_of(name)).unwrap_or(node);
                return Err(self.x.err(
                    n,
                    format!(
                        "the crop window ({name} {} + {crop_name} {}) must lie inside the film's {size_name} {}",
                        offset[axis], crop[axis], size[axis]
                    ),
                ));
            }
        }
        // Output encoding only: pathgrad picks it from the output file name.
        for name in ["pixel_format", "component_format", "file_format"] {
            p.string(&self.x, name)?;
        }
        if p.boolean(&self.x, "sample_border", false)? {
            let n = p.node_of("sample_border").unwrap_or(node);
            return Err(self.x.err(n, "sample_border is not supported (pathgrad samples inside the film only)"));
        }
        let filter = match p.take_nested(&["rfilter"])[..] {
            [] => PixelFilter::Gaussian { stddev: DEFAULT_GAUSSIAN_STDDEV },
            [f] => {
                let f = Props::parse(&self.x, f)?;
                // A positive, finite size in pixels (Mitsuba's defaults when absent).
                let size = |loader: &Self, name: &str, default: f32| -> Result<f32> {
                    match f.float(&loader.x, name)? {
                        None => Ok(default),
                        Some((v, _)) if v.is_finite() && v > 0.0 && v <= MAX_FILTER_RADIUS => Ok(v),
                        Some((v, n)) => Err(loader
                            .x
                            .err(n, format!("'{name}' must lie in (0, {MAX_FILTER_RADIUS}] pixels, got {v}"))),
                    }
                };
                let filter = match f.kind.as_str() {
                    "box" => PixelFilter::Box,
                    "tent" => PixelFilter::Tent { radius: size(self, "radius", 1.0)? },
                    "gaussian" => {
                        let stddev = size(self, "stddev", DEFAULT_GAUSSIAN_STDDEV)?;
                        PixelFilter::Gaussian { stddev: stddev.min(MAX_FILTER_RADIUS / 4.0) }
                    }
                    other => {
                        return Err(self.x.err(
                            f.node,
                            format!(
                                "unsupported plugin '{other}' (supported: box, tent, gaussian; filters with negative \
                                 lobes are not)"
                            ),
                        ));
                    }
                };
                self.finish(&f)?;
                filter
            }
            [_, second, ..] => return Err(self.x.err(second, "a film has at most one <rfilter>")),
        };
        self.finish(&p)?;
        Ok(Film { width: size[0], height: size[1], offset, crop, filter })
    }

    /// Reads a `<sampler>`'s sample count. Mitsuba's other samplers (`stratified`, `multijitter`,
    /// `orthogonal`, `ldsampler`) place samples differently for the same expectation: pathgrad
    /// draws independent samples instead, ignores their placement settings and says so once.
    fn sampler(&mut self, node: El<'a>) -> Result<()> {
        let p = Props::parse(&self.x, node)?;
        match p.kind.as_str() {
            "independent" => {}
            kind @ ("stratified" | "multijitter" | "orthogonal" | "ldsampler") => {
                p.boolean(&self.x, "jitter", true)?;
                p.float(&self.x, "strength")?;
                let w = self.x.warning(
                    node,
                    format!("sampler '{kind}' is drawn as 'independent' (the same expectation, other noise)"),
                );
                self.scene.warn(w);
            }
            other => {
                return Err(self.x.err(
                    node,
                    format!(
                        "unsupported plugin '{other}' (supported: independent; stratified, multijitter, orthogonal \
                         and ldsampler as independent)"
                    ),
                ));
            }
        }
        let count = match p.integer(&self.x, "sample_count")? {
            None => DEFAULT_SAMPLE_COUNT,
            Some((v, n)) if !(1..=i64::from(u32::MAX)).contains(&v) => {
                return Err(self.x.err(n, format!("'sample_count' must be at least 1, got {v}")));
            }
            Some((v, _)) => v,
        };
        self.scene.default_spp = Some(count as u32);
        if let Some((_, n)) = p.integer(&self.x, "seed")? {
            let w = self.x.warning(
                n,
                format!("property 'seed' of '{}' ignored: pathgrad takes the seed from the render options", p.kind),
            );
            self.scene.warn(w);
        }
        self.finish(&p)
    }

    /// Reads `<integrator>` into `scene.max_depth` (−1, Mitsuba's default, becomes
    /// [`UNBOUNDED_DEPTH_CAP`], which the renderer treats as unbounded).
    ///
    /// The wrappers `moment` and `aov` render the integrator nested in them (their image is that
    /// integrator's; pathgrad writes no second moments or AOV channels) and say so once. `direct`
    /// is a path tracer of depth 2 (Mitsuba's `direct` estimates the same image, with other
    /// noise: its sample counts per emitter and BSDF are ignored), also said once. `ptracer`
    /// (Mitsuba's particle tracer) is rendered as a path tracer of its `max_depth`: the same
    /// image where the camera sees no smooth specular surface ([`Loader::ptracer_checks`] warns
    /// otherwise, and refuses media, which Mitsuba's particle tracer does not render).
    /// `prb_projective` and `direct_projective` render as `prb` and `direct`: their projective
    /// terms differentiate geometry, which pathgrad keeps fixed; said once.
    pub(super) fn integrator(&mut self, node: El<'a>) -> Result<()> {
        let p = Props::parse(&self.x, node)?;
        if matches!(p.kind.as_str(), "moment" | "aov") {
            let nested = p.take_nested(&["integrator"]);
            if p.kind == "aov" {
                p.string(&self.x, "aovs")?;
            }
            self.finish(&p)?;
            let inner = match nested[..] {
                [i] => i,
                [] => return Err(self.x.err(node, format!("'{}' needs a nested <integrator>", p.kind))),
                [_, second, ..] => {
                    return Err(self
                        .x
                        .err(second, format!("pathgrad renders one integrator; this '{}' nests several", p.kind)));
                }
            };
            let w = self.x.warning(
                node,
                format!(
                    "'{}' integrator: pathgrad renders the integrator nested in it (the same image; no {} channels)",
                    p.kind,
                    if p.kind == "moment" { "second-moment" } else { "AOV" }
                ),
            );
            self.scene.warn(w);
            return self.integrator(inner);
        }
        if p.kind == "direct" {
            for count in ["emitter_samples", "bsdf_samples", "shading_samples"] {
                p.integer(&self.x, count)?;
            }
            let emitter_samples = match p.integer(&self.x, "emitter_samples")? {
                Some(v) => Some(v),
                None => p.integer(&self.x, "shading_samples")?,
            };
            self.direct_emitter_samples = emitter_samples.filter(|&(n, _)| n > 1);
            self.scene.max_depth = 2;
            let w = self.x.warning(
                node,
                "'direct' integrator: rendered as a path tracer of max_depth 2 (the same image, other noise)",
            );
            self.scene.warn(w);
            self.hide_emitters(&p)?;
            return self.finish(&p);
        }
        if matches!(p.kind.as_str(), "direct_projective" | "prb_projective") {
            self.projective_settings(&p)?;
        }
        if p.kind == "direct_projective" {
            self.scene.max_depth = 2;
            let w = self.x.warning(
                node,
                "'direct_projective' integrator: rendered as a path tracer of max_depth 2 (its image, other noise); \
                 its projective sampling differentiates geometry, which pathgrad keeps fixed",
            );
            self.scene.warn(w);
            p.integer(&self.x, "max_depth")?;
            self.hide_emitters(&p)?;
            return self.finish(&p);
        }
        if matches!(p.kind.as_str(), "volpath" | "volpathmis" | "prbvolpath") {
            self.volpath_integrator = Some(node);
            // Their depth counts no null-flagged BSDF sample (a thindielectric's transmission, a
            // mask's pass-through): Mitsuba's volpath.cpp, volpathmis.cpp, prbvolpath.py.
            self.scene.null_uncounted = true;
        }
        if p.kind == "ptracer" {
            p.integer(&self.x, "samples_per_pass")?;
            self.ptracer_integrator = Some(node);
        }
        if p.kind == "prb_projective" {
            let w = self.x.warning(
                node,
                "'prb_projective' integrator: rendered as prb (its image, other noise); its projective sampling \
                 differentiates geometry, which pathgrad keeps fixed",
            );
            self.scene.warn(w);
        }
        if !matches!(
            p.kind.as_str(),
            "path" | "prb" | "prb_basic" | "volpath" | "volpathmis" | "prbvolpath" | "ptracer" | "prb_projective"
        ) {
            return Err(self.x.err(
                node,
                format!(
                    "unsupported plugin '{}' (supported: path, prb, prb_basic, volpath, volpathmis, prbvolpath, \
                     direct, ptracer, prb_projective, direct_projective; moment and aov around one of them)",
                    p.kind
                ),
            ));
        }
        self.scene.max_depth = match p.integer(&self.x, "max_depth")? {
            None | Some((-1, _)) => UNBOUNDED_DEPTH_CAP,
            Some((v, n)) if v > i64::from(UNBOUNDED_DEPTH_CAP) => {
                let w = self.x.warning(
                    n,
                    format!(
                        "'max_depth' {v} is capped at {UNBOUNDED_DEPTH_CAP}, the most interactions a path can have in \
                         pathgrad"
                    ),
                );
                self.scene.warn(w);
                UNBOUNDED_DEPTH_CAP
            }
            Some((v, _)) if v >= 1 => v as u32,
            Some((v, n)) => {
                return Err(self.x.err(n, format!("'max_depth' must be at least 1, or -1 for unbounded, got {v}")));
            }
        };
        if let Some((v, n)) = p.integer(&self.x, "rr_depth")?
            && v != i64::from(DEFAULT_RR_DEPTH)
        {
            let w = self.x.warning(
                n,
                format!(
                    "property 'rr_depth' of '{}' ignored: pathgrad starts Russian roulette at depth {DEFAULT_RR_DEPTH}",
                    p.kind
                ),
            );
            self.scene.warn(w);
        }
        self.hide_emitters(&p)?;
        self.finish(&p)
    }

    /// Reads (and drops) the projective integrators' sampling settings: their sample counts and
    /// guiding act only on the geometry-gradient terms, which pathgrad does not compute.
    ///
    /// # Errors
    /// A setting of the wrong type.
    fn projective_settings(&self, p: &Props<'a>) -> Result<()> {
        for count in ["sppc", "sppp", "sppi", "guiding_rounds", "proj_seed_spp"] {
            p.integer(&self.x, count)?;
        }
        for name in ["guiding", "project_seed"] {
            p.string(&self.x, name)?;
        }
        p.boolean(&self.x, "guiding_proj", true)?;
        Ok(())
    }

    /// An integrator's `hide_emitters` into [`crate::scene::Scene::hide_emitters`]: as in every
    /// Mitsuba integrator pathgrad accepts, the camera's rays pass through emitting shapes and
    /// the environment adds nothing until the path's first counted interaction.
    ///
    /// # Errors
    /// A value that is not a boolean.
    fn hide_emitters(&mut self, p: &Props<'a>) -> Result<()> {
        self.scene.hide_emitters = p.boolean(&self.x, "hide_emitters", false)?;
        Ok(())
    }
}

/// Position, target and up of a camera whose `to_world` is `t`; a single `<lookat>` is kept
/// verbatim.
///
/// # Errors
/// A singular, mirroring, or non-similarity transform.
/// An orthographic sensor's frame from its `to_world`: a rotation (without mirroring) times a
/// scale per axis, and a translation. Returns position, target, up and the scale.
///
/// # Errors
/// A singular, mirroring or sheared transform.
pub(super) fn scaled_camera_frame(t: &Transform) -> std::result::Result<(Vec3, Vec3, Vec3, Vec3), String> {
    let m: Mat4 = t.matrix;
    let (x, y, z) = (m.x_axis.truncate(), m.y_axis.truncate(), m.z_axis.truncate());
    let (lx, ly, lz) = (x.length(), y.length(), z.length());
    if !(x.dot(y.cross(z)) > 0.0) {
        return Err("the sensor's to_world is singular or mirrors the image (pathgrad's camera cannot)".into());
    }
    let orthogonal = x.dot(y).abs() <= SIMILARITY_TOLERANCE * lx * ly
        && x.dot(z).abs() <= SIMILARITY_TOLERANCE * lx * lz
        && y.dot(z).abs() <= SIMILARITY_TOLERANCE * ly * lz;
    if !orthogonal {
        return Err("an orthographic sensor's to_world must be a rotation, a scale per axis and a translation".into());
    }
    let position = m.w_axis.truncate();
    Ok((position, position + z / lz, y / ly, Vec3::new(lx, ly, lz)))
}

pub(super) fn camera_frame(t: &Transform) -> std::result::Result<(Vec3, Vec3, Vec3), String> {
    let m: Mat4 = t.matrix;
    let (x, y, z) = (m.x_axis.truncate(), m.y_axis.truncate(), m.z_axis.truncate());
    let det = x.dot(y.cross(z));
    if !(det.abs() > 0.0) {
        return Err("the sensor's to_world is singular".into());
    }
    if det < 0.0 {
        return Err("the sensor's to_world mirrors the image (negative determinant); pathgrad's camera cannot \
                    render mirrored images"
            .into());
    }
    let (lx, ly, lz) = (x.length(), y.length(), z.length());
    let scale = lx.max(ly).max(lz);
    let similar = (lx - ly).abs() <= SIMILARITY_TOLERANCE * scale
        && (lx - lz).abs() <= SIMILARITY_TOLERANCE * scale
        && x.dot(y).abs() <= SIMILARITY_TOLERANCE * lx * ly
        && x.dot(z).abs() <= SIMILARITY_TOLERANCE * lx * lz
        && y.dot(z).abs() <= SIMILARITY_TOLERANCE * ly * lz;
    if !similar {
        return Err("the sensor's to_world must be a rotation, uniform scale and translation".into());
    }
    if let Some([origin, target, up]) = t.lookat {
        return Ok((origin, target, up));
    }
    let position = m.w_axis.truncate();
    Ok((position, position + z / lz, y / ly))
}
