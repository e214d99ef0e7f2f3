//! Why a patch was rejected, as data: the failing triangle and what it meets are
//! fields, so that a caller (the relaxation that holds the vertices of the failing
//! triangles, the repairs) reads them instead of parsing a message. The messages are
//! the log's wording.

use crate::mesh::VertexId;

/// Why a patch was rejected.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum CheckFailure {
    /// A patch triangle is degenerate.
    #[error("patch triangle {triangle} is degenerate ({why})")]
    Degenerate { triangle: usize, why: Degeneracy },
    /// The patch is not an oriented disk whose boundary is exactly the hole's loop.
    #[error("patch is not a disk closing the hole: {0}")]
    Topology(TopologyFailure),
    /// A patch triangle meets another patch triangle or a mesh face.
    #[error("patch triangle {triangle} intersects {meets}")]
    SelfIntersection { triangle: usize, meets: Meets },
}

impl CheckFailure {
    /// The patch triangles the failure names: the failing one and, for a patch-patch
    /// intersection, the other.
    pub fn triangles(&self) -> Vec<usize> {
        match self {
            CheckFailure::SelfIntersection {
                triangle,
                meets: Meets::PatchTriangle(j),
            } => vec![*triangle, *j],
            CheckFailure::SelfIntersection { triangle, .. }
            | CheckFailure::Degenerate { triangle, .. } => vec![*triangle],
            CheckFailure::Topology(_) => Vec::new(),
        }
    }
}

/// Why a triangle is degenerate.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum Degeneracy {
    /// (Nearly) zero area: at most 1e-12 times its longest edge squared.
    #[error("area {0:e}")]
    Area(f64),
    /// An angle below `checks.min_angle_deg` (the smallest angle, in degrees).
    #[error("smallest angle {0:.3} deg")]
    SmallAngle(f64),
}

/// What a failing patch triangle meets.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum Meets {
    /// Another triangle of the same patch.
    #[error("patch triangle {0}")]
    PatchTriangle(usize),
    /// A face of the mesh (its index).
    #[error("mesh face {0}")]
    MeshFace(usize),
}

/// How a patch fails to be an oriented disk closing the hole (patch numbering: loop
/// vertex `i < k`, then the new vertices).
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum TopologyFailure {
    #[error("hole vertex {0} is not in the mesh")]
    HoleVertexMissing(VertexId),
    #[error("no triangles")]
    NoTriangles,
    #[error("new vertex {0} has a non-finite coordinate")]
    NonFinite(usize),
    #[error("triangle {0} has an index out of range")]
    IndexOutOfRange(usize),
    #[error("triangle {0} repeats a vertex")]
    RepeatedVertex(usize),
    #[error("edge {0}-{1} is used twice in one direction")]
    EdgeUsedTwice(u32, u32),
    #[error("boundary edge {0}-{1} is covered with the wrong orientation")]
    BoundaryReversed(u32, u32),
    #[error("edge {0}-{1} is left open")]
    OpenEdge(u32, u32),
    #[error("chord {0}-{1} duplicates an existing mesh edge")]
    ChordIsMeshEdge(u32, u32),
    #[error("boundary edge {0}-{1} is not covered")]
    BoundaryUncovered(usize, usize),
    #[error("vertex {0} is not used by any triangle")]
    UnusedVertex(usize),
    #[error("patch is not a disk (Euler characteristic {0})")]
    NotADisk(i64),
    #[error("vertex {0} is not connected to the hole's loop")]
    Disconnected(usize),
    #[error("vertex {0} has more than one fan")]
    Pinched(usize),
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failure_names_its_patch_triangles() {
        let e = CheckFailure::SelfIntersection {
            triangle: 3,
            meets: Meets::PatchTriangle(11),
        };
        assert_eq!(e.triangles(), vec![3, 11]);
        assert_eq!(
            e.to_string(),
            "patch triangle 3 intersects patch triangle 11"
        );
        let e = CheckFailure::SelfIntersection {
            triangle: 3,
            meets: Meets::MeshFace(11),
        };
        assert_eq!(e.triangles(), vec![3]);
        assert_eq!(e.to_string(), "patch triangle 3 intersects mesh face 11");
        let e = CheckFailure::Degenerate {
            triangle: 5,
            why: Degeneracy::SmallAngle(0.25),
        };
        assert_eq!(e.triangles(), vec![5]);
        assert_eq!(
            e.to_string(),
            "patch triangle 5 is degenerate (smallest angle 0.250 deg)"
        );
        let e = CheckFailure::Topology(TopologyFailure::NotADisk(0));
        assert!(e.triangles().is_empty());
        assert_eq!(
            e.to_string(),
            "patch is not a disk closing the hole: patch is not a disk (Euler characteristic 0)"
        );
    }
}
