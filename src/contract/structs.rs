// Structs and push-constant blocks shared by Rust and GLSL, declared once.
//
// `src/contract/mod.rs` expands this into `#[repr(C)]` bytemuck structs; `build.rs` expands the same
// declarations into the GLSL twins (`generated/contract.glsl`), used by every storage buffer with
// `layout(scalar)`. A push-constant block becomes a struct too, plus a macro `PUSH_<Name>` that
// declares the kernel's `layout(push_constant, scalar)` block with the same members. Scalar layout inserts no padding and `Pod` refuses implicit padding, so the
// offsets agree by construction (STYLE.md §3). Field types: u32, f32, Vec2, Vec3, UVec2 only.

contract_structs! {
    /// Per-dispatch constants: image size, random-number key, path options, scene addresses.
    struct Globals {
        /// Image width in pixels.
        width: u32,
        /// Image height in pixels.
        height: u32,
        /// Philox key word 0: the user seed.
        key0: u32,
        /// Philox key word 1 of the pass in stream 0 (`pass_tag`): the key of adaptive pixel
        /// selection; paths use their view's `ViewCamera::key1`.
        key1: u32,
        /// Maximum number of counted interactions (`path_flags`); `u32::MAX` is unbounded.
        max_depth: u32,
        /// Russian roulette starts once `depth >= rr_depth` (depth: the counted interactions
        /// before the vertex, `vertex - 1` unless null events go uncounted); `u32::MAX` disables it.
        rr_depth: u32,
        /// `PATH_NULL_UNCOUNTED` (Mitsuba's volpath counting) and `PATH_HIDE_EMITTERS` bits.
        path_flags: u32,
        /// Number of emissive triangles.
        emitter_count: u32,
        /// Total area of the emissive triangles (area-proportional emitter sampling).
        emitter_total_area: f32,
        /// Number of views (cameras) the request renders; each has a `ViewCamera` at `addr_views`.
        view_count: u32,
        /// Parameter offset of the environment's radiance (constant: one RGB value; map: its
        /// texels, `env_width × env_height` RGB values row by row), or `NO_PARAM`.
        env_param: u32,
        /// Environment map: width in texels (longitude); 0 for a constant environment.
        env_width: u32,
        /// Environment map: height in texels (latitude, row 0 toward the map's +y).
        env_height: u32,
        /// Environment map: Mitsuba's `scale`, multiplying every texel.
        env_scale: f32,
        /// Environment map: row 0 of the rotation from world to the map's frame (`to_world`⁻¹).
        env_rot0: Vec3,
        /// Row 1 of that rotation.
        env_rot1: Vec3,
        /// Row 2 of that rotation.
        env_rot2: Vec3,
        /// Number of lights without area (`DeltaLight`: point, spot, directional).
        light_count: u32,
        /// Probability that next-event estimation samples one of them (each equally likely);
        /// emissive triangles get what neither lights nor the environment take.
        light_select_prob: f32,
        /// Probability that next-event estimation samples the environment rather than area emitters.
        env_select_prob: f32,
        /// Adjoint kernels: δL of a sample is the adjoint image's pixel times this (1 / spp).
        adjoint_scale: f32,
        /// Fixed-point gradients: the integer unit is 1 / fixed_scale.
        fixed_scale: f32,
        /// Forward mode: first parameter value with tangent 1.
        forward_begin: u32,
        /// Forward mode: one past the last parameter value with tangent 1.
        forward_end: u32,
        /// 1 if next-event estimation is on.
        nee: u32,
        /// `STRATEGY_BSDF` or `STRATEGY_DIFF`.
        strategy: u32,
        /// Differential strategy: probability of the differential technique at a capable vertex.
        diff_q: f32,
        /// Differential strategy: first parameter value of the target parameter; a vertex is
        /// capable if its material's roughness or blend weight lies in `diff_begin .. diff_end`.
        diff_begin: u32,
        /// Differential strategy: one past the target parameter's last value.
        diff_end: u32,
        /// Differential strategy: `PLACEMENT_BALANCE` or `PLACEMENT_POWER`, the weighting of its
        /// placements (ALGORITHMS.md §5.7).
        diff_placement: u32,
        /// 1 for attached sampling (issue 34, `Sampling::Attached`), 0 for detached.
        attached: u32,
        /// Attached sampling: the amplitude a of the noise added to each completed ray Jacobian
        /// (PRB supplemental §2), |Y| uniform in [a/2, a] with a random sign; 0 for none.
        jac_noise: f32,
        /// Differential strategy with several targets (ALGORITHMS.md §5.8): their number, 2 to
        /// `MAX_HEROES`; 0 for one target (`diff_begin .. diff_end`). Target k has the parameter
        /// values `hero_range{k}` (begin, end) and is the path's hero with probability `hero_p{k}`.
        hero_count: u32,
        /// Hero set: probability of target 0.
        hero_p0: f32,
        /// Hero set: probability of target 1.
        hero_p1: f32,
        /// Hero set: probability of target 2 (0 if absent).
        hero_p2: f32,
        /// Hero set: probability of target 3 (0 if absent).
        hero_p3: f32,
        /// Hero set: parameter values of target 0 (begin, one past the end).
        hero_range0: UVec2,
        /// Hero set: parameter values of target 1.
        hero_range1: UVec2,
        /// Hero set: parameter values of target 2 (empty if absent).
        hero_range2: UVec2,
        /// Hero set: parameter values of target 3 (empty if absent).
        hero_range3: UVec2,
        /// Number of BVH nodes.
        node_count: u32,
        /// Reverse-mode kernels over pixels: 1 adds each path's radiance to the accumulation
        /// image instead of replaying it (a gradient step's pass 1 on its gradient kernel, so
        /// one compiled kernel serves both passes); 0 replays every path.
        primal_only: u32,
        /// Device address of the BVH nodes (`shaders/lib/abi.glsl`); 0 on the CPU.
        addr_nodes: UVec2,
        /// Device address of the leaf-ordered triangles.
        addr_tris: UVec2,
        /// Device address of the leaf slots' triangle ids.
        addr_prim_ids: UVec2,
        /// Device address of the triangles' vertex indices and meshes (`TriVertices`, by
        /// original id).
        addr_tri_vertices: UVec2,
        /// Device address of the meshes' shading records (`MeshShading`).
        addr_meshes: UVec2,
        /// Device address of the vertex normals of the meshes that have them (`Vec3`, one a
        /// vertex, mesh after mesh).
        addr_normals: UVec2,
        /// Device address of the texture coordinates of the meshes that have them (`Vec2`).
        addr_uvs: UVec2,
        /// Device address of the emissive meshes' per-triangle emitter indices (`u32`).
        addr_emitter_ids: UVec2,
        /// Device address of the materials.
        addr_materials: UVec2,
        /// Device address of the emitters.
        addr_emitters: UVec2,
        /// Device address of the parameter values.
        addr_params: UVec2,
        /// Device address of the request's `ViewCamera`s.
        addr_views: UVec2,
        /// Device address of the media (`MediumDesc`).
        addr_media: UVec2,
        /// Device address of the media's fields (`FieldDesc`).
        addr_fields: UVec2,
        /// Device address of the environment map's sampling cells (`EnvCell`).
        addr_env_cells: UVec2,
        /// Device address of the lights without area (`DeltaLight`).
        addr_lights: UVec2,
        /// Device address of the rough plastics' coating tables (`Material::table`).
        addr_tables: UVec2,
        /// Device address of the media's majorant grids (`MediumDesc::grid`).
        addr_majorants: UVec2,
    }

    /// One view of a request: its pinhole camera and the key word of its paths. The image (and
    /// adjoint image) buffers hold the views' pixels one view after another.
    struct ViewCamera {
        /// Pinhole position (orthographic: the film's centre, on the near plane).
        origin: Vec3,
        /// Right axis scaled by tan(horizontal half field of view) (orthographic: by the film's
        /// half width in world units).
        right: Vec3,
        /// Up axis scaled by tan(vertical half field of view) (orthographic: by the half height).
        up: Vec3,
        /// Pinhole and thin lens: the direction through the image's centre, whose component
        /// along the unit viewing direction is 1 (the viewing direction itself unless the image
        /// is a crop of the film). Orthographic: the unit viewing direction.
        forward: Vec3,
        /// `LENS_PINHOLE`, `LENS_THIN` or `LENS_ORTHOGRAPHIC`.
        lens: u32,
        /// Thin lens: the aperture's radius.
        aperture_radius: f32,
        /// Thin lens: the distance of the plane in focus.
        focus_distance: f32,
        /// Philox key word 1 of the view's paths: `(stream << 8) | pass_tag`.
        key1: u32,
        /// The film's reconstruction filter: `FILTER_BOX`, `FILTER_TENT` or `FILTER_GAUSSIAN`.
        filter_kind: u32,
        /// Its radius in pixels.
        filter_radius: f32,
        /// Gaussian: −1/(2σ²), the exponent's factor.
        filter_alpha: f32,
    }

    /// One node of the compressed 8-wide BVH (Ylitie et al. 2017, as obvhs builds it): up to eight
    /// children whose boxes are quantised to 8 bits on a grid that starts at `origin` with cell
    /// sizes that are powers of two, so one node is ten 8-byte words for eight boxes (how the
    /// traversal reads it, shaders/lib/bvh.glsl). Byte k of a per-child word is child slot k.
    struct BvhNode {
        /// The grid's origin (the node's box minimum).
        origin: Vec3,
        /// Bytes 0–2: the biased exponents of the grid's cell size along x, y and z (a cell is
        /// `f32::from_bits(e << 23)`); byte 3: bit k set when child slot k is an inner node.
        exp_imask: u32,
        /// Index of the first inner child; inner children are consecutive, in slot order.
        child_base: u32,
        /// Leaf slot of the first triangle of the leaf children.
        tri_base: u32,
        /// Per child: 0 for an empty slot; an inner child `0b001` in the top three bits and 24 +
        /// its slot below; a leaf its triangle count in unary in the top three bits (1 to 3
        /// triangles) and its first triangle's offset from `tri_base` below.
        meta: UVec2,
        /// Per child: the box's low x, in cells.
        lo_x: UVec2,
        /// Per child: the box's high x, in cells.
        hi_x: UVec2,
        /// Per child: the box's low y, in cells.
        lo_y: UVec2,
        /// Per child: the box's high y, in cells.
        hi_y: UVec2,
        /// Per child: the box's low z, in cells.
        lo_z: UVec2,
        /// Per child: the box's high z, in cells.
        hi_z: UVec2,
    }

    /// Triangle vertex positions, in BVH leaf order: nine floats and a pad, five 8-byte words
    /// (how the traversal reads them).
    struct TriPositions {
        /// Vertex 0.
        v0: Vec3,
        /// Vertex 1.
        v1: Vec3,
        /// Vertex 2.
        v2: Vec3,
        /// Unused: keeps every triangle 8-byte aligned.
        pad0: u32,
    }

    /// A triangle's vertices and mesh, indexed by the original triangle id: 16 bytes a triangle.
    /// With [`MeshShading`] and the per-vertex normals (12 bytes a vertex) and texture
    /// coordinates (8) of the meshes that have them, this is the shading data the kernels read
    /// (issue 38: it replaced a 72-byte per-triangle record of three normals, three uv pairs,
    /// material, emitter and medium). A closed mesh has about half as many vertices as
    /// triangles, so the device holds per triangle: positions in leaf order 40 bytes
    /// ([`TriPositions`]), leaf slot to id 4, this 16, normals about 6 and uvs about 4 where the
    /// mesh has them, CWBVH nodes about 8 — about 74 bytes for a mesh with normals and no uvs
    /// (124 before).
    struct TriVertices {
        /// Index of vertex 0 in its mesh's vertex arrays.
        i0: u32,
        /// Index of vertex 1.
        i1: u32,
        /// Index of vertex 2.
        i2: u32,
        /// Index of its mesh in the `MeshShading` array.
        mesh: u32,
    }

    /// What the triangles of one mesh share: material, interior medium, and where its per-vertex
    /// data and its triangles' emitter indices start.
    struct MeshShading {
        /// Index into the material array.
        material: u32,
        /// Index into the media of the medium inside the mesh (behind its winding normal), or
        /// `NO_MEDIUM`.
        interior: u32,
        /// Original id of its first triangle.
        first_tri: u32,
        /// Offset of its vertex 0's normal in the vertex-normal array (`Globals::addr_normals`),
        /// or `NO_ARRAY`: the mesh has no vertex normals and shades with its face normals.
        normal_base: u32,
        /// Offset of its vertex 0's texture coordinates in the uv array (`Globals::addr_uvs`), or
        /// `NO_ARRAY`: every coordinate is 0.
        uv_base: u32,
        /// Offset of its first triangle's emitter index in the emitter-index array
        /// (`Globals::addr_emitter_ids`: an index into the emitters, or `NO_EMITTER` for a
        /// triangle of no area), or `NO_ARRAY`: the mesh does not emit.
        emitter_base: u32,
    }

    /// A field of a medium (extinction or albedo): a constant or a grid. A grid's local point is
    /// (dot(row0, p), dot(row1, p), dot(row2, p)) + shift, in the unit cube.
    struct FieldDesc {
        /// `FIELD_CONSTANT` or `FIELD_GRID`.
        kind: u32,
        /// 1 or 3 values per point.
        channels: u32,
        /// Parameter offset of the value (constant) or of voxel 0 (grid, x fastest).
        offset: u32,
        /// Voxels along x.
        res_x: u32,
        /// Voxels along y.
        res_y: u32,
        /// Voxels along z.
        res_z: u32,
        /// Row 0 of the world-to-unit-cube matrix.
        row0: Vec3,
        /// Row 1.
        row1: Vec3,
        /// Row 2.
        row2: Vec3,
        /// The translation.
        shift: Vec3,
    }

    /// A participating medium: extinction `scale · sigma_t(p)`, albedo, phase function and the
    /// majorant of delta and ratio tracking.
    struct MediumDesc {
        /// Index of its extinction field.
        sigma_t: u32,
        /// Index of its albedo field.
        albedo: u32,
        /// Parameter offset of `scale`.
        p_scale: u32,
        /// `PHASE_ISOTROPIC` or `PHASE_HG`.
        phase: u32,
        /// Parameter offset of Henyey–Greenstein's g, or `NO_PARAM`.
        p_g: u32,
        /// `scale · max(sigma_t)` over every point and channel, from the current parameters.
        majorant: f32,
        /// 1: the medium exists only inside the world box `lo`–`hi` (Mitsuba's heterogeneous
        /// medium: its sigma_t volume's bounding box); 0: wherever its shape is.
        bounded: u32,
        /// The box's minimum corner (when `bounded`).
        lo: Vec3,
        /// The box's maximum corner (when `bounded`).
        hi: Vec3,
        /// Offset of its majorant grid in the majorant array (`Globals::addr_majorants`), or
        /// `NO_PARAM`: then `majorant` holds everywhere.
        grid: u32,
        /// The majorant grid's cells along x, over the unit cube of the `sigma_t` field (0
        /// without a grid).
        grid_x: u32,
        /// Its cells along y.
        grid_y: u32,
        /// Its cells along z.
        grid_z: u32,
    }

    /// A material; its differentiable values are offsets into the parameter array.
    struct Material {
        /// `MAT_DIFFUSE`, `MAT_ROUGH_CONDUCTOR` or `MAT_BLEND`.
        tag: u32,
        /// `DIST_BECKMANN` or `DIST_GGX` (rough conductor).
        distribution: u32,
        /// Blend: material index of child 0 (weight 1 − w).
        child0: u32,
        /// Blend: material index of child 1 (weight w).
        child1: u32,
        /// Parameter offset of the RGB albedo (diffuse; the texels if textured) or specular
        /// reflectance (conductor).
        p_color: u32,
        /// Texture width in texels; 0 when the color is constant.
        tex_width: u32,
        /// Texture height in texels.
        tex_height: u32,
        /// Texture lookup: `TEX_CHECKER` (a 2×1 texture of the checkerboard's two colours), else
        /// `TEX_NEAREST` or bilinear, or-ed with `TEX_WRAP_MIRROR` or `TEX_WRAP_CLAMP` (repeat
        /// when neither).
        tex_mode: u32,
        /// 1 if the material is seen from both sides.
        two_sided: u32,
        /// Parameter offset of the roughness alpha (conductor: α_u); of a rough conductor or
        /// dielectric, `SCALAR_TEXTURE` with its texture's descriptor when textured.
        p_alpha: u32,
        /// Rough conductor: parameter offset of α_v (`p_alpha` when isotropic), or a texture as
        /// `p_alpha`.
        p_alpha_v: u32,
        /// Parameter offset of the blend weight (blend), or `SCALAR_TEXTURE` with its texture's
        /// descriptor when textured; of a smooth dielectric's η (`NO_PARAM`: `eta.x` holds it); of
        /// a conductor's (smooth or rough) RGB eta, its RGB k the three values after it
        /// (`NO_PARAM`: `eta` and `k` hold them); a
        /// plastic's specular colour slot (a parameter, `SCALAR_TEXTURE` with its descriptor, or
        /// `NO_PARAM`: `k` holds it).
        p_weight: u32,
        /// Real part of the conductor's complex index of refraction (RGB). Rough plastic: (η =
        /// int_ior/ext_ior, the coating's sampling weight w, 1 if `nonlinear` else 0).
        eta: Vec3,
        /// Imaginary part of the conductor's complex index of refraction (RGB). Plastics: their
        /// specular reflectance when it is a constant.
        k: Vec3,
        /// Textured: row 0 of the texture-coordinate transform, u' = dot(uv_row0, (u, v, 1))
        /// (Mitsuba's `to_uv`; (1, 0, 0) for none).
        uv_row0: Vec3,
        /// Textured: row 1, v' = dot(uv_row1, (u, v, 1)) ((0, 1, 0) for none).
        uv_row1: Vec3,
        /// Rough plastic: offset of its coating table in the tables array
        /// (`COATING_TABLE_LEN` floats: T(μ), ∂T/∂α, Rᵢ, ∂Rᵢ/∂α). Rough dielectric: parameter
        /// offset of its η (`NO_PARAM`: `eta.x` holds it).
        table: u32,
        /// Normal or bump map (Mitsuba's `normalmap`, `bumpmap` around this material): offset of
        /// its texels in the tables array (RGB for a normal map, one value for a bump map; row 0
        /// at v = 0); none when `nmap_width` is 0.
        nmap: u32,
        /// Normal or bump map width in texels; 0 without a map.
        nmap_width: u32,
        /// Normal or bump map height in texels.
        nmap_height: u32,
        /// Normal or bump map lookup: `TEX_NEAREST` and wrap bits as `tex_mode`, or-ed with
        /// `NMAP_BUMP` for a bump map.
        nmap_mode: u32,
        /// Bump map: Mitsuba's `scale` of the height's gradient (unused by a normal map).
        nmap_scale: f32,
        /// Mask (Mitsuba's `mask` around this material): parameter offset of its opacity, or
        /// `SCALAR_TEXTURE` with its texture's descriptor; `NO_PARAM` without a mask.
        p_opacity: u32,
    }

    /// One emissive triangle, in the order of its area CDF.
    struct EmitterTri {
        /// Original triangle id.
        tri: u32,
        /// Parameter offset of the RGB radiance.
        p_radiance: u32,
        /// Cumulative area fraction up to and including this triangle.
        cdf: f32,
        /// Triangle area.
        area: f32,
        /// Vertex 0 (counter-clockwise seen from the emitting side).
        v0: Vec3,
        /// Vertex 1.
        v1: Vec3,
        /// Vertex 2.
        v2: Vec3,
    }

    /// A light without area (Mitsuba's `point`, `spot`, `directional`, `projector`): reached only
    /// by next-event estimation, with weight 1 (no BSDF sample can hit it). 112 bytes a light (48
    /// before textured spots and projectors).
    struct DeltaLight {
        /// `LIGHT_POINT`, `LIGHT_SPOT`, `LIGHT_DIRECTIONAL` or `LIGHT_PROJECTOR`.
        kind: u32,
        /// Parameter offset of the RGB intensity (point, spot: W/sr) or irradiance (directional,
        /// a projector's constant `irradiance`); `NO_PARAM` for a projector whose irradiance is
        /// its texture.
        p_intensity: u32,
        /// Position (point, spot).
        position: Vec3,
        /// Unit direction the light shines along: a spot's axis, a directional light's travel;
        /// a projector's `to_world` · (0, 0, 1), not normalised (Mitsuba's cosine uses it so).
        axis: Vec3,
        /// Spot: cosine of the cutoff angle (no light beyond it).
        cos_cutoff: f32,
        /// Spot: cosine of the beam width (full intensity within it).
        cos_beam: f32,
        /// Spot: the cutoff angle in radians.
        cutoff: f32,
        /// Spot: 1 / (cutoff − beam width) in radians: the linear falloff's slope.
        inv_transition: f32,
        /// Textured spot, projector (`F_LIGHT_TEXTURE`): parameter offset of the texture's RGB
        /// texels (row 0 at v = 0), or `NO_PARAM` for none.
        tex: u32,
        /// Texture width in texels.
        tex_width: u32,
        /// Texture height in texels.
        tex_height: u32,
        /// Texture lookup: `TEX_NEAREST` or bilinear, or-ed with the wrap bits (as `Material::tex_mode`).
        tex_mode: u32,
        /// Projector: parameter offset of its `scale`; `NO_PARAM` otherwise.
        p_scale: u32,
        /// Textured spot, projector: the lookup's u = 0.5 + uv_scale.x · x / z and v = 0.5 +
        /// uv_scale.y · y / z of the light's local point (x, y, z) (spot: 0.5 / tan(cutoff) twice;
        /// projector: −0.5 · cot(fov_x / 2) and −0.5 · aspect · cot(fov_x / 2)).
        uv_scale: Vec2,
        /// Textured spot, projector: row 0 of the linear part of `to_world`⁻¹ (a world offset from
        /// `position` to the light's local frame).
        row0: Vec3,
        /// Row 1 of it.
        row1: Vec3,
        /// Row 2 of it.
        row2: Vec3,
    }

    /// One cell of an environment map's sampling grid (`crate::scene::envmap`): the region between
    /// four neighbouring texel centres, where the radiance is their bilinear blend. Cells are drawn
    /// through an alias table (`prob`, `alias` as in `AliasEntry`) in proportion to their mean
    /// luminance times solid angle, and then sampled uniformly in solid angle within.
    struct EnvCell {
        /// Probability of keeping the column's own cell.
        prob: f32,
        /// The cell drawn otherwise.
        alias: u32,
        /// Solid-angle density of a direction in this cell, given that the map is sampled: the
        /// cell's realised probability over its solid angle.
        pdf: f32,
    }

    /// One column of an alias table (`crate::alias::AliasTable`): keep the column's own entry
    /// with probability `prob`, else draw `alias`.
    struct AliasEntry {
        /// Probability of keeping the column's own entry.
        prob: f32,
        /// The entry drawn otherwise.
        alias: u32,
    }

    /// Test probe input: one BSDF query (`shaders/bsdf_probe.comp`).
    struct BsdfProbeCase {
        /// Leaf 0 kind (`LEAF_*`).
        kind0: u32,
        /// Leaf 0 distribution (`DIST_*`).
        dist0: u32,
        /// Leaf 0 roughness.
        alpha0: f32,
        /// Leaf 0 albedo or specular reflectance.
        color0: Vec3,
        /// Leaf 0 eta.
        eta0: Vec3,
        /// Leaf 0 k.
        k0: Vec3,
        /// Leaf 1 kind.
        kind1: u32,
        /// Leaf 1 distribution.
        dist1: u32,
        /// Leaf 1 roughness.
        alpha1: f32,
        /// Leaf 1 albedo or specular reflectance.
        color1: Vec3,
        /// Leaf 1 eta.
        eta1: Vec3,
        /// Leaf 1 k.
        k1: Vec3,
        /// Blend weight.
        weight: f32,
        /// Bit 0: a blend. Bit 1 (the differential probe only): the target of an anisotropic
        /// leaf's differential sampler is its α_v.
        blend: u32,
        /// Incident direction (local).
        wi: Vec3,
        /// Lobe uniform.
        u_lobe: f32,
        /// Direction uniforms.
        u: Vec2,
        /// A fixed direction at which eval and pdf are also queried.
        wo_eval: Vec3,
        /// Leaf 0's α_v (a rough conductor's; its α otherwise).
        alpha_v0: f32,
        /// Leaf 1's α_v.
        alpha_v1: f32,
    }

    /// Test probe output for one `BsdfProbeCase`.
    struct BsdfProbeResult {
        /// Sampled direction.
        wo: Vec3,
        /// Its pdf.
        pdf: f32,
        /// Its value.
        value: Vec3,
        /// 1 if the sample is valid.
        valid: u32,
        /// `bsdf_eval` at `wo_eval`.
        eval: Vec3,
        /// `bsdf_pdf` at `wo_eval`.
        eval_pdf: f32,
    }

    /// Test probe input: one principled BSDF query (`shaders/principled_probe.comp`).
    struct PrincipledProbeCase {
        /// `base_color`.
        base_color: Vec3,
        /// `roughness`.
        roughness: f32,
        /// `anisotropic`.
        anisotropic: f32,
        /// `metallic`.
        metallic: f32,
        /// `spec_trans`.
        spec_trans: f32,
        /// η.
        eta: f32,
        /// `spec_tint`.
        spec_tint: f32,
        /// `sheen`.
        sheen: f32,
        /// `sheen_tint`.
        sheen_tint: f32,
        /// `clearcoat`.
        clearcoat: f32,
        /// `clearcoat_gloss`.
        clearcoat_gloss: f32,
        /// `flatness`.
        flatness: f32,
        /// Sampling rates: main specular, clearcoat, diffuse.
        rates: Vec3,
        /// Incident direction (local).
        wi: Vec3,
        /// Lobe uniform.
        u_lobe: f32,
        /// Direction uniforms.
        u: Vec2,
        /// A fixed direction at which the value, its derivatives and the density are queried.
        wo_eval: Vec3,
    }

    /// Test probe output for one `PrincipledProbeCase`.
    struct PrincipledProbeResult {
        /// Sampled direction.
        wo: Vec3,
        /// 1 if the sample is valid.
        valid: u32,
        /// The value at `wo_eval`.
        eval: Vec3,
        /// The density at `wo_eval`.
        pdf: f32,
        /// ∂f̂/∂(base colour channel 0) at `wo_eval`, per image channel.
        d_base0: Vec3,
        /// ∂f̂/∂(base colour channel 1).
        d_base1: Vec3,
        /// ∂f̂/∂(base colour channel 2).
        d_base2: Vec3,
        /// ∂f̂/∂roughness.
        d_roughness: Vec3,
        /// ∂f̂/∂anisotropic.
        d_anisotropic: Vec3,
        /// ∂f̂/∂metallic.
        d_metallic: Vec3,
        /// ∂f̂/∂spec_trans.
        d_spec_trans: Vec3,
        /// ∂f̂/∂spec_tint.
        d_spec_tint: Vec3,
        /// ∂f̂/∂sheen.
        d_sheen: Vec3,
        /// ∂f̂/∂sheen_tint.
        d_sheen_tint: Vec3,
        /// ∂f̂/∂clearcoat.
        d_clearcoat: Vec3,
        /// ∂f̂/∂clearcoat_gloss.
        d_clearcoat_gloss: Vec3,
        /// ∂f̂/∂flatness.
        d_flatness: Vec3,
    }

    /// Test probe input: one thin principled BSDF query (`shaders/principled_thin_probe.comp`).
    struct PrincipledThinProbeCase {
        /// `base_color`.
        base_color: Vec3,
        /// `roughness`.
        roughness: f32,
        /// `anisotropic`.
        anisotropic: f32,
        /// `spec_trans`.
        spec_trans: f32,
        /// `eta`.
        eta: f32,
        /// `spec_tint`.
        spec_tint: f32,
        /// `sheen`.
        sheen: f32,
        /// `sheen_tint`.
        sheen_tint: f32,
        /// `flatness`.
        flatness: f32,
        /// `diff_trans` (0..2).
        diff_trans: f32,
        /// Sampling rates of the specular reflection and transmission.
        rates_specular: Vec2,
        /// Sampling rates of the diffuse reflection and transmission.
        rates_diffuse: Vec2,
        /// Incident direction (local).
        wi: Vec3,
        /// Lobe uniform.
        u_lobe: f32,
        /// Direction uniforms.
        u: Vec2,
        /// A fixed direction at which the value, its derivatives and the density are queried.
        wo_eval: Vec3,
    }

    /// Test probe output for one `PrincipledThinProbeCase`.
    struct PrincipledThinProbeResult {
        /// Sampled direction.
        wo: Vec3,
        /// 1 if the sample is valid.
        valid: u32,
        /// The value at `wo_eval`.
        eval: Vec3,
        /// The density at `wo_eval`.
        pdf: f32,
        /// ∂f̂/∂(base colour channel 0) at `wo_eval`, per image channel.
        d_base0: Vec3,
        /// ∂f̂/∂(base colour channel 1).
        d_base1: Vec3,
        /// ∂f̂/∂(base colour channel 2).
        d_base2: Vec3,
        /// ∂f̂/∂roughness.
        d_roughness: Vec3,
        /// ∂f̂/∂anisotropic.
        d_anisotropic: Vec3,
        /// ∂f̂/∂spec_trans.
        d_spec_trans: Vec3,
        /// ∂f̂/∂eta.
        d_eta: Vec3,
        /// ∂f̂/∂spec_tint.
        d_spec_tint: Vec3,
        /// ∂f̂/∂sheen.
        d_sheen: Vec3,
        /// ∂f̂/∂sheen_tint.
        d_sheen_tint: Vec3,
        /// ∂f̂/∂flatness.
        d_flatness: Vec3,
        /// ∂f̂/∂diff_trans.
        d_diff_trans: Vec3,
    }
}

contract_push_blocks! {
    /// Push constants of every render kernel (`shaders/kernel.glsl`).
    struct KernelPush {
        /// First sample index (adaptive pixel selection: first global sample) of this dispatch.
        sample_begin: u32,
        /// Samples per item.
        sample_count: u32,
        /// Items in this dispatch.
        item_count: u32,
        /// Most items one lane takes.
        lane_items: u32,
    }

    /// Push constants of the loss kernel (`shaders/loss.comp`).
    struct LossPush {
        /// Values (3 per pixel) in the image and in the target.
        count: u32,
        /// `Loss` value.
        kind: u32,
    }

    /// Push constants of the probe kernels that run a list of cases (bsdf, rng, diff, contract).
    struct CasePush {
        /// Cases in the input.
        case_count: u32,
    }

    /// Push constants of the BVH probe (`shaders/bvh_probe.comp`).
    struct BvhProbePush {
        /// Rays in the input.
        ray_count: u32,
        /// Bit 0 runs the closest-hit query, bit 1 the occlusion query.
        queries: u32,
        /// Loop iterations spent before tracing (a loop-budget burner for tests).
        burn: u32,
    }

    /// Push constants of the alias-table probe (`shaders/alias_probe.comp`).
    struct AliasProbePush {
        /// Philox key of the selection.
        key: UVec2,
        /// Entries of the table.
        table_size: u32,
        /// Samples to draw.
        sample_count: u32,
    }

    /// Push constants of the loop-budget probe (`shaders/loop_budget_probe.comp`).
    struct LoopBudgetPush {
        /// Invocations that run the loop.
        invocation_count: u32,
        /// Iterations each invocation asks for.
        iterations: u32,
    }
}
