//! Parameter names against Mitsuba's: each `tests/data/mitsuba_names/NAME.xml` loads with the
//! names that Mitsuba 3.9.1's `mi.traverse(mi.load_file(path))` lists in `NAME.keys.txt` beside it
//! (written by `regenerate.py` there).
//!
//! The rule, both ways, with `_unnamed_N` standing for Mitsuba's `object_<address>` (the file's
//! `object_ADDRk`) as one object for one object:
//! - every name pathgrad gives is one of Mitsuba's keys, but for [`PATHGRAD_ONLY`];
//! - every key of Mitsuba's of a kind pathgrad exposes ([`KINDS`]: it ends in one of those
//!   suffixes) is one of pathgrad's names, but for [`MITSUBA_ONLY`]. Other keys are of kinds
//!   pathgrad does not expose: geometry and `to_world`, sensors and films, `sampling_weight`s, a
//!   bitmap's `to_uv`.
//!
//! Every kind is exercised by some scene.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The endings of Mitsuba keys of the kinds pathgrad exposes: a diffuse `reflectance`, a bitmap's
/// or a grid's `data`, a rough conductor's `alpha`, `alpha_u`, `alpha_v` and
/// `specular_reflectance`, a conductor's `eta` and `k` (and a thin principled BSDF's `eta`), a
/// blend's `weight`, an emitter's `radiance`, a medium's constant
/// `sigma_t`/`albedo` (`.value.value`, a constvolume's value), `scale` and a phase's `g`.
const KINDS: &[&str] = &[
    ".reflectance.value",
    ".data",
    ".alpha.value",
    ".alpha_u.value",
    ".alpha_v.value",
    ".specular_reflectance.value",
    ".eta.value",
    ".k.value",
    ".weight.value",
    ".radiance.value",
    ".sigma_t.value.value",
    ".albedo.value.value",
    ".scale",
    ".phase_function.g",
];

/// Names pathgrad gives that Mitsuba does not list: a rough conductor without
/// `specular_reflectance` in the file still has pathgrad's (= 1, differentiable), where Mitsuba
/// keeps no texture to traverse.
const PATHGRAD_ONLY: &[(&str, &str)] = &[("bsdfs", "n.bsdf.specular_reflectance.value")];

/// Keys of Mitsuba's kinds that pathgrad lacks.
const MITSUBA_ONLY: &[(&str, &str)] = &[];

fn folder() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/mitsuba_names")
}

/// The scenes: every `NAME.xml` in the folder, by name.
fn scenes() -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(folder())
        .unwrap()
        .filter_map(|e| e.unwrap().file_name().into_string().ok())
        .filter_map(|f| f.strip_suffix(".xml").map(str::to_string))
        .collect();
    names.sort();
    names
}

/// Names by the object they start with, `_unnamed_N` and `object_ADDRk` (the unnamed) apart from
/// the rest: (named names, the unnamed objects' name endings).
fn split(names: &[String], unnamed_prefix: &str) -> (BTreeSet<String>, Vec<BTreeSet<String>>) {
    let mut named = BTreeSet::new();
    let mut unnamed: BTreeMap<&str, BTreeSet<String>> = BTreeMap::new();
    for n in names {
        let (head, rest) = n.split_once('.').unwrap_or((n, ""));
        if head.starts_with(unnamed_prefix) {
            unnamed.entry(head).or_default().insert(format!(".{rest}"));
        } else {
            named.insert(n.clone());
        }
    }
    (named, unnamed.into_values().collect())
}

fn of_a_kind(key: &str) -> bool {
    KINDS.iter().any(|k| key.ends_with(k))
}

#[test]
fn names_are_mitsubas_traverse_keys() {
    let scenes = scenes();
    assert!(scenes.len() >= 3, "{scenes:?}");
    let mut kinds_seen: BTreeSet<&str> = BTreeSet::new();
    for scene in &scenes {
        let keys_file = folder().join(format!("{scene}.keys.txt"));
        let text = std::fs::read_to_string(&keys_file).unwrap_or_else(|e| panic!("{}: {e}", keys_file.display()));
        assert_eq!(text.lines().next(), Some("# mitsuba 3.9.1 mi.traverse keys"), "{}", keys_file.display());
        let keys: Vec<String> = text.lines().filter(|l| !l.starts_with('#')).map(str::to_string).collect();
        let loaded = super::load(&folder().join(format!("{scene}.xml")), &[]).unwrap_or_else(|e| panic!("{e}"));
        let names: Vec<String> = loaded.params.entries().iter().map(|e| e.name.clone()).collect();

        let only = |list: &[(&str, &str)]| -> BTreeSet<String> {
            list.iter().filter(|(s, _)| s == scene).map(|(_, n)| n.to_string()).collect()
        };
        let kept: Vec<String> = keys.iter().filter(|k| of_a_kind(k)).cloned().collect();
        let (mitsuba, mitsuba_unnamed) = split(&kept, "object_ADDR");
        let (pathgrad, mut pathgrad_unnamed) = split(&names, "_unnamed_");

        let extra: Vec<&String> = pathgrad.difference(&mitsuba).filter(|n| !only(PATHGRAD_ONLY).contains(*n)).collect();
        assert!(extra.is_empty(), "{scene}: pathgrad names that Mitsuba does not list: {extra:?}");
        let missing: Vec<&String> =
            mitsuba.difference(&pathgrad).filter(|k| !only(MITSUBA_ONLY).contains(*k)).collect();
        assert!(missing.is_empty(), "{scene}: Mitsuba keys that pathgrad lacks: {missing:?}");
        for n in only(PATHGRAD_ONLY).union(&only(MITSUBA_ONLY)) {
            assert!(pathgrad.contains(n) != mitsuba.contains(n), "{scene}: {n} is no longer an exception");
        }
        // Each object Mitsuba names by its address is one of pathgrad's `_unnamed_N`, with the same
        // parameters.
        for endings in mitsuba_unnamed.iter().filter(|e| !e.is_empty()) {
            let found = pathgrad_unnamed.iter().position(|p| p == endings);
            let Some(i) = found else {
                panic!("{scene}: no _unnamed_N has {endings:?} (pathgrad's unnamed: {pathgrad_unnamed:?})")
            };
            pathgrad_unnamed.remove(i);
        }
        assert!(pathgrad_unnamed.is_empty(), "{scene}: _unnamed_N objects Mitsuba lacks: {pathgrad_unnamed:?}");

        kinds_seen.extend(names.iter().flat_map(|n| KINDS.iter().copied().filter(|k| n.ends_with(k))));
    }
    let unseen: Vec<&str> = KINDS.iter().copied().filter(|k| !kinds_seen.contains(k)).collect();
    assert!(unseen.is_empty(), "kinds no scene exercises: {unseen:?}");
}
