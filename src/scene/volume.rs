//! Voxel grids in Mitsuba's `.vol` format (version 3, float32), read and written, with Mitsuba's
//! trilinear lookup.
//!
//! The layout (little-endian): the bytes `VOL` and the version byte 3; int32 encoding (1:
//! float32); int32 resolutions x, y, z; int32 channel count; six float32 of a bounding box (min
//! then max, which Mitsuba's `gridvolume` ignores in favour of `to_world`); then x·y·z·channels
//! float32 values, x fastest, a voxel's channels together. Checked against Mitsuba 3.9.1's
//! `VolumeGrid.write` (the header and the order of a 2×3×4 grid) and its `gridvolume` lookup.
//!
//! Every check happens before anything large is allocated: the header's sizes must agree with the
//! file's length, so a short file cannot ask for gigabytes. Errors name the file.
//!
//! The Mitsuba loader reads `gridvolume` files with [`Grid::read`] (`scene/mitsuba/media.rs`); the
//! scene's media (`scene/medium.rs`) and the CPU reference (`cpu/medium.rs`) look values up with
//! [`lookup`], whose GLSL twin is the kernels' `field_rgb` (`shaders/lib/field.glsl`); so do
//! surfaces' `volume` textures.

use std::path::Path;

use glam::{UVec3, Vec3};

use crate::error::{Error, Result};
use crate::scene::Wrap;

/// Bytes before the values.
const HEADER_BYTES: usize = 48;
/// The only encoding read: float32.
const ENCODING_FLOAT32: i32 = 1;
/// The format version read and written.
const VERSION: u8 = 3;
/// At most this many values (4 GiB of float32): a larger grid is refused as absurd.
pub const MAX_VALUES: u64 = 1 << 30;

/// A grid of `channels` values per voxel over the unit cube.
#[derive(Clone, Debug, PartialEq)]
pub struct Grid {
    /// Voxels along x, y and z (each at least 1).
    pub resolution: UVec3,
    /// Values per voxel: 1 (density) or 3 (RGB albedo or σ_t).
    pub channels: u32,
    /// The file's bounding box (min, max); kept for writing back, not used by lookups.
    pub bbox: (Vec3, Vec3),
    /// `resolution.x · resolution.y · resolution.z · channels` values, x fastest.
    pub values: Vec<f32>,
}

fn vol_error(path: &Path, message: impl Into<String>) -> Error {
    Error::Scene { location: path.display().to_string(), message: message.into() }
}

impl Grid {
    /// A grid of `resolution` voxels with `channels` values each, from `values` (x fastest), over
    /// the unit cube.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for a zero resolution, a channel count other than 1 or 3, or a
    /// value count that does not match.
    pub fn new(resolution: UVec3, channels: u32, values: Vec<f32>) -> Result<Grid> {
        let count = u64::from(resolution.x) * u64::from(resolution.y) * u64::from(resolution.z) * u64::from(channels);
        let bad = |message: String| Err(Error::InvalidArgument { parameter: "Grid::new".into(), message });
        if resolution.min_element() == 0 {
            return bad(format!("resolution {resolution} has a zero"));
        }
        if channels != 1 && channels != 3 {
            return bad(format!("{channels} channels (1 or 3)"));
        }
        if count != values.len() as u64 {
            return bad(format!("{} values for {resolution} voxels of {channels} channels", values.len()));
        }
        Ok(Grid { resolution, channels, bbox: (Vec3::ZERO, Vec3::ONE), values })
    }

    /// Parses the bytes of a `.vol` file; `path` names it in errors.
    ///
    /// # Errors
    /// [`Error::Scene`] at `path` for a short header, a wrong magic, version or encoding, a zero
    /// or absurd resolution, a channel count other than 1 or 3, a length that disagrees with the
    /// header, or a value that is not finite.
    pub fn parse(path: &Path, bytes: &[u8]) -> Result<Grid> {
        if bytes.len() < HEADER_BYTES {
            return Err(vol_error(
                path,
                format!("{} bytes: too short for a .vol header ({HEADER_BYTES})", bytes.len()),
            ));
        }
        if &bytes[..3] != b"VOL" {
            return Err(vol_error(path, "not a .vol grid (it does not start with 'VOL')"));
        }
        if bytes[3] != VERSION {
            return Err(vol_error(path, format!(".vol version {} (only version {VERSION} is read)", bytes[3])));
        }
        let int = |at: usize| i32::from_le_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]]);
        let float = |at: usize| f32::from_le_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]]);
        let encoding = int(4);
        if encoding != ENCODING_FLOAT32 {
            return Err(vol_error(path, format!("encoding {encoding} (only 1, float32, is read)")));
        }
        let (x, y, z, channels) = (int(8), int(12), int(16), int(20));
        if x <= 0 || y <= 0 || z <= 0 {
            return Err(vol_error(path, format!("resolution {x}×{y}×{z}: each must be at least 1")));
        }
        if channels != 1 && channels != 3 {
            return Err(vol_error(path, format!("{channels} channels (1 or 3 are read)")));
        }
        let count = x as u64 * y as u64 * z as u64 * channels as u64;
        if count > MAX_VALUES {
            return Err(vol_error(
                path,
                format!("{x}×{y}×{z}×{channels} = {count} values exceed the {MAX_VALUES} read"),
            ));
        }
        let expected = HEADER_BYTES as u64 + 4 * count;
        if bytes.len() as u64 != expected {
            return Err(vol_error(
                path,
                format!("{} bytes, but a {x}×{y}×{z} grid of {channels} channel(s) takes {expected}", bytes.len()),
            ));
        }
        let bbox = (Vec3::new(float(24), float(28), float(32)), Vec3::new(float(36), float(40), float(44)));
        let values: Vec<f32> =
            bytes[HEADER_BYTES..].chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            let voxel = i / channels as usize;
            let (vx, vy, vz) = (voxel % x as usize, voxel / x as usize % y as usize, voxel / (x as usize * y as usize));
            return Err(vol_error(
                path,
                format!("voxel ({vx}, {vy}, {vz}) holds {} (values must be finite)", values[i]),
            ));
        }
        Ok(Grid { resolution: UVec3::new(x as u32, y as u32, z as u32), channels: channels as u32, bbox, values })
    }

    /// Reads a `.vol` file.
    ///
    /// # Errors
    /// [`Error::Io`] if it cannot be read; as [`Grid::parse`].
    pub fn read(path: &Path) -> Result<Grid> {
        let bytes = std::fs::read(path).map_err(|source| Error::Io { path: path.to_path_buf(), source })?;
        Grid::parse(path, &bytes)
    }

    /// The bytes of this grid as a `.vol` file.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(HEADER_BYTES + 4 * self.values.len());
        out.extend_from_slice(b"VOL");
        out.push(VERSION);
        for v in [
            ENCODING_FLOAT32,
            self.resolution.x as i32,
            self.resolution.y as i32,
            self.resolution.z as i32,
            self.channels as i32,
        ] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        for v in self.bbox.0.to_array().into_iter().chain(self.bbox.1.to_array()).chain(self.values.iter().copied()) {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out
    }

    /// Channel `c` at `p` in the unit cube, as Mitsuba's trilinear `gridvolume`: the continuous
    /// voxel coordinate p·res − 0.5 is clamped to [0, res − 1] on each axis and interpolated
    /// between its eight neighbours (so outside the cube the nearest face's values hold).
    pub fn lookup(&self, p: Vec3, c: u32) -> f32 {
        lookup(&self.values, self.resolution, self.channels, p, c, Wrap::Clamp)
    }

    /// The largest value of channel `c` (a majorant for delta tracking).
    pub fn max(&self, c: u32) -> f32 {
        self.values.iter().skip(c as usize).step_by(self.channels as usize).copied().fold(f32::NEG_INFINITY, f32::max)
    }
}

/// [`Grid::lookup`] on the voxel values `values` of a grid of `resolution` with `channels`, voxel
/// indices outside the grid wrapped by `wrap` (Mitsuba's `gridvolume` default is
/// [`Wrap::Clamp`]).
pub fn lookup(values: &[f32], resolution: UVec3, channels: u32, p: Vec3, c: u32, wrap: Wrap) -> f32 {
    let (lo, hi, t) = footprint(resolution, p, wrap);
    let at = |x: u32, y: u32, z: u32| values[(((z * resolution.y + y) * resolution.x + x) * channels + c) as usize];
    let lerp = |a: f32, b: f32, w: f32| a + (b - a) * w;
    let x00 = lerp(at(lo.x, lo.y, lo.z), at(hi.x, lo.y, lo.z), t.x);
    let x10 = lerp(at(lo.x, hi.y, lo.z), at(hi.x, hi.y, lo.z), t.x);
    let x01 = lerp(at(lo.x, lo.y, hi.z), at(hi.x, lo.y, hi.z), t.x);
    let x11 = lerp(at(lo.x, hi.y, hi.z), at(hi.x, hi.y, hi.z), t.x);
    lerp(lerp(x00, x10, t.y), lerp(x01, x11, t.y), t.z)
}

/// The voxels a trilinear lookup at `p` in the unit cube reads and its weights: the lower and
/// upper voxel index per axis and the fraction t towards the upper one. The continuous voxel
/// coordinate is p·res − 0.5; with [`Wrap::Clamp`] it is first clamped to [0, res − 1] (so outside
/// the cube the nearest face's values hold), otherwise the two indices per axis are wrapped
/// ([`Wrap::index`]). Shared by the lookups and their gradients (the kernels' `field_rgb` twin).
pub fn footprint(resolution: UVec3, p: Vec3, wrap: Wrap) -> (UVec3, UVec3, Vec3) {
    let r = resolution.as_vec3();
    let mut u = p * r - 0.5;
    if wrap == Wrap::Clamp {
        u = u.clamp(Vec3::ZERO, r - 1.0);
    }
    let f = u.floor();
    let (i, n) = (f.as_ivec3(), resolution.as_ivec3());
    let index = |i: i32, n: i32| wrap.index(i, n) as u32;
    let lo = UVec3::new(index(i.x, n.x), index(i.y, n.y), index(i.z, n.z));
    let hi = UVec3::new(index(i.x + 1, n.x), index(i.y + 1, n.y), index(i.z + 1, n.z));
    (lo, hi, u - f)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The 2×3×4 grid whose value at voxel (x, y, z) is its index x + 2y + 6z.
    fn ramp() -> Grid {
        Grid::new(UVec3::new(2, 3, 4), 1, (0..24).map(|v| v as f32).collect()).unwrap()
    }

    /// The header and order that Mitsuba 3.9.1's `VolumeGrid(np.arange(24).reshape(4, 3, 2, 1)).write`
    /// produces: 144 bytes, `VOL` 3, [1, 2, 3, 4, 1], the unit box, then 0, 1, 2, … in x-fastest order.
    #[test]
    fn bytes_are_mitsubas_layout_and_read_back() {
        let g = ramp();
        let bytes = g.to_bytes();
        assert_eq!(bytes.len(), 144);
        assert_eq!(&bytes[..4], b"VOL\x03");
        let ints: Vec<i32> = bytes[4..24].chunks_exact(4).map(|b| i32::from_le_bytes(b.try_into().unwrap())).collect();
        assert_eq!(ints, [1, 2, 3, 4, 1]);
        assert_eq!(f32::from_le_bytes(bytes[48 + 4 * 7..48 + 4 * 8].try_into().unwrap()), 7.0);
        assert_eq!(Grid::parse(Path::new("ramp.vol"), &bytes).unwrap(), g);
    }

    /// Mitsuba's `gridvolume.eval_1` on that grid at these points (values printed by Mitsuba
    /// 3.9.1, `scalar_rgb`): inside, on the corners and clamped outside.
    #[test]
    fn lookup_is_mitsubas_trilinear_with_clamping() {
        let g = ramp();
        for (p, mitsuba) in [
            (Vec3::new(0.3, 0.5, 0.9), 20.099_998),
            (Vec3::ZERO, 0.0),
            (Vec3::ONE, 23.0),
            (Vec3::new(0.75, 0.2, 0.4), 7.8),
            (Vec3::new(-0.5, 1.5, 0.5), 13.0),
        ] {
            let v = g.lookup(p, 0);
            assert!((v - mitsuba).abs() < 1e-5, "{p}: {v} vs Mitsuba {mitsuba}");
        }
        assert_eq!(g.max(0), 23.0);
        let rgb = Grid::new(UVec3::ONE, 3, vec![0.2, 0.5, 0.9]).unwrap();
        assert_eq!((rgb.lookup(Vec3::splat(0.7), 2), rgb.max(1)), (0.9, 0.5));
    }

    /// Mitsuba's `gridvolume.eval_1` on the ramp with each `wrap_mode` (values printed by Mitsuba
    /// 3.9.1, `scalar_rgb`, trilinear): inside but near a face (where repeat blends in the far
    /// face), and outside on every axis.
    #[test]
    fn lookup_wraps_as_mitsuba_does() {
        let g = ramp();
        let points = [
            Vec3::new(0.3, 0.5, 0.9),
            Vec3::new(-0.3, 1.2, 0.5),
            Vec3::new(1.6, -0.45, 2.3),
            Vec3::new(-1.1, 0.05, -0.7),
            Vec3::new(0.95, 0.9, 1.05),
        ];
        for (wrap, mitsuba) in [
            (Wrap::Repeat, [18.3, 10.1, 7.199_999, 6.300_001, 9.200_004]),
            (Wrap::Mirror, [20.1, 12.9, 6.199_998, 14.8, 23.0]),
            (Wrap::Clamp, [20.1, 13.0, 19.0, 0.0, 23.0]),
        ] {
            for (p, m) in points.iter().zip(mitsuba) {
                let v = lookup(&g.values, g.resolution, 1, *p, 0, wrap);
                assert!((v - m).abs() < 1e-4, "{wrap:?} at {p}: {v} vs Mitsuba {m}");
            }
        }
    }

    /// Every malformed file is refused with a message naming the file and what is wrong, before
    /// anything is allocated for its values.
    #[test]
    fn malformed_files_are_refused_by_name() {
        let good = ramp().to_bytes();
        let with = |at: usize, patch: &[u8]| {
            let mut b = good.clone();
            b[at..at + patch.len()].copy_from_slice(patch);
            b
        };
        let path = Path::new("smoke.vol");
        let cases: Vec<(Vec<u8>, &str)> = vec![
            (good[..20].to_vec(), "20 bytes: too short for a .vol header"),
            (with(0, b"PLY"), "does not start with 'VOL'"),
            (with(3, &[2]), ".vol version 2 (only version 3 is read)"),
            (with(4, &2i32.to_le_bytes()), "encoding 2 (only 1, float32, is read)"),
            (with(12, &0i32.to_le_bytes()), "resolution 2×0×4"),
            (with(8, &(-5i32).to_le_bytes()), "resolution -5×3×4"),
            (with(20, &2i32.to_le_bytes()), "2 channels"),
            (with(8, &i32::MAX.to_le_bytes()), "values exceed"),
            (good[..good.len() - 4].to_vec(), "140 bytes, but a 2×3×4 grid of 1 channel(s) takes 144"),
            ([good.clone(), vec![0; 4]].concat(), "148 bytes"),
            (with(48 + 4 * 9, &f32::NAN.to_le_bytes()), "voxel (1, 1, 1) holds NaN"),
        ];
        for (bytes, want) in cases {
            let e = Grid::parse(path, &bytes).unwrap_err().to_string();
            assert!(e.starts_with("smoke.vol: ") && e.contains(want), "{want}: {e}");
        }
        let e = Grid::read(Path::new("/nonexistent/x.vol")).unwrap_err().to_string();
        assert!(e.contains("/nonexistent/x.vol"), "{e}");
        assert!(Grid::new(UVec3::new(1, 1, 1), 2, vec![0.0; 2]).is_err());
        assert!(Grid::new(UVec3::new(1, 0, 1), 1, vec![]).is_err());
        assert!(Grid::new(UVec3::new(2, 1, 1), 1, vec![0.0]).is_err());
    }
}
