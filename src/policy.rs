//! The TOML repair policy: serde types with defaults, then validation into an
//! immutable [`Policy`].
//!
//! Every section and key is optional. `config/policy.toml` is the default policy with
//! every key commented; it is embedded in the binary ([`DEFAULT_POLICY_TOML`]).

use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The default policy file, shipped as `config/policy.toml`.
pub const DEFAULT_POLICY_TOML: &str = include_str!("../config/policy.toml");

/// A hole-filling method, as the policy spells it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// Centroid fan (paper 002 §5.1).
    Fan,
    /// Minimum-area triangulation, refinement, fairing (paper 002 §5.2).
    MinAreaFair,
    /// Improved advancing front (paper 002 §5.3).
    AdvancingFront,
    /// Improved wavefront with curvature restoration (paper 004, Huang et al. 2022).
    Wavefront,
}

impl Method {
    /// Every method, in policy spelling.
    pub const ALL: &'static [Method] = &[
        Method::Fan,
        Method::MinAreaFair,
        Method::AdvancingFront,
        Method::Wavefront,
    ];
    /// The policy spelling.
    pub fn name(self) -> &'static str {
        match self {
            Method::Fan => "fan",
            Method::MinAreaFair => "min_area_fair",
            Method::AdvancingFront => "advancing_front",
            Method::Wavefront => "wavefront",
        }
    }
}

/// Size classes and the method list of each (first method, then fallbacks).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct Dispatch {
    pub small_max: usize,
    pub middle_max: usize,
    pub small: Vec<Method>,
    pub middle: Vec<Method>,
    pub large: Vec<Method>,
}

impl Default for Dispatch {
    fn default() -> Self {
        Dispatch {
            small_max: 6,
            middle_max: 50,
            small: vec![Method::Fan, Method::MinAreaFair],
            middle: vec![Method::MinAreaFair, Method::AdvancingFront],
            large: vec![Method::AdvancingFront, Method::MinAreaFair],
        }
    }
}

/// Which boundary loops are the outer border of an open scan (skipped, not filled).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct Border {
    /// Skip a loop with more boundary vertices than this (0: no limit).
    pub max_vertices: usize,
    /// Skip a loop whose bounding-box diagonal exceeds this share of the mesh's
    /// bounding-box diagonal (0: no limit).
    pub max_bbox_share: f64,
    /// Apply the rules only to the longest loop of each connected component.
    pub only_longest: bool,
}

impl Default for Border {
    fn default() -> Self {
        Border {
            max_vertices: 0,
            max_bbox_share: 0.6,
            only_longest: true,
        }
    }
}

/// Boundary cleaning before filling (ALGORITHMS A2).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct Clean {
    /// Remove tooth faces (faces with two or more edges on a hole's boundary).
    pub remove_teeth: bool,
    /// Split boundary edges longer than this many times the loop's mean boundary edge
    /// length (0: off; the paper's value is 2.0). Changes input faces.
    pub split_long_edges: f64,
}

impl Default for Clean {
    fn default() -> Self {
        Clean {
            remove_teeth: true,
            split_long_edges: 0.0,
        }
    }
}

/// Weight of the minimum-weight triangulation.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum TriangulationWeight {
    /// Total area (paper 002).
    Area,
    /// Liepa's weight: maximum dihedral angle, then area.
    DihedralArea,
}

/// Refinement of the initial triangulation to the surrounding density.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct Refine {
    /// Density factor (paper 002: sqrt 2). 0 switches refinement off.
    pub density: f64,
    /// Weight of the initial triangulation.
    pub weight: TriangulationWeight,
    /// Loops with more vertices than this use the restricted triangulation search.
    pub restricted_search_above: usize,
}

impl Default for Refine {
    fn default() -> Self {
        Refine {
            density: std::f64::consts::SQRT_2,
            weight: TriangulationWeight::Area,
            restricted_search_above: 60,
        }
    }
}

/// Laplacian weights.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum Weights {
    Uniform,
    Cotangent,
    Fujiwara,
}

/// Fairing of the refined patch.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct Fair {
    /// 0: no fairing, 1: membrane (Laplacian), 2: thin plate (bi-Laplacian), 3: minimum variation.
    pub continuity: u8,
    /// Laplacian weights (cotangent falls back to uniform on degenerate angles).
    pub weights: Weights,
}

impl Default for Fair {
    fn default() -> Self {
        Fair {
            continuity: 2,
            weights: Weights::Cotangent,
        }
    }
}

/// The improved advancing front (paper 002 §5.3).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct Front {
    /// Below this angle (degrees) the vertex is closed with one triangle.
    pub angle_small: f64,
    /// Below this angle one new vertex on the bisector; above, two on the trisectors.
    pub angle_large: f64,
    /// Weight of the vertex normal in the corrected normal (beta = 1 - alpha).
    pub alpha: f64,
    /// Weight of the curvature term in the placement angle (omega2 = 1 - omega1).
    pub omega1: f64,
    /// A new vertex closer than this times the local edge length to a front vertex
    /// is merged into it.
    pub merge_distance: f64,
    /// Give up (and fall back) after this many front steps per boundary vertex.
    pub max_steps_per_vertex: usize,
    /// Fair the front's patch afterwards (bi-Laplacian, as `[fair]`).
    pub fair: bool,
}

impl Default for Front {
    fn default() -> Self {
        Front {
            angle_small: 75.0,
            angle_large: 135.0,
            alpha: 0.5,
            omega1: 0.5,
            merge_distance: 0.5,
            max_steps_per_vertex: 200,
            fair: true,
        }
    }
}

/// Where the wavefront puts a new point out of the vertex's tangent plane.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum WavefrontPlacement {
    /// In the plane of the two front edges (paper 004 §2.2; interpolated where that
    /// plane is ill-conditioned).
    EdgePlane,
    /// Elevation interpolated between the two front edges' elevations (follows the
    /// chords; restoration then tends to flatten).
    Interpolated,
}

/// The improved wavefront with curvature restoration (paper 004, ALGORITHMS C).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct Wavefront {
    /// At or below this front angle (degrees) the vertex is closed with one triangle.
    pub alpha: f64,
    /// At or below this angle one new point on the bisector; above, two on the trisectors.
    pub beta: f64,
    /// When the smallest front angle is at least this (degrees), a front vertex drawn
    /// at random (from `seed`) is processed instead.
    pub mu: f64,
    /// Rotate each new triangle to its expected normal (paper 004 §2.2.1).
    pub curvature_restoration: bool,
    /// Out-of-plane placement of new points.
    pub placement: WavefrontPlacement,
    /// Give up (and fall back) after this many front steps per boundary vertex.
    pub max_steps_per_vertex: usize,
    /// A new point closer than this times the hole's mean boundary edge length to a
    /// non-adjacent front vertex is merged into it.
    pub merge_distance: f64,
}

impl Default for Wavefront {
    fn default() -> Self {
        Wavefront {
            alpha: 75.0,
            beta: 135.0,
            mu: 150.0,
            curvature_restoration: true,
            placement: WavefrontPlacement::EdgePlane,
            max_steps_per_vertex: 200,
            merge_distance: 0.5,
        }
    }
}

/// Patch checks (ALGORITHMS A5).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct Checks {
    /// Reject a patch whose triangles intersect the mesh or each other.
    pub self_intersection: bool,
    /// Smallest allowed angle of a patch triangle, in degrees.
    pub min_angle_deg: f64,
}

impl Default for Checks {
    fn default() -> Self {
        Checks {
            self_intersection: true,
            min_angle_deg: 0.5,
        }
    }
}

/// Time limits.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct Limits {
    /// Per method attempt on one hole, in milliseconds; past it the next method is tried.
    pub hole_time_ms: u64,
}

impl Default for Limits {
    fn default() -> Self {
        Limits { hole_time_ms: 10_000 }
    }
}

/// Where smoothing applies.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum SmoothScope {
    Whole,
    Rings,
}

/// What smoothing does with boundary vertices.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum BoundaryRule {
    /// Boundary vertices stay where they are.
    Fixed,
    /// Boundary vertices move using only their boundary neighbours.
    BoundaryNeighbors,
}

/// Taubin lambda/mu smoothing before filling (ALGORITHMS A4).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct Smooth {
    pub enabled: bool,
    pub iterations: usize,
    pub lambda: f64,
    pub mu: f64,
    pub weights: Weights,
    pub scope: SmoothScope,
    /// With `scope = "rings"`: how many rings around each hole.
    pub rings: usize,
    pub boundary: BoundaryRule,
}

impl Default for Smooth {
    fn default() -> Self {
        Smooth {
            enabled: false,
            iterations: 10,
            lambda: 0.33,
            mu: -0.34,
            weights: Weights::Uniform,
            scope: SmoothScope::Whole,
            rings: 3,
            boundary: BoundaryRule::Fixed,
        }
    }
}

/// The whole policy as read.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, Default)]
#[serde(default, deny_unknown_fields)]
pub struct Policy {
    /// Seed of every random choice (same input + policy = same output).
    pub seed: u64,
    pub dispatch: Dispatch,
    pub border: Border,
    pub clean: Clean,
    pub refine: Refine,
    pub fair: Fair,
    pub front: Front,
    pub wavefront: Wavefront,
    pub checks: Checks,
    pub limits: Limits,
    pub smooth: Smooth,
}

/// A policy error, naming the file, line and key.
#[derive(Debug, thiserror::Error)]
#[error("{file}{}: {}{message}", line.map(|l| format!(":{l}")).unwrap_or_default(), key.as_ref().map(|k| format!("key `{k}`: ")).unwrap_or_default())]
pub struct PolicyError {
    pub file: PathBuf,
    pub line: Option<usize>,
    pub key: Option<String>,
    pub message: String,
}

impl Policy {
    /// Reads and validates a policy file.
    pub fn from_file(path: &Path) -> Result<Policy, PolicyError> {
        let text = std::fs::read_to_string(path).map_err(|e| PolicyError {
            file: path.to_path_buf(),
            line: None,
            key: None,
            message: e.to_string(),
        })?;
        Policy::from_toml_str(&text, path)
    }

    /// Parses and validates policy text; `path` names it in errors.
    pub fn from_toml_str(text: &str, path: &Path) -> Result<Policy, PolicyError> {
        let policy: Policy = toml::from_str(text).map_err(|e| {
            let line = e.span().map(|s| text[..s.start.min(text.len())].lines().count().max(1));
            PolicyError {
                file: path.to_path_buf(),
                line,
                key: None,
                message: e.message().trim().to_string(),
            }
        })?;
        policy.validate().map_err(|(key, message)| PolicyError {
            file: path.to_path_buf(),
            line: None,
            key: Some(key),
            message,
        })?;
        Ok(policy)
    }

    /// The embedded default policy.
    pub fn default_policy() -> Policy {
        Policy::default()
    }

    /// Range and consistency checks; `Err((key, message))`.
    pub fn validate(&self) -> Result<(), (String, String)> {
        let d = &self.dispatch;
        if d.small_max < 3 {
            return Err(("dispatch.small_max".into(), "must be at least 3".into()));
        }
        if d.middle_max < d.small_max {
            return Err(("dispatch.middle_max".into(), "must be at least dispatch.small_max".into()));
        }
        for (k, l) in [("dispatch.small", &d.small), ("dispatch.middle", &d.middle), ("dispatch.large", &d.large)] {
            if l.is_empty() {
                return Err((k.into(), "needs at least one method".into()));
            }
        }
        Ok(())
    }
}
