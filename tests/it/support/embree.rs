//! Embree 3 as the reference for BVH tests: closest hits and occlusion over a triangle soup.
//!
//! Self-contained on purpose (it uses no pathgrad code), so a disagreement with our BVH points at
//! our BVH. The scene is built in Embree's robust mode, which makes its ray–triangle test watertight
//! (a ray through a shared edge or vertex hits one of the triangles); triangles are two-sided
//! (Debian builds Embree without back-face culling). Ray parameters `t` are in units of the
//! direction's length: directions need not be normalised. Rays are traced one at a time with an
//! incoherent context, which is what a randomised test sends.

use embree3::{BufferUsage, Device, Format, GeometryKind, IntersectContext, Ray, RayHit, Scene, SceneFlags};

/// A committed Embree scene holding one triangle mesh; primitive ids are triangle indices.
pub struct EmbreeScene {
    /// Owns the device and (through the attached geometry) the mesh buffers.
    scene: Scene<'static>,
}

impl EmbreeScene {
    /// Builds the scene from `vertices` and `triangles` (each three indices into `vertices`).
    ///
    /// An empty `triangles` gives a scene that every ray misses.
    ///
    /// # Panics
    ///
    /// If an index is out of range (Embree would read out of bounds), or Embree fails to create the
    /// device, scene, geometry or buffers (the message carries Embree's error code).
    pub fn new(vertices: &[[f32; 3]], triangles: &[[u32; 3]]) -> EmbreeScene {
        for (i, triangle) in triangles.iter().enumerate() {
            assert!(
                triangle.iter().all(|&v| (v as usize) < vertices.len()),
                "triangle {i} {triangle:?} indexes past the {} vertices",
                vertices.len()
            );
        }
        let device = Device::new().unwrap_or_else(|e| panic!("creating the Embree device: {e:?}"));
        let mut scene = device.create_scene().unwrap_or_else(|e| panic!("creating an Embree scene: {e:?}"));
        scene.set_flags(SceneFlags::ROBUST);

        // Embree refuses zero-sized buffers, so an empty mesh is simply not attached.
        if !triangles.is_empty() {
            let mut mesh = device
                .create_geometry(GeometryKind::TRIANGLE)
                .unwrap_or_else(|e| panic!("creating an Embree triangle geometry: {e:?}"));
            // `set_new_buffer` lets Embree allocate, with the tail padding its SIMD loads of the
            // last vertex need; tightly packed `[f32; 3]` slices cannot be shared directly.
            mesh.set_new_buffer::<[f32; 3]>(
                BufferUsage::VERTEX,
                0,
                Format::FLOAT3,
                size_of::<[f32; 3]>(),
                vertices.len(),
            )
            .unwrap_or_else(|e| panic!("allocating {} Embree vertices: {e:?}", vertices.len()))
            .copy_from_slice(vertices);
            mesh.set_new_buffer::<[u32; 3]>(
                BufferUsage::INDEX,
                0,
                Format::UINT3,
                size_of::<[u32; 3]>(),
                triangles.len(),
            )
            .unwrap_or_else(|e| panic!("allocating {} Embree triangles: {e:?}", triangles.len()))
            .copy_from_slice(triangles);
            let mesh = mesh.commit();
            scene.attach_geometry(&mesh);
        }
        scene.commit();
        EmbreeScene { scene }
    }

    /// The closest hit of each `(origin, direction)` ray with `t` in `[tmin, ∞)`: `Some((t, primitive
    /// id))`, or `None` for a miss.
    pub fn closest_hits(&self, rays: &[([f32; 3], [f32; 3])], tmin: f32) -> Vec<Option<(f32, u32)>> {
        let mut context = IntersectContext::incoherent();
        rays.iter()
            .map(|&(origin, direction)| {
                let mut ray_hit = RayHit::from(Ray::segment(origin, direction, tmin, f32::INFINITY));
                self.scene.intersect(&mut context, &mut ray_hit);
                ray_hit.hit.is_valid().then_some((ray_hit.ray.tfar, ray_hit.hit.primID))
            })
            .collect()
    }

    /// Whether each `(origin, direction)` ray hits any triangle with `t` in `[tmin, tmax]`.
    pub fn occluded(&self, rays: &[([f32; 3], [f32; 3])], tmin: f32, tmax: f32) -> Vec<bool> {
        let mut context = IntersectContext::incoherent();
        rays.iter()
            .map(|&(origin, direction)| {
                let mut ray = Ray::segment(origin, direction, tmin, tmax);
                self.scene.occluded(&mut context, &mut ray)
            })
            .collect()
    }
}
