//! Mitsuba's `mesh_attribute` texture: a colour or value read from an attribute of the mesh whose BSDF holds it.

use roxmltree::NodeId;

use super::loader::Loader;
use super::xml::{El, Props};
use crate::error::Result;
use crate::params::ParamId;
use crate::scene::AttributeSource;
use crate::scene::shapes::MeshAttribute;

/// The shape whose BSDF is being built, for the `mesh_attribute` textures in it.
pub(super) struct AttributeShape {
    /// The shape's name (its parameters' prefix).
    pub name: String,
    /// The index its mesh will have in [`crate::scene::Scene::meshes`].
    pub mesh: u32,
    /// The mesh's attributes (none for a file format without them).
    pub attributes: Vec<MeshAttribute>,
}

/// BSDFs and textures nest at most this deep on the way to a `mesh_attribute` (as they are built).
const MAX_WALK: usize = 32;

impl<'a> Loader<'a> {
    /// Whether `node`, what it holds or what its `<ref>`s reach is a `mesh_attribute` texture: such
    /// an object is built for each shape that refers to it, not at scene level.
    pub(super) fn reads_mesh_attribute(&self, node: El<'a>) -> bool {
        fn walk<'a>(l: &Loader<'a>, node: El<'a>, depth: usize, seen: &mut Vec<NodeId>) -> bool {
            if depth > MAX_WALK || seen.contains(&node.id()) {
                return false;
            }
            seen.push(node.id());
            if node.has_tag_name("texture") && node.attribute("type") == Some("mesh_attribute") {
                return true;
            }
            if node.has_tag_name("ref") {
                return l.deref(node).is_ok_and(|t| walk(l, t, depth + 1, seen));
            }
            node.children().filter(|c| c.is_element()).any(|c| walk(l, c, depth + 1, seen))
        }
        walk(self, node, 0, &mut Vec::new())
    }

    /// Mitsuba's `mesh_attribute` (`p`, at `node`) read as `dim` values (3: a colour, 1: a scalar)
    /// in `range`: the attribute `name` of the shape being built becomes the parameter
    /// `SHAPE.NAME` (Mitsuba's `traverse` key of the mesh's attribute, which it exposes as
    /// differentiable), read per triangle (`face_…`) or interpolated between the hit triangle's
    /// vertices (`vertex_…`).
    ///
    /// # Errors
    /// A missing or malformed `name`, a `scale` other than 1, a texture outside a mesh's BSDF, a
    /// mesh without the attribute, an attribute of another size, values outside `range`.
    pub(super) fn mesh_attribute(
        &mut self,
        p: &Props<'a>,
        dim: u32,
        range: (f32, f32),
    ) -> Result<(ParamId, AttributeSource)> {
        let node = p.node;
        let (attr, attr_node) =
            p.string(&self.x, "name")?.ok_or_else(|| self.x.err(node, "'mesh_attribute' needs the property 'name'"))?;
        if !attr.contains("vertex_") && !attr.contains("face_") {
            return Err(self.x.err(
                attr_node,
                format!("invalid mesh attribute name '{attr}': it must start with 'vertex_' or 'face_'"),
            ));
        }
        if let Some((scale, n)) = p.float(&self.x, "scale")?
            && scale != 1.0
        {
            return Err(self.x.err(
                n,
                format!(
                    "a 'mesh_attribute' 'scale' other than 1 is not supported (got {scale}): pathgrad's parameter is \
                     the attribute itself"
                ),
            ));
        }
        self.finish(p)?;
        let Some(shape) = &self.attribute_shape else {
            return Err(self.x.err(node, "a 'mesh_attribute' texture is read only in the BSDF of a mesh shape"));
        };
        let Some(found) = shape.attributes.iter().find(|a| a.name == attr) else {
            let have: Vec<&str> = shape.attributes.iter().map(|a| a.name.as_str()).collect();
            let have = if have.is_empty() { "none".to_string() } else { have.join(", ") };
            return Err(self.x.err(
                attr_node,
                format!("shape '{}' has no mesh attribute '{attr}' (its attributes: {have})", shape.name),
            ));
        };
        if found.dim != dim {
            let what = if dim == 3 { "a colour needs 3 values" } else { "a float property needs 1 value" };
            return Err(self.x.err(
                attr_node,
                format!("mesh attribute '{attr}' of shape '{}' has {} values a row: {what}", shape.name, found.dim),
            ));
        }
        if let Some(k) = found.values.iter().position(|v| !(*v >= range.0 && *v <= range.1)) {
            let row = k / dim as usize;
            let what = if found.per_vertex { "vertex" } else { "triangle" };
            return Err(self.x.err(
                attr_node,
                format!(
                    "mesh attribute '{attr}' of shape '{}': {what} {row} has the value {} outside [{}, {}]",
                    shape.name, found.values[k], range.0, range.1
                ),
            ));
        }
        let source = AttributeSource { mesh: shape.mesh, per_vertex: found.per_vertex };
        let name = format!("{}.{attr}", shape.name);
        let id = match self.scene.params.find(&name) {
            Some(id) => id,
            None => {
                let values = found.values.clone();
                self.scene.params.add(&name, &values, range).map_err(|e| self.located(node, e))?
            }
        };
        self.attribute_reads += 1;
        Ok((id, source))
    }
}
