//! Host/GPU shared layouts: the structs of `abi_structs.rs` and the constants of `abi_consts.rs`.

use bytemuck::{Pod, Zeroable};
use glam::{UVec2, Vec2, Vec3};

include!("abi_consts.rs");

macro_rules! abi_structs {
    ($($(#[$sdoc:meta])* struct $name:ident { $($(#[$fdoc:meta])* $field:ident : $ty:ident,)* })*) => {
        $(
            $(#[$sdoc])*
            #[repr(C)]
            #[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
            pub struct $name { $($(#[$fdoc])* pub $field: $ty,)* }
        )*
    };
}

include!("abi_structs.rs");

#[cfg(test)]
mod tests {
    use super::*;

    /// Scalar layout packs 4-byte scalars and vectors of them with no padding: sizes are field sums.
    #[test]
    fn structs_have_no_padding() {
        assert_eq!(size_of::<Globals>(), 20 * 4 + 4 * 12 + 7 * 8);
        assert_eq!(size_of::<BvhNode>(), 64);
        assert_eq!(size_of::<TriPositions>(), 40);
        assert_eq!(size_of::<TriShading>(), 3 * 12 + 3 * 8 + 8);
        assert_eq!(size_of::<Material>(), 10 * 4 + 2 * 12);
        assert_eq!(size_of::<EmitterTri>(), 16 + 36);
        assert_eq!(size_of::<AliasEntry>(), 8);
    }
}
