//! Stage 2 of reading a policy: the range of every key and the rules between keys.
//! A violation names the key (and, for a rule between two keys, says it from either).

use super::{
    BlendEnergy, BlendSurface, Lssvm, Method, Settings, SmoothScope, MAX_FAIR_PASSES,
    MAX_FULL_SEARCH, MAX_HOLE_TIME_MS, MAX_HPDE_GENERATIONS, MAX_HPDE_POPULATION_FACTOR,
    MAX_PATCH_TRIANGLES, MAX_SMOOTH_ITERATIONS, MAX_THREADS, MIN_PATCH_TRIANGLES,
};

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
    pub(super) fn new(key: &'static str, message: String) -> Invalid {
        Invalid {
            key,
            message,
            other: None,
        }
    }
    pub(super) fn pair(
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

impl Settings {
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

        let sel = &self.select;
        between("select.rings", sel.rings, 1, 8)?;
        if sel.vertices_per_ring != 0 && sel.vertices_per_ring < 3 {
            return Err(Invalid::new(
                "select.vertices_per_ring",
                format!(
                    "must be 0 (off) or at least 3 (got {})",
                    sel.vertices_per_ring
                ),
            ));
        }
        if !(sel.flat_share > 0.0 && sel.flat_share <= 1.0) {
            return Err(Invalid::new(
                "select.flat_share",
                format!("must be in (0, 1] (got {})", sel.flat_share),
            ));
        }
        if !(sel.flat_angle_deg > 0.0 && sel.flat_angle_deg < 90.0) {
            return Err(Invalid::new(
                "select.flat_angle_deg",
                format!("must be in (0, 90) degrees (got {})", sel.flat_angle_deg),
            ));
        }
        if matches!(sel.flat_method, Method::Close | Method::Fan) {
            return Err(Invalid::new(
                "select.flat_method",
                format!(
                    "`{}` cannot go first on a flat rim: it adds no vertex, so it can only be a fallback",
                    sel.flat_method.name()
                ),
            ));
        }
        for (i, m) in sel.methods.iter().enumerate() {
            if sel.methods[..i].contains(m) {
                return Err(Invalid::new(
                    "select.methods",
                    format!("lists method `{}` more than once", m.name()),
                ));
            }
            if matches!(m, Method::Close | Method::Fan) {
                return Err(Invalid::new(
                    "select.methods",
                    format!(
                        "`{}` cannot be a candidate: it adds no vertex, so it can only be a fallback",
                        m.name()
                    ),
                ));
            }
        }

        closed("blend.weight_middle", self.blend.weight_middle, 0.0, 1.0)?;
        closed("blend.weight_large", self.blend.weight_large, 0.0, 1.0)?;
        if let Some(w) = self.blend.weight_flat {
            closed("blend.weight_flat", w, 0.0, 1.0)?;
        }
        if matches!(self.blend.with, Method::Close | Method::Fan) {
            return Err(Invalid::new(
                "blend.with",
                format!(
                    "`{}` cannot be blended with: it adds no vertex, so its patch is the loop's own span",
                    self.blend.with.name()
                ),
            ));
        }
        if self.blend.energy == BlendEnergy::Validate && self.blend.surface != BlendSurface::Faired
        {
            return Err(Invalid::new(
                "blend.energy",
                "\"validate\" chooses the faired surface's fairing, so it needs blend.surface = \"faired\""
                    .to_string(),
            ));
        }
        if self.blend.energy == BlendEnergy::Validate && self.fair.continuity == 0 {
            return Err(Invalid::new(
                "blend.energy",
                "\"validate\" fairs the patch, so it needs fair.continuity 1 to 3 (got 0)"
                    .to_string(),
            ));
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
        closed("border.min_area_share", b.min_area_share, 0.0, 1.0)?;

        let c = &self.clean;
        finite("clean.split_long_edges", c.split_long_edges)?;
        if c.split_long_edges != 0.0 && c.split_long_edges < 1.0 {
            return Err(Invalid::new(
                "clean.split_long_edges",
                format!("must be 0 (off) or at least 1 (got {})", c.split_long_edges),
            ));
        }

        between("rim.max_rings", self.rim.max_rings, 1, 20)?;

        closed("crack.tolerance", self.crack.tolerance, 0.0, 1.0)?;

        let r = &self.refine;
        finite("refine.density", r.density)?;
        if r.density != 0.0 && !(1.0..=4.0).contains(&r.density) {
            return Err(Invalid::new(
                "refine.density",
                format!("must be 0 (off) or between 1 and 4 (got {})", r.density),
            ));
        }
        between(
            "refine.restricted_search_above",
            r.restricted_search_above,
            3,
            MAX_FULL_SEARCH,
        )?;
        finite("refine.collapse", r.collapse)?;
        if !(0.0..1.0).contains(&r.collapse) {
            return Err(Invalid::new(
                "refine.collapse",
                format!("must be 0 (off) or in (0, 1) (got {})", r.collapse),
            ));
        }

        if self.fair.continuity > 3 {
            return Err(Invalid::new(
                "fair.continuity",
                continuity_message(u64::from(self.fair.continuity)),
            ));
        }

        at_most(
            "fair.tangential_relax",
            self.fair.tangential_relax,
            MAX_SMOOTH_ITERATIONS,
        )?;
        at_most("fair.passes", self.fair.passes, MAX_FAIR_PASSES)?;

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
        at_least("front.max_steps_per_vertex", f.max_steps_per_vertex, 1)?;

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
        area_ratio("wavefront.max_area_ratio", w.max_area_ratio)?;
        at_least("wavefront.max_steps_per_vertex", w.max_steps_per_vertex, 1)?;
        let h = &self.hpde;
        between(
            "hpde.population_factor",
            h.population_factor,
            1,
            MAX_HPDE_POPULATION_FACTOR,
        )?;
        open("hpde.f", h.f, 0.0, 2.0)?;
        closed("hpde.cr", h.cr, 0.0, 1.0)?;
        at_most("hpde.generations", h.generations, MAX_HPDE_GENERATIONS)?;
        open("hpde.ac_deg", h.ac_deg, 0.0, 180.0)?;
        open("hpde.ic_deg", h.ic_deg, 0.0, 90.0)?;
        at_most("hpde.num_smooth", h.num_smooth, MAX_SMOOTH_ITERATIONS)?;
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
        at_most("smooth.iterations", s.iterations, MAX_SMOOTH_ITERATIONS)?;
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

impl Lssvm {
    /// Range checks.
    pub fn validate(&self) -> Result<(), Invalid> {
        between("lssvm.rings", self.rings, 1, 20)?;
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
        between("lssvm.iterations", self.iterations, 1, 100)?;
        if !(self.merge_distance.is_finite() && (0.0..1.0).contains(&self.merge_distance)) {
            return Err(Invalid::new(
                "lssvm.merge_distance",
                format!("must be in [0, 1) (got {})", self.merge_distance),
            ));
        }
        area_ratio("lssvm.max_area_ratio", self.max_area_ratio)
    }
}

pub(super) fn continuity_message(got: u64) -> String {
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

/// A front's runaway limit: 0 (no limit) or at least 1 times the loop's vector area.
fn area_ratio(key: &'static str, x: f64) -> Result<(), Invalid> {
    finite(key, x)?;
    if x == 0.0 || x >= 1.0 {
        Ok(())
    } else {
        Err(Invalid::new(
            key,
            format!("must be 0 (no limit) or at least 1 (got {x})"),
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

/// `lo <= x <= hi` for a count.
fn between<T>(key: &'static str, x: T, lo: T, hi: T) -> Result<(), Invalid>
where
    T: PartialOrd + std::fmt::Display,
{
    if lo <= x && x <= hi {
        Ok(())
    } else {
        Err(Invalid::new(
            key,
            format!("must be between {lo} and {hi} (got {x})"),
        ))
    }
}

/// `x <= hi` for a count.
fn at_most<T>(key: &'static str, x: T, hi: T) -> Result<(), Invalid>
where
    T: PartialOrd + std::fmt::Display,
{
    if x <= hi {
        Ok(())
    } else {
        Err(Invalid::new(key, format!("must be at most {hi} (got {x})")))
    }
}

/// `x >= lo` for a count.
fn at_least<T>(key: &'static str, x: T, lo: T) -> Result<(), Invalid>
where
    T: PartialOrd + std::fmt::Display,
{
    if x >= lo {
        Ok(())
    } else {
        Err(Invalid::new(
            key,
            format!("must be at least {lo} (got {x})"),
        ))
    }
}
