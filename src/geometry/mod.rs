//! Geometry on `f64` points, apart from any mesh: measures of triangles and polygons
//! ([`measure`]), the exact predicates every method and the checks decide by
//! ([`predicates`]), the bounding-volume hierarchy of the self-intersection check
//! ([`bvh`]), the uniform grid of the fronts' broad phase ([`grid`]) and the edges of a
//! 3D Delaunay triangulation for the restricted triangulation search ([`delaunay3`]).

pub mod bvh;
pub mod delaunay3;
pub mod grid;
pub mod measure;
pub mod predicates;
