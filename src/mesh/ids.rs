//! Typed `u32` handles. A handle is an index into the mesh's arrays; absence is
//! expressed with `Option`, never with a sentinel value.

use serde::{Deserialize, Serialize};

macro_rules! id_type {
    ($(#[$doc:meta])* $name:ident) => {
        $(#[$doc])*
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
        pub struct $name(pub u32);

        impl $name {
            /// The handle as an array index.
            #[inline]
            pub fn idx(self) -> usize {
                self.0 as usize
            }
            /// Builds a handle from an array index.
            ///
            /// Meshes are limited to `u32::MAX` elements (the readers refuse larger inputs),
            /// so the conversion cannot truncate for any index that exists.
            #[inline]
            pub fn from_idx(i: usize) -> Self {
                debug_assert!(i <= u32::MAX as usize);
                $name(i as u32)
            }
        }

        impl std::fmt::Display for $name {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                write!(f, "{}", self.0)
            }
        }
    };
}

id_type!(
    /// A vertex of the mesh.
    VertexId
);
id_type!(
    /// A half-edge: half-edge `3f + i` runs from corner `i` to corner `i + 1` of face `f`.
    HalfedgeId
);
id_type!(
    /// A triangle of the mesh.
    FaceId
);

impl HalfedgeId {
    /// The face this half-edge belongs to.
    #[inline]
    pub fn face(self) -> FaceId {
        FaceId(self.0 / 3)
    }
    /// The corner (0, 1, 2) of the face this half-edge starts at.
    #[inline]
    pub fn corner(self) -> usize {
        (self.0 % 3) as usize
    }
    /// The next half-edge inside the same face.
    #[inline]
    pub fn next(self) -> HalfedgeId {
        let b = self.0 - self.0 % 3;
        HalfedgeId(b + (self.0 % 3 + 1) % 3)
    }
    /// The previous half-edge inside the same face.
    #[inline]
    pub fn prev(self) -> HalfedgeId {
        let b = self.0 - self.0 % 3;
        HalfedgeId(b + (self.0 % 3 + 2) % 3)
    }
}

impl FaceId {
    /// The half-edge starting at corner `i` (0..3) of this face.
    #[inline]
    pub fn halfedge(self, i: usize) -> HalfedgeId {
        HalfedgeId(self.0 * 3 + i as u32)
    }
}
