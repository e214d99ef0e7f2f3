//! [`TopologyError`]: why faces could not be added, or which invariant a mesh breaks.

use super::VertexId;

/// A change refused by [`super::Topology::add_faces`] (nothing changed), or the first
/// broken invariant [`super::Mesh::validate`] finds. The messages name the vertices,
/// faces and half-edges by index.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum TopologyError {
    // ----- add_faces -----
    #[error("vertex {0} out of range")]
    VertexOutOfRange(VertexId),
    #[error("new face {0} repeats a vertex")]
    NewFaceRepeatsVertex(usize),
    /// The directed edge exists already, or an earlier new face has it.
    #[error("directed edge {0}->{1} would be used twice")]
    DirectedEdgeTaken(VertexId, VertexId),
    #[error("edge {0}-{1} would get a third face")]
    ThirdFace(VertexId, VertexId),

    // ----- validate: topology -----
    #[error("twin array size")]
    TwinArraySize,
    #[error("more half-edges than 32-bit indices can hold")]
    TooManyHalfEdges,
    #[error("face {face} references vertex {vertex} out of range")]
    FaceVertexOutOfRange { face: usize, vertex: VertexId },
    #[error("face {face} repeats vertex {vertex}")]
    FaceRepeatsVertex { face: usize, vertex: VertexId },
    #[error("directed edge {from}->{to} used twice")]
    DirectedEdgeTwice { from: usize, to: u32 },
    #[error("twin of half-edge {0} is not symmetric")]
    TwinNotSymmetric(usize),
    #[error("half-edge {0} and its twin do not share endpoints")]
    TwinEndpoints(usize),
    #[error("boundary half-edge {half_edge} ({from}->{to}) has an unlinked opposite")]
    UnlinkedOpposite {
        half_edge: usize,
        from: VertexId,
        to: VertexId,
    },
    #[error("vertex {0} has faces but no anchor")]
    NoAnchor(usize),
    #[error("anchor of vertex {0} does not start at it")]
    AnchorElsewhere(usize),
    #[error("vertex {vertex} is non-manifold: fan has {fan} of its {faces} faces")]
    NonManifoldVertex { vertex: usize, fan: u32, faces: u32 },

    // ----- validate: geometry arrays -----
    #[error("{positions} positions for {vertices} vertices")]
    PositionCount { positions: usize, vertices: usize },
    #[error("origin array size")]
    OriginArraySize,
    #[error("colour array size")]
    ColourArraySize,
    #[error("vertex {0} has a non-finite coordinate")]
    NonFinite(usize),
}
