//! Typed `u32` indices for mesh elements.
//!
//! Conversions from `usize` happen in one checked place ([`VertexId::from_usize`],
//! [`TriId::from_usize`]) so a mesh can never silently index past `u32::MAX`.

use std::fmt;

macro_rules! typed_id {
    ($(#[$doc:meta])* $name:ident) => {
        $(#[$doc])*
        #[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
        #[repr(transparent)]
        pub struct $name(pub u32);

        impl $name {
            /// The index as `usize`, for slicing.
            #[inline]
            #[must_use]
            pub fn index(self) -> usize {
                self.0 as usize
            }

            /// Converts a `usize` index, or `None` when it does not fit in `u32`.
            #[inline]
            #[must_use]
            pub fn from_usize(index: usize) -> Option<Self> {
                u32::try_from(index).ok().map(Self)
            }
        }

        impl fmt::Display for $name {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                write!(f, "{}", self.0)
            }
        }
    };
}

typed_id!(
    /// Index of a vertex in a [`crate::TriMesh`] or a point in a [`crate::PointCloud`].
    VertexId
);
typed_id!(
    /// Index of a triangle in a [`crate::TriMesh`].
    TriId
);
