//! Scenes: loaded on the host, their parameters by name, and the CPU reference render.

use std::ffi::{CString, c_char};

use pathgrad::integrator::{RenderOptions, Sampling};
use pathgrad::params::ParamId;
use pathgrad::scene::Scene;

use crate::error::{Failure, Outcome, PgStatus, arg, arg_mut, guard, out_slice, slice, string};

/// A scene on the host: geometry, materials and the parameter values. A renderer made from it
/// takes a copy; later changes here do not reach that renderer.
pub struct PgScene {
    pub(crate) scene: Scene,
    names: Vec<CString>,
}

/// Where a parameter's values lie in the flat value array (the parameter and gradient buffers'
/// layout), and their bounds.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default)]
pub struct PgParamInfo {
    /// Index of its first value.
    pub offset: usize,
    /// Number of values (3 for RGB, 1 for scalars).
    pub count: usize,
    /// Inclusive lower bound of every value.
    pub lower: f32,
    /// Inclusive upper bound of every value.
    pub upper: f32,
}

/// Image size, samples and seed of a frame or a render. A field left 0 takes the scene's default
/// (its camera's resolution, 16 spp, its max depth); the seed 0 is a seed like any other.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default)]
pub struct PgFrameDesc {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Samples per pixel.
    pub spp: u32,
    /// Random seed.
    pub seed: u32,
    /// Maximum surface interactions per path: 0 the scene's, -1 unbounded.
    pub max_depth: i32,
    /// Nonzero: deterministic (fixed-point, bitwise reproducible) gradients, where the device has
    /// 64-bit integer atomics; else float atomics.
    pub deterministic: u32,
    /// Nonzero: attached sampling — the sampled directions move with the parameters, so that
    /// parameters acting only through them (a dielectric's index of refraction) have gradients
    /// (docs/gradients.md says what it covers); `deterministic` too. 0: detached, as Mitsuba's `prb`.
    pub attached: u32,
    /// Attached sampling's Jacobian noise amplitude, in [0, 1); 0 its default. Only with `attached`.
    pub jacobian_noise: f32,
}

impl PgFrameDesc {
    /// The render options of this description for `scene`.
    pub(crate) fn options(&self, scene: &Scene) -> Outcome<RenderOptions> {
        let mut o = RenderOptions::for_scene(scene);
        let or = |v: u32, d: u32| if v == 0 { d } else { v };
        o.width = or(self.width, o.width);
        o.height = or(self.height, o.height);
        o.spp = or(self.spp, o.spp);
        o.seed = self.seed;
        o.max_depth = match self.max_depth {
            0 => o.max_depth,
            -1 => None,
            d if d > 0 => Some(d as u32),
            d => return Err(Failure::argument(format!("desc->max_depth is {d}: 0 (the scene's), -1 or positive"))),
        };
        o.sampling = match (self.attached, self.jacobian_noise) {
            (0, a) if a != 0.0 => {
                return Err(Failure::argument(format!("desc->jacobian_noise is {a}: it applies only with attached")));
            }
            (0, _) => Sampling::Detached,
            (_, noise) => Sampling::Attached { noise },
        };
        Ok(o)
    }
}

impl PgScene {
    pub(crate) fn new(scene: Scene) -> PgScene {
        let names = scene.params.entries().iter().map(|e| CString::new(e.name.replace('\0', " ")).unwrap_or_default());
        PgScene { names: names.collect(), scene }
    }
}

/// The parameter `name` of `scene`.
pub(crate) fn find(scene: &Scene, name: &str) -> Outcome<ParamId> {
    scene.params.find(name).ok_or_else(|| {
        Failure::argument(format!("no parameter '{name}' in the scene ({} parameters)", scene.params.entries().len()))
    })
}

/// Copies the values of `name` into `out` (exactly as many as it has).
pub(crate) fn get_param(scene: &Scene, name: &str, out: *mut f32, count: usize) -> Outcome {
    let values = scene.params.get(find(scene, name)?);
    // SAFETY: the caller's guarantee (`count` writable floats).
    unsafe { out_slice(out, count, values.len(), "values") }?.copy_from_slice(values);
    Ok(())
}

/// Loads a scene: a Mitsuba XML file, a glTF file (`.gltf`, `.glb`) or `builtin:NAME`
/// (`builtin:cornell-box`). `define_names[i]`/`define_values[i]`, `define_count` of them, override
/// an XML scene's `<default>` values (null arrays with a count of 0: none).
///
/// # Safety
/// `spec` is a NUL-terminated string; the arrays hold `define_count` NUL-terminated strings each;
/// `out` is a valid place for the handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pg_scene_load(
    spec: *const c_char,
    define_names: *const *const c_char,
    define_values: *const *const c_char,
    define_count: usize,
    out: *mut *mut PgScene,
) -> PgStatus {
    guard("pg_scene_load", || {
        // SAFETY: the caller's guarantees.
        let out = unsafe { arg_mut(out, "out") }?;
        *out = std::ptr::null_mut();
        // SAFETY: the caller's guarantees.
        let spec = unsafe { string(spec, "spec") }?;
        // SAFETY: the caller's guarantees.
        let (names, values) = unsafe {
            (slice(define_names, define_count, "define_names")?, slice(define_values, define_count, "define_values")?)
        };
        let mut defines = Vec::with_capacity(define_count);
        for (&n, &v) in names.iter().zip(values) {
            // SAFETY: the caller's guarantees.
            let (n, v) = unsafe { (string(n, "define_names[i]")?, string(v, "define_values[i]")?) };
            defines.push((n.to_string(), v.to_string()));
        }
        let scene = pathgrad::scene::load(spec, &defines)?;
        *out = Box::into_raw(Box::new(PgScene::new(scene)));
        Ok(())
    })
}

/// The number of parameters (0 for a null scene).
///
/// # Safety
/// `scene` is null or a live scene.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pg_scene_param_count(scene: *const PgScene) -> usize {
    // SAFETY: the caller's guarantee.
    unsafe { scene.as_ref() }.map_or(0, |s| s.names.len())
}

/// The name of parameter `index` (valid as long as the scene), or null past the end.
///
/// # Safety
/// `scene` is null or a live scene.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pg_scene_param_name(scene: *const PgScene, index: usize) -> *const c_char {
    // SAFETY: the caller's guarantee.
    unsafe { scene.as_ref() }.and_then(|s| s.names.get(index)).map_or(std::ptr::null(), |n| n.as_ptr())
}

/// The number of values of all parameters together: the length of the flat value array, of a
/// gradient read by `pg_frame_read_gradients`, and of
/// the parameter and gradient buffers in floats (0 for a null scene).
///
/// # Safety
/// `scene` is null or a live scene.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pg_scene_value_count(scene: *const PgScene) -> usize {
    // SAFETY: the caller's guarantee.
    unsafe { scene.as_ref() }.map_or(0, |s| s.scene.params.values().len())
}

/// Where the values of parameter `name` lie, and their bounds.
///
/// # Safety
/// `scene` is null or a live scene; `name` a NUL-terminated string; `out` valid for writing.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pg_scene_param_info(
    scene: *const PgScene,
    name: *const c_char,
    out: *mut PgParamInfo,
) -> PgStatus {
    guard("pg_scene_param_info", || {
        // SAFETY: the caller's guarantees.
        let (scene, name, out) = unsafe { (arg(scene, "scene")?, string(name, "name")?, arg_mut(out, "out")?) };
        let entry = scene.scene.params.entry(find(&scene.scene, name)?);
        *out = PgParamInfo {
            offset: entry.offset as usize,
            count: entry.len as usize,
            lower: entry.bounds.0,
            upper: entry.bounds.1,
        };
        Ok(())
    })
}

/// Copies the values of parameter `name` into `values`, which holds `count` floats: exactly the
/// parameter's number of values.
///
/// # Safety
/// `scene` is null or a live scene; `name` a NUL-terminated string; `values` null or `count`
/// writable floats.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pg_scene_get_param(
    scene: *const PgScene,
    name: *const c_char,
    values: *mut f32,
    count: usize,
) -> PgStatus {
    guard("pg_scene_get_param", || {
        // SAFETY: the caller's guarantees.
        let (scene, name) = unsafe { (arg(scene, "scene")?, string(name, "name")?) };
        get_param(&scene.scene, name, values, count)
    })
}

/// Sets the values of parameter `name` in the scene (not in renderers already made from it:
/// `pg_renderer_set_param`). `count` must be the
/// parameter's number of values; each must lie within its bounds.
///
/// # Safety
/// `scene` is null or a live scene not used by another thread during the call; `name` a
/// NUL-terminated string; `values` null or `count` floats.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pg_scene_set_param(
    scene: *mut PgScene,
    name: *const c_char,
    values: *const f32,
    count: usize,
) -> PgStatus {
    guard("pg_scene_set_param", || {
        // SAFETY: the caller's guarantees.
        let (scene, name, values) =
            unsafe { (arg_mut(scene, "scene")?, string(name, "name")?, slice(values, count, "values")?) };
        find(&scene.scene, name)?;
        scene.scene.params.set(name, values)?;
        Ok(())
    })
}

/// Renders the scene on pathgrad's CPU reference (no device; slow: for checks at small sizes)
/// into `rgb`: `count` = width × height × 3 floats, row-major from the top-left. `desc` may be
/// null (the scene's defaults).
///
/// # Safety
/// `scene` is null or a live scene; `desc` null or valid; `rgb` null or `count` writable floats.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pg_scene_render_cpu(
    scene: *const PgScene,
    desc: *const PgFrameDesc,
    rgb: *mut f32,
    count: usize,
) -> PgStatus {
    guard("pg_scene_render_cpu", || {
        // SAFETY: the caller's guarantees.
        let scene = unsafe { arg(scene, "scene") }?;
        // SAFETY: the caller's guarantees.
        let options = unsafe { desc.as_ref() }.copied().unwrap_or_default().options(&scene.scene)?;
        let wanted = options.width as usize * options.height as usize * 3;
        // SAFETY: the caller's guarantees.
        let out = unsafe { out_slice(rgb, count, wanted, "rgb") }?;
        let image = pathgrad::cpu::render(&scene.scene, &options)?;
        out.copy_from_slice(image.as_slice());
        Ok(())
    })
}

/// Destroys a scene (null: nothing). Renderers made from it keep their copy.
///
/// # Safety
/// `scene` is null or a live scene, not used again.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn pg_scene_destroy(scene: *mut PgScene) {
    if !scene.is_null() {
        let _ = guard("pg_scene_destroy", || {
            // SAFETY: made by `Box::into_raw`, not used again (the caller's guarantee).
            drop(unsafe { Box::from_raw(scene) });
            Ok(())
        });
    }
}
