//! glTF binary data: buffers (GLB chunk, data URIs, files beside the scene), views and accessors.

use std::path::Path;

use ::gltf::json;
use json::validation::Checked;

use crate::error::Result;

use super::*;

impl Loader<'_> {
    /// The bytes of buffer `index`, loaded on first use.
    pub(super) fn buffer(&mut self, index: usize) -> Result<&[u8]> {
        let root = self.root;
        if self.buffers[index].is_none() {
            let buffer = &root.buffers[index];
            let at = format!("buffers[{index}]");
            let data = match (&buffer.uri, self.blob) {
                (Some(uri), _) => self.read_uri(&at, uri)?,
                (None, Some(blob)) if index == 0 => blob.to_vec(),
                (None, _) => return Err(self.error(at, "has no uri and the file has no GLB binary chunk")),
            };
            if (data.len() as u64) < buffer.byte_length.0 {
                return Err(self
                    .error(at, format!("holds {} bytes but its byteLength is {}", data.len(), buffer.byte_length.0)));
            }
            self.buffers[index] = Some(data);
        }
        Ok(self.buffers[index].as_deref().expect("loaded above"))
    }

    /// The bytes a URI names: a base64 `data:` URI, or a file relative to the glTF file.
    pub(super) fn read_uri(&self, at: &str, uri: &str) -> Result<Vec<u8>> {
        if let Some(rest) = uri.strip_prefix("data:") {
            let data = rest.split_once(";base64,").map(|(_, d)| d);
            return data
                .and_then(decode_base64)
                .ok_or_else(|| self.error(at, "data URI is not base64 ('data:<type>;base64,<data>')"));
        }
        if uri.split('/').next().is_some_and(|first| first.contains(':')) {
            return Err(self.error(at, format!("URI '{uri}': only relative paths and data: URIs are supported")));
        }
        let relative = percent_decode(uri)
            .ok_or_else(|| self.error(at, format!("URI '{uri}' is not valid percent-encoded UTF-8")))?;
        let dir = self.path.parent().unwrap_or(Path::new("."));
        let file = crate::scene::load::scene_file(dir, &relative, self.allow_outside_folder)
            .map_err(|m| self.error(at, format!("URI {m}")))?;
        std::fs::read(&file).map_err(|e| self.error(at, format!("cannot read '{relative}': {e}")))
    }

    /// The bytes of buffer view `index` and its stride.
    pub(super) fn view(&mut self, index: usize, at: &str) -> Result<(&[u8], Option<usize>)> {
        let (root, path) = (self.root, self.path);
        let view = &root.buffer_views[index];
        let (offset, length) = (view.byte_offset.map_or(0, |o| o.0), view.byte_length.0);
        let stride = view.byte_stride.map(|s| s.0).filter(|&s| s > 0);
        let buffer_index = view.buffer.value();
        let data = self.buffer(buffer_index)?;
        let end = offset.checked_add(length).filter(|&e| e <= data.len() as u64).ok_or_else(|| {
            located(
                path,
                format!("bufferViews[{index}] ({at})"),
                format!(
                    "bytes {offset}..{} lie outside buffers[{buffer_index}], which has {} bytes",
                    offset.saturating_add(length),
                    data.len()
                ),
            )
        })?;
        Ok((&data[offset as usize..end as usize], stride))
    }

    /// The elements of accessor `index` as `count × dims` raw component bytes, with the component
    /// type. An accessor without a buffer view is all zeros (glTF 2.0 §3.6.2.1).
    pub(super) fn accessor_components(
        &mut self,
        index: usize,
        dims: usize,
        what: &str,
    ) -> Result<(Vec<u8>, json::accessor::ComponentType, bool)> {
        let root = self.root;
        let accessor = &root.accessors[index];
        let at = format!("accessors[{index}] ({what})");
        if accessor.sparse.is_some() {
            return Err(self.error(at, "sparse accessors are not supported"));
        }
        let component = match accessor.component_type {
            Checked::Valid(json::accessor::GenericComponentType(c)) => c,
            Checked::Invalid => return Err(self.error(at, "invalid componentType")),
        };
        let actual_dims = match accessor.type_ {
            Checked::Valid(t) => t.multiplicity(),
            Checked::Invalid => return Err(self.error(at, "invalid type")),
        };
        if actual_dims != dims {
            let name =
                |n: usize| ["SCALAR", "VEC2", "VEC3", "VEC4"].get(n.wrapping_sub(1)).copied().unwrap_or("a matrix");
            return Err(self.error(at, format!("expected type {}, found {}", name(dims), name(actual_dims))));
        }
        let count = accessor.count.0 as usize;
        let size = component.size() * dims;
        let Some(view) = accessor.buffer_view else {
            return Ok((vec![0; count.saturating_mul(size)], component, accessor.normalized));
        };
        let offset = accessor.byte_offset.map_or(0, |o| o.0) as usize;
        let normalized = accessor.normalized;
        let path = self.path;
        let err = |message: String| located(path, &at, message);
        let (data, stride) = self.view(view.value(), &at)?;
        let stride = stride.unwrap_or(size);
        if stride < size {
            return Err(err(format!("byteStride {stride} is smaller than an element ({size} bytes)")));
        }
        let end = if count == 0 {
            Some(offset)
        } else {
            stride.checked_mul(count - 1).and_then(|s| s.checked_add(offset)).and_then(|s| s.checked_add(size))
        };
        match end {
            Some(end) if end <= data.len() => {}
            _ => {
                return Err(err(format!(
                    "{count} elements of {size} bytes from offset {offset} (stride {stride}) do not fit in bufferViews[{}], which has {} bytes",
                    view.value(),
                    data.len()
                )));
            }
        }
        let mut out = Vec::with_capacity(count * size);
        for i in 0..count {
            out.extend_from_slice(&data[offset + i * stride..offset + i * stride + size]);
        }
        Ok((out, component, normalized))
    }

    /// Accessor `index` as floats: FLOAT, or (when `allow_normalized`) normalized unsigned bytes/shorts.
    pub(super) fn read_floats(
        &mut self,
        index: usize,
        dims: usize,
        allow_normalized: bool,
        what: &str,
    ) -> Result<Vec<f32>> {
        use json::accessor::ComponentType as C;
        let (bytes, component, normalized) = self.accessor_components(index, dims, what)?;
        let values: Vec<f32> = match component {
            C::F32 => bytes.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect(),
            C::U8 if allow_normalized && normalized => bytes.iter().map(|&b| f32::from(b) / 255.0).collect(),
            C::U16 if allow_normalized && normalized => {
                bytes.chunks_exact(2).map(|b| f32::from(u16::from_le_bytes([b[0], b[1]])) / 65535.0).collect()
            }
            other => {
                let allowed =
                    if allow_normalized { "FLOAT or normalized UNSIGNED_BYTE/UNSIGNED_SHORT" } else { "FLOAT" };
                return Err(self.error(
                    format!("accessors[{index}] ({what})"),
                    format!(
                        "componentType {other:?}{} is not supported here (expected {allowed})",
                        if normalized { " normalized" } else { "" }
                    ),
                ));
            }
        };
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            return Err(
                self.error(format!("accessors[{index}] ({what})"), format!("element {} is not finite", i / dims))
            );
        }
        Ok(values)
    }

    /// Accessor `index` as vertex indices (UNSIGNED_BYTE, UNSIGNED_SHORT or UNSIGNED_INT scalars).
    pub(super) fn read_indices(&mut self, index: usize, what: &str) -> Result<Vec<u32>> {
        use json::accessor::ComponentType as C;
        let (bytes, component, _) = self.accessor_components(index, 1, what)?;
        Ok(match component {
            C::U8 => bytes.iter().map(|&b| u32::from(b)).collect(),
            C::U16 => bytes.chunks_exact(2).map(|b| u32::from(u16::from_le_bytes([b[0], b[1]]))).collect(),
            C::U32 => bytes.chunks_exact(4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect(),
            other => {
                return Err(self.error(
                    format!("accessors[{index}] ({what})"),
                    format!("componentType {other:?} cannot hold indices (expected UNSIGNED_BYTE, UNSIGNED_SHORT or UNSIGNED_INT)"),
                ));
            }
        })
    }

    // ---- materials ----
}
