//! `pathgrad params`: a scene's differentiable parameters and its sensors.

use anyhow::Result;
use pathgrad::scene::Lens;

pub(crate) fn params(spec: &str, defines: &[(String, String)], json: bool, allow_outside_folder: bool) -> Result<()> {
    let options =
        pathgrad::scene::LoadOptions { defines: defines.to_vec(), allow_outside_folder, ..Default::default() };
    let scene = pathgrad::scene::load_with(spec, &options)?;
    let table = &scene.params;
    if json {
        let items: Vec<serde_json::Value> = table
            .entries()
            .iter()
            .map(|e| {
                let values = &table.values()[e.offset as usize..(e.offset + e.len) as usize];
                // JSON has no infinity: an open upper bound is null.
                let upper = e.bounds.1.is_finite().then_some(e.bounds.1);
                serde_json::json!({"name": e.name, "size": e.len, "bounds": [e.bounds.0, upper], "values": values})
            })
            .collect();
        let sensors: Vec<serde_json::Value> = scene
            .sensors
            .iter()
            .enumerate()
            .map(|(i, s)| {
                let c = &s.camera;
                let lens = match c.lens {
                    Lens::Pinhole => serde_json::json!({"kind": "pinhole"}),
                    Lens::Thin { aperture_radius, focus_distance } => serde_json::json!({"kind": "thin",
                        "aperture_radius": aperture_radius, "focus_distance": focus_distance}),
                    Lens::Orthographic { half_height, stretch, near_clip } => serde_json::json!({
                        "kind": "orthographic", "half_height": half_height, "stretch": stretch, "near_clip": near_clip}),
                };
                serde_json::json!({"index": i, "name": s.name, "position": c.position.to_array(),
                    "target": c.target.to_array(), "up": c.up.to_array(), "fov_y_degrees": c.fov_y_degrees,
                    "width": c.width, "height": c.height, "lens": lens,
                    "window": {"min": c.window.min.to_array(), "max": c.window.max.to_array()}})
            })
            .collect();
        println!("{}", serde_json::to_string_pretty(&serde_json::json!({"params": items, "sensors": sensors}))?);
    } else {
        for e in table.entries() {
            let values = &table.values()[e.offset as usize..(e.offset + e.len) as usize];
            let shown = if values.len() <= 4 {
                format!("{values:?}")
            } else {
                let mean = values.iter().map(|&v| f64::from(v)).sum::<f64>() / values.len() as f64;
                format!("[{} values, mean {mean:.4}]", values.len())
            };
            println!("{:<48} {:>8}  [{}, {}]  {shown}", e.name, e.len, e.bounds.0, e.bounds.1);
        }
        println!("sensors (--sensor INDEX|NAME; the first is the default):");
        for (i, s) in scene.sensors.iter().enumerate() {
            let c = &s.camera;
            let projection = match c.lens {
                Lens::Pinhole => format!("fov_y {:.2}°", c.fov_y_degrees),
                Lens::Thin { aperture_radius, focus_distance } => format!(
                    "fov_y {:.2}°, thin lens of radius {aperture_radius} in focus at {focus_distance}",
                    c.fov_y_degrees
                ),
                Lens::Orthographic { half_height, .. } => format!("orthographic, {:.3} high", 2.0 * half_height),
            };
            let window = if c.window.is_whole() {
                String::new()
            } else {
                let (w, h) = c.film_size(c.width, c.height);
                format!(", cropped at ({:.0}, {:.0}) from a {w:.0}×{h:.0} film", c.window.min.x * w, c.window.min.y * h)
            };
            println!(
                "  {i}: {:<24} at {:?} towards {:?}, {projection}, {}×{}{window}",
                s.name,
                c.position.to_array(),
                c.target.to_array(),
                c.width,
                c.height
            );
        }
    }
    Ok(())
}
