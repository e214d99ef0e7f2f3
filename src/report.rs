//! The per-file repair log (serialised as JSON by `holefill fill --report` and by the
//! daemon). The schema is documented in README.md ("Repair log").

use crate::io::attrs::AttributesReport;
use crate::io::Format;
use crate::mesh::BuildReport;
use crate::policy::{BlendKeep, BlendSurface, FairEnergy, Method, Policy};
use serde::Serialize;

/// Size class of a hole.
#[derive(Clone, Copy, Debug, Serialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum HoleClass {
    Small,
    Middle,
    Large,
}

impl HoleClass {
    /// The lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            HoleClass::Small => "small",
            HoleClass::Middle => "middle",
            HoleClass::Large => "large",
        }
    }
}

/// How a hole ended.
#[derive(Clone, Copy, Debug, Serialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum HoleStatus {
    Filled,
    /// A crack zipped shut: its vertices identified with the coincident boundary
    /// vertices across it (`[crack]`), no patch.
    Stitched,
    Skipped,
    Failed,
}

/// How one method attempt on one hole ended.
#[derive(Clone, Copy, Debug, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum Outcome {
    /// The patch passed the checks and is in the mesh.
    Accepted,
    /// The method produced a patch that failed a check; it was undone.
    Rejected,
    /// The method could not produce a patch.
    Error,
    /// The per-hole time limit ran out.
    Timeout,
}

/// One method attempt.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct Attempt {
    pub method: Method,
    pub outcome: Outcome,
    /// Why it was rejected or failed (empty when accepted).
    pub reason: String,
    /// The variant of a self-checked method that made the patch, when not the
    /// method's first (the policy's own settings); absent otherwise.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub variant: Option<String>,
    pub ms: f64,
}

/// Quality of the triangles a patch added.
#[derive(Clone, Debug, Serialize, PartialEq, Default)]
pub struct PatchQuality {
    /// Share (0..1) of patch triangles with shortest edge / circumradius > 1.39.
    pub q_good_share: f64,
    /// Smallest angle of any patch triangle, degrees.
    pub min_angle_deg: f64,
    /// Share (0..1) of new interior vertices with valence 6 (`null` without new vertices).
    pub valence6_share: Option<f64>,
}

/// The per-hole choice of one hole. Mode `validate`: the hole grown by `rings` rings
/// of input faces, each candidate's patch of the grown hole measured against the
/// removed faces. Mode `rim`: the rim's edges within `rings` rings read (`rim`).
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct Selection {
    pub mode: crate::policy::SelectMode,
    pub rings: usize,
    /// Boundary vertices of the grown hole (0 when it could not be grown).
    pub grown_boundary_vertices: usize,
    /// Known points the candidates were measured against: the removed faces' vertices
    /// inside the grown hole and their centroids.
    pub known_points: usize,
    pub candidates: Vec<Candidate>,
    /// The candidate put first; `None` keeps the list's order (see `reason`).
    pub winner: Option<Method>,
    /// Why there is no winner (empty when there is one).
    pub reason: String,
    /// Mode `rim`: what the rule read.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rim: Option<RimReading>,
    pub ms: f64,
}

/// What the `rim` rule read around one hole.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct RimReading {
    /// Interior edges with both ends within the rings.
    pub edges: usize,
    /// Share (0..1) of them whose faces' normals differ by less than
    /// `select.flat_angle_deg`; `None` without edges.
    pub flat_share: Option<f64>,
}

/// One candidate of a [`Selection`].
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct Candidate {
    pub method: Method,
    /// Mean distance from the known points to the candidate's patch of the grown hole,
    /// per mille of the mesh's bounding-box diagonal; `None` when it made no patch.
    pub score: Option<f64>,
    /// Why it made no patch (empty when it did).
    pub reason: String,
    pub ms: f64,
}

/// One hole.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct HoleReport {
    pub id: usize,
    pub boundary_vertices: usize,
    pub perimeter: f64,
    pub mean_edge_length: f64,
    pub class: HoleClass,
    /// The method whose patch was accepted.
    pub method: Option<Method>,
    pub tried: Vec<Attempt>,
    pub status: HoleStatus,
    /// Why it was skipped or failed (empty when filled).
    pub reason: String,
    pub added_vertices: usize,
    pub added_faces: usize,
    /// Input faces removed around the hole by rim trimming (`[rim]`) before it was
    /// filled.
    pub rim_faces_removed: usize,
    /// Faces of islands inside the hole removed as debris (`[islands]`).
    pub island_faces_removed: usize,
    /// Islands inside the hole joined to its loop by bridge faces (two each, counted
    /// in `added_faces`) and filled with it.
    pub islands_bridged: usize,
    pub quality: Option<PatchQuality>,
    /// The per-hole choice of method, when `select.mode = "validate"` compared
    /// candidates (absent otherwise).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub selection: Option<Selection>,
    /// The accepted patch pulled toward a second surface (`blend.surface`), when the
    /// blend weight of the hole's class is set and, with `surface = "with"`, the patch
    /// is another method's than `blend.with` (absent otherwise).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub blend: Option<BlendReport>,
    pub ms: f64,
}

/// What `[blend]` did to one hole's patch.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct BlendReport {
    /// What the patch was pulled toward (`blend.surface`).
    pub surface: BlendSurface,
    /// The method whose patch it was pulled toward, with `surface = "with"`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub with: Option<Method>,
    /// The weight used: the class's, or `blend.weight_flat` where the rim reads flat;
    /// 1 where the pull that far failed the checks and the full pull passed (`reason`
    /// says so).
    pub weight: f64,
    /// The share of the rim's edges that are flat, where `blend.weight_flat` is set.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub flat_share: Option<f64>,
    /// Whether the pulled patch passed the checks and replaced the accepted one.
    pub applied: bool,
    /// Whose triangles the applied patch has (`blend.keep`, or `accepted` where
    /// `with`'s pulled patch failed the checks); `None` when not applied.
    pub kept: Option<BlendKeep>,
    /// Why it was not applied, why `blend.with`'s triangles were not kept where the
    /// accepted patch's were, or why it was pulled all the way (empty otherwise).
    pub reason: String,
    /// New vertices moved.
    pub moved_vertices: usize,
    /// Mean distance they moved, in mean boundary edge lengths of the hole.
    pub mean_shift: f64,
    /// How the faired surface's fairing was chosen, with `blend.energy = "validate"`
    /// on a large hole.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub energy: Option<EnergyChoice>,
    pub ms: f64,
}

/// The fairing chosen for a hole's faired surface (`blend.energy = "validate"`).
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct EnergyChoice {
    /// The candidate whose fairing moved the freed known vertices least (on a tie the
    /// earlier; `fair` when none could be scored).
    pub chosen: FairEnergy,
    /// Rings of known surface freed with the patch (the loop is the first).
    pub rings: usize,
    /// Each candidate's mean distance of the freed known vertices from where they
    /// are, in mean boundary edge lengths of the hole; `None` where its fairing failed.
    pub scores: Vec<(FairEnergy, Option<f64>)>,
    /// The fairing the patch was pulled toward: `chosen`, or `fair` where the pull
    /// toward the chosen one failed the checks (the blend's `reason` says so).
    pub used: FairEnergy,
    pub ms: f64,
}

/// Vertex, face and hole counts.
#[derive(Clone, Debug, Serialize, PartialEq, Default)]
pub struct Counts {
    pub vertices: usize,
    pub faces: usize,
    pub boundary_loops: usize,
}

/// What was resolved in the input before filling.
#[derive(Clone, Debug, Serialize, PartialEq, Default)]
pub struct Resolved {
    /// What the reader did (polygons fanned, STL vertices welded, ...).
    pub reader: Vec<String>,
    /// What the mesh builder resolved.
    pub mesh: BuildReport,
    /// Tooth faces removed by boundary cleaning.
    pub tooth_faces_removed: usize,
    /// Long boundary edges split by boundary cleaning.
    pub long_edges_split: usize,
    /// Degenerate boundary loops (fewer than 3 vertices) that cannot be filled.
    pub degenerate_loops: usize,
    /// Boundary vertices identified with a coincident boundary vertex (`[crack]`);
    /// each stays in the output, unreferenced.
    pub stitched_vertices: usize,
    /// Input faces whose corners changed by that identification.
    pub stitched_faces: usize,
    /// Floating pieces of fewer than `debris.remove_below_faces` faces removed, and
    /// their faces.
    pub debris_pieces_removed: usize,
    pub debris_faces_removed: usize,
}

/// Durations in milliseconds.
#[derive(Clone, Debug, Serialize, PartialEq, Default)]
pub struct Timings {
    pub read_ms: f64,
    pub smooth_ms: f64,
    pub fill_ms: f64,
    /// Carrying the input's attributes to the output (not part of the fill time).
    pub attributes_ms: f64,
    pub write_ms: f64,
    /// Rendering the picture (on its own thread, while the model is written) and
    /// writing it (`holefill fill --picture`; 0 without).
    pub picture_ms: f64,
}

/// A file path with its format.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct FileRef {
    pub path: String,
    pub format: Format,
}

/// Hole totals.
#[derive(Clone, Debug, Serialize, PartialEq, Default)]
pub struct Summary {
    pub holes: usize,
    pub filled: usize,
    pub stitched: usize,
    pub skipped: usize,
    pub failed: usize,
}

/// The whole repair log of one file.
#[derive(Clone, Debug, Serialize)]
pub struct RepairReport {
    pub holefill_version: &'static str,
    pub input: Option<FileRef>,
    pub output: Option<FileRef>,
    pub before: Counts,
    pub after: Counts,
    pub resolved: Resolved,
    pub smoothing: Option<SmoothingReport>,
    pub policy: Policy,
    pub timings: Timings,
    pub summary: Summary,
    pub holes: Vec<HoleReport>,
    /// What the input carried besides positions and faces, and what became of it.
    pub attributes: AttributesReport,
    /// Where each hole of `holes` (same order) is in the repaired mesh, for pictures of
    /// the repair ([`crate::picture`]); not part of the log.
    #[serde(skip)]
    pub traces: Vec<HoleTrace>,
}

/// Where one hole is in the repaired mesh (vertex and face indices of the soup that
/// [`crate::repair`] returns).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct HoleTrace {
    /// The boundary loop, oriented so that a patch triangle `(v[i], v[i+1], x)` agrees
    /// with the surrounding faces.
    pub boundary: Vec<u32>,
    /// The faces the hole's patch added (empty when it was not filled).
    pub patch: std::ops::Range<u32>,
}

/// What smoothing did.
#[derive(Clone, Debug, Serialize, PartialEq, Default)]
pub struct SmoothingReport {
    pub iterations: usize,
    pub vertices_moved: usize,
    pub max_displacement: f64,
}

impl RepairReport {
    /// An empty log for a policy.
    pub fn new(policy: &Policy) -> RepairReport {
        RepairReport {
            holefill_version: env!("CARGO_PKG_VERSION"),
            input: None,
            output: None,
            before: Counts::default(),
            after: Counts::default(),
            resolved: Resolved::default(),
            smoothing: None,
            policy: policy.clone(),
            timings: Timings::default(),
            summary: Summary::default(),
            holes: Vec::new(),
            attributes: AttributesReport::default(),
            traces: Vec::new(),
        }
    }

    /// Recomputes the summary from the holes.
    pub fn summarise(&mut self) {
        let mut s = Summary {
            holes: self.holes.len(),
            ..Default::default()
        };
        for h in &self.holes {
            match h.status {
                HoleStatus::Filled => s.filled += 1,
                HoleStatus::Stitched => s.stitched += 1,
                HoleStatus::Skipped => s.skipped += 1,
                HoleStatus::Failed => s.failed += 1,
            }
        }
        self.summary = s;
    }

    /// The log as pretty JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).unwrap_or_else(|e| format!("{{\"error\": \"{e}\"}}"))
    }
}
