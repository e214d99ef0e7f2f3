//! The library's layers point one way (ARCHITECTURE.md): this test reads every file of
//! the library under `src/`, finds every `crate::` and `super::` path in its code (use
//! trees expanded; comments and string literals passed over), places the module it
//! names in [`LAYERS`] and fails on any import of a later layer, or of another unit of
//! the same layer (so no method imports another). A module of the library that has no
//! place in the list fails too. With every import pointing to an earlier layer, the
//! units' import graph has no cycle.
//!
//! Test code (`tests.rs` files, `#[cfg(test)]` modules and uses) follows the same rule,
//! except that it may use the unit tests' fixtures, `testutil`. The binary's modules
//! (those `src/main.rs` declares) sit above every layer and are not read.

use std::collections::BTreeSet;
use std::fs;
use std::path::{Path, PathBuf};

/// The layers, first to last; each imports only from those before it. A module belongs
/// to the longest entry its path starts with; `lib.rs` is the facade over them all.
const LAYERS: &[&[&str]] = &[
    // plain data and a hasher, importing nothing of the crate
    &["fasthash", "policy"],
    &["io"],
    &["mesh"],
    // the repair log's types (file, build report, holes and attempts)
    &["report"],
    &["geometry"],
    // optional Taubin smoothing of the mesh before the fill
    &["smooth"],
    &["patch"],
    // the unit tests' fixtures (any test code may use them)
    &["testutil"],
    &["check"],
    &["fill::kit"],
    // the methods: none imports another
    &[
        "fill::fan",
        "fill::min_area_fair",
        "fill::advancing_front",
        "fill::wavefront",
        "fill::hpde",
        "fill::lssvm_poisson",
        "fill::close",
    ],
    &["fill::dispatch", "fill"],
    &["pipeline"],
    // pictures of repairs
    &["picture"],
];

/// Where a module stands: (layer, unit); `None` for a module with no place.
fn place(path: &[String]) -> Option<(usize, String)> {
    let mut best: Option<(usize, &str, usize)> = None;
    for (layer, units) in LAYERS.iter().enumerate() {
        for unit in units.iter() {
            let segs: Vec<&str> = unit.split("::").collect();
            if segs.len() <= path.len()
                && segs.iter().zip(path).all(|(a, b)| *a == b)
                && best.is_none_or(|b| segs.len() > b.2)
            {
                best = Some((layer, unit, segs.len()));
            }
        }
    }
    best.map(|(l, u, _)| (l, u.to_string()))
}

#[derive(Debug, Clone, PartialEq)]
enum Tok {
    Ident(String),
    PathSep,
    Punct(char),
}

/// The code's tokens with their line numbers: identifiers, `::` and punctuation;
/// comments, string, char and number literals left out.
fn tokens(src: &str) -> Vec<(Tok, usize)> {
    let c: Vec<char> = src.chars().collect();
    let mut out = Vec::new();
    let (mut i, mut line) = (0, 1);
    let ident_start = |ch: char| ch.is_alphabetic() || ch == '_';
    let ident_char = |ch: char| ch.is_alphanumeric() || ch == '_';
    // skips a (raw) string literal whose opening quote is at `i`, with `hashes` #s
    let skip_str = |i: &mut usize, line: &mut usize, raw: bool, hashes: usize| {
        *i += 1;
        while *i < c.len() {
            match c[*i] {
                '\\' if !raw => {
                    *i += 1;
                    if c.get(*i) == Some(&'\n') {
                        *line += 1;
                    }
                }
                '"' if (0..hashes).all(|k| c.get(*i + 1 + k) == Some(&'#')) => {
                    *i += 1 + hashes;
                    return;
                }
                '\n' => *line += 1,
                _ => {}
            }
            *i += 1;
        }
    };
    while i < c.len() {
        let ch = c[i];
        if ch == '\n' {
            line += 1;
            i += 1;
        } else if ch.is_whitespace() {
            i += 1;
        } else if ch == '/' && c.get(i + 1) == Some(&'/') {
            while i < c.len() && c[i] != '\n' {
                i += 1;
            }
        } else if ch == '/' && c.get(i + 1) == Some(&'*') {
            let mut depth = 0;
            while i < c.len() {
                if c[i] == '/' && c.get(i + 1) == Some(&'*') {
                    depth += 1;
                    i += 2;
                } else if c[i] == '*' && c.get(i + 1) == Some(&'/') {
                    depth -= 1;
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    if c[i] == '\n' {
                        line += 1;
                    }
                    i += 1;
                }
            }
        } else if ch == '"' {
            skip_str(&mut i, &mut line, false, 0);
        } else if (ch == 'r' || (ch == 'b' && c.get(i + 1) == Some(&'r')))
            && matches!(
                c.get(i + if ch == 'b' { 2 } else { 1 }),
                Some('"') | Some('#')
            )
        {
            // r"…", r#"…"#, br"…" (or the raw identifier r#name)
            let mut j = i + if ch == 'b' { 2 } else { 1 };
            let mut hashes = 0;
            while c.get(j) == Some(&'#') {
                hashes += 1;
                j += 1;
            }
            if c.get(j) == Some(&'"') {
                i = j;
                skip_str(&mut i, &mut line, true, hashes);
            } else {
                // raw identifier
                i = j;
            }
        } else if ch == 'b' && c.get(i + 1) == Some(&'"') {
            i += 1;
            skip_str(&mut i, &mut line, false, 0);
        } else if ch == '\'' || (ch == 'b' && c.get(i + 1) == Some(&'\'')) {
            let j = if ch == 'b' { i + 1 } else { i };
            if c.get(j + 1) == Some(&'\\') {
                // escaped char literal
                let mut k = j + 2;
                while k < c.len() && c[k] != '\'' {
                    k += 1;
                }
                i = k + 1;
            } else if c.get(j + 2) == Some(&'\'') {
                i = j + 3;
            } else {
                // a lifetime or label
                i = j + 1;
            }
        } else if ch.is_ascii_digit() {
            while i < c.len() && (ident_char(c[i]) || c[i] == '.') {
                i += 1;
            }
        } else if ident_start(ch) {
            let s = i;
            while i < c.len() && ident_char(c[i]) {
                i += 1;
            }
            out.push((Tok::Ident(c[s..i].iter().collect()), line));
        } else if ch == ':' && c.get(i + 1) == Some(&':') {
            out.push((Tok::PathSep, line));
            i += 2;
        } else {
            out.push((Tok::Punct(ch), line));
            i += 1;
        }
    }
    out
}

fn is_ident(t: Option<&(Tok, usize)>, s: &str) -> bool {
    matches!(t, Some((Tok::Ident(x), _)) if x == s)
}

fn is_punct(t: Option<&(Tok, usize)>, ch: char) -> bool {
    matches!(t, Some((Tok::Punct(x), _)) if *x == ch)
}

/// The paths of a use tree (or of a plain path) starting at `toks[i]`, each appended to
/// `prefix`; returns the index after it.
fn tree(
    toks: &[(Tok, usize)],
    mut i: usize,
    mut prefix: Vec<String>,
    out: &mut Vec<Vec<String>>,
) -> usize {
    loop {
        match toks.get(i).map(|t| &t.0) {
            Some(Tok::Ident(s)) => {
                if s != "self" {
                    prefix.push(s.clone());
                }
                i += 1;
                if matches!(toks.get(i), Some((Tok::PathSep, _))) {
                    i += 1;
                    continue;
                }
                out.push(prefix);
                return i;
            }
            Some(Tok::Punct('{')) => {
                i += 1;
                let mut depth = 0;
                loop {
                    match toks.get(i).map(|t| &t.0) {
                        None => return i,
                        Some(Tok::Punct('}')) if depth == 0 => return i + 1,
                        Some(Tok::Punct(',')) if depth == 0 => i += 1,
                        Some(Tok::Ident(_)) | Some(Tok::Punct('{')) | Some(Tok::Punct('*'))
                            if depth == 0
                                && (i == 0
                                    || matches!(
                                        toks[i - 1].0,
                                        Tok::Punct('{') | Tok::Punct(',')
                                    )) =>
                        {
                            i = tree(toks, i, prefix.clone(), out);
                        }
                        Some(Tok::Punct('{')) => {
                            depth += 1;
                            i += 1;
                        }
                        Some(Tok::Punct('}')) => {
                            depth -= 1;
                            i += 1;
                        }
                        // `as name` and the like
                        _ => i += 1,
                    }
                }
            }
            _ => {
                out.push(prefix);
                return i;
            }
        }
    }
}

struct Import {
    line: usize,
    path: Vec<String>,
    test: bool,
}

/// Every `crate::`/`super::` path of a file whose module is `module`, made absolute,
/// with whether it stands in test code. `test_file`: the whole file is test code.
fn imports(src: &str, module: &[String], test_file: bool) -> Vec<Import> {
    let toks = tokens(src);
    let mut out = Vec::new();
    // inline modules: (name, brace depth inside it, test)
    let mut stack: Vec<(String, usize, bool)> = Vec::new();
    let mut depth = 0usize;
    // a `#[cfg(test)]` use reaches to its `;`
    let mut test_use_until: Option<usize> = None;
    let mut i = 0;
    while i < toks.len() {
        let cfg_test = is_punct(toks.get(i), '#')
            && is_punct(toks.get(i + 1), '[')
            && is_ident(toks.get(i + 2), "cfg")
            && is_punct(toks.get(i + 3), '(')
            && is_ident(toks.get(i + 4), "test")
            && is_punct(toks.get(i + 5), ')')
            && is_punct(toks.get(i + 6), ']');
        if cfg_test {
            // the item it applies to, past `pub`, `pub(crate)` and other attributes
            let mut j = i + 7;
            loop {
                if is_punct(toks.get(j), '#') && is_punct(toks.get(j + 1), '[') {
                    while j < toks.len() && !is_punct(toks.get(j), ']') {
                        j += 1;
                    }
                    j += 1;
                } else if is_ident(toks.get(j), "pub") {
                    j += 1;
                    if is_punct(toks.get(j), '(') {
                        while j < toks.len() && !is_punct(toks.get(j), ')') {
                            j += 1;
                        }
                        j += 1;
                    }
                } else {
                    break;
                }
            }
            if is_ident(toks.get(j), "mod") && is_punct(toks.get(j + 2), '{') {
                if let Some((Tok::Ident(name), _)) = toks.get(j + 1) {
                    depth += 1;
                    stack.push((name.clone(), depth, true));
                    i = j + 3;
                    continue;
                }
            }
            if is_ident(toks.get(j), "use") {
                let mut k = j;
                while k < toks.len() && !is_punct(toks.get(k), ';') {
                    k += 1;
                }
                test_use_until = Some(k);
            }
            i += 7;
            continue;
        }
        match &toks[i].0 {
            Tok::Ident(m) if m == "mod" && is_punct(toks.get(i + 2), '{') => {
                if let Some((Tok::Ident(name), _)) = toks.get(i + 1) {
                    depth += 1;
                    let test = stack.last().is_some_and(|s| s.2);
                    stack.push((name.clone(), depth, test));
                    i += 3;
                    continue;
                }
            }
            Tok::Punct('{') => depth += 1,
            Tok::Punct('}') => {
                if stack.last().is_some_and(|s| s.1 == depth) {
                    stack.pop();
                }
                depth = depth.saturating_sub(1);
            }
            Tok::Ident(root)
                if (root == "crate" || root == "super")
                    && matches!(toks.get(i + 1), Some((Tok::PathSep, _)))
                    && !is_ident(i.checked_sub(1).and_then(|k| toks.get(k)), "in")
                    && !matches!(i.checked_sub(1).map(|k| &toks[k].0), Some(Tok::PathSep)) =>
            {
                let line = toks[i].1;
                let mut here: Vec<String> = module.to_vec();
                here.extend(stack.iter().map(|s| s.0.clone()));
                let mut base: Vec<String> = Vec::new();
                let mut j = i;
                if root == "crate" {
                    j += 2;
                } else {
                    base = here.clone();
                    while is_ident(toks.get(j), "super")
                        && matches!(toks.get(j + 1), Some((Tok::PathSep, _)))
                    {
                        base.pop();
                        j += 2;
                    }
                }
                let mut paths = Vec::new();
                let end = tree(&toks, j, base, &mut paths);
                let test =
                    test_file || stack.iter().any(|s| s.2) || test_use_until.is_some_and(|k| i < k);
                out.extend(paths.into_iter().map(|path| Import { line, path, test }));
                i = end.max(i + 1);
                continue;
            }
            _ => {}
        }
        i += 1;
    }
    out
}

/// The module path of a file below `src/`: `a/mod.rs` and `a.rs` are `a`.
fn module_of(rel: &Path) -> Vec<String> {
    let mut segs: Vec<String> = rel
        .iter()
        .map(|s| s.to_string_lossy().trim_end_matches(".rs").to_string())
        .collect();
    if matches!(segs.last().map(String::as_str), Some("mod") | Some("lib")) {
        segs.pop();
    }
    segs
}

fn rs_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            rs_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// The modules `src/main.rs` declares (`mod name;`): the binary's, not the library's.
fn binary_modules(src: &Path) -> BTreeSet<String> {
    let toks = tokens(&fs::read_to_string(src.join("main.rs")).unwrap());
    (0..toks.len())
        .filter(|&i| is_ident(toks.get(i), "mod") && is_punct(toks.get(i + 2), ';'))
        .filter_map(|i| match &toks[i + 1].0 {
            Tok::Ident(n) => Some(n.clone()),
            _ => None,
        })
        .collect()
}

/// Test files: `tests.rs` files and the modules below them.
fn is_test_file(module: &[String]) -> bool {
    module.iter().any(|s| s == "tests") || module.first().is_some_and(|s| s == "testutil")
}

fn library_files() -> Vec<(PathBuf, Vec<String>)> {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let bin = binary_modules(&src);
    let mut files = Vec::new();
    rs_files(&src, &mut files);
    files.sort();
    files
        .into_iter()
        .filter_map(|p| {
            let rel = p.strip_prefix(&src).unwrap().to_path_buf();
            let module = module_of(&rel);
            let binary =
                rel == Path::new("main.rs") || module.first().is_some_and(|m| bin.contains(m));
            (!binary).then_some((rel, module))
        })
        .collect()
}

/// Every import that breaks the layering, as `file:line: what`.
fn violations() -> Vec<String> {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let files = library_files();
    let top: BTreeSet<String> = files
        .iter()
        .filter_map(|(_, m)| m.first().cloned())
        .collect();
    let mut bad = Vec::new();
    for (rel, module) in &files {
        let from = if module.is_empty() {
            None // lib.rs: the facade imports anything
        } else {
            match place(module) {
                Some(p) => Some(p),
                None => {
                    bad.push(format!(
                        "src/{}: module {} has no place in the layers (tests/layers.rs, LAYERS)",
                        rel.display(),
                        module.join("::")
                    ));
                    continue;
                }
            }
        };
        let Some((from_layer, from_unit)) = from else {
            continue;
        };
        let text = fs::read_to_string(src.join(rel)).unwrap();
        for im in imports(&text, module, is_test_file(module)) {
            let to = match place(&im.path) {
                Some(p) => p,
                // an item of lib.rs (the facade), or a module with no place
                None if im.path.first().is_none_or(|s| !top.contains(s)) => {
                    (LAYERS.len(), String::new())
                }
                None => {
                    bad.push(format!(
                        "src/{}:{}: crate::{} has no place in the layers",
                        rel.display(),
                        im.line,
                        im.path.join("::")
                    ));
                    continue;
                }
            };
            let ok = to.1 == from_unit || to.0 < from_layer || (im.test && to.1 == "testutil");
            if !ok {
                let what = if to.0 == from_layer {
                    "another unit of the same layer"
                } else if to.1.is_empty() {
                    "the facade (lib.rs)"
                } else {
                    "a later layer"
                };
                bad.push(format!(
                    "src/{}:{}: {} ({}) imports crate::{}, {} ({}){}",
                    rel.display(),
                    im.line,
                    module.join("::"),
                    from_unit,
                    im.path.join("::"),
                    what,
                    if to.1.is_empty() { "lib" } else { &to.1 },
                    if im.test { " [test code]" } else { "" }
                ));
            }
        }
    }
    bad
}

#[test]
fn imports_point_to_earlier_layers_only() {
    let bad = violations();
    assert!(
        bad.is_empty(),
        "{} imports break the layers:\n{}",
        bad.len(),
        bad.join("\n")
    );
}

/// The reader finds what it must: a use tree, `super` paths, inline test modules, and
/// nothing in comments or strings.
#[test]
fn the_reader_finds_paths_in_code_only() {
    let src = r##"
        use crate::{mesh::{self, Mesh}, geometry::predicates as p};
        // use crate::pipeline::repair;
        /* crate::fill::dispatch */
        const S: &str = "crate::fill::wavefront";
        const R: &str = r#"crate::pipeline"#;
        fn f<'a>(x: &'a str) -> char { let _ = super::step::go(); '"' }
        pub(in crate::fill) fn g() { crate::fill::kit::relax::RELAX_STEP; }
        #[cfg(test)]
        mod tests {
            use super::*;
            use crate::testutil::icosphere;
        }
    "##;
    let module = vec![
        "fill".to_string(),
        "wavefront".to_string(),
        "wave".to_string(),
    ];
    let got: Vec<(String, bool)> = imports(src, &module, false)
        .into_iter()
        .map(|im| (im.path.join("::"), im.test))
        .collect();
    let want: Vec<(String, bool)> = [
        ("mesh", false),
        ("mesh::Mesh", false),
        ("geometry::predicates", false),
        ("fill::wavefront::step::go", false),
        ("fill::kit::relax::RELAX_STEP", false),
        ("fill::wavefront::wave", true),
        ("testutil::icosphere", true),
    ]
    .iter()
    .map(|(p, t)| (p.to_string(), *t))
    .collect();
    assert_eq!(got, want);
    assert_eq!(place(&module).unwrap().1, "fill::wavefront");
    assert_eq!(
        place(&["fill".into(), "kit".into(), "x".into()]).unwrap().1,
        "fill::kit"
    );
    assert!(place(&["nowhere".into()]).is_none());
}
