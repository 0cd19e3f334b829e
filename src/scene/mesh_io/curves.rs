//! Mitsuba's curve files (`linearcurve`, `bsplinecurve`): one control point `x y z radius` a
//! line, curves separated by blank lines.

use std::path::Path;

use glam::Vec4;

use super::{read_file, scene_error};
use crate::error::Result;

/// The curves of a curve file, each as its control points `(x, y, z, radius)` in file order.
///
/// The format is Mitsuba's (`src/shapes/linearcurve.cpp`): a line of four numbers is a control
/// point, a line holding only spaces or tabs ends the current curve, and a curve needs at least
/// `min_points` control points (2 for a linear curve, 4 for a cubic B-spline). Stricter than
/// Mitsuba, which reads the first four numbers of a line and ignores the rest, a line with more
/// than four fields is an error, as is a negative radius (Mitsuba passes it on to Embree).
///
/// ```
/// # let dir = std::env::temp_dir().join(format!("pathgrad-curves-doc-{}", std::process::id()));
/// # std::fs::create_dir_all(&dir).unwrap();
/// let path = dir.join("two.txt");
/// std::fs::write(&path, "0 0 0 0.1\n1 0 0 0.1\n\n0 1 0 0.2\n1 1 0 0.3\n2 1 0 0.2\n")?;
/// let curves = pathgrad::scene::mesh_io::load_curves(&path, 2)?;
/// assert_eq!(curves.len(), 2);
/// assert_eq!(curves[1].len(), 3);
/// assert_eq!(curves[1][1].w, 0.3);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
///
/// # Errors
/// [`Error::Io`](crate::Error::Io) if the file cannot be read; [`Error::Scene`](crate::Error::Scene)
/// at `file:line` for a line that is not four finite numbers, a negative radius, or a curve with
/// fewer than `min_points` control points (at its first line); at `file` for a file without
/// control points.
pub fn load_curves(path: &Path, min_points: usize) -> Result<Vec<Vec<Vec4>>> {
    let bytes = read_file(path)?;
    let text = std::str::from_utf8(&bytes).map_err(|e| scene_error(path, None, format!("not UTF-8 text ({e})")))?;
    let mut curves: Vec<Vec<Vec4>> = Vec::new();
    // The current curve and the line it started on.
    let mut current: Option<(Vec<Vec4>, usize)> = None;
    let finish = |curve: Option<(Vec<Vec4>, usize)>, curves: &mut Vec<Vec<Vec4>>| -> Result<()> {
        if let Some((points, first_line)) = curve {
            if points.len() < min_points {
                return Err(scene_error(
                    path,
                    Some(first_line),
                    format!("a curve needs at least {min_points} control points, this one has {}", points.len()),
                ));
            }
            curves.push(points);
        }
        Ok(())
    };
    for (i, line) in text.lines().enumerate() {
        let number = i + 1;
        let fields: Vec<&str> = line.split([' ', '\t', '\r']).filter(|f| !f.is_empty()).collect();
        if fields.is_empty() {
            finish(current.take(), &mut curves)?;
            continue;
        }
        if fields.len() != 4 {
            return Err(scene_error(
                path,
                Some(number),
                format!("a control point is four numbers 'x y z radius', this line has {} fields", fields.len()),
            ));
        }
        let mut v = [0.0f32; 4];
        for (slot, field) in v.iter_mut().zip(&fields) {
            *slot = match field.parse::<f32>() {
                Ok(x) if x.is_finite() => x,
                _ => return Err(scene_error(path, Some(number), format!("'{field}' is not a finite number"))),
            };
        }
        if v[3] < 0.0 {
            return Err(scene_error(path, Some(number), format!("the radius must be ≥ 0, got {}", v[3])));
        }
        current.get_or_insert_with(|| (Vec::new(), number)).0.push(Vec4::from_array(v));
    }
    finish(current.take(), &mut curves)?;
    if curves.is_empty() {
        return Err(scene_error(path, None, "no control points (an empty curve file)"));
    }
    Ok(curves)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn load(name: &str, text: &str, min_points: usize) -> Result<Vec<Vec<Vec4>>> {
        let dir = std::env::temp_dir().join(format!("pathgrad-curves-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        load_curves(&path, min_points)
    }

    fn message(e: crate::Error) -> String {
        e.to_string()
    }

    #[test]
    fn curves_split_at_blank_lines() {
        let c = load("split.txt", "\n0 0 0 1\n1 0 0 1\n \t\n\n2 0 0 0.5\r\n3 0 0 0.25\r\n4 0 0 0\n\n", 2).unwrap();
        assert_eq!(c.len(), 2);
        assert_eq!(c[0], vec![Vec4::new(0.0, 0.0, 0.0, 1.0), Vec4::new(1.0, 0.0, 0.0, 1.0)]);
        assert_eq!(c[1].len(), 3);
        assert_eq!(c[1][2], Vec4::new(4.0, 0.0, 0.0, 0.0));
    }

    #[test]
    fn bad_lines_are_located() {
        let e = message(load("three.txt", "0 0 0 1\n1 0 0\n", 2).unwrap_err());
        assert!(e.contains("three.txt:2") && e.contains("has 3 fields"), "{e}");
        let e = message(load("nan.txt", "0 0 0 1\n1 0 nan 1\n", 2).unwrap_err());
        assert!(e.contains("nan.txt:2") && e.contains("'nan' is not a finite number"), "{e}");
        let e = message(load("word.txt", "0 0 0 1\n1 0 0 1\n\n1 0 x 1\n", 2).unwrap_err());
        assert!(e.contains("word.txt:4") && e.contains("'x'"), "{e}");
        let e = message(load("neg.txt", "0 0 0 1\n1 0 0 -1\n", 2).unwrap_err());
        assert!(e.contains("neg.txt:2") && e.contains("radius must be ≥ 0"), "{e}");
    }

    #[test]
    fn short_and_empty_files_are_refused() {
        let e = message(load("short.txt", "0 0 0 1\n1 0 0 1\n\n\n5 0 0 1\n", 2).unwrap_err());
        assert!(e.contains("short.txt:5") && e.contains("at least 2 control points, this one has 1"), "{e}");
        let e = message(load("cubic.txt", "0 0 0 1\n1 0 0 1\n2 0 0 1\n", 4).unwrap_err());
        assert!(e.contains("cubic.txt:1") && e.contains("at least 4"), "{e}");
        let e = message(load("empty.txt", "\n  \n", 2).unwrap_err());
        assert!(e.contains("empty.txt") && e.contains("no control points"), "{e}");
    }
}
