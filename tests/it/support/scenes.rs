//! Scenes built for tests: variants that exercise what the built-in scenes do not.

use glam::Vec3;
use pathgrad::bsdf::Distribution;
use pathgrad::scene::builtin::FURNACE_RADIANCE;
use pathgrad::scene::shapes::{Geometry, cuboid, quad, sphere};
use pathgrad::scene::{Albedo, Camera, Material, PixelFilter, Scene};

/// The furnace with its ceiling removed and a constant environment of the same radiance: paths
/// reach emitted radiance 1 through both next-event techniques (area and environment). Inside: an
/// albedo-1 sphere, a textured albedo-1 box and a two-sided albedo-1 quad seen from its back.
pub fn open_furnace() -> Scene {
    let camera = Camera {
        position: Vec3::new(0.0, 0.5, 3.0),
        target: Vec3::ZERO,
        up: Vec3::Y,
        fov_y_degrees: 45.0,
        width: 48,
        height: 48,
        filter: PixelFilter::Box,
        lens: pathgrad::scene::Lens::Pinhole,
        window: pathgrad::scene::FilmWindow::default(),
    };
    let mut s = Scene::new("test:open-furnace", camera);
    let white = s.add_diffuse("object", Vec3::ONE).unwrap();
    let black = s.add_diffuse("walls", Vec3::ZERO).unwrap();
    let texture = s.add_texture("box.reflectance.data", 2, 2, &[1.0; 12]).unwrap();
    let textured = s.add_material(Material::Diffuse { albedo: Albedo::Bitmap(texture) });
    let two_sided = s.add_material(Material::TwoSided(white));
    let walls = cuboid(Vec3::ZERO, Vec3::splat(4.0));
    // Drop the +y face (the third quad of `cuboid`: triangles 4 and 5) and turn the rest inwards.
    let indices: Vec<[u32; 3]> =
        walls.indices.iter().enumerate().filter(|(i, _)| *i / 2 != 2).map(|(_, t)| [t[0], t[2], t[1]]).collect();
    let inward = Geometry { normals: walls.normals.map(|n| n.into_iter().map(|v| -v).collect()), indices, ..walls };
    s.add_mesh("walls", inward, black, Some(Vec3::splat(FURNACE_RADIANCE))).unwrap();
    s.set_environment("environment.radiance.value", Vec3::splat(FURNACE_RADIANCE)).unwrap();
    let ball = Geometry { normals: None, ..sphere(Vec3::new(-0.8, 0.0, 0.0), 0.6, 24, 48, false) };
    s.add_mesh("sphere", ball, white, None).unwrap();
    s.add_mesh("box", cuboid(Vec3::new(0.8, -0.3, 0.0), Vec3::splat(0.4)), textured, None).unwrap();
    // Faces away from the camera (normal −z): only its back is seen.
    s.add_mesh("card", quad(Vec3::new(0.0, 0.3, 1.0), Vec3::Y * 0.3, Vec3::X * 0.3), two_sided, None).unwrap();
    s.max_depth = 64;
    s
}

/// A checker-textured two-sided floor, a GGX sphere and an area light under a coloured environment:
/// every feature of the path loop with non-trivial values, for the GPU-vs-CPU comparison.
pub fn textured_environment() -> Scene {
    let camera = Camera {
        position: Vec3::new(0.0, 1.0, 3.0),
        target: Vec3::ZERO,
        up: Vec3::Y,
        fov_y_degrees: 40.0,
        width: 64,
        height: 48,
        filter: PixelFilter::Box,
        lens: pathgrad::scene::Lens::Pinhole,
        window: pathgrad::scene::FilmWindow::default(),
    };
    let mut s = Scene::new("test:textured-environment", camera);
    let mut texels = Vec::new();
    for y in 0..4 {
        for x in 0..4 {
            let c = if (x + y) % 2 == 0 { [0.8, 0.7, 0.2] } else { [0.1, 0.2, 0.6] };
            texels.extend_from_slice(&c);
        }
    }
    let texture = s.add_texture("floor.reflectance.data", 4, 4, &texels).unwrap();
    let floor = s.add_material(Material::Diffuse { albedo: Albedo::Bitmap(texture) });
    let floor = s.add_material(Material::TwoSided(floor));
    let metal = s
        .add_rough_conductor("ball", Distribution::Ggx, 0.15, Vec3::new(0.9, 0.6, 0.4), Vec3::ZERO, Vec3::ONE)
        .unwrap();
    let black = s.add_diffuse("light", Vec3::ZERO).unwrap();
    s.add_mesh("floor", quad(Vec3::new(0.0, -0.5, 0.0), Vec3::Z * 2.0, Vec3::X * 2.0), floor, None).unwrap();
    s.add_mesh("ball", sphere(Vec3::new(0.0, 0.1, 0.0), 0.5, 24, 48, false), metal, None).unwrap();
    s.add_mesh(
        "light",
        quad(Vec3::new(0.5, 1.5, 0.5), Vec3::X * 0.3, Vec3::Z * 0.3),
        black,
        Some(Vec3::new(6.0, 5.0, 4.0)),
    )
    .unwrap();
    s.set_environment("environment.radiance.value", Vec3::new(0.3, 0.4, 0.6)).unwrap();
    s
}

/// A frosted (rough dielectric, GGX α 0.2) pane filling most of the view, a small area light behind
/// it and a dim environment: the pane's roughness spreads the light it transmits, so the image
/// depends strongly on α through both of the dielectric's lobes.
pub fn frosted_pane() -> Scene {
    let camera = Camera {
        position: Vec3::new(0.0, 0.0, 3.0),
        target: Vec3::ZERO,
        up: Vec3::Y,
        fov_y_degrees: 40.0,
        width: 32,
        height: 32,
        filter: PixelFilter::Box,
        lens: pathgrad::scene::Lens::Pinhole,
        window: pathgrad::scene::FilmWindow::default(),
    };
    let mut s = Scene::new("test:frosted-pane", camera);
    let glass = s.add_rough_dielectric("pane", 0.2, Vec3::new(0.9, 0.85, 0.8), 1.5).unwrap();
    let black = s.add_diffuse("light", Vec3::ZERO).unwrap();
    // Normals a × b: the pane and the light face +z, the camera.
    s.add_mesh("pane", quad(Vec3::ZERO, Vec3::X * 0.8, Vec3::Y * 0.8), glass, None).unwrap();
    s.add_mesh(
        "light",
        quad(Vec3::new(0.2, 0.1, -1.0), Vec3::X * 0.15, Vec3::Y * 0.15),
        black,
        Some(Vec3::splat(20.0)),
    )
    .unwrap();
    s.set_environment("environment.radiance.value", Vec3::new(0.2, 0.25, 0.3)).unwrap();
    s
}

/// Meshes whose PLOC trees are deeper than the traversal stack (issue "Fast kernels" item 4): a
/// 1000-vertex convex polygon triangulated as a fan (the floor) and a 1000-segment cylinder with
/// 1000-gon fan caps, under an area light. Before the builder bounded the depth these failed with
/// "BVH: depth 267 exceeds the traversal stack (64)".
pub fn deep_meshes() -> Scene {
    const N: u32 = 1000;
    let camera = Camera {
        position: Vec3::new(0.0, 2.0, 4.0),
        target: Vec3::ZERO,
        up: Vec3::Y,
        fov_y_degrees: 40.0,
        width: 64,
        height: 48,
        filter: PixelFilter::Box,
        lens: pathgrad::scene::Lens::Pinhole,
        window: pathgrad::scene::FilmWindow::default(),
    };
    let mut s = Scene::new("test:deep-meshes", camera);
    let grey = s.add_diffuse("grey", Vec3::splat(0.6)).unwrap();
    let black = s.add_diffuse("light", Vec3::ZERO).unwrap();
    let ring = |r: f32, y: f32| -> Vec<Vec3> {
        (0..N)
            .map(|i| {
                let phi = std::f32::consts::TAU * i as f32 / N as f32;
                Vec3::new(r * phi.cos(), y, -r * phi.sin())
            })
            .collect()
    };
    // Counter-clockwise seen from +y: a fan from vertex 0.
    let fan = |base: u32, up: bool| -> Vec<[u32; 3]> {
        (1..N - 1).map(|i| if up { [base, base + i, base + i + 1] } else { [base, base + i + 1, base + i] }).collect()
    };
    let polygon =
        Geometry { positions: ring(2.0, -0.5), normals: None, uvs: None, indices: fan(0, true), ..Default::default() };
    s.add_mesh("polygon", polygon, grey, None).unwrap();
    let mut positions = ring(0.5, -0.5);
    positions.extend(ring(0.5, 0.5));
    let mut indices = fan(0, false);
    indices.extend(fan(N, true));
    for i in 0..N {
        let j = (i + 1) % N;
        indices.push([i, j, N + j]);
        indices.push([i, N + j, N + i]);
    }
    s.add_mesh("cylinder", Geometry { positions, normals: None, uvs: None, indices, ..Default::default() }, grey, None)
        .unwrap();
    s.add_mesh("light", quad(Vec3::new(0.0, 2.0, 0.0), Vec3::X * 0.5, -Vec3::Z * 0.5), black, Some(Vec3::splat(8.0)))
        .unwrap();
    s
}

/// The conformance matrix's scene `name` (`tests/conformance/scenes/NAME.xml`).
pub fn conformance(name: &str) -> Scene {
    let path = format!("{}/tests/conformance/scenes/{name}.xml", env!("CARGO_MANIFEST_DIR"));
    pathgrad::scene::load(&path, &[]).unwrap_or_else(|e| panic!("{path}: {e}"))
}

/// `tests/data/scenes/NAME.xml` (scenes written for one test; `tests/data/xml/` holds malformed ones).
pub fn data_scene(name: &str) -> Scene {
    let path = format!("{}/tests/data/scenes/{name}.xml", env!("CARGO_MANIFEST_DIR"));
    pathgrad::scene::load(&path, &[]).unwrap_or_else(|e| panic!("{path}: {e}"))
}
