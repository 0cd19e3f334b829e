//! The host/GPU contract: every struct, constant, enumeration and push-constant block the kernels share.
//!
//! Each item is written once, in Rust, in one of four files that `build.rs` also reads:
//! `consts.rs` (integers: bindings, random-number slots, feature bits, limits), `floats.rs`
//! (epsilons and clamps), `enums.rs` (tags and losses) and `structs.rs` (buffer layouts and push
//! constants). build.rs turns them into glslc macro definitions (`-D`) and `generated/contract.glsl`, so
//! no `.glsl` file restates a value; `tests/it/twins.rs` reads every value back from a kernel, and
//! a source scan there refuses a shader that defines a contract name or a push-constant block of
//! its own. The CPU reference, the BVH builder and the random numbers use the same items.
//!
//! ```
//! use pathgrad::contract::{KernelPush, Loss, FLOAT_CONSTANTS, RAY_OFFSET};
//! assert_eq!(Loss::from_value(Loss::RelMse.value()), Some(Loss::RelMse));
//! assert!(FLOAT_CONSTANTS.contains(&("RAY_OFFSET", RAY_OFFSET)));
//! assert_eq!(size_of::<KernelPush>(), 16);
//! ```

use bytemuck::{Pod, Zeroable};
use glam::{UVec2, Vec2, Vec3};

include!("consts.rs");
include!("floats.rs");
include!("enums.rs");

macro_rules! contract_structs {
    ($($(#[$sdoc:meta])* struct $name:ident { $($(#[$fdoc:meta])* $field:ident : $ty:ident,)* })*) => {
        $(
            $(#[$sdoc])*
            #[repr(C)]
            #[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
            pub struct $name { $($(#[$fdoc])* pub $field: $ty,)* }
        )*
    };
}

macro_rules! contract_push_blocks {
    ($($(#[$sdoc:meta])* struct $name:ident { $($(#[$fdoc:meta])* $field:ident : $ty:ident,)* })*) => {
        contract_structs! { $($(#[$sdoc])* struct $name { $($(#[$fdoc])* $field: $ty,)* })* }
    };
}

include!("structs.rs");

#[cfg(test)]
mod tests {
    use super::*;

    /// Scalar layout packs 4-byte scalars and vectors of them with no padding: sizes are field sums.
    #[test]
    fn structs_have_no_padding() {
        assert_eq!(size_of::<Globals>(), 36 * 4 + 3 * 12 + 22 * 8);
        assert_eq!(size_of::<ViewCamera>(), 4 * 12 + 7 * 4);
        assert_eq!(size_of::<BvhNode>(), 80);
        assert_eq!(size_of::<TriPositions>(), 40);
        assert_eq!(size_of::<TriVertices>(), 16);
        assert_eq!(size_of::<MeshShading>(), 6 * 4);
        assert_eq!(size_of::<FieldDesc>(), 6 * 4 + 4 * 12);
        assert_eq!(size_of::<MediumDesc>(), 11 * 4 + 2 * 12);
        assert_eq!(size_of::<Material>(), 19 * 4 + 4 * 12);
        assert_eq!(size_of::<EmitterTri>(), 16 + 36);
        assert_eq!(size_of::<AliasEntry>(), 8);
        assert_eq!(size_of::<EnvCell>(), 12);
        assert_eq!(size_of::<DeltaLight>(), 11 * 4 + 5 * 12 + 8);
        assert_eq!(size_of::<KernelPush>(), 16);
        assert_eq!(size_of::<AliasProbePush>(), 16);
    }

    /// Names are unique across the integer, enumeration and float tables (they share one macro namespace).
    #[test]
    fn contract_names_are_unique() {
        let mut names: Vec<&str> = INT_CONSTANTS.iter().chain(ENUM_CONSTANTS).map(|(n, _)| *n).collect();
        names.extend(FLOAT_CONSTANTS.iter().map(|(n, _)| *n));
        let count = names.len();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), count);
    }
}
