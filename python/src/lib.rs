//! `pathgrad._pathgrad`: the native half of pathgrad's Python package — scenes, renders and
//! gradients as NumPy arrays, on a Vulkan device or the CPU reference.
//!
//! The Python package (`python/pathgrad/`) wraps these functions: it checks shapes and dtypes,
//! gives keyword arguments their defaults and builds the PyTorch bridge. Everything here takes
//! plain values: names, numbers and one-dimensional `float32` arrays. Every render and gradient
//! runs with the GIL released.

use std::path::PathBuf;
use std::sync::{Arc, Mutex, MutexGuard};

use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray1};
use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

use pathgrad::backend::Backend;
use pathgrad::gpu::renderer::GradMode;
use pathgrad::gpu::{Context, ContextDesc, DeviceChoice, Renderer};
use pathgrad::image::Image;
use pathgrad::integrator::{DEFAULT_JACOBIAN_NOISE, RenderOptions, Sampling, View};
use pathgrad::loss::Loss;
use pathgrad::params::{Gradients, ParamId};
use pathgrad::rng::PassTag;
use pathgrad::scene::{Lens, LoadOptions};

/// Parameter names with their array shapes, in the order results list them.
type Shaped = Vec<(String, Vec<usize>)>;

/// Samples per pixel when neither the call nor the scene says (the CLI's default too).
const DEFAULT_SPP: u32 = 16;

/// The Python exception for a library error: a class of `pathgrad.errors` chosen by the error's
/// kind, carrying the library's message.
fn to_py(e: pathgrad::Error) -> PyErr {
    use pathgrad::Error as E;
    let class = match &e {
        E::Scene { .. } => "SceneError",
        E::InvalidArgument { .. } => "ArgumentError",
        E::Io { .. } | E::Output { .. } | E::Image { .. } => "FileError",
        E::Numeric { .. } | E::NonFiniteGradient { .. } => "NumericError",
        _ => "DeviceError",
    };
    error_of(class, python_names(&e.to_string()))
}

/// An exception of class `class` of `pathgrad.errors` carrying `message`.
fn error_of(class: &str, message: String) -> PyErr {
    Python::attach(|py| {
        match py.import("pathgrad.errors").and_then(|m| m.getattr(class)) {
            Ok(ty) => PyErr::from_type(ty.cast_into().expect("pathgrad.errors holds exception classes"), message),
            // Only without the Python package around this module (imported on its own).
            Err(_) => PyRuntimeError::new_err(message),
        }
    })
}

/// The library's option names (`RenderOptions::spp`) in `text` spelled as this package's keyword
/// arguments (`spp`), as the command-line program spells them as its flags.
fn python_names(text: &str) -> String {
    const NAMES: &[(&str, &str)] = &[
        ("RenderOptions::width/height", "width/height"),
        ("RenderOptions::spp", "spp"),
        ("RenderOptions::max_depth", "max_depth"),
        ("GradMode::Deterministic", "deterministic"),
        ("LoadOptions::allow_outside_folder", "allow_outside_folder"),
        ("LoadOptions::environment_map", "env"),
        ("LoadOptions::environment", "env"),
        ("LoadOptions::sensor", "sensor"),
        ("View::sensor", "sensor"),
        ("DeviceChoice", "device"),
    ];
    NAMES.iter().fold(text.to_string(), |t, (library, python)| t.replace(library, python))
}

/// An `ArgumentError` naming `parameter`.
fn argument(parameter: &str, message: String) -> PyErr {
    to_py(pathgrad::Error::InvalidArgument { parameter: parameter.to_string(), message })
}

/// Where a scene renders: the CPU reference, or a Vulkan device chosen as the CLI's `--device`
/// chooses (`None`: the default device).
#[derive(Clone, Debug, PartialEq, Eq)]
enum Device {
    Reference,
    Vulkan(Option<String>),
}

impl Device {
    /// `None`, `"cpu"` or `"reference"` (the CPU reference), `"lavapipe"`, an index or a UUID.
    fn parse(device: Option<&str>) -> Device {
        match device.map(str::trim) {
            None => Device::Vulkan(None),
            Some(d) if d.eq_ignore_ascii_case("cpu") || d.eq_ignore_ascii_case("reference") => Device::Reference,
            Some(d) => Device::Vulkan(Some(d.to_string())),
        }
    }
}

/// One Vulkan context per device selector, shared by every scene of the process (renderers hold
/// their context; contexts live until the process ends).
static CONTEXTS: Mutex<Vec<(Option<String>, Arc<Context>)>> = Mutex::new(Vec::new());

fn context(selector: &Option<String>) -> pathgrad::Result<Arc<Context>> {
    let mut contexts = CONTEXTS.lock().unwrap_or_else(|p| p.into_inner());
    if let Some((_, ctx)) = contexts.iter().find(|(s, _)| s == selector) {
        return Ok(ctx.clone());
    }
    let device = selector.as_deref().map(DeviceChoice::parse).unwrap_or_default();
    let validation = std::env::var("PATHGRAD_VALIDATION").is_ok_and(|v| v == "1");
    let ctx = Context::new(&ContextDesc { device, validation })?;
    contexts.push((selector.clone(), ctx.clone()));
    Ok(ctx)
}

/// A backend opened on one device, and the parameter version it last received.
struct Opened {
    device: Device,
    backend: Box<dyn Backend + Send>,
    version: u64,
}

/// A scene's host state: the scene with the current parameter values, and its backends.
struct State {
    scene: pathgrad::scene::Scene,
    /// Bumped by every parameter change; a backend whose `version` lags is sent the values
    /// before its next render.
    version: u64,
    backends: Vec<Opened>,
}

impl State {
    /// The backend on `device`, opened on first use and holding the current parameter values.
    fn backend(&mut self, device: &Device) -> pathgrad::Result<&mut dyn Backend> {
        let index = match self.backends.iter().position(|o| &o.device == device) {
            Some(i) => i,
            None => {
                let backend: Box<dyn Backend + Send> = match device {
                    Device::Reference => Box::new(pathgrad::cpu::Reference::new(&self.scene)?),
                    Device::Vulkan(selector) => Box::new(Renderer::new(&context(selector)?, &self.scene)?),
                };
                self.backends.push(Opened { device: device.clone(), backend, version: self.version });
                self.backends.len() - 1
            }
        };
        let opened = &mut self.backends[index];
        if opened.version != self.version {
            opened.backend.set_params(&self.scene.params)?;
            opened.version = self.version;
        }
        Ok(opened.backend.as_mut())
    }

    /// What to render: the scene's size, `spp` (else the scene's, else 16), `seed`, `max_depth`
    /// (else the scene's; −1 unbounded).
    fn options(&self, spp: Option<u32>, seed: u32, max_depth: Option<i64>) -> pathgrad::Result<RenderOptions> {
        let mut o = RenderOptions::for_scene(&self.scene);
        o.spp = spp.or(self.scene.default_spp).unwrap_or(DEFAULT_SPP);
        o.seed = seed;
        o.max_depth = match max_depth {
            None => Some(self.scene.max_depth),
            Some(-1) => None,
            Some(d) if d >= 1 && d <= i64::from(u32::MAX) => Some(d as u32),
            Some(d) => {
                return Err(pathgrad::Error::InvalidArgument {
                    parameter: "max_depth".into(),
                    message: format!("{d}: must be at least 1, or -1 for unbounded"),
                });
            }
        };
        o.validate()?;
        Ok(o)
    }

    /// The parameters `wrt` names (all if `None`) that a gradient sampled as `sampling`
    /// differentiates ([`pathgrad::attached::differentiated`]: detached sampling leaves a smooth
    /// dielectric's index of refraction out of "all", and refuses it by name): their ids, and
    /// their names with shapes.
    fn chosen(&self, wrt: Option<&[String]>, sampling: Sampling) -> pathgrad::Result<(Vec<ParamId>, Shaped)> {
        let params = &self.scene.params;
        let ids: Vec<ParamId> = match wrt {
            None => (0..params.entries().len() as u32).map(ParamId).collect(),
            Some(names) => names
                .iter()
                .map(|n| {
                    params.find(n).ok_or_else(|| pathgrad::Error::InvalidArgument {
                        parameter: "wrt".into(),
                        message: format!("'{n}' is not a parameter of {}", self.scene.source),
                    })
                })
                .collect::<pathgrad::Result<Vec<_>>>()?,
        };
        let named = if wrt.is_some() { ids.clone() } else { Vec::new() };
        let ids = pathgrad::attached::differentiated(&self.scene, ids, &named, sampling)?;
        let names = ids.iter().map(|&id| (params.entry(id).name.clone(), self.scene.param_shape(id))).collect();
        Ok((ids, names))
    }

    /// `values` (flat: one `(height, width, 3)` image per view, one after another) as images of
    /// `options`' size; `what` names the argument in errors.
    fn images(options: &RenderOptions, views: usize, values: &[f32], what: &str) -> pathgrad::Result<Vec<Image>> {
        let (w, h) = (options.width, options.height);
        let per = 3 * w as usize * h as usize;
        if values.len() != per * views {
            return Err(pathgrad::Error::InvalidArgument {
                parameter: what.into(),
                message: format!(
                    "{} values for {views} sensor(s) of {w}×{h} RGB: expected {}",
                    values.len(),
                    per * views
                ),
            });
        }
        values.chunks(per).map(|c| Image::from_rgb(w, h, c.to_vec())).collect()
    }

    /// The views of sensors `sensors` (indices into the scene's sensors).
    fn views(&self, sensors: &[usize]) -> pathgrad::Result<Vec<View>> {
        if sensors.is_empty() {
            return Err(pathgrad::Error::InvalidArgument {
                parameter: "sensors".into(),
                message: "an empty list: name at least one sensor".into(),
            });
        }
        sensors
            .iter()
            .map(
                |&i| if i == self.scene.sensor { Ok(View::current(&self.scene)) } else { View::sensor(&self.scene, i) },
            )
            .collect()
    }
}

/// A loaded scene: its parameters' current values and the renderers opened on it.
///
/// Made by `pathgrad.load`; the Python class `pathgrad.Scene` wraps it.
#[pyclass(name = "Scene", module = "pathgrad._pathgrad", frozen)]
struct PyScene {
    state: Mutex<State>,
}

impl PyScene {
    fn lock(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }
}

/// The `float32` values of `array` (one-dimensional, any strides) as a vector.
fn values_of(array: &PyReadonlyArray1<'_, f32>) -> Vec<f32> {
    match array.as_slice() {
        Ok(s) => s.to_vec(),
        Err(_) => array.as_array().iter().copied().collect(),
    }
}

/// `values` as a NumPy array of `shape`, handing over the vector without a copy.
fn array<'py>(py: Python<'py>, values: Vec<f32>, shape: &[usize]) -> PyResult<Bound<'py, PyAny>> {
    let flat = PyArray1::from_vec(py, values);
    Ok(flat.reshape(shape.to_vec())?.into_any())
}

#[pymethods]
impl PyScene {
    /// Where the scene came from: the file or `builtin:NAME`.
    #[getter]
    fn source(&self) -> String {
        self.lock().scene.source.clone()
    }

    /// The size every render has: `(width, height)`.
    #[getter]
    fn size(&self) -> (u32, u32) {
        let s = &self.lock().scene;
        (s.camera.width, s.camera.height)
    }

    /// The loader's warnings (features rendered differently than the file asks, and why).
    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.lock().scene.warnings.clone()
    }

    /// The parameter names, in table order.
    fn param_names(&self) -> Vec<String> {
        self.lock().scene.params.entries().iter().map(|e| e.name.clone()).collect()
    }

    /// `(shape, (lower, upper))` of parameter `name`.
    fn param_info(&self, name: &str) -> PyResult<(Vec<usize>, (f32, f32))> {
        let state = self.lock();
        let id = find(&state.scene, name)?;
        Ok((state.scene.param_shape(id), state.scene.params.entry(id).bounds))
    }

    /// A copy of parameter `name`'s values, in its shape.
    fn get_param<'py>(&self, py: Python<'py>, name: &str) -> PyResult<Bound<'py, PyAny>> {
        let (values, shape) = {
            let state = self.lock();
            let id = find(&state.scene, name)?;
            (state.scene.params.get(id).to_vec(), state.scene.param_shape(id))
        };
        array(py, values, &shape)
    }

    /// Sets parameter `name` to `values` (flat, the parameter's length; finite, inside bounds).
    fn set_param(&self, name: &str, values: PyReadonlyArray1<'_, f32>) -> PyResult<()> {
        let values = values_of(&values);
        let mut state = self.lock();
        state.scene.params.set(name, &values).map_err(to_py)?;
        state.version += 1;
        Ok(())
    }

    /// Every sensor as a dict: index, name, position, target, up, fov_y_degrees, width, height,
    /// lens.
    fn sensors<'py>(&self, py: Python<'py>) -> PyResult<Vec<Bound<'py, PyDict>>> {
        let state = self.lock();
        let mut out = Vec::new();
        for (i, s) in state.scene.sensors.iter().enumerate() {
            let c = &s.camera;
            let d = PyDict::new(py);
            d.set_item("index", i)?;
            d.set_item("name", &s.name)?;
            d.set_item("position", c.position.to_array())?;
            d.set_item("target", c.target.to_array())?;
            d.set_item("up", c.up.to_array())?;
            d.set_item("fov_y_degrees", c.fov_y_degrees)?;
            d.set_item("width", c.width)?;
            d.set_item("height", c.height)?;
            let lens = match c.lens {
                Lens::Pinhole => "pinhole",
                Lens::Thin { .. } => "thinlens",
                Lens::Orthographic { .. } => "orthographic",
            };
            d.set_item("lens", lens)?;
            out.push(d);
        }
        Ok(out)
    }

    /// The sensor `selector` names (an index as text, or a name) as an index.
    fn sensor_index(&self, selector: &str) -> PyResult<usize> {
        self.lock().scene.sensor_index(selector).map_err(to_py)
    }

    /// How many backends are open on the scene (tests: a renderer is opened once per device).
    fn open_backends(&self) -> usize {
        self.lock().backends.len()
    }
}

fn find(scene: &pathgrad::scene::Scene, name: &str) -> PyResult<pathgrad::params::ParamId> {
    scene.params.find(name).ok_or_else(|| {
        let known: Vec<&str> = scene.params.entries().iter().map(|e| e.name.as_str()).collect();
        let shown = if known.len() > 12 { format!("{}, …", known[..12].join(", ")) } else { known.join(", ") };
        error_of(
            "UnknownParameterError",
            format!("invalid parameter name: '{name}' is not a parameter of {} (parameters: {shown})", scene.source),
        )
    })
}

/// Loads a scene: a Mitsuba XML or glTF file, or `builtin:NAME`.
#[pyfunction]
#[pyo3(signature = (spec, defines, width=None, height=None, sensor=None, env=None, env_map=None, allow_outside_folder=false))]
#[allow(clippy::too_many_arguments)]
fn load(
    py: Python<'_>,
    spec: String,
    defines: Vec<(String, String)>,
    width: Option<u32>,
    height: Option<u32>,
    sensor: Option<String>,
    env: Option<[f32; 3]>,
    env_map: Option<PathBuf>,
    allow_outside_folder: bool,
) -> PyResult<PyScene> {
    let options = LoadOptions {
        defines,
        width,
        height,
        allow_outside_folder,
        sensor,
        environment: env,
        environment_map: env_map,
    };
    let scene = py.detach(|| pathgrad::scene::load_with(&spec, &options)).map_err(to_py)?;
    Ok(PyScene { state: Mutex::new(State { scene, version: 0, backends: Vec::new() }) })
}

/// Renders `sensors` of `scene` on `device`: an array of shape `(len(sensors), height, width, 3)`.
#[pyfunction]
#[pyo3(signature = (scene, sensors, spp=None, seed=0, device=None, max_depth=None))]
fn render<'py>(
    py: Python<'py>,
    scene: &PyScene,
    sensors: Vec<usize>,
    spp: Option<u32>,
    seed: u32,
    device: Option<String>,
    max_depth: Option<i64>,
) -> PyResult<Bound<'py, PyAny>> {
    let device = Device::parse(device.as_deref());
    let images = py
        .detach(|| -> pathgrad::Result<Vec<Image>> {
            let mut state = scene.lock();
            let options = state.options(spp, seed, max_depth)?;
            let views = state.views(&sensors)?;
            state.backend(&device)?.render_views(&options, &views, PassTag::Primal, &mut |_, _| {})
        })
        .map_err(to_py)?;
    stacked(py, images)
}

/// `images` (one size) as one array of shape `(count, height, width, 3)`.
fn stacked(py: Python<'_>, images: Vec<Image>) -> PyResult<Bound<'_, PyAny>> {
    let (w, h) = (images[0].width() as usize, images[0].height() as usize);
    let count = images.len();
    let values = if count == 1 {
        images.into_iter().next().expect("one image").into_rgb()
    } else {
        images.iter().flat_map(|i| i.as_slice().iter().copied()).collect()
    };
    array(py, values, &[count, h, w, 3])
}

/// The reverse-mode gradient of Σ ⟨adjoint_v, image_v⟩ over `sensors`: `adjoint` is flat, the
/// sensors' `(height, width, 3)` images one after another. Returns `{name: array}` for the
/// parameters `wrt` (all if `None`).
#[pyfunction]
#[pyo3(signature = (scene, adjoint, sensors, wrt=None, spp=None, seed=0, device=None, max_depth=None, deterministic=false, sampling="detached", jacobian_noise=None))]
#[allow(clippy::too_many_arguments)]
fn backward<'py>(
    py: Python<'py>,
    scene: &PyScene,
    adjoint: PyReadonlyArray1<'_, f32>,
    sensors: Vec<usize>,
    wrt: Option<Vec<String>>,
    spp: Option<u32>,
    seed: u32,
    device: Option<String>,
    max_depth: Option<i64>,
    deterministic: bool,
    sampling: &str,
    jacobian_noise: Option<f32>,
) -> PyResult<Bound<'py, PyDict>> {
    let adjoint = values_of(&adjoint);
    let device = Device::parse(device.as_deref());
    let mode = if deterministic { GradMode::Deterministic } else { GradMode::Float };
    let sampling = sampling_of(sampling, jacobian_noise)?;
    let (gradients, names) = py
        .detach(|| -> pathgrad::Result<(Gradients, Shaped)> {
            let mut state = scene.lock();
            let mut options = state.options(spp, seed, max_depth)?;
            let views = state.views(&sensors)?;
            let adjoints = State::images(&options, views.len(), &adjoint, "adjoint")?;
            options.sampling = sampling;
            options.validate()?;
            let (ids, names) = state.chosen(wrt.as_deref(), sampling)?;
            let backend = state.backend(&device)?;
            options.differentiate = backend.param_kinds(&ids);
            Ok((backend.backward_views(&options, &views, &adjoints, mode)?, names))
        })
        .map_err(to_py)?;
    gradient_dict(py, &gradients, names)
}

/// `sampling` (`detached` or `attached`) and `jacobian_noise` (attached only) as the library's
/// [`Sampling`], as the program's `--sampling` and `--jacobian-noise`.
fn sampling_of(sampling: &str, jacobian_noise: Option<f32>) -> PyResult<Sampling> {
    match (sampling, jacobian_noise) {
        ("detached", None) => Ok(Sampling::Detached),
        ("detached", Some(a)) => Err(argument("jacobian_noise", format!("{a} applies only to sampling=\"attached\""))),
        ("attached", a) => Ok(Sampling::Attached { noise: a.unwrap_or(DEFAULT_JACOBIAN_NOISE) }),
        (other, _) => Err(argument("sampling", format!("'{other}': expected detached or attached"))),
    }
}

/// `{name: array of its shape}` for `names` out of `gradients`.
fn gradient_dict<'py>(py: Python<'py>, gradients: &Gradients, names: Shaped) -> PyResult<Bound<'py, PyDict>> {
    let out = PyDict::new(py);
    for (name, shape) in names {
        let values = gradients.get(&name).expect("the gradients have the table's layout").to_vec();
        out.set_item(&name, array(py, values, &shape)?)?;
    }
    Ok(out)
}

/// A gradient step's loss and gradient, as `pathgrad grad` takes it: pass 1 renders `sensors`
/// at `spp`, the loss `loss` (`l1`, `l2`, `relmse`, `relmse_max`) against `targets` (flat, one
/// image per sensor) is averaged over the sensors, and one gradient pass differentiates it.
/// Returns `(loss, {name: array})` for the parameters `wrt` (all if `None`).
#[pyfunction]
#[pyo3(signature = (scene, targets, sensors, loss="relmse", wrt=None, spp=None, seed=0, device=None, max_depth=None, deterministic=false, sampling="detached", jacobian_noise=None))]
#[allow(clippy::too_many_arguments)]
fn loss_and_gradient<'py>(
    py: Python<'py>,
    scene: &PyScene,
    targets: PyReadonlyArray1<'_, f32>,
    sensors: Vec<usize>,
    loss: &str,
    wrt: Option<Vec<String>>,
    spp: Option<u32>,
    seed: u32,
    device: Option<String>,
    max_depth: Option<i64>,
    deterministic: bool,
    sampling: &str,
    jacobian_noise: Option<f32>,
) -> PyResult<(f64, Bound<'py, PyDict>)> {
    let loss = match loss {
        "l1" => Loss::L1,
        "l2" => Loss::L2,
        "relmse" => Loss::RelMse,
        "relmse_max" => Loss::RelMseMax,
        other => return Err(argument("loss", format!("'{other}': expected l1, l2, relmse or relmse_max"))),
    };
    let targets = values_of(&targets);
    let device = Device::parse(device.as_deref());
    let mode = if deterministic { GradMode::Deterministic } else { GradMode::Float };
    let sampling = sampling_of(sampling, jacobian_noise)?;
    let (value, gradients, names) = py
        .detach(|| -> pathgrad::Result<(f64, Gradients, Shaped)> {
            let mut state = scene.lock();
            let mut options = state.options(spp, seed, max_depth)?;
            let views = state.views(&sensors)?;
            let targets = State::images(&options, views.len(), &targets, "targets")?;
            options.sampling = sampling;
            options.validate()?;
            let (ids, names) = state.chosen(wrt.as_deref(), sampling)?;
            let backend = state.backend(&device)?;
            options.differentiate = backend.param_kinds(&ids);
            let (value, gradients) =
                backend.loss_and_gradient_views(&options, options.spp, &views, &targets, loss, mode)?;
            Ok((value, gradients, names))
        })
        .map_err(to_py)?;
    Ok((value, gradient_dict(py, &gradients, names)?))
}

/// The forward-mode image gradient ∂image/∂`name` of the scene's sensor: `(height, width, 3)`;
/// `sampling` and `jacobian_noise` as `grad`'s.
#[pyfunction]
#[pyo3(signature = (scene, name, spp=None, seed=0, device=None, max_depth=None, sampling="detached", jacobian_noise=None))]
#[allow(clippy::too_many_arguments)]
fn image_gradient<'py>(
    py: Python<'py>,
    scene: &PyScene,
    name: String,
    spp: Option<u32>,
    seed: u32,
    device: Option<String>,
    max_depth: Option<i64>,
    sampling: &str,
    jacobian_noise: Option<f32>,
) -> PyResult<Bound<'py, PyAny>> {
    let device = Device::parse(device.as_deref());
    let sampling = sampling_of(sampling, jacobian_noise)?;
    let image = py
        .detach(|| -> pathgrad::Result<Image> {
            let mut state = scene.lock();
            let mut options = state.options(spp, seed, max_depth)?;
            options.sampling = sampling;
            state.backend(&device)?.image_gradient(&options, &name)
        })
        .map_err(to_py)?;
    stacked(py, vec![image])
}

/// Reads an EXR image: `(height, width, 3)` `float32`.
#[pyfunction]
fn read_image<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyAny>> {
    let image = py.detach(|| Image::read_exr(&path)).map_err(to_py)?;
    let (w, h) = (image.width() as usize, image.height() as usize);
    array(py, image.into_rgb(), &[h, w, 3])
}

/// Writes `values` (flat, `height × width × 3`) as an EXR (HDR) or PNG (sRGB, clamped) file.
#[pyfunction]
fn write_image(
    py: Python<'_>,
    path: PathBuf,
    width: u32,
    height: u32,
    values: PyReadonlyArray1<'_, f32>,
) -> PyResult<()> {
    let image = Image::from_rgb(width, height, values_of(&values)).map_err(to_py)?;
    py.detach(|| image.save(&path)).map_err(to_py)
}

/// The Vulkan devices: `(index, name, driver, missing features)` each.
#[pyfunction]
fn devices(py: Python<'_>) -> PyResult<Vec<Bound<'_, PyTuple>>> {
    let list = py.detach(pathgrad::gpu::list_devices).map_err(to_py)?;
    list.into_iter()
        .map(|d| {
            PyTuple::new(
                py,
                [
                    d.index.into_pyobject(py)?.into_any(),
                    d.name.into_pyobject(py)?.into_any(),
                    d.driver.into_pyobject(py)?.into_any(),
                    d.missing.into_pyobject(py)?.into_any(),
                ],
            )
        })
        .collect()
}

/// The variables the package sets before any Vulkan call (`pathgrad::gpu::lavapipe_environment`:
/// lavapipe's vector width and Mesa's shader cache folder), as (name, value) pairs.
#[pyfunction]
fn lavapipe_environment() -> Vec<(&'static str, String)> {
    pathgrad::gpu::lavapipe_environment()
}

#[pymodule]
fn _pathgrad(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyScene>()?;
    m.add_function(wrap_pyfunction!(load, m)?)?;
    m.add_function(wrap_pyfunction!(render, m)?)?;
    m.add_function(wrap_pyfunction!(backward, m)?)?;
    m.add_function(wrap_pyfunction!(image_gradient, m)?)?;
    m.add_function(wrap_pyfunction!(loss_and_gradient, m)?)?;
    m.add_function(wrap_pyfunction!(read_image, m)?)?;
    m.add_function(wrap_pyfunction!(write_image, m)?)?;
    m.add_function(wrap_pyfunction!(devices, m)?)?;
    m.add_function(wrap_pyfunction!(lavapipe_environment, m)?)?;
    Ok(())
}
