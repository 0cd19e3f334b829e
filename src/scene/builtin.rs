//! Built-in named scenes (`builtin:NAME`): the Cornell box with a rough conductor sphere, the white
//! furnace, and a diffuse+GGX blend object.

use glam::Vec3;

use crate::bsdf::Distribution;
use crate::error::{Error, Result};
use crate::scene::shapes::{cuboid, quad, sphere};
use crate::scene::{Camera, Scene};

/// The names `builtin:NAME` accepts, with a line on each.
pub const BUILTIN_SCENES: &[(&str, &str)] = &[
    ("cornell-box", "diffuse walls, an area light and a rough Beckmann conductor sphere"),
    ("furnace", "albedo-1 diffuse objects inside a black box emitting radiance 1: every pixel's expected value is 1"),
    ("blend", "a diffuse+GGX blend sphere on a diffuse plane under an area light"),
];

/// Builds the built-in scene `name` (without the `builtin:` prefix).
///
/// # Errors
/// [`Error::Scene`] for an unknown name, listing the known ones.
///
/// ```
/// let scene = pathgrad::scene::builtin::load("cornell-box").unwrap();
/// assert!(scene.params.find("sphere.bsdf.alpha.value").is_some());
/// ```
pub fn load(name: &str) -> Result<Scene> {
    match name {
        "cornell-box" => cornell_box(),
        "furnace" => furnace(),
        "blend" => blend(),
        _ => Err(Error::Scene {
            location: format!("builtin:{name}"),
            message: format!(
                "unknown built-in scene (known: {})",
                BUILTIN_SCENES.iter().map(|(n, _)| *n).collect::<Vec<_>>().join(", ")
            ),
        }),
    }
}

/// Mitsuba's default conductor (no `material`): eta = 0, k = 1, for which Fresnel is exactly 1.
const PERFECT_ETA: Vec3 = Vec3::ZERO;
const PERFECT_K: Vec3 = Vec3::ONE;

fn cornell_box() -> Result<Scene> {
    let camera = Camera {
        position: Vec3::new(0.0, 0.0, 3.9),
        target: Vec3::ZERO,
        up: Vec3::Y,
        fov_y_degrees: 38.0,
        width: 256,
        height: 256,
        filter: crate::scene::PixelFilter::Box,
        lens: crate::scene::Lens::Pinhole,
        window: crate::scene::FilmWindow::default(),
    };
    let mut s = Scene::new("builtin:cornell-box", camera);
    let white = s.add_diffuse("white", Vec3::new(0.725, 0.71, 0.68))?;
    let red = s.add_diffuse("red", Vec3::new(0.63, 0.065, 0.05))?;
    let green = s.add_diffuse("green", Vec3::new(0.14, 0.45, 0.091))?;
    // The light's and the sphere's materials are named as scenes/cornell-box/cornell-box.xml (and Mitsuba)
    // name an unnamed BSDF nested in a shape: `SHAPE.bsdf`. One scene, one set of names.
    let black = s.add_diffuse("light.bsdf", Vec3::ZERO)?;
    let metal = s.add_rough_conductor("sphere.bsdf", Distribution::Beckmann, 0.2, Vec3::ONE, PERFECT_ETA, PERFECT_K)?;
    // The box spans [-1, 1]³ without its front wall; every wall faces inwards.
    s.add_mesh("floor", quad(Vec3::new(0.0, -1.0, 0.0), Vec3::Z, Vec3::X), white, None)?;
    s.add_mesh("ceiling", quad(Vec3::new(0.0, 1.0, 0.0), Vec3::X, Vec3::Z), white, None)?;
    s.add_mesh("back", quad(Vec3::new(0.0, 0.0, -1.0), Vec3::X, Vec3::Y), white, None)?;
    s.add_mesh("left", quad(Vec3::new(-1.0, 0.0, 0.0), Vec3::Y, Vec3::Z), red, None)?;
    s.add_mesh("right", quad(Vec3::new(1.0, 0.0, 0.0), Vec3::Z, Vec3::Y), green, None)?;
    s.add_mesh(
        "light",
        quad(Vec3::new(0.0, 0.995, 0.0), Vec3::X * 0.25, Vec3::Z * 0.2),
        black,
        Some(Vec3::new(17.0, 12.0, 4.0)),
    )?;
    s.add_mesh("sphere", sphere(Vec3::new(0.35, -0.55, 0.1), 0.45, 48, 96, false), metal, None)?;
    s.add_mesh("block", cuboid(Vec3::new(-0.4, -0.4, -0.35), Vec3::new(0.3, 0.6, 0.3)), white, None)?;
    Ok(s)
}

/// Radiance of the furnace's walls; the expected value of every pixel.
pub const FURNACE_RADIANCE: f32 = 1.0;

fn furnace() -> Result<Scene> {
    let camera = Camera {
        position: Vec3::new(0.0, 0.0, 3.0),
        target: Vec3::ZERO,
        up: Vec3::Y,
        fov_y_degrees: 40.0,
        width: 64,
        height: 64,
        filter: crate::scene::PixelFilter::Box,
        lens: crate::scene::Lens::Pinhole,
        window: crate::scene::FilmWindow::default(),
    };
    let mut s = Scene::new("builtin:furnace", camera);
    let white = s.add_diffuse("object", Vec3::ONE)?;
    let black = s.add_diffuse("walls", Vec3::ZERO)?;
    // Inward-facing walls emit everywhere; the objects reflect everything they receive, so with
    // unbounded depth the radiance leaving any point is exactly FURNACE_RADIANCE. The sphere and
    // the box see each other, so paths bounce between them (the test covers multiple bounces).
    let walls = cuboid(Vec3::ZERO, Vec3::splat(4.0));
    let inward = crate::scene::shapes::Geometry {
        normals: walls.normals.map(|n| n.into_iter().map(|v| -v).collect()),
        indices: walls.indices.iter().map(|t| [t[0], t[2], t[1]]).collect(),
        ..walls
    };
    s.add_mesh("walls", inward, black, Some(Vec3::splat(FURNACE_RADIANCE)))?;
    // Flat-shaded: interpolated normals would make the albedo-1 surface lose a little energy to
    // directions inside the shading hemisphere but below the geometric one (measured ~3e-4).
    let ball =
        crate::scene::shapes::Geometry { normals: None, ..sphere(Vec3::new(-0.7, 0.0, 0.0), 0.8, 32, 64, false) };
    s.add_mesh("sphere", ball, white, None)?;
    s.add_mesh("box", cuboid(Vec3::new(0.75, -0.2, 0.2), Vec3::new(0.5, 0.8, 0.5)), white, None)?;
    s.max_depth = 64;
    Ok(s)
}

fn blend() -> Result<Scene> {
    let camera = Camera {
        position: Vec3::new(0.0, 1.2, 3.6),
        target: Vec3::new(0.0, 0.1, 0.0),
        up: Vec3::Y,
        fov_y_degrees: 35.0,
        width: 256,
        height: 192,
        filter: crate::scene::PixelFilter::Box,
        lens: crate::scene::Lens::Pinhole,
        window: crate::scene::FilmWindow::default(),
    };
    let mut s = Scene::new("builtin:blend", camera);
    let floor = s.add_diffuse("floor", Vec3::new(0.5, 0.5, 0.5))?;
    let base = s.add_diffuse("base", Vec3::new(0.1, 0.6, 0.35))?;
    let coat = s.add_rough_conductor("coat", Distribution::Ggx, 0.08, Vec3::ONE, PERFECT_ETA, PERFECT_K)?;
    let object = s.add_blend("object", 0.5, [base, coat])?;
    // The light's and the sphere's materials are named as scenes/cornell-box/cornell-box.xml (and Mitsuba)
    // name an unnamed BSDF nested in a shape: `SHAPE.bsdf`. One scene, one set of names.
    let black = s.add_diffuse("light.bsdf", Vec3::ZERO)?;
    s.add_mesh("floor", quad(Vec3::new(0.0, -0.5, 0.0), Vec3::Z * 3.0, Vec3::X * 3.0), floor, None)?;
    s.add_mesh("object", sphere(Vec3::new(0.0, 0.1, 0.0), 0.6, 48, 96, false), object, None)?;
    s.add_mesh("light", quad(Vec3::new(-0.8, 2.4, 0.6), Vec3::X * 0.6, Vec3::Z * 0.6), black, Some(Vec3::splat(8.0)))?;
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_builtin_is_valid() {
        for (name, _) in BUILTIN_SCENES {
            load(name).unwrap().validate().unwrap_or_else(|e| panic!("{name}: {e}"));
        }
        assert!(load("nope").unwrap_err().to_string().contains("cornell-box"));
    }
}
