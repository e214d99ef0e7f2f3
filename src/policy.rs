//! The TOML repair policy: read raw, then validated once into an immutable [`Policy`].
//!
//! Every section and key is optional (defaults apply). `config/policy.toml` is the
//! default policy with every key commented (what it does, unit, range, default, paper);
//! it is embedded in the binary as [`DEFAULT_POLICY_TOML`], and a unit test checks that
//! it parses to exactly [`Policy::default`], so the file and the code cannot drift.
//!
//! Reading has two stages, like ripgrep's low-level and high-level arguments:
//! 1. *raw*: the text is parsed into a spanned TOML tree and every key is read into
//!    its field by type (an unknown section, key, method or value name is an error with
//!    a "did you mean" when a valid name is close; a wrong type names the key); the
//!    line of every key is remembered;
//! 2. *validated*: [`Policy::validate`] checks every range and every consistency rule
//!    between keys, and an error is reported at the line of the offending key.
//!
//! Errors read `FILE:LINE: key `section.key`: message`, e.g.
//! `policy.toml:12: key `front.angle_small`: must be between 0 and 180 (got 200)`.
//! The one list of valid keys is [`SECTIONS`].
//!
//! [`Policy`] still derives `Deserialize` (the repair log embeds it), but a policy file
//! should be read with [`Policy::from_file`] or [`Policy::from_toml_str`], which validate.

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use toml::de::{DeString, DeTable, DeValue};
use toml::Spanned;

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
    /// Plain advancing front, LS-SVM prediction of the Laplacian, Poisson solve (paper 003).
    LssvmPoisson,
    /// Improved wavefront with curvature restoration (paper 004, Huang et al. 2022).
    Wavefront,
    /// Prediction by differential evolution + constrained Delaunay (paper 000).
    Hpde,
}

impl Method {
    /// Every method, in policy spelling.
    pub const ALL: &'static [Method] = &[
        Method::Fan,
        Method::MinAreaFair,
        Method::AdvancingFront,
        Method::LssvmPoisson,
        Method::Wavefront,
        Method::Hpde,
    ];
    /// The policy spelling.
    pub fn name(self) -> &'static str {
        match self {
            Method::Fan => "fan",
            Method::MinAreaFair => "min_area_fair",
            Method::AdvancingFront => "advancing_front",
            Method::LssvmPoisson => "lssvm_poisson",
            Method::Wavefront => "wavefront",
            Method::Hpde => "hpde",
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
            // chosen from the methods table (README): wavefront first is the most
            // accurate on middle and large bench holes, with the best triangles
            middle: vec![
                Method::Wavefront,
                Method::MinAreaFair,
                Method::AdvancingFront,
            ],
            large: vec![
                Method::Wavefront,
                Method::AdvancingFront,
                Method::MinAreaFair,
            ],
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
            remove_teeth: false,
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
    /// Tangential relaxation steps applied to every patch after its method (0: off);
    /// evens out the triangles without moving the faired surface.
    pub tangential_relax: usize,
}

impl Default for Fair {
    fn default() -> Self {
        Fair {
            continuity: 2,
            weights: Weights::Cotangent,
            tangential_relax: 30,
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

/// LS-SVM + Poisson (paper 003, Xu et al. 2013; ALGORITHMS E).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct Lssvm {
    /// Rings of mesh vertices around the hole whose Laplacians train the regression.
    pub rings: usize,
    /// LS-SVM regularisation `gamma` of eq. 11/14 (larger: closer fit, less smoothing).
    pub gamma: f64,
    /// RBF kernel width sigma, in units of the hole loop's radius (perimeter / 2π).
    pub kernel_width: f64,
    /// Outer iterations of predict-then-solve (the Laplacian is recomputed each time).
    pub iterations: usize,
    /// A new front vertex closer than this times the mean boundary edge length to a
    /// front vertex is merged into it.
    pub merge_distance: f64,
}

impl Default for Lssvm {
    fn default() -> Self {
        Lssvm {
            rings: 3,
            gamma: 10.0,
            kernel_width: 0.7,
            iterations: 2,
            merge_distance: 0.5,
        }
    }
}

/// HPDE: prediction by differential evolution (paper 000 §4; ALGORITHMS D).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct Hpde {
    /// DE population size per section plane = this times the number of predicted points.
    pub population_factor: usize,
    /// DE mutation factor F.
    pub f: f64,
    /// DE crossover rate CR.
    pub cr: f64,
    /// DE generations per section plane.
    pub generations: usize,
    /// Critical dihedral angle Ac (degrees): below it the hole is handled as two planes.
    pub ac_deg: f64,
    /// Critical angle Ic (degrees) between a correspondence line and the boundary.
    pub ic_deg: f64,
    /// Smoothing iterations of the new vertices (NumSmooth).
    pub num_smooth: usize,
    /// Edges shorter than this times EdgeLen are collapsed.
    pub collapse_rate: f64,
    /// Target spacing of predicted points, times EdgeLen.
    pub spacing: f64,
    /// Each circular arc also passes through its ring point AP (TV = P - AP is then
    /// the arc's secant); false: the arc is tangent to TV at P (the literal reading).
    pub arcs_through_ring: bool,
    /// When the loop projects to no simple polygon on any plane, map it to a circle
    /// (by arc length) instead of failing.
    pub disk_fallback: bool,
}

impl Default for Hpde {
    fn default() -> Self {
        Hpde {
            population_factor: 3,
            f: 0.8,
            cr: 0.05,
            generations: 50,
            ac_deg: 90.0,
            ic_deg: 12.0,
            num_smooth: 60,
            collapse_rate: 0.6,
            spacing: 0.8,
            arcs_through_ring: true,
            disk_fallback: true,
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
    /// After this many front steps per boundary vertex, close the rest as residual fronts.
    pub max_steps_per_vertex: usize,
    /// A new point closer than this times the hole's mean boundary edge length to a
    /// non-adjacent front vertex is merged into it.
    pub merge_distance: f64,
    /// A loop with more boundary vertices is left to the next method (0: no limit).
    pub max_boundary_vertices: usize,
    /// The front has run away (climbed over the hole into a dome or folded) when its
    /// patch's area passes this many times the loop's vector area: the run stops and
    /// the method goes on to its residual-closing variants (0: no limit).
    pub max_area_ratio: f64,
}

impl Default for Wavefront {
    fn default() -> Self {
        Wavefront {
            alpha: 75.0,
            beta: 135.0,
            mu: 150.0,
            curvature_restoration: true,
            placement: WavefrontPlacement::EdgePlane,
            max_steps_per_vertex: 4,
            merge_distance: 0.5,
            max_boundary_vertices: 2000,
            max_area_ratio: 2.0,
        }
    }
}

impl Lssvm {
    /// Range checks.
    pub fn validate(&self) -> Result<(), Invalid> {
        if self.rings == 0 || self.rings > 20 {
            return Err(Invalid::new(
                "lssvm.rings",
                format!("must be in 1..=20 (got {})", self.rings),
            ));
        }
        if !(self.gamma.is_finite() && self.gamma > 0.0 && self.gamma <= 1e10) {
            return Err(Invalid::new(
                "lssvm.gamma",
                format!("must be in (0, 1e10] (got {})", self.gamma),
            ));
        }
        if !(self.kernel_width.is_finite() && self.kernel_width > 0.0 && self.kernel_width <= 100.0)
        {
            return Err(Invalid::new(
                "lssvm.kernel_width",
                format!("must be in (0, 100] (got {})", self.kernel_width),
            ));
        }
        if self.iterations == 0 || self.iterations > 100 {
            return Err(Invalid::new(
                "lssvm.iterations",
                format!("must be in 1..=100 (got {})", self.iterations),
            ));
        }
        if !(self.merge_distance.is_finite() && (0.0..1.0).contains(&self.merge_distance)) {
            return Err(Invalid::new(
                "lssvm.merge_distance",
                format!("must be in [0, 1) (got {})", self.merge_distance),
            ));
        }
        Ok(())
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
    /// Threads that fill independent holes at once (0: one per core). The output
    /// does not depend on it.
    pub threads: usize,
    /// Largest patch (triangles) a method builds for one hole (0: no limit):
    /// min_area_fair grades its density (fine along the loop, coarse inside) to stay
    /// near half of it, the other methods give up
    /// when their estimate (or, for advancing_front, their patch) exceeds it.
    pub max_patch_triangles: usize,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            hole_time_ms: 10_000,
            threads: 0,
            max_patch_triangles: 50_000,
        }
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
    pub hpde: Hpde,
    pub checks: Checks,
    pub limits: Limits,
    pub smooth: Smooth,
    pub lssvm: Lssvm,
}

/// A name as the policy spells it (methods and the other string-valued keys).
pub trait PolicyName: Copy + 'static {
    /// Every value, in policy spelling order.
    const VALUES: &'static [Self];
    /// The policy spelling.
    fn policy_name(self) -> &'static str;
}

impl PolicyName for Method {
    const VALUES: &'static [Method] = Method::ALL;
    fn policy_name(self) -> &'static str {
        self.name()
    }
}

impl PolicyName for TriangulationWeight {
    const VALUES: &'static [TriangulationWeight] =
        &[TriangulationWeight::Area, TriangulationWeight::DihedralArea];
    fn policy_name(self) -> &'static str {
        match self {
            TriangulationWeight::Area => "area",
            TriangulationWeight::DihedralArea => "dihedral_area",
        }
    }
}

impl PolicyName for WavefrontPlacement {
    const VALUES: &'static [WavefrontPlacement] = &[
        WavefrontPlacement::EdgePlane,
        WavefrontPlacement::Interpolated,
    ];
    fn policy_name(self) -> &'static str {
        match self {
            WavefrontPlacement::EdgePlane => "edge_plane",
            WavefrontPlacement::Interpolated => "interpolated",
        }
    }
}

impl PolicyName for Weights {
    const VALUES: &'static [Weights] = &[Weights::Uniform, Weights::Cotangent, Weights::Fujiwara];
    fn policy_name(self) -> &'static str {
        match self {
            Weights::Uniform => "uniform",
            Weights::Cotangent => "cotangent",
            Weights::Fujiwara => "fujiwara",
        }
    }
}

impl PolicyName for SmoothScope {
    const VALUES: &'static [SmoothScope] = &[SmoothScope::Whole, SmoothScope::Rings];
    fn policy_name(self) -> &'static str {
        match self {
            SmoothScope::Whole => "whole",
            SmoothScope::Rings => "rings",
        }
    }
}

impl PolicyName for BoundaryRule {
    const VALUES: &'static [BoundaryRule] = &[BoundaryRule::Fixed, BoundaryRule::BoundaryNeighbors];
    fn policy_name(self) -> &'static str {
        match self {
            BoundaryRule::Fixed => "fixed",
            BoundaryRule::BoundaryNeighbors => "boundary_neighbors",
        }
    }
}

/// Keys outside any section.
pub const TOP_LEVEL_KEYS: &[&str] = &["seed"];

/// Every section and its keys, in the order of `config/policy.toml`. This is the one
/// list behind unknown-key errors and their suggestions; a unit test checks that the
/// default file sets every key listed here.
pub const SECTIONS: &[(&str, &[&str])] = &[
    (
        "dispatch",
        &["small_max", "middle_max", "small", "middle", "large"],
    ),
    (
        "border",
        &["max_vertices", "max_bbox_share", "only_longest"],
    ),
    ("clean", &["remove_teeth", "split_long_edges"]),
    ("refine", &["density", "weight", "restricted_search_above"]),
    ("fair", &["continuity", "weights", "tangential_relax"]),
    (
        "front",
        &[
            "angle_small",
            "angle_large",
            "alpha",
            "omega1",
            "merge_distance",
            "max_steps_per_vertex",
            "fair",
        ],
    ),
    (
        "wavefront",
        &[
            "alpha",
            "beta",
            "mu",
            "curvature_restoration",
            "placement",
            "max_steps_per_vertex",
            "merge_distance",
            "max_boundary_vertices",
            "max_area_ratio",
        ],
    ),
    (
        "hpde",
        &[
            "population_factor",
            "f",
            "cr",
            "generations",
            "ac_deg",
            "ic_deg",
            "num_smooth",
            "collapse_rate",
            "spacing",
            "arcs_through_ring",
            "disk_fallback",
        ],
    ),
    ("checks", &["self_intersection", "min_angle_deg"]),
    (
        "limits",
        &["hole_time_ms", "threads", "max_patch_triangles"],
    ),
    (
        "smooth",
        &[
            "enabled",
            "iterations",
            "lambda",
            "mu",
            "weights",
            "scope",
            "rings",
            "boundary",
        ],
    ),
    (
        "lssvm",
        &[
            "rings",
            "gamma",
            "kernel_width",
            "iterations",
            "merge_distance",
        ],
    ),
];

/// Largest policy file [`Policy::from_file`] reads (1 MiB; the default file is about 7 KB).
pub const MAX_POLICY_BYTES: u64 = 1 << 20;
/// Largest `refine.restricted_search_above`: the full search takes O(k^2) memory.
pub const MAX_FULL_SEARCH: usize = 2000;
/// Largest `limits.threads`.
pub const MAX_THREADS: usize = 1024;
/// Smallest and largest `limits.max_patch_triangles` (besides 0).
pub const MIN_PATCH_TRIANGLES: usize = 100;
pub const MAX_PATCH_TRIANGLES: usize = 100_000_000;

/// Largest `limits.hole_time_ms` (one day).
pub const MAX_HOLE_TIME_MS: u64 = 86_400_000;
/// Largest `smooth.iterations` (and `hpde.num_smooth`).
pub const MAX_SMOOTH_ITERATIONS: usize = 10_000;
/// Largest `hpde.population_factor`.
pub const MAX_HPDE_POPULATION_FACTOR: usize = 100;
/// Largest `hpde.generations`.
pub const MAX_HPDE_GENERATIONS: usize = 100_000;

/// A policy error, naming the file, line and key.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{}{}: {}{message}", file.display(), line.map(|l| format!(":{l}")).unwrap_or_default(), key.as_ref().map(|k| format!("key `{k}`: ")).unwrap_or_default())]
pub struct PolicyError {
    /// The policy file as given.
    pub file: PathBuf,
    /// 1-based line of the offending key or value, when the file has one.
    pub line: Option<usize>,
    /// Dotted key, e.g. `dispatch.small_max`.
    pub key: Option<String>,
    /// What is wrong.
    pub message: String,
}

/// A range or consistency violation found by [`Policy::validate`].
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("key `{key}`: {message}")]
pub struct Invalid {
    /// Dotted key, e.g. `front.angle_small`.
    pub key: &'static str,
    /// What is wrong, with the value found.
    pub message: String,
    /// For a rule between two keys: the same problem told from the other key, used
    /// when a file sets only that other key.
    pub other: Option<(&'static str, String)>,
}

impl Invalid {
    fn new(key: &'static str, message: String) -> Invalid {
        Invalid {
            key,
            message,
            other: None,
        }
    }
    fn pair(
        key: &'static str,
        message: String,
        other: &'static str,
        other_message: String,
    ) -> Invalid {
        Invalid {
            key,
            message,
            other: Some((other, other_message)),
        }
    }
}

impl Policy {
    /// Reads and validates a policy file (at most [`MAX_POLICY_BYTES`]).
    pub fn from_file(path: &Path) -> Result<Policy, PolicyError> {
        use std::io::Read;
        let error = |message: String| PolicyError {
            file: path.to_path_buf(),
            line: None,
            key: None,
            message,
        };
        let file =
            std::fs::File::open(path).map_err(|e| error(format!("cannot read the policy: {e}")))?;
        let mut text = String::new();
        file.take(MAX_POLICY_BYTES + 1)
            .read_to_string(&mut text)
            .map_err(|e| error(format!("cannot read the policy: {e}")))?;
        if text.len() as u64 > MAX_POLICY_BYTES {
            return Err(error(format!(
                "larger than {MAX_POLICY_BYTES} bytes; this is not a policy file"
            )));
        }
        Policy::from_toml_str(&text, path)
    }

    /// Parses and validates policy text; `path` names it in errors.
    pub fn from_toml_str(text: &str, path: &Path) -> Result<Policy, PolicyError> {
        let root = DeTable::parse(text).map_err(|e| syntax_error(text, path, &e))?;
        let mut reader = Reader {
            text,
            file: path,
            lines: BTreeMap::new(),
        };
        let policy = reader.read(root.get_ref())?;
        policy.validate().map_err(|inv| {
            let (key, message) = match inv.other {
                Some((other, other_message))
                    if !reader.lines.contains_key(inv.key) && reader.lines.contains_key(other) =>
                {
                    (other, other_message)
                }
                _ => (inv.key, inv.message),
            };
            PolicyError {
                file: path.to_path_buf(),
                line: reader.lines.get(key).copied(),
                key: Some(key.to_string()),
                message,
            }
        })?;
        Ok(policy)
    }

    /// The embedded default policy ([`DEFAULT_POLICY_TOML`]), equal to
    /// [`Policy::default`] (a unit test checks it).
    pub fn default_policy() -> Policy {
        static DEFAULT: OnceLock<Policy> = OnceLock::new();
        DEFAULT
            .get_or_init(|| {
                Policy::from_toml_str(DEFAULT_POLICY_TOML, Path::new("config/policy.toml"))
                    .unwrap_or_default()
            })
            .clone()
    }

    /// Range and consistency checks of every key; the first violation, in file order.
    pub fn validate(&self) -> Result<(), Invalid> {
        let d = &self.dispatch;
        if d.small_max < 3 {
            return Err(Invalid::new(
                "dispatch.small_max",
                format!("must be at least 3 (got {})", d.small_max),
            ));
        }
        if d.middle_max < d.small_max {
            return Err(Invalid::pair(
                "dispatch.middle_max",
                format!(
                    "must be at least dispatch.small_max = {} (got {})",
                    d.small_max, d.middle_max
                ),
                "dispatch.small_max",
                format!(
                    "must be at most dispatch.middle_max = {} (got {})",
                    d.middle_max, d.small_max
                ),
            ));
        }
        for (key, list) in [
            ("dispatch.small", &d.small),
            ("dispatch.middle", &d.middle),
            ("dispatch.large", &d.large),
        ] {
            if list.is_empty() {
                return Err(Invalid::new(key, "needs at least one method".into()));
            }
            for (i, m) in list.iter().enumerate() {
                if list[..i].contains(m) {
                    return Err(Invalid::new(
                        key,
                        format!("lists method `{}` more than once", m.name()),
                    ));
                }
            }
        }

        let b = &self.border;
        if b.max_vertices != 0 && b.max_vertices < 3 {
            return Err(Invalid::new(
                "border.max_vertices",
                format!(
                    "must be 0 (no limit) or at least 3 (got {})",
                    b.max_vertices
                ),
            ));
        }
        closed("border.max_bbox_share", b.max_bbox_share, 0.0, 10.0)?;

        let c = &self.clean;
        finite("clean.split_long_edges", c.split_long_edges)?;
        if c.split_long_edges != 0.0 && c.split_long_edges < 1.0 {
            return Err(Invalid::new(
                "clean.split_long_edges",
                format!("must be 0 (off) or at least 1 (got {})", c.split_long_edges),
            ));
        }

        let r = &self.refine;
        finite("refine.density", r.density)?;
        if r.density != 0.0 && !(1.0..=4.0).contains(&r.density) {
            return Err(Invalid::new(
                "refine.density",
                format!("must be 0 (off) or between 1 and 4 (got {})", r.density),
            ));
        }
        if !(3..=MAX_FULL_SEARCH).contains(&r.restricted_search_above) {
            return Err(Invalid::new(
                "refine.restricted_search_above",
                format!(
                    "must be between 3 and {MAX_FULL_SEARCH} (got {})",
                    r.restricted_search_above
                ),
            ));
        }

        if self.fair.continuity > 3 {
            return Err(Invalid::new(
                "fair.continuity",
                continuity_message(u64::from(self.fair.continuity)),
            ));
        }

        if self.fair.tangential_relax > MAX_SMOOTH_ITERATIONS {
            return Err(Invalid::new(
                "fair.tangential_relax",
                format!(
                    "must be at most {MAX_SMOOTH_ITERATIONS} (got {})",
                    self.fair.tangential_relax
                ),
            ));
        }

        let f = &self.front;
        open("front.angle_small", f.angle_small, 0.0, 180.0)?;
        open("front.angle_large", f.angle_large, 0.0, 180.0)?;
        if f.angle_large <= f.angle_small {
            return Err(Invalid::pair(
                "front.angle_large",
                format!(
                    "must be greater than front.angle_small = {} (got {})",
                    f.angle_small, f.angle_large
                ),
                "front.angle_small",
                format!(
                    "must be less than front.angle_large = {} (got {})",
                    f.angle_large, f.angle_small
                ),
            ));
        }
        closed("front.alpha", f.alpha, 0.0, 1.0)?;
        closed("front.omega1", f.omega1, 0.0, 1.0)?;
        closed("front.merge_distance", f.merge_distance, 0.0, 1.0)?;
        if f.max_steps_per_vertex < 1 {
            return Err(Invalid::new(
                "front.max_steps_per_vertex",
                format!("must be at least 1 (got {})", f.max_steps_per_vertex),
            ));
        }

        let w = &self.wavefront;
        open("wavefront.alpha", w.alpha, 0.0, 180.0)?;
        open("wavefront.beta", w.beta, 0.0, 180.0)?;
        if w.beta <= w.alpha {
            return Err(Invalid::pair(
                "wavefront.beta",
                format!(
                    "must be greater than wavefront.alpha = {} (got {})",
                    w.alpha, w.beta
                ),
                "wavefront.alpha",
                format!(
                    "must be less than wavefront.beta = {} (got {})",
                    w.beta, w.alpha
                ),
            ));
        }
        finite("wavefront.mu", w.mu)?;
        if !(w.mu > 0.0 && w.mu <= 180.0) {
            return Err(Invalid::new(
                "wavefront.mu",
                format!("must be greater than 0 and at most 180 (got {})", w.mu),
            ));
        }
        closed("wavefront.merge_distance", w.merge_distance, 0.0, 1.0)?;
        finite("wavefront.max_area_ratio", w.max_area_ratio)?;
        if !(w.max_area_ratio == 0.0 || w.max_area_ratio >= 1.0) {
            return Err(Invalid::new(
                "wavefront.max_area_ratio",
                format!(
                    "must be 0 (no limit) or at least 1 (got {})",
                    w.max_area_ratio
                ),
            ));
        }
        if w.max_steps_per_vertex < 1 {
            return Err(Invalid::new(
                "wavefront.max_steps_per_vertex",
                format!("must be at least 1 (got {})", w.max_steps_per_vertex),
            ));
        }
        let h = &self.hpde;
        if !(1..=MAX_HPDE_POPULATION_FACTOR).contains(&h.population_factor) {
            return Err(Invalid::new(
                "hpde.population_factor",
                format!(
                    "must be between 1 and {MAX_HPDE_POPULATION_FACTOR} (got {})",
                    h.population_factor
                ),
            ));
        }
        open("hpde.f", h.f, 0.0, 2.0)?;
        closed("hpde.cr", h.cr, 0.0, 1.0)?;
        if h.generations > MAX_HPDE_GENERATIONS {
            return Err(Invalid::new(
                "hpde.generations",
                format!(
                    "must be at most {MAX_HPDE_GENERATIONS} (got {})",
                    h.generations
                ),
            ));
        }
        open("hpde.ac_deg", h.ac_deg, 0.0, 180.0)?;
        open("hpde.ic_deg", h.ic_deg, 0.0, 90.0)?;
        if h.num_smooth > MAX_SMOOTH_ITERATIONS {
            return Err(Invalid::new(
                "hpde.num_smooth",
                format!(
                    "must be at most {MAX_SMOOTH_ITERATIONS} (got {})",
                    h.num_smooth
                ),
            ));
        }
        closed("hpde.collapse_rate", h.collapse_rate, 0.0, 1.0)?;
        closed("hpde.spacing", h.spacing, 0.25, 4.0)?;

        let min_angle = self.checks.min_angle_deg;
        finite("checks.min_angle_deg", min_angle)?;
        if !(0.0..30.0).contains(&min_angle) {
            return Err(Invalid::new(
                "checks.min_angle_deg",
                if min_angle == 30.0 {
                    format!("must be less than 30 (got {min_angle})")
                } else {
                    format!("must be at least 0 and less than 30 (got {min_angle})")
                },
            ));
        }

        let ms = self.limits.hole_time_ms;
        if ms > MAX_HOLE_TIME_MS {
            return Err(Invalid::new(
                "limits.hole_time_ms",
                format!(
                    "must be 0 (no limit) or between 1 and {MAX_HOLE_TIME_MS} (one day) (got {ms})"
                ),
            ));
        }
        let threads = self.limits.threads;
        if threads > MAX_THREADS {
            return Err(Invalid::new(
                "limits.threads",
                format!("must be 0 (one per core) or between 1 and {MAX_THREADS} (got {threads})"),
            ));
        }

        let mt = self.limits.max_patch_triangles;
        if mt != 0 && !(MIN_PATCH_TRIANGLES..=MAX_PATCH_TRIANGLES).contains(&mt) {
            return Err(Invalid::new(
                "limits.max_patch_triangles",
                format!(
                    "must be 0 (no limit) or between {MIN_PATCH_TRIANGLES} and {MAX_PATCH_TRIANGLES} (got {mt})"
                ),
            ));
        }

        let s = &self.smooth;
        if s.iterations > MAX_SMOOTH_ITERATIONS {
            return Err(Invalid::new(
                "smooth.iterations",
                format!(
                    "must be at most {MAX_SMOOTH_ITERATIONS} (got {})",
                    s.iterations
                ),
            ));
        }
        open("smooth.lambda", s.lambda, 0.0, 1.0)?;
        finite("smooth.mu", s.mu)?;
        if s.mu <= -1.0 {
            return Err(Invalid::new(
                "smooth.mu",
                format!("must be greater than -1 (got {})", s.mu),
            ));
        }
        if s.mu >= -s.lambda {
            return Err(Invalid::pair(
                "smooth.mu",
                format!(
                    "must be less than -smooth.lambda = {} so that the second step un-shrinks (got {})",
                    -s.lambda, s.mu
                ),
                "smooth.lambda",
                format!(
                    "must be less than -smooth.mu = {} so that the second step un-shrinks (got {})",
                    -s.mu, s.lambda
                ),
            ));
        }
        if s.scope == SmoothScope::Rings && s.rings < 1 {
            return Err(Invalid::pair(
                "smooth.rings",
                format!(
                    "must be at least 1 when smooth.scope = \"rings\" (got {})",
                    s.rings
                ),
                "smooth.scope",
                format!(
                    "is \"rings\" but smooth.rings = {}; set smooth.rings to at least 1",
                    s.rings
                ),
            ));
        }
        self.lssvm.validate()?;
        Ok(())
    }
}

fn continuity_message(got: u64) -> String {
    format!("must be 0, 1, 2 or 3 (got {got})")
}

fn finite(key: &'static str, x: f64) -> Result<(), Invalid> {
    if x.is_finite() {
        Ok(())
    } else {
        Err(Invalid::new(
            key,
            format!("must be a finite number (got {x})"),
        ))
    }
}

/// `lo <= x <= hi`.
fn closed(key: &'static str, x: f64, lo: f64, hi: f64) -> Result<(), Invalid> {
    finite(key, x)?;
    if (lo..=hi).contains(&x) {
        Ok(())
    } else {
        Err(Invalid::new(
            key,
            format!("must be between {lo} and {hi} (got {x})"),
        ))
    }
}

/// `lo < x < hi`.
fn open(key: &'static str, x: f64, lo: f64, hi: f64) -> Result<(), Invalid> {
    finite(key, x)?;
    let message = if x == lo {
        format!("must be greater than {lo} (got {x})")
    } else if x == hi {
        format!("must be less than {hi} (got {x})")
    } else if x < lo || x > hi {
        format!("must be between {lo} and {hi} (got {x})")
    } else {
        return Ok(());
    };
    Err(Invalid::new(key, message))
}

/// A TOML syntax error with its line, column and, for a duplicate key, the key.
fn syntax_error(text: &str, path: &Path, e: &toml::de::Error) -> PolicyError {
    let mut message = format!("TOML syntax error: {}", e.message().trim());
    let mut line = None;
    if let Some(span) = e.span() {
        let start = span.start.min(text.len());
        line = Some(line_of(text, start));
        let snippet = text.get(start..span.end.min(text.len())).unwrap_or("");
        if e.message().trim() == "duplicate key" && !snippet.is_empty() && !snippet.contains('\n') {
            message = format!(
                "`{snippet}` appears twice (each key and each [table] may be set only once)"
            );
        } else {
            let line_start = text.as_bytes()[..start]
                .iter()
                .rposition(|&b| b == b'\n')
                .map_or(0, |i| i + 1);
            let column = text
                .get(line_start..start)
                .map_or(1, |s| s.chars().count() + 1);
            message = format!(
                "TOML syntax error at column {column}: {}",
                e.message().trim()
            );
        }
    }
    PolicyError {
        file: path.to_path_buf(),
        line,
        key: None,
        message,
    }
}

/// 1-based line of a byte offset.
fn line_of(text: &str, offset: usize) -> usize {
    let end = offset.min(text.len());
    text.as_bytes()[..end]
        .iter()
        .filter(|&&b| b == b'\n')
        .count()
        + 1
}

/// Entries of a table in the order they appear in the file.
fn in_file_order<'t, 'i>(
    table: &'t DeTable<'i>,
) -> Vec<(&'t Spanned<DeString<'i>>, &'t Spanned<DeValue<'i>>)> {
    let mut entries: Vec<_> = table.iter().collect();
    entries.sort_by_key(|(k, _)| k.span().start);
    entries
}

/// `a`/`an` and the TOML type of a value, with the value when it is short.
fn describe(v: &DeValue) -> String {
    match v {
        DeValue::String(s) => format!("a string (\"{}\")", s.escape_default()),
        DeValue::Integer(i) => format!("an integer ({i})"),
        DeValue::Float(f) => format!("a float ({f})"),
        DeValue::Boolean(b) => format!("a boolean ({b})"),
        DeValue::Datetime(d) => format!("a date-time ({d})"),
        DeValue::Array(_) => "an array".into(),
        DeValue::Table(_) => "a table".into(),
    }
}

/// Edit distance (optimal string alignment: insertions, deletions, substitutions and
/// transpositions of neighbours each cost 1), over characters.
pub fn edit_distance(a: &str, b: &str) -> usize {
    let a: Vec<char> = a.chars().collect();
    let b: Vec<char> = b.chars().collect();
    let w = b.len() + 1;
    let mut d = vec![0usize; (a.len() + 1) * w];
    for (i, row) in d.chunks_mut(w).enumerate() {
        row[0] = i;
    }
    for (j, cell) in d.iter_mut().take(w).enumerate() {
        *cell = j;
    }
    for i in 1..=a.len() {
        for j in 1..=b.len() {
            let cost = usize::from(a[i - 1] != b[j - 1]);
            let mut best = (d[(i - 1) * w + j] + 1)
                .min(d[i * w + j - 1] + 1)
                .min(d[(i - 1) * w + j - 1] + cost);
            if i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1] {
                best = best.min(d[(i - 2) * w + j - 2] + 1);
            }
            d[i * w + j] = best;
        }
    }
    d[a.len() * w + b.len()]
}

/// The valid name closest to `typed` (case, `-` and spaces ignored), when it is close
/// enough to be a misspelling: at most a third of the typed length in edits (at least
/// 1), or a part of the name (3 characters or more, e.g. `time_ms` for `hole_time_ms`).
pub fn did_you_mean<'c>(typed: &str, candidates: &[&'c str]) -> Option<&'c str> {
    let norm = |s: &str| s.trim().to_lowercase().replace(['-', ' '], "_");
    let t = norm(typed);
    let len = t.chars().count();
    let limit = (len / 3).max(1);
    candidates
        .iter()
        .map(|&c| {
            let n = norm(c);
            (edit_distance(&t, &n), len >= 3 && n.contains(&t), c)
        })
        .filter(|&(d, part, _)| d <= limit || part)
        .min_by_key(|&(d, _, _)| d)
        .map(|(_, _, c)| c)
}

/// The sections that have a key of this name, if any.
fn sections_with_key(name: &str) -> Option<Vec<&'static str>> {
    let found: Vec<&str> = SECTIONS
        .iter()
        .filter(|(_, keys)| keys.contains(&name))
        .map(|(s, _)| *s)
        .collect();
    (!found.is_empty()).then_some(found)
}

/// `[a]`, `[a] or [b]`.
fn sections_list(sections: &[&str]) -> String {
    sections
        .iter()
        .map(|s| format!("[{s}]"))
        .collect::<Vec<_>>()
        .join(" or ")
}

/// Stage 1: the spanned TOML tree read into a [`Policy`] (types checked, ranges not),
/// remembering the line of every key for stage 2.
struct Reader<'a> {
    text: &'a str,
    file: &'a Path,
    /// Dotted key -> 1-based line.
    lines: BTreeMap<String, usize>,
}

impl Reader<'_> {
    fn error(&self, span: Range<usize>, key: &str, message: String) -> PolicyError {
        PolicyError {
            file: self.file.to_path_buf(),
            line: Some(line_of(self.text, span.start)),
            key: Some(key.to_string()),
            message,
        }
    }

    fn type_error(&self, key: &str, v: &Spanned<DeValue>, expected: &str) -> PolicyError {
        self.error(
            v.span(),
            key,
            format!("expected {expected}, got {}", describe(v.get_ref())),
        )
    }

    fn read(&mut self, root: &DeTable) -> Result<Policy, PolicyError> {
        let mut p = Policy::default();
        for (k, v) in in_file_order(root) {
            let name: &str = k.get_ref();
            self.lines
                .insert(name.to_string(), line_of(self.text, k.span().start));
            if name == "seed" {
                p.seed = self.uint(name, v)?;
                continue;
            }
            let Some(&(section, _)) = SECTIONS.iter().find(|(s, _)| *s == name) else {
                return Err(self.unknown_top_level(k, v));
            };
            let DeValue::Table(table) = v.get_ref() else {
                let mut e = self.type_error(name, v, &format!("a table ([{name}])"));
                if let DeValue::Array(_) = v.get_ref() {
                    e.message
                        .push_str(&format!("; write [{name}], not [[{name}]]"));
                }
                return Err(e);
            };
            for (k2, v2) in in_file_order(table) {
                let key_name: &str = k2.get_ref();
                let path = format!("{section}.{key_name}");
                self.lines
                    .insert(path.clone(), line_of(self.text, k2.span().start));
                if !self.set(&mut p, section, key_name, &path, v2)? {
                    return Err(self.unknown_key(section, k2, &path));
                }
            }
        }
        Ok(p)
    }

    /// Sets one key; `Ok(false)` when the section has no such key.
    fn set(
        &self,
        p: &mut Policy,
        section: &str,
        name: &str,
        key: &str,
        v: &Spanned<DeValue>,
    ) -> Result<bool, PolicyError> {
        match (section, name) {
            ("dispatch", "small_max") => p.dispatch.small_max = self.usize(key, v)?,
            ("dispatch", "middle_max") => p.dispatch.middle_max = self.usize(key, v)?,
            ("dispatch", "small") => p.dispatch.small = self.methods(key, v)?,
            ("dispatch", "middle") => p.dispatch.middle = self.methods(key, v)?,
            ("dispatch", "large") => p.dispatch.large = self.methods(key, v)?,
            ("border", "max_vertices") => p.border.max_vertices = self.usize(key, v)?,
            ("border", "max_bbox_share") => p.border.max_bbox_share = self.float(key, v)?,
            ("border", "only_longest") => p.border.only_longest = self.boolean(key, v)?,
            ("clean", "remove_teeth") => p.clean.remove_teeth = self.boolean(key, v)?,
            ("clean", "split_long_edges") => p.clean.split_long_edges = self.float(key, v)?,
            ("refine", "density") => p.refine.density = self.float(key, v)?,
            ("refine", "weight") => p.refine.weight = self.named(key, v)?,
            ("refine", "restricted_search_above") => {
                p.refine.restricted_search_above = self.usize(key, v)?
            }
            ("fair", "continuity") => {
                let n = self.uint(key, v)?;
                p.fair.continuity = u8::try_from(n)
                    .map_err(|_| self.error(v.span(), key, continuity_message(n)))?;
            }
            ("fair", "weights") => p.fair.weights = self.named(key, v)?,
            ("fair", "tangential_relax") => p.fair.tangential_relax = self.usize(key, v)?,
            ("front", "angle_small") => p.front.angle_small = self.float(key, v)?,
            ("front", "angle_large") => p.front.angle_large = self.float(key, v)?,
            ("front", "alpha") => p.front.alpha = self.float(key, v)?,
            ("front", "omega1") => p.front.omega1 = self.float(key, v)?,
            ("front", "merge_distance") => p.front.merge_distance = self.float(key, v)?,
            ("front", "max_steps_per_vertex") => {
                p.front.max_steps_per_vertex = self.usize(key, v)?
            }
            ("front", "fair") => p.front.fair = self.boolean(key, v)?,
            ("wavefront", "alpha") => p.wavefront.alpha = self.float(key, v)?,
            ("wavefront", "beta") => p.wavefront.beta = self.float(key, v)?,
            ("wavefront", "mu") => p.wavefront.mu = self.float(key, v)?,
            ("wavefront", "curvature_restoration") => {
                p.wavefront.curvature_restoration = self.boolean(key, v)?
            }
            ("wavefront", "placement") => p.wavefront.placement = self.named(key, v)?,
            ("wavefront", "max_steps_per_vertex") => {
                p.wavefront.max_steps_per_vertex = self.usize(key, v)?
            }
            ("wavefront", "merge_distance") => p.wavefront.merge_distance = self.float(key, v)?,
            ("wavefront", "max_boundary_vertices") => {
                p.wavefront.max_boundary_vertices = self.usize(key, v)?
            }
            ("wavefront", "max_area_ratio") => p.wavefront.max_area_ratio = self.float(key, v)?,
            ("lssvm", "rings") => p.lssvm.rings = self.usize(key, v)?,
            ("lssvm", "gamma") => p.lssvm.gamma = self.float(key, v)?,
            ("lssvm", "kernel_width") => p.lssvm.kernel_width = self.float(key, v)?,
            ("lssvm", "iterations") => p.lssvm.iterations = self.usize(key, v)?,
            ("lssvm", "merge_distance") => p.lssvm.merge_distance = self.float(key, v)?,
            ("hpde", "population_factor") => p.hpde.population_factor = self.usize(key, v)?,
            ("hpde", "f") => p.hpde.f = self.float(key, v)?,
            ("hpde", "cr") => p.hpde.cr = self.float(key, v)?,
            ("hpde", "generations") => p.hpde.generations = self.usize(key, v)?,
            ("hpde", "ac_deg") => p.hpde.ac_deg = self.float(key, v)?,
            ("hpde", "ic_deg") => p.hpde.ic_deg = self.float(key, v)?,
            ("hpde", "num_smooth") => p.hpde.num_smooth = self.usize(key, v)?,
            ("hpde", "collapse_rate") => p.hpde.collapse_rate = self.float(key, v)?,
            ("hpde", "spacing") => p.hpde.spacing = self.float(key, v)?,
            ("hpde", "arcs_through_ring") => p.hpde.arcs_through_ring = self.boolean(key, v)?,
            ("hpde", "disk_fallback") => p.hpde.disk_fallback = self.boolean(key, v)?,
            ("checks", "self_intersection") => p.checks.self_intersection = self.boolean(key, v)?,
            ("checks", "min_angle_deg") => p.checks.min_angle_deg = self.float(key, v)?,
            ("limits", "hole_time_ms") => p.limits.hole_time_ms = self.uint(key, v)?,
            ("limits", "threads") => p.limits.threads = self.usize(key, v)?,
            ("limits", "max_patch_triangles") => {
                p.limits.max_patch_triangles = self.usize(key, v)?
            }
            ("smooth", "enabled") => p.smooth.enabled = self.boolean(key, v)?,
            ("smooth", "iterations") => p.smooth.iterations = self.usize(key, v)?,
            ("smooth", "lambda") => p.smooth.lambda = self.float(key, v)?,
            ("smooth", "mu") => p.smooth.mu = self.float(key, v)?,
            ("smooth", "weights") => p.smooth.weights = self.named(key, v)?,
            ("smooth", "scope") => p.smooth.scope = self.named(key, v)?,
            ("smooth", "rings") => p.smooth.rings = self.usize(key, v)?,
            ("smooth", "boundary") => p.smooth.boundary = self.named(key, v)?,
            _ => return Ok(false),
        }
        Ok(true)
    }

    fn unknown_top_level(&self, k: &Spanned<DeString>, v: &Spanned<DeValue>) -> PolicyError {
        let name: &str = k.get_ref();
        let is_table = matches!(v.get_ref(), DeValue::Table(_));
        let section_names: Vec<&str> = SECTIONS.iter().map(|(s, _)| *s).collect();
        let mut candidates = section_names.clone();
        candidates.extend_from_slice(TOP_LEVEL_KEYS);
        let what = if is_table {
            "unknown section"
        } else {
            "unknown key"
        };
        let hint = if let Some(s) = did_you_mean(name, &candidates) {
            if section_names.contains(&s) {
                format!("did you mean [{s}]?")
            } else {
                format!("did you mean `{s}`?")
            }
        } else if let Some(s) = sections_with_key(name) {
            let dotted = s
                .iter()
                .map(|s| format!("`{s}.{name}`"))
                .collect::<Vec<_>>()
                .join(" or ");
            format!(
                "`{name}` belongs in {}: write it under the section or as {dotted}",
                sections_list(&s)
            )
        } else {
            format!(
                "the top level has `{}` and the sections [{}]",
                TOP_LEVEL_KEYS.join("`, `"),
                section_names.join("], [")
            )
        };
        self.error(k.span(), name, format!("{what}; {hint}"))
    }

    fn unknown_key(&self, section: &str, k: &Spanned<DeString>, path: &str) -> PolicyError {
        let name: &str = k.get_ref();
        let keys = SECTIONS
            .iter()
            .find(|(s, _)| *s == section)
            .map(|(_, keys)| *keys)
            .unwrap_or_default();
        let hint = if let Some(s) = did_you_mean(name, keys) {
            format!("did you mean `{s}`?")
        } else if TOP_LEVEL_KEYS.contains(&name) {
            format!("`{name}` belongs at the top level, before any [section]")
        } else if let Some(s) = sections_with_key(name) {
            format!("`{name}` belongs in {}, not [{section}]", sections_list(&s))
        } else {
            format!("[{section}] has `{}`", keys.join("`, `"))
        };
        self.error(k.span(), path, format!("unknown key; {hint}"))
    }

    fn int(&self, key: &str, v: &Spanned<DeValue>) -> Result<i64, PolicyError> {
        match v.get_ref() {
            DeValue::Integer(i) => i64::from_str_radix(i.as_str(), i.radix()).map_err(|_| {
                self.error(v.span(), key, format!("integer {i} is too large for TOML"))
            }),
            _ => Err(self.type_error(key, v, "an integer")),
        }
    }

    fn uint(&self, key: &str, v: &Spanned<DeValue>) -> Result<u64, PolicyError> {
        let n = self.int(key, v)?;
        u64::try_from(n)
            .map_err(|_| self.error(v.span(), key, format!("must not be negative (got {n})")))
    }

    fn usize(&self, key: &str, v: &Spanned<DeValue>) -> Result<usize, PolicyError> {
        let n = self.uint(key, v)?;
        usize::try_from(n)
            .map_err(|_| self.error(v.span(), key, format!("integer {n} is too large")))
    }

    /// A number: a TOML float, or an integer (`angle_small = 90` means 90.0).
    fn float(&self, key: &str, v: &Spanned<DeValue>) -> Result<f64, PolicyError> {
        match v.get_ref() {
            DeValue::Float(f) => f
                .as_str()
                .parse::<f64>()
                .map_err(|_| self.error(v.span(), key, format!("cannot read the number {f}"))),
            DeValue::Integer(_) => Ok(self.int(key, v)? as f64),
            _ => Err(self.type_error(key, v, "a number")),
        }
    }

    fn boolean(&self, key: &str, v: &Spanned<DeValue>) -> Result<bool, PolicyError> {
        match v.get_ref() {
            DeValue::Boolean(b) => Ok(*b),
            _ => Err(self.type_error(key, v, "a boolean (true or false)")),
        }
    }

    /// A name from `T::VALUES`, with a suggestion for a misspelling.
    fn name_of<T: PolicyName>(
        &self,
        key: &str,
        v: &Spanned<DeValue>,
        what: &str,
    ) -> Result<T, PolicyError> {
        let names: Vec<&str> = T::VALUES.iter().map(|t| t.policy_name()).collect();
        let list = format!("\"{}\"", names.join("\", \""));
        let DeValue::String(s) = v.get_ref() else {
            return Err(self.type_error(key, v, &format!("a {what} ({list})")));
        };
        if let Some(&t) = T::VALUES.iter().find(|t| t.policy_name() == s.as_ref()) {
            return Ok(t);
        }
        let hint = match did_you_mean(s, &names) {
            Some(m) => format!("did you mean \"{m}\"? "),
            None => String::new(),
        };
        Err(self.error(
            v.span(),
            key,
            format!(
                "unknown {what} \"{}\"; {hint}({what}s: {list})",
                s.escape_default()
            ),
        ))
    }

    fn named<T: PolicyName>(&self, key: &str, v: &Spanned<DeValue>) -> Result<T, PolicyError> {
        self.name_of(key, v, "value")
    }

    fn methods(&self, key: &str, v: &Spanned<DeValue>) -> Result<Vec<Method>, PolicyError> {
        let DeValue::Array(items) = v.get_ref() else {
            return Err(self.type_error(
                key,
                v,
                "an array of method names such as [\"fan\", \"min_area_fair\"]",
            ));
        };
        items
            .iter()
            .map(|item| self.name_of::<Method>(key, item, "method"))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn parse(text: &str) -> Result<Policy, PolicyError> {
        Policy::from_toml_str(text, Path::new("policy.toml"))
    }

    fn err(text: &str) -> PolicyError {
        match parse(text) {
            Ok(p) => panic!("expected an error for {text:?}, got {p:?}"),
            Err(e) => e,
        }
    }

    #[test]
    fn default_file_is_default_policy() {
        let p = parse(DEFAULT_POLICY_TOML).unwrap();
        assert_eq!(p, Policy::default());
        assert_eq!(Policy::default_policy(), Policy::default());
        // The serde path (used for the repair log) reads the file the same way.
        let serde: Policy = toml::from_str(DEFAULT_POLICY_TOML).unwrap();
        assert_eq!(serde, Policy::default());
        assert!(Policy::default().validate().is_ok());
    }

    #[test]
    fn default_file_sets_every_key() {
        let root = DeTable::parse(DEFAULT_POLICY_TOML).unwrap();
        let root = root.get_ref();
        for key in TOP_LEVEL_KEYS {
            assert!(root.get(*key).is_some(), "config/policy.toml lacks `{key}`");
        }
        let mut n = 0;
        for (section, keys) in SECTIONS {
            let Some(DeValue::Table(t)) = root.get(*section).map(|v| v.get_ref()) else {
                panic!("config/policy.toml lacks [{section}]");
            };
            assert_eq!(t.len(), keys.len(), "[{section}] has keys not in SECTIONS");
            for key in *keys {
                assert!(
                    t.get(*key).is_some(),
                    "config/policy.toml lacks {section}.{key}"
                );
                n += 1;
            }
        }
        assert_eq!(root.len(), TOP_LEVEL_KEYS.len() + SECTIONS.len());
        assert_eq!(n, SECTIONS.iter().map(|(_, k)| k.len()).sum::<usize>());
    }

    #[test]
    fn every_listed_key_is_read() {
        // A key listed in SECTIONS but missing from `Reader::set` would be reported unknown.
        for (section, keys) in SECTIONS {
            for key in *keys {
                let root = DeTable::parse(DEFAULT_POLICY_TOML).unwrap();
                let v = &root.get_ref()[*section].get_ref()[*key];
                let r = Reader {
                    text: DEFAULT_POLICY_TOML,
                    file: Path::new("x"),
                    lines: BTreeMap::new(),
                };
                let mut p = Policy::default();
                assert!(
                    r.set(&mut p, section, key, key, v).unwrap(),
                    "{section}.{key}"
                );
            }
        }
    }

    #[test]
    fn empty_and_partial_files_use_defaults() {
        assert_eq!(parse("").unwrap(), Policy::default());
        assert_eq!(parse("# nothing\n\n").unwrap(), Policy::default());
        assert_eq!(parse("[dispatch]\n").unwrap(), Policy::default());
        let p = parse("seed = 7\n[front]\nangle_small = 80\n").unwrap();
        let want = Policy {
            seed: 7,
            front: Front {
                angle_small: 80.0,
                ..Front::default()
            },
            ..Policy::default()
        };
        assert_eq!(p, want);
    }

    #[test]
    fn dotted_keys_and_inline_tables_are_read() {
        let p =
            parse("dispatch.small_max = 8\nsmooth = { enabled = true, iterations = 4 }\n").unwrap();
        assert_eq!(p.dispatch.small_max, 8);
        assert!(p.smooth.enabled);
        assert_eq!(p.smooth.iterations, 4);
        let p =
            parse("[dispatch]\nsmall = [\n  \"fan\",\n]\nlarge = [\"min_area_fair\"]\n").unwrap();
        assert_eq!(p.dispatch.small, vec![Method::Fan]);
        assert_eq!(p.dispatch.large, vec![Method::MinAreaFair]);
    }

    #[test]
    fn unknown_key_names_line_and_suggests() {
        let e = err("seed = 1\n\n[dispatch]\nsmal_max = 4\n");
        assert_eq!(e.line, Some(4));
        assert_eq!(e.key.as_deref(), Some("dispatch.smal_max"));
        assert_eq!(
            e.to_string(),
            "policy.toml:4: key `dispatch.smal_max`: unknown key; did you mean `small_max`?"
        );
        // Transposition, case.
        assert!(err("[smooth]\nlmabda = 0.3\n")
            .message
            .contains("did you mean `lambda`?"));
        assert!(err("[smooth]\nITERATIONS = 3\n")
            .message
            .contains("did you mean `iterations`?"));
        // Dotted key and inline table.
        let e = err("\n\nfront.angel_small = 70\n");
        assert_eq!(
            (e.line, e.key.as_deref()),
            (Some(3), Some("front.angel_small"))
        );
        assert!(e.message.contains("did you mean `angle_small`?"));
        let e = err("\nfront = { alpha = 0.5,\n  omega = 0.5 }\n");
        assert_eq!((e.line, e.key.as_deref()), (Some(3), Some("front.omega")));
        assert!(e.message.contains("did you mean `omega1`?"), "{e}");
    }

    #[test]
    fn unknown_key_without_close_match_lists_or_places_it() {
        let e = err("[limits]\nbananas = 3\n");
        assert_eq!(e.line, Some(2));
        assert_eq!(
            e.message,
            "unknown key; [limits] has `hole_time_ms`, `threads`, `max_patch_triangles`"
        );
        let e = err("[front]\nonly_longest = true\n");
        assert_eq!(
            e.message,
            "unknown key; `only_longest` belongs in [border], not [front]"
        );
        let e = err("[smooth]\nseed = 3\n");
        assert!(e.message.contains("belongs at the top level"), "{e}");
        let e = err("[front]\nweights = \"uniform\"\n");
        assert_eq!(
            e.message,
            "unknown key; `weights` belongs in [fair] or [smooth], not [front]"
        );
        let e = err("[limits]\ntime_ms = 5\n");
        assert_eq!(e.message, "unknown key; did you mean `hole_time_ms`?");
        let e = err("weights = \"uniform\"\n");
        assert_eq!(
            e.message,
            "unknown key; `weights` belongs in [fair] or [smooth]: write it under the section \
             or as `fair.weights` or `smooth.weights`"
        );
        let e = err("small_max = 3\n");
        assert_eq!(e.key.as_deref(), Some("small_max"));
        assert!(e.message.contains("belongs in [dispatch]"), "{e}");
    }

    #[test]
    fn unknown_section_suggests() {
        let e = err("seed = 0\n[dispach]\nsmall_max = 4\n");
        assert_eq!(e.line, Some(2));
        assert_eq!(e.key.as_deref(), Some("dispach"));
        assert_eq!(e.message, "unknown section; did you mean [dispatch]?");
        let e = err("sed = 4\n");
        assert_eq!(e.message, "unknown key; did you mean `seed`?");
        let e = err("[output]\nx = 1\n");
        assert!(
            e.message
                .starts_with("unknown section; the top level has `seed`"),
            "{e}"
        );
    }

    #[test]
    fn unknown_method_suggests() {
        let e = err("[dispatch]\nsmall_max = 5\nmiddle = [\n  \"min_area_fair\",\n  \"advancing-front\",\n]\n");
        assert_eq!(e.line, Some(5));
        assert_eq!(e.key.as_deref(), Some("dispatch.middle"));
        assert_eq!(
            e.message,
            format!(
                "unknown method \"advancing-front\"; did you mean \"advancing_front\"? (methods: {})",
                Method::ALL
                    .iter()
                    .map(|m| format!("\"{}\"", m.name()))
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        );
        let e = err("[dispatch]\nsmall = [\"delaunay\"]\n");
        assert!(
            e.message
                .starts_with("unknown method \"delaunay\"; (methods: \"fan\", \"min_area_fair\", \"advancing_front\""),
            "{}",
            e.message
        );
        let e = err("[dispatch]\nsmall = \"fan\"\n");
        assert!(
            e.message.starts_with("expected an array of method names"),
            "{e}"
        );
        assert!(e.message.ends_with("got a string (\"fan\")"), "{e}");
    }

    #[test]
    fn unknown_enum_value_suggests() {
        let e = err("[fair]\nweights = \"cotan\"\n");
        assert_eq!(e.key.as_deref(), Some("fair.weights"));
        assert!(e.message.contains("did you mean \"cotangent\"?"), "{e}");
        let e = err("[smooth]\nscope = \"ring\"\n");
        assert!(e.message.contains("did you mean \"rings\"?"), "{e}");
        let e = err("[refine]\nweight = 1\n");
        assert_eq!(
            e.message,
            "expected a value (\"area\", \"dihedral_area\"), got an integer (1)"
        );
    }

    #[test]
    fn wrong_types_name_key_and_line() {
        let e = err("[dispatch]\nsmall_max = \"six\"\n");
        assert_eq!(
            e.to_string(),
            "policy.toml:2: key `dispatch.small_max`: expected an integer, got a string (\"six\")"
        );
        let e = err("[dispatch]\nsmall_max = 6.0\n");
        assert_eq!(e.message, "expected an integer, got a float (6.0)");
        let e = err("[border]\nonly_longest = \"yes\"\n");
        assert_eq!(
            e.message,
            "expected a boolean (true or false), got a string (\"yes\")"
        );
        let e = err("[front]\nalpha = \"half\"\n");
        assert_eq!(e.message, "expected a number, got a string (\"half\")");
        let e = err("[limits]\nhole_time_ms = -5\n");
        assert_eq!(e.message, "must not be negative (got -5)");
        let e = err("dispatch = 3\n");
        assert_eq!(e.key.as_deref(), Some("dispatch"));
        assert_eq!(
            e.message,
            "expected a table ([dispatch]), got an integer (3)"
        );
        let e = err("[[smooth]]\nenabled = true\n");
        assert!(e.message.ends_with("write [smooth], not [[smooth]]"), "{e}");
        let e = err("[fair]\ncontinuity = 300\n");
        assert_eq!(e.message, "must be 0, 1, 2 or 3 (got 300)");
        // Integers are accepted for numbers, in any radix.
        assert_eq!(
            parse("[front]\nangle_large = 0x8c\n")
                .unwrap()
                .front
                .angle_large,
            140.0
        );
        assert_eq!(parse("seed = 1_000\n").unwrap().seed, 1000);
    }

    #[test]
    fn syntax_errors_have_a_line() {
        let e = err("seed = 1\n[dispatch\nsmall_max = 3\n");
        assert_eq!(e.line, Some(2));
        assert_eq!(e.key, None);
        assert_eq!(
            e.message,
            "TOML syntax error at column 10: unclosed table, expected `]`"
        );
        let e = err("[front]\nalpha = 0.5\nalpha = 0.6\n");
        assert_eq!(e.line, Some(3));
        assert_eq!(
            e.message,
            "`alpha` appears twice (each key and each [table] may be set only once)"
        );
        let e = err("[front]\nalpha = 0.5\n\n[front]\n");
        assert_eq!(e.line, Some(4));
        assert!(e.message.starts_with("`front` appears twice"), "{e}");
        let e = err("seed = \"abc\n");
        assert_eq!(e.line, Some(1));
        assert!(
            e.message.starts_with("TOML syntax error at column 12"),
            "{e}"
        );
    }

    #[test]
    fn out_of_range_names_line_of_key() {
        let text = "# comment\nseed = 3\n\n[dispatch]\nsmall_max = 5\n\n[front]\nalpha = 0.5\n\n\n\nangle_small = 200\n";
        let e = err(text);
        assert_eq!(
            e.to_string(),
            "policy.toml:12: key `front.angle_small`: must be between 0 and 180 (got 200)"
        );
        let e = err("\nfront.angle_small = 0\n");
        assert_eq!(
            e.to_string(),
            "policy.toml:2: key `front.angle_small`: must be greater than 0 (got 0)"
        );
        let e = err("front = {\n alpha = 0.2, angle_large = 180 }\n");
        assert_eq!(
            e.to_string(),
            "policy.toml:2: key `front.angle_large`: must be less than 180 (got 180)"
        );
        // Same key name in two sections: the right one.
        let e =
            err("[fair]\nweights = \"uniform\"\n[smooth]\nweights = \"uniform\"\nlambda = 1.5\n");
        assert_eq!(e.line, Some(5));
    }

    /// `(text, key, message)`: each range rule, one at a time.
    const RANGE_CASES: &[(&str, &str, &str)] = &[
        ("[dispatch]\nsmall_max = 2", "dispatch.small_max", "must be at least 3 (got 2)"),
        ("[dispatch]\nmiddle_max = 5", "dispatch.middle_max", "must be at least dispatch.small_max = 6 (got 5)"),
        ("[dispatch]\nsmall_max = 60", "dispatch.small_max", "must be at most dispatch.middle_max = 50 (got 60)"),
        ("[dispatch]\nsmall = []", "dispatch.small", "needs at least one method"),
        ("[dispatch]\nlarge = [\"fan\", \"advancing_front\", \"fan\"]", "dispatch.large", "lists method `fan` more than once"),
        ("[border]\nmax_vertices = 2", "border.max_vertices", "must be 0 (no limit) or at least 3 (got 2)"),
        ("[border]\nmax_bbox_share = 11", "border.max_bbox_share", "must be between 0 and 10 (got 11)"),
        ("[border]\nmax_bbox_share = -0.1", "border.max_bbox_share", "must be between 0 and 10 (got -0.1)"),
        ("[border]\nmax_bbox_share = nan", "border.max_bbox_share", "must be a finite number (got NaN)"),
        ("[clean]\nsplit_long_edges = 0.5", "clean.split_long_edges", "must be 0 (off) or at least 1 (got 0.5)"),
        ("[clean]\nsplit_long_edges = inf", "clean.split_long_edges", "must be a finite number (got inf)"),
        ("[refine]\ndensity = 0.5", "refine.density", "must be 0 (off) or between 1 and 4 (got 0.5)"),
        ("[refine]\ndensity = 4.5", "refine.density", "must be 0 (off) or between 1 and 4 (got 4.5)"),
        ("[refine]\nrestricted_search_above = 2", "refine.restricted_search_above", "must be between 3 and 2000 (got 2)"),
        ("[refine]\nrestricted_search_above = 5000", "refine.restricted_search_above", "must be between 3 and 2000 (got 5000)"),
        ("[fair]\ncontinuity = 4", "fair.continuity", "must be 0, 1, 2 or 3 (got 4)"),
        ("[front]\nangle_small = -5", "front.angle_small", "must be between 0 and 180 (got -5)"),
        ("[front]\nangle_large = 70", "front.angle_large", "must be greater than front.angle_small = 75 (got 70)"),
        ("[front]\nangle_small = 140", "front.angle_small", "must be less than front.angle_large = 135 (got 140)"),
        ("[front]\nangle_small = 100\nangle_large = 100", "front.angle_large", "must be greater than front.angle_small = 100 (got 100)"),
        ("[front]\nalpha = 1.5", "front.alpha", "must be between 0 and 1 (got 1.5)"),
        ("[front]\nomega1 = -1", "front.omega1", "must be between 0 and 1 (got -1)"),
        ("[front]\nmerge_distance = 2", "front.merge_distance", "must be between 0 and 1 (got 2)"),
        ("[front]\nmax_steps_per_vertex = 0", "front.max_steps_per_vertex", "must be at least 1 (got 0)"),
        ("[checks]\nmin_angle_deg = 30", "checks.min_angle_deg", "must be less than 30 (got 30)"),
        ("[checks]\nmin_angle_deg = -1", "checks.min_angle_deg", "must be at least 0 and less than 30 (got -1)"),
        ("[limits]\nhole_time_ms = 86400001", "limits.hole_time_ms", "must be 0 (no limit) or between 1 and 86400000 (one day) (got 86400001)"),
        ("[smooth]\niterations = 10001", "smooth.iterations", "must be at most 10000 (got 10001)"),
        ("[smooth]\nlambda = 0", "smooth.lambda", "must be greater than 0 (got 0)"),
        ("[smooth]\nlambda = 1", "smooth.lambda", "must be less than 1 (got 1)"),
        ("[smooth]\nmu = -1", "smooth.mu", "must be greater than -1 (got -1)"),
        ("[smooth]\nmu = -0.2", "smooth.mu", "must be less than -smooth.lambda = -0.33 so that the second step un-shrinks (got -0.2)"),
        ("[smooth]\nlambda = 0.5", "smooth.lambda", "must be less than -smooth.mu = 0.34 so that the second step un-shrinks (got 0.5)"),
        ("[smooth]\nscope = \"rings\"\nrings = 0", "smooth.rings", "must be at least 1 when smooth.scope = \"rings\" (got 0)"),
        ("[smooth]\nrings = 0\nscope = \"rings\"", "smooth.rings", "must be at least 1 when smooth.scope = \"rings\" (got 0)"),
    ];

    #[test]
    fn every_range_rule() {
        for (text, key, message) in RANGE_CASES {
            let e = err(&format!("seed = 1\n{text}\n"));
            assert_eq!(e.key.as_deref(), Some(*key), "{text}: {e}");
            assert_eq!(e.message, *message, "{text}");
            let want_line = 2 + text
                .lines()
                .position(|l| l.starts_with(key.split('.').nth(1).unwrap()))
                .unwrap();
            assert_eq!(e.line, Some(want_line), "{text}: {e}");
        }
        // Boundary values that are valid.
        for text in [
            "[dispatch]\nsmall_max = 3\nmiddle_max = 3",
            "[border]\nmax_vertices = 3\nmax_bbox_share = 10",
            "[border]\nmax_bbox_share = 0",
            "[clean]\nsplit_long_edges = 1",
            "[refine]\ndensity = 0",
            "[refine]\ndensity = 4\nrestricted_search_above = 2000",
            "[fair]\ncontinuity = 0",
            "[front]\nangle_small = 0.001\nangle_large = 179.999\nalpha = 0\nomega1 = 1\nmerge_distance = 0",
            "[checks]\nmin_angle_deg = 0",
            "[limits]\nhole_time_ms = 0",
            "[limits]\nhole_time_ms = 86400000",
            "[smooth]\niterations = 10000\nscope = \"rings\"\nrings = 1",
            "[smooth]\nrings = 0",
            "[smooth]\nlambda = 0.5\nmu = -0.9",
        ] {
            assert!(parse(text).is_ok(), "{text}: {:?}", parse(text));
        }
    }

    #[test]
    fn pair_rule_when_only_one_key_is_in_the_file() {
        // Only middle_max in the file: named.
        let e = err("[dispatch]\nmiddle_max = 4\n");
        assert_eq!(
            (e.key.as_deref(), e.line),
            (Some("dispatch.middle_max"), Some(2))
        );
        // Neither key in the file (programmatic policy): the primary key, no line.
        let mut p = Policy::default();
        p.front.angle_small = 150.0;
        let inv = p.validate().unwrap_err();
        assert_eq!(inv.key, "front.angle_large");
        assert_eq!(inv.other.as_ref().map(|o| o.0), Some("front.angle_small"));
    }

    #[test]
    fn validate_catches_programmatic_values() {
        let mut p = Policy::default();
        p.fair.continuity = 9;
        assert_eq!(p.validate().unwrap_err().key, "fair.continuity");
        let mut p = Policy::default();
        p.dispatch.middle = vec![Method::Fan, Method::Fan];
        assert_eq!(
            p.validate().unwrap_err().to_string(),
            "key `dispatch.middle`: lists method `fan` more than once"
        );
    }

    #[test]
    fn file_errors() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("nope.toml");
        let e = Policy::from_file(&missing).unwrap_err();
        assert_eq!(e.file, missing);
        assert!(e.message.starts_with("cannot read the policy"), "{e}");
        let bad = dir.path().join("bad.toml");
        std::fs::write(&bad, [0xff, 0xfe, b'\n']).unwrap();
        assert!(Policy::from_file(&bad).is_err());
        let big = dir.path().join("big.toml");
        std::fs::write(&big, "# padding\n".repeat(200_000)).unwrap();
        let e = Policy::from_file(&big).unwrap_err();
        assert!(e.message.starts_with("larger than 1048576 bytes"), "{e}");
        let good = dir.path().join("good.toml");
        std::fs::write(&good, "[smooth]\nenabled = true\n").unwrap();
        assert!(Policy::from_file(&good).unwrap().smooth.enabled);
    }

    #[test]
    fn edit_distance_and_suggestions() {
        assert_eq!(edit_distance("", ""), 0);
        assert_eq!(edit_distance("abc", ""), 3);
        assert_eq!(edit_distance("kitten", "sitting"), 3);
        assert_eq!(edit_distance("lmabda", "lambda"), 1);
        assert_eq!(edit_distance("small_max", "smal_max"), 1);
        assert_eq!(
            did_you_mean("smal_max", &["small_max", "middle_max"]),
            Some("small_max")
        );
        assert_eq!(
            did_you_mean("midle_max", &["small_max", "middle_max"]),
            Some("middle_max")
        );
        assert_eq!(did_you_mean("xyz", &["fan"]), None);
        assert_eq!(did_you_mean("Fan", &["fan"]), Some("fan"));
        assert_eq!(
            did_you_mean(
                "minareafair",
                Method::ALL
                    .iter()
                    .map(|m| m.name())
                    .collect::<Vec<_>>()
                    .as_slice()
            ),
            Some("min_area_fair")
        );
    }

    fn arb_methods() -> impl Strategy<Value = Vec<Method>> {
        Just(Method::ALL.to_vec())
            .prop_shuffle()
            .prop_flat_map(|v| (1..=v.len()).prop_map(move |n| v[..n].to_vec()))
    }

    fn arb_name<T: PolicyName + std::fmt::Debug>() -> impl Strategy<Value = T> {
        proptest::sample::select(T::VALUES)
    }

    prop_compose! {
        fn arb_hpde()(
            population_factor in 1usize..=100, f in 0.001f64..1.999, cr in 0.0f64..=1.0,
            generations in 0usize..=100_000, ac_deg in 0.001f64..179.999,
            ic_deg in 0.001f64..89.999, num_smooth in 0usize..=10_000,
            collapse_rate in 0.0f64..=1.0, spacing in 0.25f64..=4.0, arcs_through_ring: bool,
            disk_fallback: bool,
        ) -> Hpde {
            Hpde {
                population_factor, f, cr, generations, ac_deg, ic_deg, num_smooth,
                collapse_rate, spacing, arcs_through_ring, disk_fallback,
            }
        }
    }

    prop_compose! {
        fn arb_policy()(
            seed in 0u64..=i64::MAX as u64,
            small_max in 3usize..100, extra in 0usize..1000,
            small in arb_methods(), middle in arb_methods(), large in arb_methods(),
            max_vertices in prop_oneof![Just(0usize), 3usize..100_000],
            max_bbox_share in 0.0f64..=10.0, only_longest: bool, remove_teeth: bool,
            split_long_edges in prop_oneof![Just(0.0f64), 1.0f64..100.0],
            density in prop_oneof![Just(0.0f64), 1.0f64..=4.0],
            weight in arb_name::<TriangulationWeight>(), restricted_search_above in 3usize..=2000,
            continuity in 0u8..=3, fair_weights in arb_name::<Weights>(),
            angles in (0.001f64..179.0).prop_flat_map(|a| (Just(a), (a + 0.5)..179.99)),
            alpha in 0.0f64..=1.0, omega1 in 0.0f64..=1.0, merge_distance in 0.0f64..=1.0,
            max_steps_per_vertex in 1usize..10_000, front_fair: bool,
            self_intersection: bool, min_angle_deg in 0.0f64..29.9,
            hole_time_ms in 0u64..=86_400_000,
            enabled: bool, iterations in 0usize..=10_000,
            lm in (0.01f64..0.9).prop_flat_map(|l| (Just(l), -0.999f64..(-l - 0.001))),
            smooth_weights in arb_name::<Weights>(), scope in arb_name::<SmoothScope>(),
            rings in 1usize..50, boundary in arb_name::<BoundaryRule>(),
            hpde in arb_hpde(),
        ) -> Policy {
            Policy {
                seed,
                dispatch: Dispatch { small_max, middle_max: small_max + extra, small, middle, large },
                border: Border { max_vertices, max_bbox_share, only_longest },
                clean: Clean { remove_teeth, split_long_edges },
                refine: Refine { density, weight, restricted_search_above },
                fair: Fair { continuity, weights: fair_weights, tangential_relax: 100 },
                front: Front {
                    angle_small: angles.0, angle_large: angles.1, alpha, omega1, merge_distance,
                    max_steps_per_vertex, fair: front_fair,
                },
                wavefront: Wavefront::default(),
                hpde,
                checks: Checks { self_intersection, min_angle_deg },
                limits: Limits { hole_time_ms, ..Limits::default() },
                smooth: Smooth {
                    enabled, iterations, lambda: lm.0, mu: lm.1, weights: smooth_weights, scope, rings, boundary,
                },
                ..Policy::default()
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        /// A valid policy written as TOML reads back exactly (every key, bit-exact floats),
        /// and the serde path agrees.
        #[test]
        fn valid_policies_round_trip(p in arb_policy()) {
            prop_assert!(p.validate().is_ok(), "{:?}", p.validate());
            let text = toml::to_string(&p).unwrap();
            prop_assert_eq!(&parse(&text).unwrap(), &p);
            let serde: Policy = toml::from_str(&text).unwrap();
            prop_assert_eq!(&serde, &p);
        }

        /// Arbitrary text (mostly near-TOML) never panics.
        #[test]
        fn arbitrary_text_never_panics(text in "(\\[[a-z_.]{0,12}\\]\n|[a-z_.\"]{1,14} = [-0-9.a-z\"\\[\\]{},]{0,14}\n|#.*\n){0,8}") {
            let _ = parse(&text);
        }
    }
}
