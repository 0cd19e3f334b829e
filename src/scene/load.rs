//! Loading a scene by name: `LoadOptions` (defines, the rendered size, where files may be read), the folder rule, image decoding.

use std::path::{Component, Path, PathBuf};
use std::time::Instant;

use super::{Scene, builtin, gltf, mesh_io, mitsuba};
use crate::error::{Error, Result};
use crate::phases::{Memory, Phase, PhaseReport};

/// How [`load_with`] reads a scene.
///
/// # Example
///
/// ```
/// use pathgrad::scene::{LoadOptions, load_with};
///
/// // The Cornell box XML, tessellated and sized for a 64-pixel-wide render.
/// let path = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/cornell-box/cornell-box.xml");
/// let scene = load_with(path, &LoadOptions { width: Some(64), ..LoadOptions::default() })?;
/// assert_eq!((scene.camera.width, scene.camera.height), (64, 64));
/// # Ok::<(), pathgrad::error::Error>(())
/// ```
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LoadOptions {
    /// Overrides of a Mitsuba XML scene's `<default>` values (`-D name=value`).
    pub defines: Vec<(String, String)>,
    /// The image width to render, if not the scene's own. The scene's camera takes this size
    /// (with only a width, the height follows the film's aspect ratio), and curved shapes are
    /// tessellated for the size actually rendered.
    pub width: Option<u32>,
    /// The image height to render, if not the scene's own (see `width`).
    pub height: Option<u32>,
    /// Let the scene read files outside its own folder: absolute paths, `..`, or links that lead
    /// out. Off by default, so that a scene from elsewhere can read nothing but its own files.
    pub allow_outside_folder: bool,
    /// The sensor to render, by index or name ([`Scene::sensor_index`]); the first if `None`. Its
    /// film gives the default size, and curved shapes are tessellated for it.
    pub sensor: Option<String>,
    /// A constant environment of this linear RGB radiance: it lights a scene that brings no light
    /// of its own (most glTF assets), as a differentiable parameter `env.radiance.value`; a scene
    /// with its own constant environment has that one's radiance replaced instead (with a
    /// warning; the parameter keeps its name).
    pub environment: Option<[f32; 3]>,
    /// An environment map file (EXR, Radiance HDR, or PNG and other 8-bit formats, sRGB-decoded)
    /// lighting the scene as Mitsuba's `envmap` does with its default frame and scale 1: latitude
    /// and longitude, +y up. Its texels are the parameter `env.data`. Not together with
    /// `environment`, nor on a scene that has an environment of its own.
    pub environment_map: Option<std::path::PathBuf>,
}

/// Applies [`LoadOptions::environment`] and [`LoadOptions::environment_map`] to a scene being
/// loaded, before its loader decides whether it has any light.
///
/// # Errors
/// As [`apply_environment`]; an unreadable map, both options, or a map for a scene with an
/// environment of its own.
pub(crate) fn apply_environments(scene: &mut Scene, options: &LoadOptions) -> Result<()> {
    let Some(path) = &options.environment_map else { return apply_environment(scene, options.environment) };
    let invalid =
        |message: String| Error::InvalidArgument { parameter: "LoadOptions::environment_map".into(), message };
    let bad = |message: String| Err(invalid(message));
    if options.environment.is_some() {
        return bad("give a constant environment or a map, not both".into());
    }
    if let Some(id) = scene.environment {
        return bad(format!(
            "the scene has an environment of its own ('{}'); a map from the options replaces none",
            scene.params.entry(id).name
        ));
    }
    let shown = path.display();
    if !path.is_file() {
        return bad(format!("environment map '{shown}' not found"));
    }
    let (width, height, texels) =
        read_image_linear(path, false).map_err(|m| invalid(format!("reading '{shown}': {m}")))?;
    if height < 2 {
        return bad(format!("'{shown}': an environment map needs at least 2 rows, it has {height}"));
    }
    if let Some(v) = texels.iter().find(|v| !(v.is_finite() && **v >= 0.0)) {
        return bad(format!("'{shown}': a texel has value {v} (radiance must be finite and ≥ 0)"));
    }
    let map = super::envmap::EnvMap { width, height, scale: 1.0, to_local: glam::Mat3::IDENTITY };
    scene.set_environment_map("env.data", map, &texels)
}

/// Applies [`LoadOptions::environment`] to a scene being loaded, before its loader decides
/// whether it has any light.
///
/// # Errors
/// A radiance that is negative or not finite.
pub(crate) fn apply_environment(scene: &mut Scene, environment: Option<[f32; 3]>) -> Result<()> {
    let Some(rgb) = environment else { return Ok(()) };
    if !rgb.iter().all(|v| v.is_finite() && *v >= 0.0) {
        return Err(Error::InvalidArgument {
            parameter: "LoadOptions::environment".into(),
            message: format!("the radiance {rgb:?} must be finite and ≥ 0 in every channel"),
        });
    }
    match scene.environment {
        Some(id) if scene.env_map.is_some() => Err(Error::InvalidArgument {
            parameter: "LoadOptions::environment".into(),
            message: format!(
                "the scene's own environment '{}' is a map (envmap); a constant radiance replaces only a \
                 constant environment",
                scene.params.entry(id).name
            ),
        }),
        Some(id) => {
            let name = scene.params.entry(id).name.clone();
            scene.params.set(&name, &rgb)?;
            scene.warn(format!(
                "the scene's own environment '{name}' takes the radiance {rgb:?} of LoadOptions::environment"
            ));
            Ok(())
        }
        None => scene.set_environment("env.radiance.value", glam::Vec3::from(rgb)),
    }
}

impl LoadOptions {
    /// The image size for a film of `film` pixels (width, height) under these options: with only
    /// a width, the height keeps the film's aspect ratio, rounded to the nearest pixel (at least 1).
    pub fn size_for(&self, film: (u32, u32)) -> (u32, u32) {
        match (self.width, self.height) {
            (Some(w), Some(h)) => (w, h),
            (Some(w), None) => {
                let fw = u64::from(film.0.max(1));
                (w, ((u64::from(w) * u64::from(film.1) + fw / 2) / fw).max(1) as u32)
            }
            (None, Some(h)) => (film.0, h),
            (None, None) => film,
        }
    }
}

/// Loads the scene `spec` names: `builtin:NAME` (see [`builtin::BUILTIN_SCENES`]), a Mitsuba 3
/// XML file (`.xml`, whose `<default>` values `defines` override: `-D name=value`), or a glTF 2.0
/// file (`.gltf`, `.glb`); with the default [`LoadOptions`] otherwise.
///
/// # Errors
/// As [`load_with`].
pub fn load(spec: &str, defines: &[(String, String)]) -> Result<Scene> {
    load_with(spec, &LoadOptions { defines: defines.to_vec(), ..LoadOptions::default() })
}

/// Loads the scene `spec` names (as [`load`]) with `options`.
///
/// # Errors
/// [`Error::Scene`] for an unknown built-in or extension, `defines` for a scene that is not XML,
/// a file the scene names outside its folder (unless allowed), and every loader error (with its
/// file:line:col); [`Error::Io`] for unreadable files.
pub fn load_with(spec: &str, options: &LoadOptions) -> Result<Scene> {
    let path = Path::new(spec);
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    if let Some((name, _)) = options.defines.first()
        && ext.as_deref() != Some("xml")
    {
        return Err(Error::Scene {
            location: spec.to_string(),
            message: format!(
                "-D {name}=…: only a Mitsuba XML scene has <default> values to override (see `pathgrad params` for the parameters of this one)"
            ),
        });
    }
    let mut scene = if let Some(name) = spec.strip_prefix("builtin:") {
        let mut scene = builtin::load(name)?;
        apply_environments(&mut scene, options)?;
        scene
    } else {
        match ext.as_deref() {
            Some("xml") => {
                check_scene_file(path)?;
                mitsuba::load_with(path, options)?
            }
            Some("gltf" | "glb") => {
                check_scene_file(path)?;
                gltf::load_with(path, options)?
            }
            _ => {
                if path.exists() && !path.is_file() {
                    check_scene_file(path)?;
                }
                return Err(Error::Scene {
                    location: spec.to_string(),
                    message: format!(
                        "unsupported scene format (supported: .xml (Mitsuba 3), .gltf/.glb, builtin:NAME with NAME one of {})",
                        builtin::BUILTIN_SCENES.iter().map(|(n, _)| *n).collect::<Vec<_>>().join(", ")
                    ),
                });
            }
        }
    };
    if let Some(selector) = &options.sensor {
        let chosen = scene.sensor_index(selector)?;
        scene.camera = scene.sensors[chosen].camera;
        scene.sensor = chosen;
    }
    let (width, height) = options.size_for((scene.camera.width, scene.camera.height));
    scene.camera.width = width;
    scene.camera.height = height;
    scene.validate()?;
    Ok(scene)
}

/// Loads `spec` as [`load_with`] does and records two phases in `report`:
///
/// - `parse`: reading and decoding the mesh files (OBJ, PLY, `.serialized`; a glTF file's read
///   and JSON/binary parse), summed over the scene's files, with the memory after the last one;
/// - `assemble`: the rest of the load (the scene file, shapes, materials, parameters,
///   validation), with the memory at its end.
///
/// # Errors
/// As [`load_with`]; nothing is recorded on failure.
pub fn load_reporting(spec: &str, options: &LoadOptions, report: &mut PhaseReport) -> Result<Scene> {
    let start = Instant::now();
    // A count left by an earlier, failed load on this thread is not this load's.
    mesh_io::take_decode_time();
    let loaded = load_with(spec, options);
    let total = start.elapsed().as_secs_f64();
    let (decode, decode_memory) = mesh_io::take_decode_time();
    let scene = loaded?;
    report.push(Phase { name: "parse", seconds: decode, memory: decode_memory.or_else(Memory::now) });
    report.push(Phase { name: "assemble", seconds: (total - decode).max(0.0), memory: Memory::now() });
    Ok(scene)
}

/// Says plainly when a scene path is not a readable file (a directory, a device) or is missing.
fn check_scene_file(path: &Path) -> Result<()> {
    let problem = match std::fs::metadata(path) {
        Ok(meta) if meta.is_dir() => "is a directory, not a scene file",
        Ok(meta) if !meta.is_file() => "is not a regular file (a device or pipe), not a scene file",
        Ok(_) => return Ok(()),
        Err(source) => return Err(Error::Io { path: path.to_path_buf(), source }),
    };
    Err(Error::Scene { location: path.display().to_string(), message: problem.into() })
}

/// Resolves `name`, a file a scene in folder `dir` refers to, and applies the folder rule: unless
/// `allow_outside` is set, the file must lie inside `dir` — no absolute path, no `..` that climbs
/// out, and (for a file that exists) no symbolic link leading out. Returns the path to read, or
/// the message of the refusal.
pub(crate) fn scene_file(dir: &Path, name: &str, allow_outside: bool) -> std::result::Result<PathBuf, String> {
    let dir = if dir.as_os_str().is_empty() { Path::new(".") } else { dir };
    let relative = Path::new(name);
    let path = dir.join(relative);
    if allow_outside {
        return Ok(path);
    }
    let refuse = |why: &str| {
        Err(format!(
            "'{name}' {why}: a scene reads only files inside its own folder ({}) unless reading outside is \
             allowed (LoadOptions::allow_outside_folder)",
            dir.display()
        ))
    };
    let mut depth = 0i64;
    for component in relative.components() {
        match component {
            Component::Prefix(_) | Component::RootDir => return refuse("is an absolute path"),
            Component::ParentDir => depth -= 1,
            Component::Normal(_) => depth += 1,
            Component::CurDir => {}
        }
        if depth < 0 {
            return refuse("climbs out of the scene's folder");
        }
    }
    if let (Ok(real), Ok(real_dir)) = (path.canonicalize(), dir.canonicalize())
        && !real.starts_with(&real_dir)
    {
        return refuse(&format!("leads out of the scene's folder (to {}) through a symbolic link", real.display()));
    }
    Ok(path)
}

/// Decodes an image file's bytes (PNG, JPEG, … whatever the `image` crate reads), saying how large
/// it is when it is too large to decode (the crate's own message names no size).
pub(crate) fn decode_image(bytes: &[u8]) -> std::result::Result<image::DynamicImage, String> {
    let reader = || image::ImageReader::new(std::io::Cursor::new(bytes)).with_guessed_format();
    let decoded = reader().map_err(|e| e.to_string())?.decode();
    decoded.map_err(|e| match e {
        image::ImageError::Limits(limit) => match reader().ok().and_then(|r| r.into_dimensions().ok()) {
            Some((w, h)) => format!(
                "{w}×{h} pixels ({:.0} MiB as 8-bit RGBA) is too large to decode ({limit})",
                f64::from(w) * f64::from(h) * 4.0 / (1024.0 * 1024.0)
            ),
            None => format!("too large to decode ({limit})"),
        },
        e => e.to_string(),
    })
}

/// Decodes an image into linear RGB texels, row 0 = the file's top row (Mitsuba's v = 0). PNG
/// (and any other 8- or 16-bit format the `image` crate reads) is sRGB-encoded unless `raw`; EXR
/// and Radiance HDR are linear.
pub(crate) fn read_image_linear(path: &Path, raw: bool) -> std::result::Result<(u32, u32, Vec<f32>), String> {
    let is_exr = path.extension().and_then(|e| e.to_str()).is_some_and(|e| e.eq_ignore_ascii_case("exr"));
    if is_exr {
        let image = exr::prelude::read_first_rgba_layer_from_file(
            path,
            |size, _| (size.width(), vec![0.0f32; size.width() * size.height() * 3]),
            |(width, texels): &mut (usize, Vec<f32>), pos, (r, g, b, _a): (f32, f32, f32, f32)| {
                let i = 3 * (pos.y() * *width + pos.x());
                if let Some(t) = texels.get_mut(i..i + 3) {
                    t.copy_from_slice(&[r, g, b]);
                }
            },
        )
        .map_err(|e| e.to_string())?;
        let size = image.layer_data.size;
        let (w, h) = (u32::try_from(size.width()), u32::try_from(size.height()));
        let (Ok(w), Ok(h)) = (w, h) else { return Err("image too large".into()) };
        return Ok((w, h, image.layer_data.channel_data.pixels.1));
    }
    let bytes = std::fs::read(path).map_err(|e| e.to_string())?;
    let decoded = crate::scene::load::decode_image(&bytes)?;
    let linear = matches!(decoded.color(), image::ColorType::Rgb32F | image::ColorType::Rgba32F);
    let image = decoded.to_rgb32f();
    let (w, h) = image.dimensions();
    let mut texels = image.into_raw();
    if !raw && !linear {
        for t in &mut texels {
            *t = crate::scene::gltf::srgb_to_linear(*t);
        }
    }
    Ok((w, h, texels))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_folder_rule() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir(dir.path().join("sub")).unwrap();
        std::fs::write(dir.path().join("sub/a.obj"), "").unwrap();
        let ok = |name: &str| scene_file(dir.path(), name, false);
        assert_eq!(ok("sub/a.obj").unwrap(), dir.path().join("sub/a.obj"));
        assert!(ok("sub/../sub/a.obj").is_ok(), "a '..' that stays inside is fine");
        assert!(ok("missing.obj").is_ok(), "a missing file is the reader's error to report");
        for (name, why) in
            [("/etc/passwd", "is an absolute path"), ("../x.obj", "climbs out"), ("sub/../../x.obj", "climbs out")]
        {
            let e = ok(name).unwrap_err();
            assert!(e.contains(why) && e.contains("LoadOptions::allow_outside_folder"), "{name}: {e}");
        }
        std::os::unix::fs::symlink("/etc", dir.path().join("etc")).unwrap();
        let e = ok("etc/hostname").unwrap_err();
        assert!(e.contains("symbolic link"), "{e}");
        assert_eq!(scene_file(dir.path(), "/etc/passwd", true).unwrap(), Path::new("/etc/passwd"));
    }

    #[test]
    fn an_image_too_large_to_decode_gives_its_size() {
        // A PNG declaring 100 000 × 100 000 pixels (40 GB decoded), with no data.
        let mut png = vec![0x89, b'P', b'N', b'G', 0x0D, 0x0A, 0x1A, 0x0A];
        let mut ihdr = b"IHDR".to_vec();
        ihdr.extend_from_slice(&100_000u32.to_be_bytes());
        ihdr.extend_from_slice(&100_000u32.to_be_bytes());
        ihdr.extend_from_slice(&[8, 6, 0, 0, 0]);
        png.extend_from_slice(&13u32.to_be_bytes());
        png.extend_from_slice(&ihdr);
        png.extend_from_slice(&crc32(&ihdr).to_be_bytes());
        for chunk in [&b"IDAT"[..], &b"IEND"[..]] {
            png.extend_from_slice(&0u32.to_be_bytes());
            png.extend_from_slice(chunk);
            png.extend_from_slice(&crc32(chunk).to_be_bytes());
        }
        let e = decode_image(&png).unwrap_err();
        assert!(e.contains("100000×100000 pixels") && e.contains("too large to decode"), "{e}");
    }

    /// The CRC-32 of PNG chunks (ISO 3309).
    fn crc32(bytes: &[u8]) -> u32 {
        let mut crc = !0u32;
        for &b in bytes {
            crc ^= u32::from(b);
            for _ in 0..8 {
                crc = if crc & 1 != 0 { (crc >> 1) ^ 0xEDB8_8320 } else { crc >> 1 };
            }
        }
        !crc
    }

    #[test]
    fn sizes_follow_the_film_aspect() {
        let o = |width, height| LoadOptions { width, height, ..LoadOptions::default() };
        assert_eq!(o(None, None).size_for((256, 192)), (256, 192));
        assert_eq!(o(Some(64), None).size_for((256, 192)), (64, 48));
        assert_eq!(o(None, Some(10)).size_for((256, 192)), (256, 10));
        assert_eq!(o(Some(3), Some(4)).size_for((256, 192)), (3, 4));
        assert_eq!(o(Some(1), None).size_for((256, 16)), (1, 1));
        // Rounded, not truncated: glTF's aspect 1.5 at 512 wide is 512×341; at 96 wide, 96×64.
        assert_eq!(o(Some(96), None).size_for((512, 341)), (96, 64));
    }
}
