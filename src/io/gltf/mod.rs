//! glTF 2.0: `.gltf` (JSON with its buffers) and `.glb` (binary), parsed and validated
//! by the `gltf` crate.
//!
//! Reading takes the triangle primitives of every mesh with triangles as one mesh
//! (points, lines, strips and fans are kept as they are, not repaired). Several such
//! meshes are read only when they share one frame: every node that places one of them
//! has the same world transform (equal matrices), so that their vertices are in the same
//! coordinates; otherwise the document is refused with that reason (moving input
//! vertices into a common frame would change them). glTF vertices belong to one primitive and
//! are split at UV and normal seams, so the reader welds the vertices whose positions
//! are bit-identical into one mesh vertex (in order of first appearance): seams and
//! primitive borders are not holes. Each glTF vertex's normal and texture coordinate
//! become corner values; its colour the vertex colour (the first glTF vertex of a
//! welded vertex gives it).
//!
//! Writing a mesh read from glTF keeps the document: buffers, images, materials,
//! nodes, extensions and primitives are written back byte for byte. The patches become
//! one new primitive per primitive whose faces surround them (same material), with
//! their own accessors in a new stretch of buffer; rim vertices are repeated there
//! with their input values (glTF primitives share no vertices). A primitive that lost
//! input faces (rim trimming, debris) gets a new index accessor. Attributes the new
//! primitive cannot be given (tangents, a second UV set, skinning) are left out of it.
//! Other inputs are written as a new document: one mesh with one primitive, `f32`
//! positions, and normals, texture coordinates and colours when the mesh has them.
//!
//! External buffers of a `.gltf` are read from names relative to the file, never from
//! an absolute path, a `..` component or a URL; `data:` URIs are decoded. A `.gltf`
//! written keeps the external names it read (those files travel beside it) and holds
//! the new stretch as a `data:` URI; a `.glb` holds it in its binary chunk.

mod reader;
mod writer;

pub(crate) use reader::read;
pub(crate) use writer::write;

const FLOAT: u32 = 5126;
const UNSIGNED_INT: u32 = 5125;
const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;
const TRIANGLES: u32 = 4;

#[cfg(test)]
mod tests;
