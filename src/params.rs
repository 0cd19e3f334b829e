//! `ParamTable`: every differentiable value of a scene as a named range of one `f32` array
//! (ARCHITECTURE.md decision 1). Materials and emitters refer to parameters by offset.

use std::collections::HashMap;

use crate::error::{Error, Result};

/// A handle to one parameter: its index in the table.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct ParamId(pub u32);

/// One named parameter: a slice `offset .. offset + len` of the value array.
#[derive(Clone, Debug, PartialEq)]
pub struct ParamEntry {
    /// Stable name, e.g. `red.reflectance.value`.
    pub name: String,
    /// First element in the value array.
    pub offset: u32,
    /// Number of elements (3 for RGB, 1 for scalars).
    pub len: u32,
    /// Inclusive bounds every element must stay within.
    pub bounds: (f32, f32),
}

/// The names, shapes and bounds of a scene's parameters, and their current values.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ParamTable {
    entries: Vec<ParamEntry>,
    values: Vec<f32>,
    /// Entry index by name: adding and finding are O(1), so a scene of 100 000 emitters loads in
    /// linear time.
    by_name: HashMap<String, u32>,
}

impl ParamTable {
    /// Adds a parameter with initial `values`.
    ///
    /// # Errors
    /// [`Error::Scene`] naming the parameter if the name is taken, a value is not finite or lies
    /// outside `bounds`.
    pub fn add(&mut self, name: &str, values: &[f32], bounds: (f32, f32)) -> Result<ParamId> {
        if self.by_name.contains_key(name) {
            return Err(Error::Scene { location: format!("parameter {name}"), message: "defined twice".into() });
        }
        for &v in values {
            if !v.is_finite() || v < bounds.0 || v > bounds.1 {
                return Err(Error::Scene {
                    location: format!("parameter {name}"),
                    message: format!("value {v} is outside [{}, {}]", bounds.0, bounds.1),
                });
            }
        }
        let id = ParamId(self.entries.len() as u32);
        self.by_name.insert(name.to_string(), id.0);
        self.entries.push(ParamEntry {
            name: name.to_string(),
            offset: self.values.len() as u32,
            len: values.len() as u32,
            bounds,
        });
        self.values.extend_from_slice(values);
        Ok(id)
    }

    /// The entry of `id`.
    pub fn entry(&self, id: ParamId) -> &ParamEntry {
        &self.entries[id.0 as usize]
    }

    /// Every entry in definition order.
    pub fn entries(&self) -> &[ParamEntry] {
        &self.entries
    }

    /// The flat value array that the GPU sees.
    pub fn values(&self) -> &[f32] {
        &self.values
    }

    /// The values of one parameter.
    pub fn get(&self, id: ParamId) -> &[f32] {
        let e = self.entry(id);
        &self.values[e.offset as usize..(e.offset + e.len) as usize]
    }

    /// Looks a parameter up by name.
    pub fn find(&self, name: &str) -> Option<ParamId> {
        self.by_name.get(name).map(|&i| ParamId(i))
    }

    /// Sets the values of the parameter called `name`.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for an unknown name, a wrong number of values, or values outside
    /// the parameter's bounds.
    pub fn set(&mut self, name: &str, values: &[f32]) -> Result<()> {
        let id = self.find(name).ok_or_else(|| Error::InvalidArgument {
            parameter: name.to_string(),
            message: format!(
                "no such parameter (known: {})",
                self.entries.iter().map(|e| e.name.as_str()).collect::<Vec<_>>().join(", ")
            ),
        })?;
        let e = self.entry(id).clone();
        if values.len() != e.len as usize {
            return Err(Error::InvalidArgument {
                parameter: name.to_string(),
                message: format!("expects {} values, got {}", e.len, values.len()),
            });
        }
        if let Some(v) = values.iter().find(|v| !v.is_finite() || **v < e.bounds.0 || **v > e.bounds.1) {
            return Err(Error::InvalidArgument {
                parameter: name.to_string(),
                message: format!("value {v} is outside [{}, {}]", e.bounds.0, e.bounds.1),
            });
        }
        self.values[e.offset as usize..(e.offset + e.len) as usize].copy_from_slice(values);
        Ok(())
    }
}

impl ParamTable {
    /// The parameters whose names match any of `patterns` (`*` matches any run of characters, `?`
    /// one character), in table order.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming a pattern that matches nothing.
    pub fn select(&self, patterns: &[&str]) -> Result<Vec<ParamId>> {
        let mut chosen = Vec::new();
        for pattern in patterns {
            let before = chosen.len();
            for (i, e) in self.entries.iter().enumerate() {
                if glob_match(pattern, &e.name) && !chosen.contains(&ParamId(i as u32)) {
                    chosen.push(ParamId(i as u32));
                }
            }
            if chosen.len() == before && !self.entries.iter().any(|e| glob_match(pattern, &e.name)) {
                // Mitsuba exposes indices of refraction; pathgrad does not (yet).
                let last = pattern.rsplit('.').find(|p| *p != "value").unwrap_or("");
                let ior = if matches!(last, "eta" | "k" | "int_ior" | "ext_ior" | "specular") {
                    ": smooth `dielectric`s and `thindielectric`s expose their index of refraction as NAME.eta \
                     (it acts through the directions it refracts into: differentiable with attached sampling, \
                     --sampling attached), `conductor`s and `roughconductor`s their complex one as \
                     NAME.eta.value and NAME.k.value (RGB; they act on the weight: differentiable in both \
                     modes); rough dielectrics', plastics' and principled BSDFs' are not parameters"
                } else if pattern.contains("normalmap") || pattern.contains("nested_texture") {
                    ": a normal or bump map's texels are not parameters in pathgrad (they move the shading \
                     frame, whose derivative is not built; Mitsuba's `normalmap.data`, `nested_texture.data`); \
                     the nested BSDF's parameters (`….nested_bsdf.…`) are"
                } else if matches!(
                    last,
                    "control_points"
                        | "segment_indices"
                        | "control_point_count"
                        | "vertex_positions"
                        | "vertex_normals"
                        | "vertex_texcoords"
                        | "faces"
                        | "grid"
                        | "to_world"
                ) {
                    ": geometry is fixed in pathgrad (Mitsuba's curve control points, mesh vertices, SDF \
                     grids and shapes' to_world are parameters there, not here); materials' and emitters' \
                     values are"
                } else {
                    ""
                };
                return Err(Error::InvalidArgument {
                    parameter: pattern.to_string(),
                    message: format!(
                        "matches no parameter{ior} (known: {})",
                        self.entries.iter().map(|e| e.name.as_str()).collect::<Vec<_>>().join(", ")
                    ),
                });
            }
        }
        chosen.sort_by_key(|p| p.0);
        Ok(chosen)
    }
}

/// Whether `name` matches the glob `pattern` (`*` any run, `?` one character).
pub fn glob_match(pattern: &str, name: &str) -> bool {
    let (p, n): (Vec<char>, Vec<char>) = (pattern.chars().collect(), name.chars().collect());
    let (mut pi, mut ni, mut star, mut mark) = (0, 0, None, 0);
    while ni < n.len() {
        if pi < p.len() && (p[pi] == '?' || p[pi] == n[ni]) {
            pi += 1;
            ni += 1;
        } else if pi < p.len() && p[pi] == '*' {
            star = Some(pi);
            mark = ni;
            pi += 1;
        } else if let Some(sp) = star {
            pi = sp + 1;
            mark += 1;
            ni = mark;
        } else {
            return false;
        }
    }
    p[pi..].iter().all(|&c| c == '*')
}

/// A gradient with the layout of a [`ParamTable`]: one value per parameter value.
///
/// Deterministic gradients also keep the exact sums they were rounded from (64-bit fixed point
/// on a GPU, f64 on the CPU reference), so that [`Gradients::mean`] of several — the views of a
/// step, the items of a batch — is exact, and equal bit for bit to the same sum taken in one pass.
#[derive(Clone, Debug, PartialEq)]
pub struct Gradients {
    entries: Vec<ParamEntry>,
    values: Vec<f32>,
    exact: Option<Exact>,
}

/// The exact sums behind a gradient's values.
#[derive(Clone, Debug, PartialEq)]
enum Exact {
    /// Integer sums; a value is `sum · unit`.
    Fixed { sums: Vec<i64>, unit: f64 },
    /// f64 sums (the CPU reference's fixed-order sums).
    Wide(Vec<f64>),
}

impl Gradients {
    /// Wraps `values` laid out as `table`.
    ///
    /// # Panics
    /// If the lengths differ (an internal invariant: gradients are made by the renderers).
    pub fn new(table: &ParamTable, values: Vec<f32>) -> Gradients {
        assert_eq!(values.len(), table.values().len(), "a gradient has one value per parameter value");
        Gradients { entries: table.entries().to_vec(), values, exact: None }
    }

    /// A gradient of fixed-point sums: value i is `sums[i] · unit`.
    pub(crate) fn from_fixed(table: &ParamTable, sums: Vec<i64>, unit: f64) -> Gradients {
        let values = sums.iter().map(|&v| (v as f64 * unit) as f32).collect();
        Gradients { exact: Some(Exact::Fixed { sums, unit }), ..Gradients::new(table, values) }
    }

    /// A gradient of f64 sums.
    pub(crate) fn from_wide(table: &ParamTable, sums: Vec<f64>) -> Gradients {
        let values = sums.iter().map(|&v| v as f32).collect();
        Gradients { exact: Some(Exact::Wide(sums)), ..Gradients::new(table, values) }
    }

    /// The gradient of the parameter called `name`.
    pub fn get(&self, name: &str) -> Option<&[f32]> {
        self.entries
            .iter()
            .find(|e| e.name == name)
            .map(|e| &self.values[e.offset as usize..(e.offset + e.len) as usize])
    }

    /// Every value, in the parameter table's layout.
    pub fn values(&self) -> &[f32] {
        &self.values
    }

    /// The parameter entries.
    pub fn entries(&self) -> &[ParamEntry] {
        &self.entries
    }

    /// Checks that the gradient is laid out as `table`.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `gradients` if the layouts differ.
    pub fn check_layout(&self, table: &ParamTable) -> Result<()> {
        if self.entries != table.entries() {
            return Err(Error::InvalidArgument {
                parameter: "gradients".into(),
                message: "the gradient's layout differs from the parameter table's".into(),
            });
        }
        Ok(())
    }

    /// The fixed-point sums and their unit, for a deterministic GPU gradient.
    pub fn fixed_point(&self) -> Option<(&[i64], f64)> {
        match &self.exact {
            Some(Exact::Fixed { sums, unit }) => Some((sums, *unit)),
            _ => None,
        }
    }

    /// The mean of `parts` (one layout), summed in their order: exactly (integer or f64 sums)
    /// when every part keeps exact sums of one kind, else in f64 from the f32 values.
    ///
    /// ```
    /// use pathgrad::params::{Gradients, ParamTable};
    /// let mut table = ParamTable::default();
    /// table.add("w", &[0.5], (0.0, 1.0))?;
    /// let mean = Gradients::mean(&[Gradients::new(&table, vec![1.0]), Gradients::new(&table, vec![2.0])])?;
    /// assert_eq!(mean.values(), &[1.5]);
    /// # Ok::<(), pathgrad::Error>(())
    /// ```
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for no parts or parts of different layouts; [`Error::Numeric`]
    /// if a fixed-point sum overflows.
    pub fn mean(parts: &[Gradients]) -> Result<Gradients> {
        Gradients::sum_divided(parts, parts.len())
    }

    /// The sum of `parts` divided by `count`, as [`Gradients::mean`] takes it (the mean of the
    /// `count` views a multi-view pass summed).
    pub(crate) fn sum_divided(parts: &[Gradients], count: usize) -> Result<Gradients> {
        let bad = |m: String| Err(Error::InvalidArgument { parameter: "gradients".into(), message: m });
        let Some(first) = parts.first() else { return bad("a mean of no gradients".into()) };
        if let Some(other) = parts.iter().find(|g| g.entries != first.entries) {
            return bad(format!(
                "gradients of different parameter tables ({} and {} entries)",
                first.entries.len(),
                other.entries.len()
            ));
        }
        let n = first.values.len();
        let divisor = count as f64;
        let fixed: Option<Vec<(&[i64], f64)>> = parts.iter().map(Gradients::fixed_point).collect();
        if let Some(fixed) = fixed
            && fixed.iter().all(|&(_, unit)| unit == fixed[0].1)
        {
            let mut sums = vec![0i64; n];
            for (part, _) in &fixed {
                for (s, &v) in sums.iter_mut().zip(part.iter()) {
                    *s = s.checked_add(v).ok_or_else(|| Error::Numeric {
                        kernel: "gradient mean",
                        message: "a fixed-point gradient sum overflowed 64 bits".into(),
                    })?;
                }
            }
            let unit = fixed[0].1 / divisor;
            let values = sums.iter().map(|&v| (v as f64 * unit) as f32).collect();
            return Ok(Gradients { entries: first.entries.clone(), values, exact: Some(Exact::Fixed { sums, unit }) });
        }
        let wide: Option<Vec<&Vec<f64>>> = parts
            .iter()
            .map(|g| match &g.exact {
                Some(Exact::Wide(v)) => Some(v),
                _ => None,
            })
            .collect();
        let mut sums = vec![0f64; n];
        match wide {
            Some(wide) => {
                for part in wide {
                    sums.iter_mut().zip(part).for_each(|(s, v)| *s += v);
                }
                let means: Vec<f64> = sums.iter().map(|s| s / divisor).collect();
                let values = means.iter().map(|&v| v as f32).collect();
                Ok(Gradients { entries: first.entries.clone(), values, exact: Some(Exact::Wide(means)) })
            }
            None => {
                for part in parts {
                    sums.iter_mut().zip(&part.values).for_each(|(s, &v)| *s += f64::from(v));
                }
                let values = sums.iter().map(|s| (s / divisor) as f32).collect();
                Ok(Gradients { entries: first.entries.clone(), values, exact: None })
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn entries_are_contiguous_ranges_of_one_array() {
        let mut t = ParamTable::default();
        let a = t.add("a.reflectance.value", &[0.1, 0.2, 0.3], (0.0, 1.0)).unwrap();
        let b = t.add("b.alpha.value", &[0.5], (1e-3, 1.0)).unwrap();
        assert_eq!(t.entry(a).offset, 0);
        assert_eq!(t.entry(b).offset, 3);
        assert_eq!(t.values(), &[0.1, 0.2, 0.3, 0.5]);
        t.set("b.alpha.value", &[0.25]).unwrap();
        assert_eq!(t.get(b), &[0.25]);
    }

    #[test]
    fn bad_values_are_rejected_with_the_name() {
        let mut t = ParamTable::default();
        let e = t.add("x.alpha.value", &[0.0], (1e-3, 1.0)).unwrap_err().to_string();
        assert!(e.contains("x.alpha.value") && e.contains("outside"), "{e}");
        t.add("y", &[1.0], (0.0, 2.0)).unwrap();
        assert!(t.set("y", &[f32::NAN]).is_err());
        assert!(t.set("y", &[1.0, 2.0]).unwrap_err().to_string().contains("expects 1"));
        assert!(t.set("z", &[1.0]).unwrap_err().to_string().contains("no such parameter"));
    }

    #[test]
    fn globs_select_parameters() {
        assert!(glob_match("*.alpha.value", "sphere.bsdf.alpha.value"));
        assert!(glob_match("s?here.*", "sphere.bsdf.alpha.value"));
        assert!(!glob_match("*.alpha", "sphere.bsdf.alpha.value"));
        let mut t = ParamTable::default();
        t.add("a.alpha.value", &[0.1], (0.0, 1.0)).unwrap();
        t.add("b.reflectance.value", &[0.1; 3], (0.0, 1.0)).unwrap();
        t.add("c.alpha.value", &[0.1], (0.0, 1.0)).unwrap();
        assert_eq!(t.select(&["*.alpha.value"]).unwrap(), vec![ParamId(0), ParamId(2)]);
        assert!(t.select(&["nope*"]).unwrap_err().to_string().contains("matches no parameter"));
        // Indices of refraction: which BSDFs expose theirs, and under which names.
        let e = t.select(&["ball.bsdf.k.value"]).unwrap_err().to_string();
        assert!(e.contains("NAME.eta.value and NAME.k.value") && e.contains("both modes"), "{e}");
        let e = t.select(&["glass.bsdf.int_ior"]).unwrap_err().to_string();
        assert!(e.contains("as NAME.eta") && e.contains("--sampling attached"), "{e}");
        // Mitsuba's geometry keys are refused by name.
        for key in ["curve.control_points", "mesh.vertex_positions", "sdf.grid", "sdf.to_world"] {
            let e = t.select(&[key]).unwrap_err().to_string();
            assert!(e.contains(key) && e.contains("geometry is fixed in pathgrad"), "{e}");
        }
    }
}
