//! Mitsuba's `mesh_attribute` texture: what the loader binds it to and every refusal, by message.

use std::path::Path;

use super::loader::{load_mesh_file, load_path};
use super::tests::wrap;
use crate::contract::{TEX_ATTR_FACE, TEX_ATTR_VERTEX};
use crate::scene::{Albedo, LoadOptions, Material, Scene};

/// A tetrahedron as ASCII PLY with a colour per vertex (`r g b`: `vertex_color`), a two-value run
/// per vertex (ignored), and per face a colour (`tint_0 1 2`: `face_tint`) and a weight
/// (`weight_x`: `face_weight`, `weight` each).
fn tetrahedron(weight: f32) -> String {
    let head = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n\
                property float r\nproperty float g\nproperty float b\nproperty float pair_0\nproperty float pair_1\n\
                element face 4\nproperty list uchar int vertex_indices\nproperty float tint_0\nproperty float tint_1\n\
                property float tint_2\nproperty float weight_x\nend_header\n";
    let vertices = "0 0 0 0.1 0.2 0.3 5 5\n1 0 0 0.4 0.5 0.6 5 5\n0 1 0 0.7 0.8 0.9 5 5\n0 0 1 0.2 0.4 0.6 5 5\n";
    let faces = format!(
        "3 0 2 1 0.1 0.1 0.1 {weight}\n3 0 1 3 0.2 0.2 0.2 0.25\n3 0 3 2 0.3 0.3 0.3 0.5\n3 1 2 3 0.4 0.4 0.4 0.75\n"
    );
    format!("{head}{vertices}{faces}")
}

/// Loads `body` (in a scene with a sensor) from a folder holding `tet.ply` (face weight `weight`).
fn load_with_mesh(body: &str, weight: f32) -> crate::error::Result<Scene> {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("tet.ply"), tetrahedron(weight)).unwrap();
    std::fs::write(dir.path().join("s.xml"), wrap(body)).unwrap();
    load_path(&dir.path().join("s.xml"), &LoadOptions::default(), load_mesh_file)
}

const TET: &str = r#"<string name="filename" value="tet.ply"/>"#;

fn attribute(name: &str) -> String {
    format!(r#"<string name="name" value="{name}"/>"#)
}

#[test]
fn issue_31_mesh_attributes_become_their_shapes_parameters() {
    // One top-level texture reached by two shapes' BSDFs: each shape reads its own attribute.
    let body = format!(
        r#"<texture type="mesh_attribute" id="w">{}</texture>
           <shape type="ply" id="a">{TET}<bsdf type="diffuse"><texture type="mesh_attribute" name="reflectance">{}</texture></bsdf></shape>
           <shape type="ply" id="b">{TET}<bsdf type="blendbsdf"><ref name="weight" id="w"/><bsdf type="diffuse"/><bsdf type="roughconductor"/></bsdf></shape>
           <shape type="ply" id="c">{TET}<bsdf type="blendbsdf"><ref name="weight" id="w"/><bsdf type="diffuse"/><bsdf type="diffuse"/></bsdf></shape>
           <shape type="ply" id="d">{TET}<bsdf type="twosided"><bsdf type="diffuse"><texture type="mesh_attribute" name="reflectance">{}</texture></bsdf></bsdf></shape>"#,
        attribute("face_weight"),
        attribute("vertex_color"),
        attribute("face_tint")
    );
    let s = load_with_mesh(&body, 0.125).unwrap_or_else(|e| panic!("{e}"));
    let value = |name: &str| s.params.get(s.params.find(name).unwrap_or_else(|| panic!("{name} missing"))).to_vec();
    assert_eq!(value("a.vertex_color")[3..6], [0.4, 0.5, 0.6]);
    assert_eq!(value("b.face_weight"), [0.125, 0.25, 0.5, 0.75]);
    assert_eq!(value("c.face_weight"), [0.125, 0.25, 0.5, 0.75]);
    assert_eq!(value("d.face_tint").len(), 12);
    // Only the attributes a BSDF reads are parameters; the two-value run is no attribute.
    assert!(s.params.find("a.face_weight").is_none() && s.params.find("a.vertex_pair").is_none());
    let Material::Diffuse { albedo: Albedo::Attribute { source, .. } } = s.materials[s.meshes[0].material.0 as usize]
    else {
        panic!("a's colour is not its attribute")
    };
    assert!(source.per_vertex && source.mesh == 0);
    let flat = crate::scene::flat::FlatScene::new(&s).unwrap();
    assert_eq!(flat.materials[s.meshes[0].material.0 as usize].tex_mode, TEX_ATTR_VERTEX);
    let weight = s.scalar_textures.iter().filter(|t| t.attribute.is_some_and(|a| !a.per_vertex)).count();
    assert_eq!(weight, 2, "b and c each have their own weight texture");
    let tinted = flat.materials.iter().filter(|m| m.tex_mode == TEX_ATTR_FACE).count();
    assert!(tinted >= 1, "d's colour reads per face");
}

#[test]
fn issue_31_mesh_attribute_refusals_name_the_problem() {
    let diffuse = |props: &str| {
        format!(
            r#"<shape type="ply" id="a">{TET}<bsdf type="diffuse"><texture type="mesh_attribute" name="reflectance">{props}</texture></bsdf></shape>"#
        )
    };
    let blend = |props: &str| {
        format!(
            r#"<shape type="ply" id="a">{TET}<bsdf type="blendbsdf"><texture type="mesh_attribute" name="weight">{props}</texture><bsdf type="diffuse"/><bsdf type="diffuse"/></bsdf></shape>"#
        )
    };
    let cases: Vec<(String, f32, &str)> = vec![
        (diffuse(""), 0.5, "'mesh_attribute' needs the property 'name'"),
        (
            diffuse(&attribute("color")),
            0.5,
            "invalid mesh attribute name 'color': it must start with 'vertex_' or 'face_'",
        ),
        (
            diffuse(&format!(r#"{}<float name="scale" value="2"/>"#, attribute("vertex_color"))),
            0.5,
            "a 'mesh_attribute' 'scale' other than 1 is not supported (got 2)",
        ),
        (
            diffuse(&attribute("vertex_normal")),
            0.5,
            "shape 'a' has no mesh attribute 'vertex_normal' (its attributes: vertex_color, face_tint, face_weight)",
        ),
        (
            blend(&attribute("vertex_color")),
            0.5,
            "mesh attribute 'vertex_color' of shape 'a' has 3 values a row: a float property needs 1 value",
        ),
        (
            diffuse(&attribute("face_weight")),
            0.5,
            "mesh attribute 'face_weight' of shape 'a' has 1 values a row: a colour needs 3 values",
        ),
        (
            blend(&attribute("face_weight")),
            1.5,
            "mesh attribute 'face_weight' of shape 'a': triangle 0 has the value 1.5 outside [0, 1]",
        ),
        (
            format!(
                r#"<bsdf type="diffuse" id="shared"><texture type="mesh_attribute" name="reflectance">{}</texture></bsdf>
                   <shape type="ply" id="a">{TET}<ref id="shared"/></shape><shape type="ply" id="b">{TET}<ref id="shared"/></shape>"#,
                attribute("vertex_color")
            ),
            0.5,
            "this BSDF reads the mesh attributes of shape 'a' and cannot be shared with another shape",
        ),
        (
            format!(
                r#"<shape type="cube" id="box"><bsdf type="diffuse"><texture type="mesh_attribute" name="reflectance">{}</texture></bsdf></shape>"#,
                attribute("vertex_color")
            ),
            0.5,
            "shape 'box' has no mesh attribute 'vertex_color' (its attributes: none)",
        ),
    ];
    for (body, weight, expect) in cases {
        let err = load_with_mesh(&body, weight).err().unwrap_or_else(|| panic!("{body} loaded")).to_string();
        assert!(err.contains(expect), "{body}:\n{err}");
        assert!(Path::new(err.split(':').next().unwrap()).ends_with("s.xml"), "the message names the file: {err}");
        assert!(err.contains("s.xml:"), "and the line: {err}");
    }
}
