use super::*;
use proptest::prelude::*;
use toml::de::{DeTable, DeValue};

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
    let serde: Settings = toml::from_str(DEFAULT_POLICY_TOML).unwrap();
    assert_eq!(serde, *Policy::default());
    assert!(Settings::default().validate().is_ok());
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
        let optional = |key: &str| {
            OPTIONAL_KEYS
                .iter()
                .any(|(s, k, _)| s == section && *k == key)
        };
        let required = keys.iter().filter(|k| !optional(k)).count();
        assert_eq!(t.len(), required, "[{section}] has keys not in SECTIONS");
        for key in keys.iter().filter(|k| !optional(k)) {
            assert!(
                t.get(*key).is_some(),
                "config/policy.toml lacks {section}.{key}"
            );
            n += 1;
        }
    }
    assert_eq!(root.len(), TOP_LEVEL_KEYS.len() + SECTIONS.len());
    assert_eq!(
        n + OPTIONAL_KEYS.len(),
        SECTIONS.iter().map(|(_, k)| k.len()).sum::<usize>()
    );
}

#[test]
fn empty_and_partial_files_use_defaults() {
    assert_eq!(parse("").unwrap(), Policy::default());
    assert_eq!(parse("# nothing\n\n").unwrap(), Policy::default());
    assert_eq!(parse("[dispatch]\n").unwrap(), Policy::default());
    let p = parse("seed = 7\n[front]\nangle_small = 80\n").unwrap();
    let want = Settings {
        seed: 7,
        front: Front {
            angle_small: 80.0,
            ..Front::default()
        },
        ..Settings::default()
    };
    assert_eq!(*p, want);
}

#[test]
fn blend_keep_reads_both_values_and_names_them_when_wrong() {
    assert_eq!(Policy::default().blend.keep, BlendKeep::With);
    let p = parse("[blend]\nweight_large = 0.5\nkeep = \"accepted\"\n").unwrap();
    assert_eq!(p.blend.keep, BlendKeep::Accepted);
    assert_eq!(p.blend.weight_large, 0.5);
    let e = err("[blend]\nkeep = \"both\"\n").to_string();
    assert!(
        e.contains("policy.toml:2")
            && e.contains("blend.keep")
            && e.contains("\"with\", \"accepted\""),
        "{e}"
    );
}

#[test]
fn blend_surface_and_flat_weight_read_and_are_named_when_wrong() {
    let d = Policy::default();
    assert_eq!(
        (d.blend.surface, d.blend.weight_flat),
        (BlendSurface::With, None)
    );
    let p =
        parse("[blend]\nweight_large = 0.9\nweight_flat = 0.3\nsurface = \"faired\"\n").unwrap();
    assert_eq!(p.blend.surface, BlendSurface::Faired);
    assert_eq!(p.blend.weight_flat, Some(0.3));
    let e = err("[blend]\nsurface = \"both\"\n").to_string();
    assert!(
        e.contains("blend.surface") && e.contains("\"with\", \"faired\""),
        "{e}"
    );
    let e = err("[blend]\nweight_flat = 1.5\n").to_string();
    assert!(
        e.contains("blend.weight_flat") && e.contains("between 0 and 1"),
        "{e}"
    );
}

#[test]
fn refine_collapse_is_a_share_below_one() {
    assert_eq!(Policy::default().refine.collapse, 0.75);
    assert_eq!(
        parse("[refine]\ncollapse = 0\n").unwrap().refine.collapse,
        0.0
    );
    let e = err("[refine]\ncollapse = 1.5\n").to_string();
    assert!(
        e.contains("policy.toml:2") && e.contains("refine.collapse"),
        "{e}"
    );
}

#[test]
fn dotted_keys_and_inline_tables_are_read() {
    let p = parse("dispatch.small_max = 8\nsmooth = { enabled = true, iterations = 4 }\n").unwrap();
    assert_eq!(p.dispatch.small_max, 8);
    assert!(p.smooth.enabled);
    assert_eq!(p.smooth.iterations, 4);
    let p = parse("[dispatch]\nsmall = [\n  \"fan\",\n]\nlarge = [\"min_area_fair\"]\n").unwrap();
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
    let e = err(
        "[dispatch]\nsmall_max = 5\nmiddle = [\n  \"min_area_fair\",\n  \"advancing-front\",\n]\n",
    );
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
    let e = err("[fair]\nweights = \"uniform\"\n[smooth]\nweights = \"uniform\"\nlambda = 1.5\n");
    assert_eq!(e.line, Some(5));
}

/// `(text, key, message)`: each range rule, one at a time.
const RANGE_CASES: &[(&str, &str, &str)] = &[
    (
        "[dispatch]\nsmall_max = 2",
        "dispatch.small_max",
        "must be at least 3 (got 2)",
    ),
    (
        "[dispatch]\nmiddle_max = 5",
        "dispatch.middle_max",
        "must be at least dispatch.small_max = 6 (got 5)",
    ),
    (
        "[dispatch]\nsmall_max = 60",
        "dispatch.small_max",
        "must be at most dispatch.middle_max = 50 (got 60)",
    ),
    (
        "[dispatch]\nsmall = []",
        "dispatch.small",
        "needs at least one method",
    ),
    (
        "[dispatch]\nlarge = [\"fan\", \"advancing_front\", \"fan\"]",
        "dispatch.large",
        "lists method `fan` more than once",
    ),
    (
        "[border]\nmax_vertices = 2",
        "border.max_vertices",
        "must be 0 (no limit) or at least 3 (got 2)",
    ),
    (
        "[border]\nmax_bbox_share = 11",
        "border.max_bbox_share",
        "must be between 0 and 10 (got 11)",
    ),
    (
        "[border]\nmax_bbox_share = -0.1",
        "border.max_bbox_share",
        "must be between 0 and 10 (got -0.1)",
    ),
    (
        "[border]\nmax_bbox_share = nan",
        "border.max_bbox_share",
        "must be a finite number (got NaN)",
    ),
    (
        "[clean]\nsplit_long_edges = 0.5",
        "clean.split_long_edges",
        "must be 0 (off) or at least 1 (got 0.5)",
    ),
    (
        "[clean]\nsplit_long_edges = inf",
        "clean.split_long_edges",
        "must be a finite number (got inf)",
    ),
    (
        "[refine]\ndensity = 0.5",
        "refine.density",
        "must be 0 (off) or between 1 and 4 (got 0.5)",
    ),
    (
        "[refine]\ndensity = 4.5",
        "refine.density",
        "must be 0 (off) or between 1 and 4 (got 4.5)",
    ),
    (
        "[refine]\nrestricted_search_above = 2",
        "refine.restricted_search_above",
        "must be between 3 and 2000 (got 2)",
    ),
    (
        "[refine]\nrestricted_search_above = 5000",
        "refine.restricted_search_above",
        "must be between 3 and 2000 (got 5000)",
    ),
    (
        "[fair]\ncontinuity = 4",
        "fair.continuity",
        "must be 0, 1, 2 or 3 (got 4)",
    ),
    (
        "[fair]\npasses = 21",
        "fair.passes",
        "must be at most 20 (got 21)",
    ),
    (
        "[select]\nflat_share = 0",
        "select.flat_share",
        "must be in (0, 1] (got 0)",
    ),
    (
        "[select]\nflat_share = 1.5",
        "select.flat_share",
        "must be in (0, 1] (got 1.5)",
    ),
    (
        "[select]\nflat_angle_deg = 90",
        "select.flat_angle_deg",
        "must be in (0, 90) degrees (got 90)",
    ),
    (
        "[select]\nflat_method = \"close\"",
        "select.flat_method",
        "`close` cannot go first on a flat rim: it adds no vertex, so it can only be a fallback",
    ),
    (
        "[front]\nangle_small = -5",
        "front.angle_small",
        "must be between 0 and 180 (got -5)",
    ),
    (
        "[front]\nangle_large = 70",
        "front.angle_large",
        "must be greater than front.angle_small = 75 (got 70)",
    ),
    (
        "[front]\nangle_small = 140",
        "front.angle_small",
        "must be less than front.angle_large = 135 (got 140)",
    ),
    (
        "[front]\nangle_small = 100\nangle_large = 100",
        "front.angle_large",
        "must be greater than front.angle_small = 100 (got 100)",
    ),
    (
        "[front]\nalpha = 1.5",
        "front.alpha",
        "must be between 0 and 1 (got 1.5)",
    ),
    (
        "[front]\nomega1 = -1",
        "front.omega1",
        "must be between 0 and 1 (got -1)",
    ),
    (
        "[front]\nmerge_distance = 2",
        "front.merge_distance",
        "must be between 0 and 1 (got 2)",
    ),
    (
        "[front]\nmax_steps_per_vertex = 0",
        "front.max_steps_per_vertex",
        "must be at least 1 (got 0)",
    ),
    (
        "[lssvm]\nmax_area_ratio = 0.5",
        "lssvm.max_area_ratio",
        "must be 0 (no limit) or at least 1 (got 0.5)",
    ),
    (
        "[checks]\nmin_angle_deg = 30",
        "checks.min_angle_deg",
        "must be less than 30 (got 30)",
    ),
    (
        "[checks]\nmin_angle_deg = -1",
        "checks.min_angle_deg",
        "must be at least 0 and less than 30 (got -1)",
    ),
    (
        "[limits]\nhole_time_ms = 86400001",
        "limits.hole_time_ms",
        "must be 0 (no limit) or between 1 and 86400000 (one day) (got 86400001)",
    ),
    (
        "[smooth]\niterations = 10001",
        "smooth.iterations",
        "must be at most 10000 (got 10001)",
    ),
    (
        "[smooth]\nlambda = 0",
        "smooth.lambda",
        "must be greater than 0 (got 0)",
    ),
    (
        "[smooth]\nlambda = 1",
        "smooth.lambda",
        "must be less than 1 (got 1)",
    ),
    (
        "[smooth]\nmu = -1",
        "smooth.mu",
        "must be greater than -1 (got -1)",
    ),
    (
        "[smooth]\nmu = -0.2",
        "smooth.mu",
        "must be less than -smooth.lambda = -0.33 so that the second step un-shrinks (got -0.2)",
    ),
    (
        "[smooth]\nlambda = 0.5",
        "smooth.lambda",
        "must be less than -smooth.mu = 0.34 so that the second step un-shrinks (got 0.5)",
    ),
    (
        "[smooth]\nscope = \"rings\"\nrings = 0",
        "smooth.rings",
        "must be at least 1 when smooth.scope = \"rings\" (got 0)",
    ),
    (
        "[smooth]\nrings = 0\nscope = \"rings\"",
        "smooth.rings",
        "must be at least 1 when smooth.scope = \"rings\" (got 0)",
    ),
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
    let mut p = Settings::default();
    p.front.angle_small = 150.0;
    let inv = p.validate().unwrap_err();
    assert_eq!(inv.key, "front.angle_large");
    assert_eq!(inv.other.as_ref().map(|o| o.0), Some("front.angle_small"));
}

#[test]
fn validate_catches_programmatic_values() {
    let mut p = Settings::default();
    p.fair.continuity = 9;
    assert_eq!(p.validate().unwrap_err().key, "fair.continuity");
    let mut p = Settings::default();
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
        search in arb_name::<Search>(), collapse in prop_oneof![Just(0.0f64), 0.01f64..0.99],
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
        hpde in arb_hpde(), keep in arb_name::<BlendKeep>(),
        surface in arb_name::<BlendSurface>(),
        weight_flat in proptest::option::of(0.0f64..=1.0),
    ) -> Settings {
        Settings {
            seed,
            dispatch: Dispatch { small_max, middle_max: small_max + extra, small, middle, large },
            border: Border { max_vertices, max_bbox_share, min_area_share: 0.25, only_longest },
            clean: Clean { remove_teeth, split_long_edges },
            refine: Refine { density, weight, restricted_search_above, search, collapse },
            fair: Fair { continuity, weights: fair_weights, tangential_relax: 100, passes: 2 },
            front: Front {
                angle_small: angles.0, angle_large: angles.1, alpha, omega1, merge_distance,
                max_steps_per_vertex, fair: front_fair,
            },
            wavefront: Wavefront::default(),
            hpde,
            checks: Checks { self_intersection, min_angle_deg },
            limits: Limits { hole_time_ms, ..Limits::default() },
            blend: Blend { keep, surface, weight_flat, ..Blend::default() },
            smooth: Smooth {
                enabled, iterations, lambda: lm.0, mu: lm.1, weights: smooth_weights, scope, rings, boundary,
            },
            ..Settings::default()
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
        prop_assert_eq!(&*parse(&text).unwrap(), &p);
        let serde: Settings = toml::from_str(&text).unwrap();
        prop_assert_eq!(&serde, &p);
    }

    /// Arbitrary text (mostly near-TOML) never panics.
    #[test]
    fn arbitrary_text_never_panics(text in "(\\[[a-z_.]{0,12}\\]\n|[a-z_.\"]{1,14} = [-0-9.a-z\"\\[\\]{},]{0,14}\n|#.*\n){0,8}") {
        let _ = parse(&text);
    }
}

#[test]
fn blend_energy_reads_and_needs_the_faired_surface() {
    assert_eq!(Policy::default().blend.energy, BlendEnergy::Fair);
    let p = parse("[blend]\nweight_large = 0.9\nsurface = \"faired\"\nenergy = \"validate\"\n")
        .unwrap();
    assert_eq!(p.blend.energy, BlendEnergy::Validate);
    let e = err("[blend]\nenergy = \"validate\"\n").to_string();
    assert!(e.contains("blend.energy") && e.contains("faired"), "{e}");
    let e = err("[blend]\nsurface = \"faired\"\nenergy = \"validate\"\n[fair]\ncontinuity = 0\n")
        .to_string();
    assert!(
        e.contains("blend.energy") && e.contains("fair.continuity"),
        "{e}"
    );
    let e = err("[blend]\nenergy = \"best\"\n").to_string();
    assert!(
        e.contains("blend.energy") && e.contains("\"fair\", \"validate\""),
        "{e}"
    );
}
