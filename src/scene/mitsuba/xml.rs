//! XML plumbing for the Mitsuba loader: element locations, `$name` substitution, property values
//! (`<float>`, `<rgb>`, …) and `<transform>` elements.

use std::cell::Cell;
use std::collections::HashMap;

use glam::{Mat4, Vec3, Vec4};
use roxmltree::Node;

use crate::error::{Error, Result};

/// An element of the parsed document.
pub(super) type El<'a> = Node<'a, 'a>;

/// The property tags and the object tags an object element may contain.
const PROPERTY_TAGS: &[&str] =
    &["boolean", "float", "integer", "point", "rgb", "spectrum", "string", "transform", "vector"];
/// The D65 illuminant in linear sRGB as Mitsuba 3.9.1's RGB variants integrate it (an emitter's
/// `<spectrum value="1"/>` reads back as these values from `mi.traverse`, in float32).
pub(super) const D65_RGB: [f32; 3] = [1.204_793_9, 0.948_291, 0.908_916_06];
const OBJECT_TAGS: &[&str] = &[
    "bsdf",
    "emitter",
    "film",
    "integrator",
    "medium",
    "phase",
    "ref",
    "rfilter",
    "sampler",
    "sensor",
    "shape",
    "texture",
    "volume",
];

/// A `<default>` or `-D` value and whether any attribute used it.
struct Define {
    value: String,
    used: Cell<bool>,
}

/// The document with its file name and defines: turns elements into locations, attribute values
/// (after `$name` substitution) and errors.
pub(super) struct Xml<'a> {
    /// The file name as messages show it.
    pub file: String,
    doc: &'a roxmltree::Document<'a>,
    defines: HashMap<String, Define>,
    /// Where the document's bytes came from, when it has files spliced in (`<include>`).
    sources: Option<&'a super::include::Sources>,
    /// Warnings raised while reading values (a `<rotate>` about a non-unit axis), waiting for the
    /// loader to take them ([`Xml::take_warnings`]).
    notes: std::cell::RefCell<Vec<String>>,
}

/// Whether `name` is a valid `$name` identifier: `[A-Za-z_][A-Za-z0-9_]*`.
pub(super) fn is_identifier(name: &str) -> bool {
    let mut chars = name.chars();
    chars.next().is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
}

/// `<tag>`, with its `id` or else its `name` attribute (raw, before substitution): how messages
/// name an element.
pub(super) fn describe(node: El<'_>) -> String {
    let tag = node.tag_name().name();
    match (node.attribute("id"), node.attribute("name")) {
        (Some(id), _) => format!("<{tag} id=\"{id}\">"),
        (None, Some(name)) => format!("<{tag} name=\"{name}\">"),
        (None, None) => format!("<{tag}>"),
    }
}

impl<'a> Xml<'a> {
    /// Wraps a parsed document.
    pub fn new(file: String, doc: &'a roxmltree::Document<'a>) -> Xml<'a> {
        Xml { file, doc, defines: HashMap::new(), sources: None, notes: std::cell::RefCell::default() }
    }

    /// Locates nodes in the files `sources` spliced together (the document is its text).
    pub fn with_sources(self, sources: &'a super::include::Sources) -> Xml<'a> {
        Xml { sources: Some(sources), ..self }
    }

    /// Adds or replaces a define.
    pub fn define(&mut self, name: &str, value: &str) {
        self.defines.insert(name.to_string(), Define { value: value.to_string(), used: Cell::new(false) });
    }

    /// The defines no attribute referred to, sorted.
    pub fn unused_defines(&self) -> Vec<String> {
        let mut names: Vec<String> =
            self.defines.iter().filter(|(_, d)| !d.used.get()).map(|(n, _)| n.clone()).collect();
        names.sort();
        names
    }

    /// `file:line:col` of `node`'s start.
    pub fn loc(&self, node: El<'_>) -> String {
        if let Some(sources) = self.sources {
            return sources.location(node.range().start);
        }
        let p = self.doc.text_pos_at(node.range().start);
        format!("{}:{}:{}", self.file, p.row, p.col)
    }

    /// An [`Error::Scene`] at `node`: `file:line:col: <tag id="…">: message`.
    pub fn err(&self, node: El<'_>, message: impl std::fmt::Display) -> Error {
        Error::Scene { location: self.loc(node), message: format!("{}: {message}", describe(node)) }
    }

    /// A located warning about `node`: `file:line:col: message`.
    pub fn warning(&self, node: El<'_>, message: impl std::fmt::Display) -> String {
        format!("{}: {message}", self.loc(node))
    }

    /// Records a located warning about `node` for the loader to report.
    pub fn note(&self, node: El<'_>, message: impl std::fmt::Display) {
        let w = self.warning(node, message);
        self.notes.borrow_mut().push(w);
    }

    /// The warnings recorded by [`Xml::note`] since the last call, in order.
    pub fn take_warnings(&self) -> Vec<String> {
        std::mem::take(&mut self.notes.borrow_mut())
    }

    /// Attribute `name` of `node` with every `$name` replaced by its define.
    ///
    /// # Errors
    /// A reference to an undefined name.
    pub fn attr(&self, node: El<'_>, name: &str) -> Result<Option<String>> {
        let Some(raw) = node.attribute(name) else { return Ok(None) };
        let mut out = String::with_capacity(raw.len());
        let mut rest = raw;
        while let Some(i) = rest.find('$') {
            out.push_str(&rest[..i]);
            let after = &rest[i + 1..];
            let len = after.find(|c: char| !(c.is_ascii_alphanumeric() || c == '_')).unwrap_or(after.len());
            let key = &after[..len];
            if key.is_empty() {
                out.push('$');
            } else {
                let d = self.defines.get(key).ok_or_else(|| {
                    self.err(
                        node,
                        format!(
                            "undefined parameter '${key}' in attribute '{name}' (define it with \
                             <default name=\"{key}\" value=\"…\"/> or -D {key}=VALUE)"
                        ),
                    )
                })?;
                d.used.set(true);
                out.push_str(&d.value);
            }
            rest = &after[len..];
        }
        out.push_str(rest);
        Ok(Some(out))
    }

    /// Attribute `name`, which must be present.
    ///
    /// # Errors
    /// A missing attribute or an undefined `$name`.
    pub fn required(&self, node: El<'_>, name: &str) -> Result<String> {
        self.attr(node, name)?.ok_or_else(|| self.err(node, format!("missing attribute '{name}'")))
    }

    /// Fails if `node` has an attribute outside `allowed` or non-blank text inside it.
    ///
    /// # Errors
    /// Naming the attribute.
    pub fn check_attrs(&self, node: El<'_>, allowed: &[&str]) -> Result<()> {
        for a in node.attributes() {
            if a.namespace().is_some() || !allowed.contains(&a.name()) {
                return Err(
                    self.err(node, format!("unexpected attribute '{}' (allowed: {})", a.name(), allowed.join(", ")))
                );
            }
        }
        for c in node.children() {
            if c.is_text() && c.text().is_some_and(|t| !t.trim().is_empty()) {
                return Err(self.err(node, "unexpected text inside the element"));
            }
        }
        Ok(())
    }

    /// The numbers of `text` (separated by commas and/or white space), each finite.
    ///
    /// # Errors
    /// Naming `what` and the offending token.
    pub fn numbers(&self, node: El<'_>, what: &str, text: &str) -> Result<Vec<f32>> {
        text.split(|c: char| c == ',' || c.is_whitespace())
            .filter(|t| !t.is_empty())
            .map(|t| match t.parse::<f32>() {
                Ok(v) if v.is_finite() => Ok(v),
                Ok(_) => Err(self.err(node, format!("{what}: '{t}' is not a finite number"))),
                Err(_) => Err(self.err(node, format!("{what}: expected a number, got '{t}'"))),
            })
            .collect()
    }

    /// One finite number.
    ///
    /// # Errors
    /// As [`Xml::numbers`], or a count other than one.
    pub fn number(&self, node: El<'_>, what: &str, text: &str) -> Result<f32> {
        match self.numbers(node, what, text)?[..] {
            [v] => Ok(v),
            _ => Err(self.err(node, format!("{what}: expected one number, got '{text}'"))),
        }
    }

    /// Three numbers, from attribute `value` (one number is repeated) or from `x`/`y`/`z` (missing
    /// ones are `default`).
    ///
    /// # Errors
    /// As [`Xml::numbers`], a count other than one or three, or both forms at once.
    pub fn vec3_attrs(&self, node: El<'_>, default: f32, allow_single: bool) -> Result<Vec3> {
        let value = self.attr(node, "value")?;
        let xyz = [self.attr(node, "x")?, self.attr(node, "y")?, self.attr(node, "z")?];
        match value {
            Some(v) if xyz.iter().all(Option::is_none) => self.triple(node, "value", &v, allow_single),
            Some(_) => Err(self.err(node, "give either 'value' or 'x'/'y'/'z', not both")),
            None => {
                let mut out = [default; 3];
                for (o, (a, s)) in out.iter_mut().zip(["x", "y", "z"].iter().zip(&xyz)) {
                    if let Some(s) = s {
                        *o = self.number(node, a, s)?;
                    }
                }
                Ok(Vec3::from_array(out))
            }
        }
    }

    /// Three numbers from `text` (or one, repeated, when `allow_single`).
    ///
    /// # Errors
    /// As [`Xml::numbers`] or a wrong count.
    pub fn triple(&self, node: El<'_>, what: &str, text: &str, allow_single: bool) -> Result<Vec3> {
        match self.numbers(node, what, text)?[..] {
            [v] if allow_single => Ok(Vec3::splat(v)),
            [x, y, z] => Ok(Vec3::new(x, y, z)),
            _ => Err(self.err(
                node,
                format!("{what}: expected {}3 numbers, got '{text}'", if allow_single { "1 or " } else { "" }),
            )),
        }
    }
}

/// A property's value.
#[derive(Clone, Debug, PartialEq)]
pub(super) enum Value {
    /// `<float>`.
    Float(f32),
    /// `<integer>`.
    Integer(i64),
    /// `<boolean>`.
    Boolean(bool),
    /// `<string>`.
    Str(String),
    /// `<rgb>`.
    Color(Vec3),
    /// A constant `<spectrum>`: grey, except in an emitter's radiance, where Mitsuba's RGB modes
    /// read it as that multiple of the D65 illuminant ([`D65_RGB`]).
    Spectrum(f32),
    /// A `<spectrum>` of wavelength:value pairs in linear sRGB as Mitsuba's RGB variants read it
    /// ([`super::spectrum`]): for a bounded colour (a reflectance), an unbounded one (η, k, σ_t),
    /// and an emitter's radiance.
    Pairs { bounded: Vec3, unbounded: Vec3, emitted: Vec3 },
    /// `<point>` or `<vector>`.
    Point(Vec3),
    /// `<transform>`.
    Transform(Transform),
}

/// A parsed `<transform>`: the matrix and, when it is exactly one `<lookat>`, its three points
/// (cameras keep them verbatim so a look-at camera is reproduced bit for bit).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Transform {
    /// The accumulated matrix.
    pub matrix: Mat4,
    /// `(origin, target, up)` of a transform that is a single `<lookat>`.
    pub lookat: Option<[Vec3; 3]>,
}

/// One property of an object element.
pub(super) struct Prop<'a> {
    name: String,
    value: Value,
    node: El<'a>,
    used: Cell<bool>,
}

/// One object nested in an object element (`<bsdf>`, `<ref>`, …), with its `name` attribute.
pub(super) struct Nested<'a> {
    name: Option<String>,
    node: El<'a>,
    used: Cell<bool>,
}

/// The properties and nested objects of one object element (`<shape type="…">`, …), each marked
/// when a plugin reads it so that [`Props::finish`] can report the rest.
pub(super) struct Props<'a> {
    /// The element.
    pub node: El<'a>,
    /// Its `type` attribute.
    pub kind: String,
    props: Vec<Prop<'a>>,
    nested: Vec<Nested<'a>>,
    finished: Cell<bool>,
}

impl<'a> Props<'a> {
    /// Reads the children of object element `node`.
    ///
    /// # Errors
    /// Unexpected attributes, malformed property elements, duplicate names, unsupported element
    /// tags.
    pub fn parse(x: &Xml<'_>, node: El<'a>) -> Result<Props<'a>> {
        x.check_attrs(node, &["type", "id", "name"])?;
        let kind = x.required(node, "type")?;
        let mut out = Props { node, kind, props: Vec::new(), nested: Vec::new(), finished: Cell::new(false) };
        for c in node.children() {
            if c.is_text() && c.text().is_some_and(|t| !t.trim().is_empty()) {
                return Err(x.err(node, "unexpected text inside the element"));
            }
            if !c.is_element() {
                continue;
            }
            let tag = c.tag_name().name();
            if PROPERTY_TAGS.contains(&tag) {
                let name = x.required(c, "name")?;
                if out.props.iter().any(|p| p.name == name) || out.nested_named(&name).is_some() {
                    return Err(x.err(c, format!("property '{name}' is given twice")));
                }
                let value = property(x, c)?;
                out.props.push(Prop { name, value, node: c, used: Cell::new(false) });
            } else if OBJECT_TAGS.contains(&tag) {
                let name = x.attr(c, "name")?;
                if let Some(n) = &name
                    && (out.props.iter().any(|p| &p.name == n) || out.nested_named(n).is_some())
                {
                    return Err(x.err(c, format!("property '{n}' is given twice")));
                }
                out.nested.push(Nested { name, node: c, used: Cell::new(false) });
            } else {
                return Err(x.err(
                    c,
                    format!(
                        "unsupported element <{tag}> (supported inside an object: {}, {})",
                        PROPERTY_TAGS.join(", "),
                        OBJECT_TAGS.join(", ")
                    ),
                ));
            }
        }
        Ok(out)
    }

    fn nested_named(&self, name: &str) -> Option<&Nested<'a>> {
        self.nested.iter().find(|n| n.name.as_deref() == Some(name))
    }

    fn get(&self, name: &str) -> Option<&Prop<'a>> {
        let p = self.props.iter().find(|p| p.name == name)?;
        p.used.set(true);
        Some(p)
    }

    /// The element of property `name`, if given (does not mark it used).
    pub fn node_of(&self, name: &str) -> Option<El<'a>> {
        self.props.iter().find(|p| p.name == name).map(|p| p.node).or_else(|| self.nested_named(name).map(|n| n.node))
    }

    /// Whether property `name` (a value or a named nested object) is given.
    pub fn has(&self, name: &str) -> bool {
        self.node_of(name).is_some()
    }

    fn wrong_type(&self, x: &Xml<'_>, p: &Prop<'a>, expected: &str) -> Error {
        x.err(p.node, format!("property '{}' of '{}' must be {expected}", p.name, self.kind))
    }

    /// A nested object given for a value property is an error naming what the property accepts.
    fn no_object(&self, x: &Xml<'_>, name: &str, expected: &str) -> Result<()> {
        match self.nested_named(name) {
            Some(n) => {
                n.used.set(true);
                Err(x.err(n.node, format!("property '{name}' of '{}' must be {expected}", self.kind)))
            }
            None => Ok(()),
        }
    }

    /// Float property `name` with its element (an `<integer>` is accepted too).
    ///
    /// # Errors
    /// A property of another type.
    pub fn float(&self, x: &Xml<'_>, name: &str) -> Result<Option<(f32, El<'a>)>> {
        self.no_object(x, name, "a <float>")?;
        match self.get(name) {
            None => Ok(None),
            Some(Prop { value: Value::Float(v), node, .. }) => Ok(Some((*v, *node))),
            Some(Prop { value: Value::Integer(v), node, .. }) => Ok(Some((*v as f32, *node))),
            Some(p) => Err(self.wrong_type(x, p, "a <float>")),
        }
    }

    /// Integer property `name` with its element.
    ///
    /// # Errors
    /// A property of another type.
    pub fn integer(&self, x: &Xml<'_>, name: &str) -> Result<Option<(i64, El<'a>)>> {
        self.no_object(x, name, "an <integer>")?;
        match self.get(name) {
            None => Ok(None),
            Some(Prop { value: Value::Integer(v), node, .. }) => Ok(Some((*v, *node))),
            Some(p) => Err(self.wrong_type(x, p, "an <integer>")),
        }
    }

    /// Boolean property `name`, `default` when absent.
    ///
    /// # Errors
    /// A property of another type.
    pub fn boolean(&self, x: &Xml<'_>, name: &str, default: bool) -> Result<bool> {
        self.no_object(x, name, "a <boolean>")?;
        match self.get(name) {
            None => Ok(default),
            Some(Prop { value: Value::Boolean(v), .. }) => Ok(*v),
            Some(p) => Err(self.wrong_type(x, p, "a <boolean>")),
        }
    }

    /// String property `name` with its element.
    ///
    /// # Errors
    /// A property of another type.
    pub fn string(&self, x: &Xml<'_>, name: &str) -> Result<Option<(String, El<'a>)>> {
        self.no_object(x, name, "a <string>")?;
        match self.get(name) {
            None => Ok(None),
            Some(Prop { value: Value::Str(v), node, .. }) => Ok(Some((v.clone(), *node))),
            Some(p) => Err(self.wrong_type(x, p, "a <string>")),
        }
    }

    /// Colour property `name` (`<rgb>`, constant `<spectrum>`, or `<float>` for grey) with its
    /// element. A nested object under this name is an error (callers that accept textures look
    /// for it with [`Props::object`] first).
    ///
    /// # Errors
    /// A property of another type.
    pub fn color(&self, x: &Xml<'_>, name: &str) -> Result<Option<(Vec3, El<'a>)>> {
        self.no_object(x, name, "an <rgb>, a constant <spectrum> or a <float>")?;
        match self.get(name) {
            None => Ok(None),
            Some(Prop { value: Value::Color(v), node, .. }) => Ok(Some((*v, *node))),
            Some(Prop { value: Value::Float(v) | Value::Spectrum(v), node, .. }) => Ok(Some((Vec3::splat(*v), *node))),
            Some(Prop { value: Value::Pairs { bounded, .. }, node, .. }) => Ok(Some((*bounded, *node))),
            Some(p) => Err(self.wrong_type(x, p, "an <rgb>, a constant <spectrum> or a <float>")),
        }
    }

    /// As [`Props::color`], for a colour without an upper bound (η, k): a spectrum of pairs is
    /// not clamped at 1.
    ///
    /// # Errors
    /// As [`Props::color`].
    pub fn color_unbounded(&self, x: &Xml<'_>, name: &str) -> Result<Option<(Vec3, El<'a>)>> {
        match self.get(name) {
            Some(Prop { value: Value::Pairs { unbounded, .. }, node, .. }) => Ok(Some((*unbounded, *node))),
            _ => self.color(x, name),
        }
    }

    /// Emitted radiance `name` with its element: as [`Props::color`], except that a constant
    /// `<spectrum value="v"/>` is v times the D65 illuminant, as Mitsuba 3's RGB variants read
    /// an emitter's uniform spectrum (a `<float>` or `<rgb>` is taken as given).
    ///
    /// # Errors
    /// A property of another type.
    pub fn radiance(&self, x: &Xml<'_>, name: &str) -> Result<Option<(Vec3, El<'a>)>> {
        match self.get(name) {
            Some(Prop { value: Value::Spectrum(v), node, .. }) => Ok(Some((Vec3::from(D65_RGB) * *v, *node))),
            Some(Prop { value: Value::Pairs { emitted, .. }, node, .. }) => Ok(Some((*emitted, *node))),
            _ => self.color(x, name),
        }
    }

    /// Property `name` as given: one value for a `<float>`, three for an `<rgb>` or constant
    /// `<spectrum>` (media keep grey and RGB values apart).
    ///
    /// # Errors
    /// A property of another type.
    pub fn values(&self, x: &Xml<'_>, name: &str) -> Result<Option<(Vec<f32>, El<'a>)>> {
        self.no_object(x, name, "an <rgb>, a constant <spectrum>, a <float> or a <volume>")?;
        match self.get(name) {
            None => Ok(None),
            Some(Prop { value: Value::Color(v), node, .. }) => Ok(Some((v.to_array().to_vec(), *node))),
            Some(Prop { value: Value::Spectrum(v), node, .. }) => Ok(Some((vec![*v; 3], *node))),
            Some(Prop { value: Value::Pairs { unbounded, .. }, node, .. }) => {
                Ok(Some((unbounded.to_array().to_vec(), *node)))
            }
            Some(Prop { value: Value::Float(v), node, .. }) => Ok(Some((vec![*v], *node))),
            Some(p) => Err(self.wrong_type(x, p, "an <rgb>, a constant <spectrum>, a <float> or a <volume>")),
        }
    }

    /// Point or vector property `name` with its element.
    ///
    /// # Errors
    /// A property of another type.
    pub fn point(&self, x: &Xml<'_>, name: &str) -> Result<Option<(Vec3, El<'a>)>> {
        self.no_object(x, name, "a <point>")?;
        match self.get(name) {
            None => Ok(None),
            Some(Prop { value: Value::Point(v), node, .. }) => Ok(Some((*v, *node))),
            Some(p) => Err(self.wrong_type(x, p, "a <point>")),
        }
    }

    /// Transform property `name` with its element.
    ///
    /// # Errors
    /// A property of another type.
    pub fn transform(&self, x: &Xml<'_>, name: &str) -> Result<Option<(Transform, El<'a>)>> {
        self.no_object(x, name, "a <transform>")?;
        match self.get(name) {
            None => Ok(None),
            Some(Prop { value: Value::Transform(t), node, .. }) => Ok(Some((*t, *node))),
            Some(p) => Err(self.wrong_type(x, p, "a <transform>")),
        }
    }

    /// The nested object (or `<ref>`) called `name`, marked used.
    pub fn object(&self, name: &str) -> Option<El<'a>> {
        let n = self.nested_named(name)?;
        n.used.set(true);
        Some(n.node)
    }

    /// The nested objects with tag `tag` (a `<ref>` counts for any tag), in document order, that
    /// nothing has claimed yet; they are marked used.
    pub fn take_nested(&self, tags: &[&str]) -> Vec<El<'a>> {
        self.nested
            .iter()
            .filter(|n| !n.used.get() && tags.contains(&n.node.tag_name().name()))
            .map(|n| {
                n.used.set(true);
                n.node
            })
            .collect()
    }

    /// Reports what no plugin read: a warning per unknown property (into `warnings`), an error for
    /// a nested object nobody claimed. Only the first call reports.
    ///
    /// # Errors
    /// An unclaimed nested object.
    pub fn finish(&self, x: &Xml<'_>, warnings: &mut Vec<String>) -> Result<()> {
        if self.finished.replace(true) {
            return Ok(());
        }
        for p in self.props.iter().filter(|p| !p.used.get()) {
            warnings.push(x.warning(p.node, format!("unknown property '{}' of '{}' ignored", p.name, self.kind)));
        }
        for n in self.nested.iter().filter(|n| !n.used.get()) {
            let tag = n.node.tag_name().name();
            match &n.name {
                Some(name) => {
                    warnings.push(x.warning(n.node, format!("unknown property '{name}' of '{}' ignored", self.kind)))
                }
                None => return Err(x.err(n.node, format!("a <{tag}> is not expected inside '{}'", self.kind))),
            }
        }
        Ok(())
    }
}

/// Parses one property element.
fn property(x: &Xml<'_>, node: El<'_>) -> Result<Value> {
    let tag = node.tag_name().name();
    if tag == "transform" {
        x.check_attrs(node, &["name"])?;
        return Ok(Value::Transform(transform(x, node)?));
    }
    if matches!(tag, "point" | "vector") {
        x.check_attrs(node, &["name", "value", "x", "y", "z"])?;
        return Ok(Value::Point(x.vec3_attrs(node, 0.0, false)?));
    }
    x.check_attrs(node, &["name", "value"])?;
    let value = x.required(node, "value")?;
    Ok(match tag {
        "float" => Value::Float(x.number(node, "value", &value)?),
        "integer" => Value::Integer(
            value.trim().parse().map_err(|_| x.err(node, format!("expected an integer, got '{value}'")))?,
        ),
        "boolean" => Value::Boolean(match value.trim().to_ascii_lowercase().as_str() {
            "true" => true,
            "false" => false,
            _ => return Err(x.err(node, format!("expected 'true' or 'false', got '{value}'"))),
        }),
        "string" => Value::Str(value),
        "rgb" => Value::Color(x.triple(node, "value", &value, true)?),
        "spectrum" => {
            if value.contains(':') {
                let (w, v) = super::spectrum::parse_pairs(&value).map_err(|m| x.err(node, m))?;
                Value::Pairs {
                    bounded: super::spectrum::to_srgb(&w, &v, true, true),
                    unbounded: super::spectrum::to_srgb(&w, &v, false, true),
                    emitted: super::spectrum::to_srgb(&w, &v, false, false),
                }
            } else {
                match x.numbers(node, "value", &value)?[..] {
                    [v] => Value::Spectrum(v),
                    _ => {
                        return Err(x.err(
                            node,
                            format!(
                                "a <spectrum> is one number or wavelength:value pairs ('400:0.1, 500:0.3'), got \
                                 '{value}'"
                            ),
                        ));
                    }
                }
            }
        }
        _ => unreachable!("property() is called only for PROPERTY_TAGS, which are all matched above"),
    })
}

/// The matrix of a `<transform>`: each child left-multiplies what came before, so later elements
/// apply after earlier ones (Mitsuba's order).
///
/// # Errors
/// Unknown children, malformed numbers, degenerate rotations and look-ats.
pub(super) fn transform(x: &Xml<'_>, node: El<'_>) -> Result<Transform> {
    let mut matrix = Mat4::IDENTITY;
    let mut count = 0;
    let mut lookat = None;
    for c in node.children() {
        if c.is_text() && c.text().is_some_and(|t| !t.trim().is_empty()) {
            return Err(x.err(node, "unexpected text inside the element"));
        }
        if !c.is_element() {
            continue;
        }
        count += 1;
        let step = match c.tag_name().name() {
            "translate" => {
                x.check_attrs(c, &["value", "x", "y", "z"])?;
                Mat4::from_translation(x.vec3_attrs(c, 0.0, false)?)
            }
            "scale" => {
                x.check_attrs(c, &["value", "x", "y", "z"])?;
                Mat4::from_scale(x.vec3_attrs(c, 1.0, true)?)
            }
            "rotate" => {
                x.check_attrs(c, &["value", "x", "y", "z", "angle"])?;
                let axis = x.vec3_attrs(c, 0.0, false)?;
                let angle = x.number(c, "angle", &x.required(c, "angle")?)?;
                if axis.length_squared() == 0.0 || !axis.length_squared().is_finite() {
                    return Err(x.err(c, "the rotation axis must be a non-zero vector"));
                }
                if (axis.length() - 1.0).abs() > 1e-5 {
                    x.note(
                        c,
                        format!(
                            "the rotation axis ({}, {}, {}) has length {}: as Mitsuba 3 does, the matrix is built \
                             from the axis as given (cos θ·I + (1 − cos θ)·a·aᵀ + sin θ·[a]×), which scales and \
                             shears unless the axis is a unit vector; normalise the axis for a pure rotation",
                            axis.x,
                            axis.y,
                            axis.z,
                            axis.length()
                        ),
                    );
                }
                rotation_as_given(axis, angle.to_radians())
            }
            "matrix" => {
                x.check_attrs(c, &["value"])?;
                let v = x.numbers(c, "value", &x.required(c, "value")?)?;
                match v.len() {
                    16 => Mat4::from_cols_slice(&v).transpose(),
                    9 => Mat4::from_mat3(glam::Mat3::from_cols_slice(&v).transpose()),
                    n => return Err(x.err(c, format!("a matrix needs 16 (or 9) numbers, got {n}"))),
                }
            }
            "lookat" => {
                x.check_attrs(c, &["origin", "target", "up"])?;
                let origin = x.triple(c, "origin", &x.required(c, "origin")?, false)?;
                let target = x.triple(c, "target", &x.required(c, "target")?, false)?;
                let up = match x.attr(c, "up")? {
                    Some(u) => x.triple(c, "up", &u, false)?,
                    None => Vec3::ZERO,
                };
                let (m, up) = look_at(origin, target, up).map_err(|m| x.err(c, m))?;
                lookat = Some([origin, target, up]);
                m
            }
            other => {
                return Err(x.err(
                    c,
                    format!(
                        "unsupported transform element <{other}> (supported: translate, rotate, scale, matrix, lookat)"
                    ),
                ));
            }
        };
        matrix = step * matrix;
    }
    let m = matrix.to_cols_array();
    if m.iter().any(|v| !v.is_finite()) {
        return Err(x.err(node, "the transform is not finite"));
    }
    if matrix.row(3) != Vec4::W {
        return Err(x.err(node, "projective transforms are not supported (the last row must be 0 0 0 1)"));
    }
    Ok(Transform { matrix, lookat: if count == 1 { lookat } else { None } })
}

/// Rodrigues' matrix `cos θ·I + (1 − cos θ)·a·aᵀ + sin θ·[a]×` with the axis `a` as given, as
/// Mitsuba 3 builds a `<rotate>` (it does not normalise the axis): a rotation only for a unit axis.
pub(super) fn rotation_as_given(a: Vec3, theta: f32) -> Mat4 {
    let (s, c) = theta.sin_cos();
    let k = 1.0 - c;
    let col = |e: Vec3, cross: Vec3| (a * (k * a.dot(e)) + e * c + cross * s).extend(0.0);
    Mat4::from_cols(
        col(Vec3::X, a.cross(Vec3::X)),
        col(Vec3::Y, a.cross(Vec3::Y)),
        col(Vec3::Z, a.cross(Vec3::Z)),
        Vec4::W,
    )
}

/// Mitsuba's look-at matrix: columns `left = up × dir`, `up' = dir × left`, `dir`, `origin`, so
/// that local +z looks at `target` and local +y is up. A zero `up` (the attribute left out) is
/// Mitsuba's: the first vector of its `coordinate_system(dir)` (Duff et al.'s basis, the sign of
/// dir.z taken as +1 at ±0, as Dr.Jit's `sign`). Another perpendicular would turn the frame about
/// the view: a textured spot's or projector's image, or a camera's, by a quarter turn. Returns the
/// matrix and the up vector used.
///
/// # Errors
/// Coincident origin and target, or `up` parallel to the view.
pub(super) fn look_at(origin: Vec3, target: Vec3, up: Vec3) -> std::result::Result<(Mat4, Vec3), String> {
    let dir = (target - origin).normalize_or_zero();
    if dir == Vec3::ZERO {
        return Err("lookat: origin and target coincide".into());
    }
    // Mitsuba's coordinate_system is the shading frame's (crate::sampling::Frame).
    let up = if up == Vec3::ZERO { crate::sampling::Frame::from_normal(dir).t } else { up };
    let left = up.cross(dir).normalize_or_zero();
    if left == Vec3::ZERO {
        return Err("lookat: 'up' is parallel to the viewing direction".into());
    }
    let new_up = dir.cross(left);
    Ok((Mat4::from_cols(left.extend(0.0), new_up.extend(0.0), dir.extend(0.0), origin.extend(1.0)), up))
}
