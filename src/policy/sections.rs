//! The sections of a policy, each a plain struct with the default of every key (the
//! values of `config/policy.toml`), and the names of the string-valued keys.

use super::Method;
use serde::{Deserialize, Serialize};

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
            small: vec![Method::Fan, Method::MinAreaFair, Method::Close],
            // chosen from the methods table (README): wavefront first is the most
            // accurate on middle and large bench holes, with the best triangles
            middle: vec![
                Method::Wavefront,
                Method::MinAreaFair,
                Method::AdvancingFront,
                Method::Close,
            ],
            large: vec![
                Method::Wavefront,
                Method::AdvancingFront,
                Method::MinAreaFair,
                Method::Close,
            ],
        }
    }
}

/// How the method for a hole is chosen among its class's list.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum SelectMode {
    /// The list's order: the first method whose patch passes the checks.
    First,
    /// Self-validation: the hole is grown by `select.rings` rings of known surface,
    /// each candidate fills the grown hole, and the one whose patch passes closest to
    /// the removed known surface goes first (the rest keep the list's order).
    Validate,
    /// A rule from the rim: where most edges within `select.rings` rings of the loop
    /// are flat (dihedral angle under `select.flat_angle_deg`, a piecewise-planar CAD
    /// surface), `select.flat_method` goes first; elsewhere the list's order.
    Rim,
}

/// Per-hole choice of method (`[select]`).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct Select {
    pub mode: SelectMode,
    /// Rings of input faces around the hole removed for the self-validation (at least).
    pub rings: usize,
    /// One ring per this many boundary vertices when that is more than `rings` (a
    /// large hole is grown deeper, so that the known points test more than the rim);
    /// 0: always `rings`.
    pub vertices_per_ring: usize,
    /// The candidates: the methods of a hole's list that are also here, when at least
    /// two are.
    pub methods: Vec<Method>,
    /// Mode `rim`: the share of the rim's interior edges that must be flat for
    /// `flat_method` to go first.
    pub flat_share: f64,
    /// Mode `rim`: an edge is flat when the normals of its two faces differ by less
    /// than this many degrees.
    pub flat_angle_deg: f64,
    /// Mode `rim`: the method put first on a flat rim.
    pub flat_method: Method,
}

impl Default for Select {
    fn default() -> Self {
        Select {
            mode: SelectMode::First,
            rings: 2,
            vertices_per_ring: 25,
            methods: vec![Method::Wavefront, Method::MinAreaFair],
            flat_share: 0.5,
            flat_angle_deg: 0.5,
            flat_method: Method::Wavefront,
        }
    }
}

/// The accepted patch pulled toward a second surface (`[blend]`).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct Blend {
    /// How far each new vertex of a middle hole's accepted patch moves toward the
    /// second surface: 0 off, 1 onto it.
    pub weight_middle: f64,
    /// The same for a large hole.
    pub weight_large: f64,
    /// The weight, in place of the class's, for a middle or large hole whose rim reads
    /// flat (the `select` rim rule: `select.flat_share` of the edges within
    /// `select.rings` rings bend less than `select.flat_angle_deg`); absent: the
    /// class's weight. Blending stays off where the class's weight is 0.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub weight_flat: Option<f64>,
    /// The second surface: `with`'s own patch of the hole, or the accepted patch faired.
    pub surface: BlendSurface,
    /// The second method, run on the same hole (not `fan` or `close`), with
    /// `surface = "with"`. A patch made by this method itself is kept as it is.
    pub with: Method,
    /// Whose triangles the blended patch has, with `surface = "with"`: the surface is
    /// the same (`weight` of the way from the accepted patch to `with`'s), the
    /// triangles are either's.
    pub keep: BlendKeep,
    /// The fairing of the faired surface (`surface = "faired"`): `fair`, the `[fair]`
    /// keys on every hole; `validate`, chosen for each large hole among three (the
    /// `[fair]` keys, the umbrella energy, minimum variation) by which one, with rings
    /// of the known surface around the patch freed too, moves them least.
    pub energy: BlendEnergy,
}

/// How the faired surface is faired (`blend.energy`).
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum BlendEnergy {
    /// The `[fair]` keys.
    Fair,
    /// Chosen per large hole by freeing known rings ([`FairEnergy`]).
    Validate,
}

/// A fairing of a patch's new vertices (the candidates of `blend.energy = "validate"`).
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum FairEnergy {
    /// `Δ^c x = 0` with the `[fair]` keys (by default the thin plate, cotangent weights,
    /// each Laplacian over its vertex's Voronoi area).
    Fair,
    /// The least-squares umbrella energy `Σ_v |x_v − Σ_u w_vu x_u / W_v|²` (the `[fair]`
    /// weights, each Laplacian over its weight sum `W_v`, every vertex counted alike),
    /// as MeshLib's `positionVertsSmoothly` fairs a filled hole.
    Umbrella,
    /// `Δ³ x = 0` with the `[fair]` weights (minimum variation).
    MinimumVariation,
}

impl FairEnergy {
    /// The name in the repair log.
    pub fn name(self) -> &'static str {
        match self {
            FairEnergy::Fair => "fair",
            FairEnergy::Umbrella => "umbrella",
            FairEnergy::MinimumVariation => "minimum_variation",
        }
    }
}

/// What an accepted patch is pulled toward (`blend.surface`).
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum BlendSurface {
    /// `blend.with`'s own patch of the hole (its closest points).
    With,
    /// The accepted patch itself with its new vertices faired (`Δ^c x = 0` with the
    /// `[fair]` keys, the loop and the outer rings fixed) on its own triangles: each
    /// new vertex moves toward its own faired position, and the triangles are kept.
    Faired,
}

/// Whose triangles a blended patch keeps (`blend.keep`).
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum BlendKeep {
    /// `blend.with`'s patch, its new vertices put onto the blended surface (the
    /// accepted patch moved `weight` of the way to `with`'s): the wavefront's rows are
    /// better shaped than a refined thin plate's triangles. The accepted patch pulled
    /// as below when that fails the checks.
    With,
    /// The accepted patch, its new vertices moved `weight` of the way to `with`'s.
    Accepted,
}

impl Default for Blend {
    fn default() -> Self {
        Blend {
            weight_middle: 0.0,
            weight_large: 0.0,
            weight_flat: None,
            surface: BlendSurface::With,
            with: Method::Wavefront,
            keep: BlendKeep::With,
            energy: BlendEnergy::Fair,
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
    /// Skip a loop whose vector area is at least this share of the area of its
    /// connected component (0: off): the border of an open surface spans about its
    /// whole piece (a range image 0.5), a hole in a surface closed but for its holes
    /// a small part of it (the bench's largest synthetic hole 0.14).
    pub min_area_share: f64,
    /// Apply the rules only to the longest loop of each connected component.
    pub only_longest: bool,
}

impl Default for Border {
    fn default() -> Self {
        Border {
            max_vertices: 0,
            max_bbox_share: 0.0,
            min_area_share: 0.25,
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

/// Rim trimming, the last step of the fallback chain: when every method of
/// a hole's list failed, the input faces around the loop are removed ring by ring and
/// the larger hole filled. Changes input faces (each counted in the log).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct Rim {
    /// Trim the rim of a hole every method failed on.
    pub trim: bool,
    /// Most rings of faces removed around one hole.
    pub max_rings: usize,
    /// Most input faces removed around one hole (0: no limit).
    pub max_faces: usize,
}

impl Default for Rim {
    fn default() -> Self {
        Rim {
            trim: true,
            max_rings: 3,
            max_faces: 500,
        }
    }
}

/// Cracks: boundary vertices that coincide with another boundary vertex
/// are identified, zipping the crack shut instead of filling it (the loop is logged
/// `stitched`). Changes the corners of the input faces at the crack (counted in the log).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct Crack {
    /// Zip cracks before filling.
    pub stitch: bool,
    /// Two boundary vertices coincide when they are closer than this share of the
    /// smaller of their local boundary edge lengths (0: exactly the same position).
    pub tolerance: f64,
}

impl Default for Crack {
    fn default() -> Self {
        Crack {
            stitch: true,
            tolerance: 0.1,
        }
    }
}

/// What is done with an island that is not removed.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum IslandMode {
    /// Joined to the hole's loop by two bridge faces, the region filled as one patch.
    Bridge,
    /// Only removed (below `remove_below_faces`); a larger island leaves its hole
    /// skipped.
    Remove,
}

/// Islands: the border of another piece of surface lying inside a hole.
/// Never a patch over an island: small ones are removed as debris, larger ones bridged
/// to the hole's loop (or, when that cannot be done, the hole is skipped).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct Islands {
    pub mode: IslandMode,
    /// Islands of fewer faces are removed (counted per hole: `island_faces_removed`).
    pub remove_below_faces: usize,
}

impl Default for Islands {
    fn default() -> Self {
        Islands {
            mode: IslandMode::Bridge,
            remove_below_faces: 10,
        }
    }
}

/// Floating debris: connected pieces of fewer faces than this are removed
/// before filling (0: kept).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, Default)]
#[serde(default, deny_unknown_fields)]
pub struct Debris {
    pub remove_below_faces: usize,
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
    /// The search space of the exhaustive triangulation (loops up to
    /// `restricted_search_above` vertices).
    pub search: Search,
    /// `min_area_fair`'s relaxation collapses patch edges shorter than this times the
    /// local scale (0: none).
    pub collapse: f64,
}

/// Where the initial triangulation of a loop up to `refine.restricted_search_above`
/// vertices is searched.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum Search {
    /// Every triangulation of the loop.
    Full,
    /// Among the edges of the loop's 3D Delaunay triangulation, as CGAL does; every
    /// triangulation when none is found there.
    Delaunay,
    /// `min_area_fair` makes its patch from both and keeps the one of larger area;
    /// the other methods search every triangulation.
    Both,
}

impl Refine {
    /// Whether a loop's triangulation (every method's but `min_area_fair`'s under
    /// `"both"`, which makes both itself) is searched among its Delaunay edges first.
    pub fn delaunay_first(&self) -> bool {
        self.search == Search::Delaunay
    }
}

impl Default for Refine {
    fn default() -> Self {
        Refine {
            density: std::f64::consts::SQRT_2,
            weight: TriangulationWeight::DihedralArea,
            restricted_search_above: 400,
            search: Search::Full,
            collapse: 0.75,
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
    /// `min_area_fair`: passes that relax the faired patch on its own surface and fair
    /// it again, so that the layout and the cotangent weights come from the faired
    /// surface rather than the flat first guess (0: one fairing only).
    pub passes: usize,
}

impl Default for Fair {
    fn default() -> Self {
        Fair {
            continuity: 2,
            weights: Weights::Cotangent,
            tangential_relax: 30,
            passes: 3,
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
    /// The initial front has run away when its patch's area passes this times the
    /// loop's vector area (0: no limit).
    pub max_area_ratio: f64,
}

impl Default for Lssvm {
    fn default() -> Self {
        Lssvm {
            rings: 3,
            gamma: 10.0,
            kernel_width: 0.7,
            iterations: 2,
            merge_distance: 0.5,
            max_area_ratio: 3.0,
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

impl Limits {
    /// The threads that fill holes: [`Limits::threads`], 0 meaning one per core.
    pub fn fill_threads(&self) -> usize {
        match self.threads {
            0 => std::thread::available_parallelism().map_or(1, |n| n.get()),
            n => n,
        }
    }
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

/// A name as the policy spells it (methods and the other string-valued keys).
pub trait PolicyName: Copy + 'static {
    /// Every value, in policy spelling order.
    const VALUES: &'static [Self];
    /// The policy spelling.
    fn policy_name(self) -> &'static str;
}

/// [`PolicyName`] for a plain enum: its variants in spelling order, each with its
/// spelling (one list, so the values and the names cannot disagree).
macro_rules! policy_names {
    ($t:ident { $($v:ident => $name:literal),+ $(,)? }) => {
        impl PolicyName for $t {
            const VALUES: &'static [$t] = &[$($t::$v),+];
            fn policy_name(self) -> &'static str {
                match self {
                    $($t::$v => $name),+
                }
            }
        }
    };
}

policy_names!(Search { Full => "full", Delaunay => "delaunay", Both => "both" });
policy_names!(BlendKeep { With => "with", Accepted => "accepted" });
policy_names!(BlendSurface { With => "with", Faired => "faired" });
policy_names!(BlendEnergy { Fair => "fair", Validate => "validate" });
policy_names!(TriangulationWeight { Area => "area", DihedralArea => "dihedral_area" });
policy_names!(WavefrontPlacement { EdgePlane => "edge_plane", Interpolated => "interpolated" });
policy_names!(Weights { Uniform => "uniform", Cotangent => "cotangent", Fujiwara => "fujiwara" });
policy_names!(SmoothScope { Whole => "whole", Rings => "rings" });
policy_names!(SelectMode { First => "first", Validate => "validate", Rim => "rim" });
policy_names!(IslandMode { Bridge => "bridge", Remove => "remove" });
policy_names!(BoundaryRule { Fixed => "fixed", BoundaryNeighbors => "boundary_neighbors" });

impl PolicyName for Method {
    const VALUES: &'static [Method] = Method::ALL;
    fn policy_name(self) -> &'static str {
        self.name()
    }
}
