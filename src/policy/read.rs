//! Stage 1 of reading a policy: the TOML text parsed into a spanned tree and every key
//! read into its field by type. An unknown section, key or name is an error with a
//! "did you mean" when a valid one is close; the line of every key is remembered for
//! the errors of stage 2.

use super::validate::continuity_message;
use super::{Method, PolicyError, PolicyName, Settings};
use std::collections::BTreeMap;
use std::ops::Range;
use std::path::Path;
use toml::de::{DeString, DeTable, DeValue};
use toml::Spanned;

/// Keys outside any section.
pub const TOP_LEVEL_KEYS: &[&str] = &["seed"];

/// The keys of [`SECTIONS`] that may be left out, each with a value it takes (the
/// shipped `config/policy.toml` sets every other key, and shows these in a comment).
pub const OPTIONAL_KEYS: &[(&str, &str, &str)] = &[("blend", "weight_flat", "0.3")];

/// Every section and its keys, in the order of `config/policy.toml`. This is the one
/// list behind unknown-key errors and their suggestions; a unit test checks that the
/// default file sets every key listed here but the [`OPTIONAL_KEYS`].
pub const SECTIONS: &[(&str, &[&str])] = &[
    (
        "dispatch",
        &["small_max", "middle_max", "small", "middle", "large"],
    ),
    (
        "select",
        &[
            "mode",
            "rings",
            "vertices_per_ring",
            "methods",
            "flat_share",
            "flat_angle_deg",
            "flat_method",
        ],
    ),
    (
        "blend",
        &[
            "weight_middle",
            "weight_large",
            "weight_flat",
            "surface",
            "with",
            "keep",
            "energy",
        ],
    ),
    (
        "border",
        &[
            "max_vertices",
            "max_bbox_share",
            "min_area_share",
            "only_longest",
        ],
    ),
    ("clean", &["remove_teeth", "split_long_edges"]),
    ("rim", &["trim", "max_rings", "max_faces"]),
    ("crack", &["stitch", "tolerance"]),
    ("islands", &["mode", "remove_below_faces"]),
    ("debris", &["remove_below_faces"]),
    (
        "refine",
        &[
            "density",
            "weight",
            "restricted_search_above",
            "search",
            "collapse",
        ],
    ),
    (
        "fair",
        &["continuity", "weights", "tangential_relax", "passes"],
    ),
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
            "max_area_ratio",
        ],
    ),
];

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

/// Stage 1: the spanned TOML tree read into [`Settings`] (types checked, ranges not),
/// remembering the line of every key for stage 2.
/// Stage 1: `text` read into settings, with the 1-based line of every dotted key it
/// sets; `path` names the file in errors.
pub(super) fn read(
    text: &str,
    path: &Path,
) -> Result<(Settings, BTreeMap<String, usize>), PolicyError> {
    let root = DeTable::parse(text).map_err(|e| syntax_error(text, path, &e))?;
    let mut reader = Reader {
        text,
        file: path,
        lines: BTreeMap::new(),
    };
    let settings = reader.read(root.get_ref())?;
    Ok((settings, reader.lines))
}

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

    fn read(&mut self, root: &DeTable) -> Result<Settings, PolicyError> {
        let mut p = Settings::default();
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
        p: &mut Settings,
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
            ("border", "min_area_share") => p.border.min_area_share = self.float(key, v)?,
            ("border", "only_longest") => p.border.only_longest = self.boolean(key, v)?,
            ("clean", "remove_teeth") => p.clean.remove_teeth = self.boolean(key, v)?,
            ("clean", "split_long_edges") => p.clean.split_long_edges = self.float(key, v)?,
            ("select", "mode") => p.select.mode = self.named(key, v)?,
            ("select", "rings") => p.select.rings = self.usize(key, v)?,
            ("select", "vertices_per_ring") => p.select.vertices_per_ring = self.usize(key, v)?,
            ("select", "methods") => p.select.methods = self.methods(key, v)?,
            ("select", "flat_share") => p.select.flat_share = self.float(key, v)?,
            ("select", "flat_angle_deg") => p.select.flat_angle_deg = self.float(key, v)?,
            ("select", "flat_method") => {
                p.select.flat_method = self.name_of::<Method>(key, v, "method")?
            }
            ("blend", "weight_middle") => p.blend.weight_middle = self.float(key, v)?,
            ("blend", "weight_large") => p.blend.weight_large = self.float(key, v)?,
            ("blend", "weight_flat") => p.blend.weight_flat = Some(self.float(key, v)?),
            ("blend", "surface") => p.blend.surface = self.named(key, v)?,
            ("blend", "with") => p.blend.with = self.name_of::<Method>(key, v, "method")?,
            ("blend", "keep") => p.blend.keep = self.named(key, v)?,
            ("blend", "energy") => p.blend.energy = self.named(key, v)?,
            ("rim", "trim") => p.rim.trim = self.boolean(key, v)?,
            ("rim", "max_rings") => p.rim.max_rings = self.usize(key, v)?,
            ("rim", "max_faces") => p.rim.max_faces = self.usize(key, v)?,
            ("crack", "stitch") => p.crack.stitch = self.boolean(key, v)?,
            ("crack", "tolerance") => p.crack.tolerance = self.float(key, v)?,
            ("islands", "mode") => p.islands.mode = self.named(key, v)?,
            ("islands", "remove_below_faces") => {
                p.islands.remove_below_faces = self.usize(key, v)?
            }
            ("debris", "remove_below_faces") => p.debris.remove_below_faces = self.usize(key, v)?,
            ("refine", "density") => p.refine.density = self.float(key, v)?,
            ("refine", "weight") => p.refine.weight = self.named(key, v)?,
            ("refine", "restricted_search_above") => {
                p.refine.restricted_search_above = self.usize(key, v)?
            }
            ("refine", "search") => p.refine.search = self.named(key, v)?,
            ("refine", "collapse") => p.refine.collapse = self.float(key, v)?,
            ("fair", "continuity") => {
                let n = self.uint(key, v)?;
                p.fair.continuity = u8::try_from(n)
                    .map_err(|_| self.error(v.span(), key, continuity_message(n)))?;
            }
            ("fair", "weights") => p.fair.weights = self.named(key, v)?,
            ("fair", "tangential_relax") => p.fair.tangential_relax = self.usize(key, v)?,
            ("fair", "passes") => p.fair.passes = self.usize(key, v)?,
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
            ("lssvm", "max_area_ratio") => p.lssvm.max_area_ratio = self.float(key, v)?,
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
    use crate::policy::DEFAULT_POLICY_TOML;

    #[test]
    fn every_listed_key_is_read() {
        // A key listed in SECTIONS but missing from `Reader::set` would be reported unknown.
        for (section, keys) in SECTIONS {
            for key in *keys {
                let optional = OPTIONAL_KEYS
                    .iter()
                    .find(|(s, k, _)| s == section && k == key)
                    .map(|(_, _, v)| format!("[{section}]\n{key} = {v}\n"));
                let text = optional.as_deref().unwrap_or(DEFAULT_POLICY_TOML);
                let root = DeTable::parse(text).unwrap();
                let v = &root.get_ref()[*section].get_ref()[*key];
                let r = Reader {
                    text,
                    file: Path::new("x"),
                    lines: BTreeMap::new(),
                };
                let mut p = Settings::default();
                assert!(
                    r.set(&mut p, section, key, key, v).unwrap(),
                    "{section}.{key}"
                );
            }
        }
    }
}
