//! Geometry on `f64` points, apart from any mesh: measures of triangles and polygons
//! ([`measure`]), the exact predicates every method and the checks decide by
//! ([`predicates`]), the bounding-volume hierarchy of the self-intersection check
//! ([`bvh`]) and the uniform grid of the fronts' broad phase ([`grid`]).

pub mod bvh;
pub mod grid;
pub mod measure;
pub mod predicates;
