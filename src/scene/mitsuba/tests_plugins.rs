//! The plugin list ([`super::plugins`]) against the loader and the documentation: every listed
//! plugin is accepted, every other plugin of Mitsuba 3.9.1 is refused by name, and
//! `docs/mitsuba-plugins.md` is what the list generates.

use std::path::Path;

use super::loader::load_text;
use super::plugins::{Category, PLUGINS, markdown};
use super::tests::{SENSOR, obj_for_tests};

/// Mitsuba 3.9.1's plugins by category (its `src/<category>/*.cpp`, and the Python integrators;
/// volumes under their XML names).
const MITSUBA: &[(Category, &[&str])] = &[
    (
        Category::Bsdf,
        &[
            "blendbsdf",
            "bumpmap",
            "circular",
            "conductor",
            "dielectric",
            "diffuse",
            "hair",
            "mask",
            "measured",
            "measured_polarized",
            "normalmap",
            "null",
            "plastic",
            "polarizer",
            "pplastic",
            "principled",
            "principledthin",
            "retarder",
            "roughconductor",
            "roughdielectric",
            "roughplastic",
            "thindielectric",
            "twosided",
        ],
    ),
    (
        Category::Emitter,
        &[
            "area",
            "constant",
            "directional",
            "directionalarea",
            "envmap",
            "point",
            "projector",
            "spot",
            "sunsky",
            "timed_sunsky",
        ],
    ),
    (
        Category::Shape,
        &[
            "blender",
            "bsplinecurve",
            "cube",
            "cylinder",
            "disk",
            "ellipsoids",
            "ellipsoidsmesh",
            "instance",
            "linearcurve",
            "merge",
            "obj",
            "ply",
            "rectangle",
            "sdfgrid",
            "serialized",
            "shapegroup",
            "sphere",
        ],
    ),
    (Category::Texture, &["bitmap", "checkerboard", "mesh_attribute", "volume"]),
    (Category::Medium, &["heterogeneous", "homogeneous"]),
    (Category::Phase, &["blendphase", "hg", "isotropic", "rayleigh", "sggx", "tabphase"]),
    (Category::Volume, &["constvolume", "gridvolume"]),
    (
        Category::Sensor,
        &["batch", "distant", "irradiancemeter", "orthographic", "perspective", "radiancemeter", "thinlens"],
    ),
    (Category::Film, &["hdrfilm", "specfilm"]),
    (Category::Rfilter, &["box", "catmullrom", "gaussian", "lanczos", "mitchell", "tent"]),
    (Category::Sampler, &["independent", "ldsampler", "multijitter", "orthogonal", "stratified"]),
    (
        Category::Integrator,
        &[
            "aov",
            "depth",
            "direct",
            "direct_projective",
            "moment",
            "path",
            "prb",
            "prb_basic",
            "prb_projective",
            "prbvolpath",
            "ptracer",
            "stokes",
            "volpath",
            "volpathmis",
            "volprim_rf_basic",
        ],
    ),
];

const FILM: &str = r#"<film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film>"#;
const LIGHT: &str = r#"<shape type="cube" id="lamp"><emitter type="area"/></shape>"#;

/// A scene holding one `category` object of plugin `name`, as small as the loader lets it be.
fn scene_with(category: Category, name: &str) -> String {
    let sensor = |inside: &str| {
        format!(
            r#"<sensor type="perspective"><transform name="to_world"><lookat origin="0, 0, 5" target="0, 0, 0"/></transform>{inside}</sensor>"#
        )
    };
    let body = match category {
        Category::Bsdf => format!(r#"{SENSOR}<shape type="cube"><bsdf type="{name}"/></shape>{LIGHT}"#),
        Category::Emitter if name == "area" => format!(r#"{SENSOR}{LIGHT}"#),
        Category::Emitter => format!(r#"{SENSOR}<emitter type="{name}"/><shape type="cube"/>"#),
        Category::Shape => format!(r#"{SENSOR}<shape type="{name}"/>{LIGHT}"#),
        Category::Texture => {
            format!(
                r#"{SENSOR}<shape type="cube"><bsdf type="diffuse"><texture name="reflectance" type="{name}"/></bsdf></shape>{LIGHT}"#
            )
        }
        Category::Medium => {
            format!(
                r#"{SENSOR}<shape type="cube"><bsdf type="null"/><medium type="{name}" name="interior"/></shape>{LIGHT}"#
            )
        }
        Category::Phase => format!(
            r#"{SENSOR}<shape type="cube"><bsdf type="null"/><medium type="homogeneous" name="interior"><phase type="{name}"/></medium></shape>{LIGHT}"#
        ),
        Category::Volume => format!(
            r#"{SENSOR}<shape type="cube"><bsdf type="null"/><medium type="heterogeneous" name="interior"><volume type="{name}" name="sigma_t"/></medium></shape>{LIGHT}"#
        ),
        Category::Sensor => format!(r#"<sensor type="{name}">{FILM}</sensor>{LIGHT}"#),
        Category::Film => format!(r#"{}{LIGHT}"#, sensor(&format!(r#"<film type="{name}"/>"#))),
        Category::Rfilter => {
            format!(r#"{}{LIGHT}"#, sensor(&format!(r#"<film type="hdrfilm"><rfilter type="{name}"/></film>"#)))
        }
        Category::Sampler => format!(r#"{}{LIGHT}"#, sensor(&format!(r#"{FILM}<sampler type="{name}"/>"#))),
        Category::Integrator => format!(r#"<integrator type="{name}"/>{SENSOR}{LIGHT}"#),
    };
    format!(r#"<scene version="3.0.0">{body}</scene>"#)
}

/// Whether loading says plugin `name` is unsupported (any other error — a missing property — is
/// the plugin being read).
fn refused(category: Category, name: &str) -> Option<String> {
    let xml = scene_with(category, name);
    match load_text(&xml, Path::new("tests/data/xml/plugins.xml"), &[], obj_for_tests) {
        Err(e) if e.to_string().contains(&format!("unsupported plugin '{name}'")) => Some(e.to_string()),
        _ => None,
    }
}

#[test]
fn every_listed_plugin_is_accepted_and_every_other_refused() {
    for &(category, all) in MITSUBA {
        for &name in all {
            let listed = PLUGINS.iter().any(|p| p.category == category && p.name == name);
            match (listed, refused(category, name)) {
                (true, Some(e)) => panic!("<{}> '{name}' is listed but refused: {e}", category.tag()),
                (false, None) => panic!("<{}> '{name}' is accepted but not listed in plugins.rs", category.tag()),
                _ => {}
            }
        }
    }
    // Nothing is listed that Mitsuba does not have.
    for p in PLUGINS {
        let known = MITSUBA.iter().any(|&(c, all)| c == p.category && all.contains(&p.name));
        assert!(known, "<{}> '{}' is not a Mitsuba 3.9.1 plugin", p.category.tag(), p.name);
    }
}

#[test]
fn the_plugin_documentation_is_generated_from_the_list() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/mitsuba-plugins.md");
    let generated = markdown();
    if std::env::var_os("PATHGRAD_BLESS").is_some() {
        std::fs::write(&path, &generated).unwrap();
    }
    let committed = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(committed == generated, "{} is stale: run the tests with PATHGRAD_BLESS=1", path.display());
}
