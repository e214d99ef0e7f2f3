//! A hole and a proposed patch: the loop to fill ([`Hole`]), the triangles and new
//! vertices a method proposes for it ([`Patch`]), and applying an accepted patch to the
//! mesh ([`apply_patch`]).

use crate::mesh::{Mesh, TopologyError, VertexId};
use crate::policy::Policy;
use crate::report::{HoleClass, HoleReport, HoleStatus};
use glam::DVec3;

/// A boundary loop to fill.
#[derive(Clone, Debug)]
pub struct Hole {
    /// Index of the hole in the log.
    pub id: usize,
    /// The loop, oriented so that a patch triangle `(v[i], v[i+1], x)` agrees with the
    /// surrounding faces.
    pub vertices: Vec<VertexId>,
    /// Sum of boundary edge lengths.
    pub perimeter: f64,
    /// Mean boundary edge length.
    pub mean_edge_length: f64,
    /// Size class.
    pub class: HoleClass,
}

impl Hole {
    /// The log entry of this hole with `status` and `reason`, before any method is
    /// tried: nothing added or removed, no quality, no time.
    pub fn report(&self, status: HoleStatus, reason: String) -> HoleReport {
        HoleReport {
            id: self.id,
            boundary_vertices: self.len(),
            perimeter: self.perimeter,
            mean_edge_length: self.mean_edge_length,
            class: self.class,
            method: None,
            tried: Vec::new(),
            status,
            reason,
            added_vertices: 0,
            added_faces: 0,
            rim_faces_removed: 0,
            island_faces_removed: 0,
            islands_bridged: 0,
            quality: None,
            selection: None,
            blend: None,
            ms: 0.0,
        }
    }

    /// Measures a loop.
    pub fn new(id: usize, mesh: &Mesh, vertices: Vec<VertexId>, policy: &Policy) -> Hole {
        let k = vertices.len();
        let perimeter: f64 = (0..k)
            .map(|i| (mesh.pos(vertices[(i + 1) % k]) - mesh.pos(vertices[i])).length())
            .sum();
        let class = if k <= policy.dispatch.small_max {
            HoleClass::Small
        } else if k <= policy.dispatch.middle_max {
            HoleClass::Middle
        } else {
            HoleClass::Large
        };
        Hole {
            id,
            mean_edge_length: if k > 0 { perimeter / k as f64 } else { 0.0 },
            vertices,
            perimeter,
            class,
        }
    }
    /// Boundary vertex count.
    pub fn len(&self) -> usize {
        self.vertices.len()
    }
    /// True for an empty loop.
    pub fn is_empty(&self) -> bool {
        self.vertices.is_empty()
    }
}

/// A proposed patch. Vertex index `i < k` (k = loop length) is the hole's `i`-th
/// boundary vertex; `i >= k` is `new_vertices[i - k]`. Triangles are oriented like
/// the hole (see [`Hole::vertices`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Patch {
    pub new_vertices: Vec<DVec3>,
    pub triangles: Vec<[u32; 3]>,
}

impl Patch {
    /// The corners of each triangle, loop vertices read from `mesh`; a triangle that
    /// names a vertex neither the loop nor the patch has is left out.
    pub fn triangle_positions(&self, mesh: &Mesh, hole: &Hole) -> Vec<[DVec3; 3]> {
        let k = hole.vertices.len();
        let pos = |i: u32| -> Option<DVec3> {
            let i = i as usize;
            if i < k {
                Some(mesh.pos(hole.vertices[i]))
            } else {
                self.new_vertices.get(i - k).copied()
            }
        };
        self.triangles
            .iter()
            .filter_map(|t| Some([pos(t[0])?, pos(t[1])?, pos(t[2])?]))
            .collect()
    }

    /// Total area of the triangles of [`Patch::triangle_positions`].
    pub fn area(&self, mesh: &Mesh, hole: &Hole) -> f64 {
        self.triangle_positions(mesh, hole)
            .iter()
            .map(|t| crate::geometry::measure::tri_area(t[0], t[1], t[2]))
            .sum()
    }
}

/// Why a patch could not be applied (the mesh is left as it was).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum ApplyError {
    /// A triangle names a patch vertex that is neither a loop vertex nor new.
    #[error("patch references a vertex that does not exist")]
    NoSuchVertex { index: u32 },
    /// The mesh refused the faces (an edge would be used twice, ...).
    #[error("patch would break the mesh: {0}")]
    BreaksMesh(#[source] TopologyError),
}

/// Adds a checked patch to the mesh. Returns the range of new face indices.
/// On failure the mesh is left as it was.
pub fn apply_patch(
    mesh: &mut Mesh,
    hole: &Hole,
    patch: &Patch,
) -> Result<std::ops::Range<usize>, ApplyError> {
    let k = hole.len();
    let nv0 = mesh.num_vertices();
    let nf0 = mesh.num_faces();
    let colors = mesh.colors.as_ref().map(|c| {
        let bc: Vec<[f32; 3]> = hole.vertices.iter().map(|v| c[v.idx()]).collect();
        bc
    });
    for &p in &patch.new_vertices {
        let col = colors
            .as_ref()
            .map(|bc| interpolate_color(mesh, hole, bc, p));
        mesh.add_vertex(p, col);
    }
    let map = |i: u32| -> Result<VertexId, ApplyError> {
        let j = i as usize;
        if j < k {
            Ok(hole.vertices[j])
        } else if j - k < patch.new_vertices.len() {
            Ok(VertexId::from_idx(nv0 + j - k))
        } else {
            Err(ApplyError::NoSuchVertex { index: i })
        }
    };
    let mut faces = Vec::with_capacity(patch.triangles.len());
    for t in &patch.triangles {
        match (map(t[0]), map(t[1]), map(t[2])) {
            (Ok(a), Ok(b), Ok(c)) => faces.push([a, b, c]),
            (Err(e), _, _) | (_, Err(e), _) | (_, _, Err(e)) => {
                mesh.truncate_vertices(nv0);
                return Err(e);
            }
        }
    }
    if let Err(e) = mesh.add_faces(&faces) {
        mesh.truncate_vertices(nv0);
        return Err(ApplyError::BreaksMesh(e));
    }
    Ok(nf0..mesh.num_faces())
}

/// Colour of a new vertex: inverse-distance weighting of the loop's colours.
fn interpolate_color(mesh: &Mesh, hole: &Hole, bc: &[[f32; 3]], p: DVec3) -> [f32; 3] {
    let mut acc = [0.0f64; 3];
    let mut wsum = 0.0;
    for (i, &v) in hole.vertices.iter().enumerate() {
        let d = (mesh.pos(v) - p).length_squared().max(1e-300);
        let w = 1.0 / d;
        for c in 0..3 {
            acc[c] += w * bc[i][c] as f64;
        }
        wsum += w;
    }
    if wsum > 0.0 {
        [
            (acc[0] / wsum) as f32,
            (acc[1] / wsum) as f32,
            (acc[2] / wsum) as f32,
        ]
    } else {
        [0.5, 0.5, 0.5]
    }
}
