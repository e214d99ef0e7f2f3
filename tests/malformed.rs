//! Malformed input never crashes `holefill fill`: every file of the corpus in
//! `tests/data/malformed/` (listed with its expected outcome in the folder's
//! README.md) is run through the real binary, under a 1 GB address-space limit
//! (`ulimit -v`, so that allocating what a header merely claims fails the test) and
//! a 20 s time limit. A malformed file must exit 65 with a message naming the file
//! and the reason, and leave nothing behind (no output, no temporary file); a valid
//! one must exit 0 or 2 and write the output. No run may panic.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_holefill");
const TIME_LIMIT: Duration = Duration::from_secs(20);
/// Address-space limit for the child, in KiB (1 GiB).
const VMEM_KIB: u64 = 1 << 20;

fn corpus_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/malformed")
}

/// What a corpus file must do.
#[derive(Debug, Clone)]
enum Expect {
    /// Exit 0 or 2, output written.
    Reads,
    /// Exit 65, stderr holds this substring.
    Error(String),
}

/// The manifest: rows `| `file` | reads |` or `| `file` | error: substring |`.
fn manifest() -> Vec<(String, Expect)> {
    let text = std::fs::read_to_string(corpus_dir().join("README.md")).expect("README.md");
    let mut rows = Vec::new();
    for line in text.lines() {
        let cells: Vec<&str> = line.split('|').map(str::trim).collect();
        let [_, file, expect, ..] = cells.as_slice() else {
            continue;
        };
        let Some(file) = file.strip_prefix('`').and_then(|f| f.strip_suffix('`')) else {
            continue;
        };
        let expect = if *expect == "reads" {
            Expect::Reads
        } else if let Some(s) = expect.strip_prefix("error:") {
            let s = s.trim().trim_matches('`');
            assert!(!s.is_empty(), "{file}: empty error substring");
            Expect::Error(s.to_string())
        } else {
            panic!("{file}: bad expectation '{expect}'");
        };
        rows.push((file.to_string(), expect));
    }
    rows
}

struct Run {
    code: Option<i32>,
    stderr: String,
}

/// Runs `holefill ARGS` under the address-space limit, killing it after the time limit.
fn run(args: &[&str]) -> Run {
    let script = format!("ulimit -v {VMEM_KIB} && exec \"$0\" \"$@\"");
    let mut child = Command::new("sh")
        .arg("-c")
        .arg(script)
        .arg(BIN)
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn sh");
    let mut stderr = child.stderr.take().expect("stderr");
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = std::io::Read::read_to_string(&mut stderr, &mut s);
        s
    });
    let start = Instant::now();
    let status = loop {
        if let Some(st) = child.try_wait().expect("wait") {
            break st;
        }
        if start.elapsed() > TIME_LIMIT {
            let _ = child.kill();
            let _ = child.wait();
            panic!("holefill {args:?} did not finish within {TIME_LIMIT:?}");
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    Run {
        code: status.code(),
        stderr: reader.join().unwrap_or_default(),
    }
}

/// The output path for an input: same extension (`.obj` for unknown ones).
fn output_for(input: &Path, dir: &Path) -> PathBuf {
    let ext = input
        .extension()
        .and_then(|e| e.to_str())
        .filter(|e| matches!(*e, "obj" | "ply" | "stl" | "off"))
        .unwrap_or("obj");
    dir.join(format!("out.{ext}"))
}

/// Checks one input against its expectation; returns a description of the failure.
fn check(input: &Path, expect: &Expect, extra: &[&str]) -> Result<(), String> {
    let dir = tempfile::tempdir().map_err(|e| e.to_string())?;
    let out = output_for(input, dir.path());
    let (i, o) = (input.to_str().unwrap_or(""), out.to_str().unwrap_or(""));
    let mut args = vec!["fill", "-q", i, o];
    args.extend_from_slice(extra);
    let r = run(&args);
    let name = input
        .file_name()
        .and_then(|n| n.to_str())
        .unwrap_or_default();
    if r.stderr.contains("panicked") {
        return Err(format!("{name}: panic: {}", r.stderr));
    }
    let left: Vec<_> = std::fs::read_dir(dir.path())
        .map_err(|e| e.to_string())?
        .filter_map(|e| e.ok())
        .map(|e| e.file_name())
        .collect();
    match expect {
        Expect::Reads => {
            if !matches!(r.code, Some(0 | 2)) {
                return Err(format!(
                    "{name}: expected to read (exit 0 or 2), got {:?}: {}",
                    r.code, r.stderr
                ));
            }
            if !out.exists() {
                return Err(format!("{name}: exit {:?} but no output", r.code));
            }
        }
        Expect::Error(sub) => {
            if r.code != Some(65) {
                return Err(format!(
                    "{name}: expected exit 65, got {:?}: {}",
                    r.code, r.stderr
                ));
            }
            if !r.stderr.contains(name) {
                return Err(format!(
                    "{name}: the error does not name the file: {}",
                    r.stderr
                ));
            }
            if !r.stderr.contains(sub.as_str()) {
                return Err(format!(
                    "{name}: the error lacks '{sub}': {}",
                    r.stderr.trim()
                ));
            }
            if !left.is_empty() {
                return Err(format!("{name}: files left behind: {left:?}"));
            }
        }
    }
    Ok(())
}

#[test]
fn corpus_manifest_lists_every_file() {
    let rows = manifest();
    assert!(rows.len() >= 40, "only {} corpus files", rows.len());
    let listed: std::collections::BTreeSet<_> = rows.iter().map(|(f, _)| f.clone()).collect();
    assert_eq!(listed.len(), rows.len(), "a file is listed twice");
    let mut on_disk = std::collections::BTreeSet::new();
    for e in std::fs::read_dir(corpus_dir()).expect("corpus dir") {
        let name = e.expect("entry").file_name().to_string_lossy().into_owned();
        if name != "README.md" && name != "generate.py" {
            on_disk.insert(name);
        }
    }
    let missing: Vec<_> = on_disk.difference(&listed).collect();
    let extra: Vec<_> = listed.difference(&on_disk).collect();
    assert!(missing.is_empty(), "not in README.md: {missing:?}");
    assert!(extra.is_empty(), "listed but missing: {extra:?}");
    for (f, _) in &rows {
        let len = std::fs::metadata(corpus_dir().join(f)).expect("meta").len();
        assert!(
            len <= 16 * 1024,
            "{f}: corpus files must stay small ({len} bytes)"
        );
    }
}

#[test]
fn every_corpus_file_gives_its_expected_outcome() {
    let dir = corpus_dir();
    let failures: Vec<String> = manifest()
        .iter()
        .filter_map(|(f, e)| check(&dir.join(f), e, &[]).err())
        .collect();
    assert!(
        failures.is_empty(),
        "{} failures:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

#[test]
fn single_line_of_100_mb_is_refused_without_buffering_it_all() {
    let dir = tempfile::tempdir().expect("tempdir");
    let input = dir.path().join("one_line_100mb.obj");
    {
        use std::io::Write;
        let mut f = std::io::BufWriter::new(std::fs::File::create(&input).expect("create"));
        f.write_all(b"v").expect("write");
        let chunk = b" 1".repeat(1 << 16);
        for _ in 0..(100 << 20) / chunk.len() {
            f.write_all(&chunk).expect("write");
        }
        f.flush().expect("flush");
    }
    let r = check(&input, &Expect::Error("line too long".into()), &[]);
    assert!(r.is_ok(), "{r:?}");
}

#[test]
fn header_claiming_2_pow_31_vertices_allocates_nothing_of_it() {
    // Tiny bodies under a header that claims 2^31 elements, in every format with a
    // header count; the child runs under `ulimit -v` 1 GB, so reserving what the
    // header claims (2^31 × 24 bytes) would abort it instead of exiting 65.
    let dir = tempfile::tempdir().expect("tempdir");
    let n = 1u64 << 31;
    let cases: Vec<(&str, Vec<u8>)> = vec![
        (
            "claim.ply",
            format!(
                "ply\nformat binary_little_endian 1.0\nelement vertex {n}\nproperty float x\n\
                 property float y\nproperty float z\nelement face 1\n\
                 property list uchar int vertex_indices\nend_header\n"
            )
            .into_bytes()
            .into_iter()
            .chain([0u8; 64])
            .collect(),
        ),
        (
            "claim.off",
            format!("OFF\n{n} 1 0\n0 0 0\n3 0 0 0\n").into_bytes(),
        ),
        ("claim.stl", {
            let mut b = vec![b' '; 80];
            b.extend_from_slice(&(n as u32).to_le_bytes());
            b.extend_from_slice(&[0u8; 50]);
            b
        }),
    ];
    for (name, bytes) in cases {
        let p = dir.path().join(name);
        std::fs::write(&p, bytes).expect("write");
        let r = check(&p, &Expect::Error("2147483648".into()), &[]);
        assert!(r.is_ok(), "{r:?}");
    }
}

fn tetra_dir() -> tempfile::TempDir {
    let dir = tempfile::tempdir().expect("tempdir");
    let src = corpus_dir();
    for (from, to) in [
        ("obj_mixed_line_endings.obj", "tetra.obj"),
        ("ply_binary_le_valid.ply", "tetra.ply"),
        ("stl_binary_valid.stl", "tetra.stl"),
        ("off_utf8_bom.off", "tetra.off"),
        ("stl_ascii_mixed_line_endings.stl", "tetra_ascii.stl"),
        ("ply_ascii_utf8_bom.ply", "tetra_ascii.ply"),
    ] {
        std::fs::copy(src.join(from), dir.path().join(to)).expect("copy");
    }
    dir
}

const TETRAS: [&str; 6] = [
    "tetra.obj",
    "tetra.ply",
    "tetra.stl",
    "tetra.off",
    "tetra_ascii.stl",
    "tetra_ascii.ply",
];

#[test]
fn max_faces_limit_is_enforced_in_every_reader() {
    // Each file is a tetrahedron: 4 vertices, 4 triangles.
    let dir = tetra_dir();
    for name in TETRAS {
        let p = dir.path().join(name);
        let over = check(
            &p,
            &Expect::Error("max_faces = 3".into()),
            &["--max-faces", "3"],
        );
        assert!(over.is_ok(), "{over:?}");
        let at = check(&p, &Expect::Reads, &["--max-faces", "4"]);
        assert!(at.is_ok(), "{at:?}");
    }
}

#[test]
fn max_vertices_limit_is_enforced_in_every_reader() {
    let dir = tetra_dir();
    for name in TETRAS {
        let p = dir.path().join(name);
        let over = check(
            &p,
            &Expect::Error("max_vertices = 3".into()),
            &["--max-vertices", "3"],
        );
        assert!(over.is_ok(), "{over:?}");
        let at = check(&p, &Expect::Reads, &["--max-vertices", "4"]);
        assert!(at.is_ok(), "{at:?}");
    }
}

#[test]
fn max_file_bytes_limit_is_checked_before_reading() {
    let dir = tetra_dir();
    for name in TETRAS {
        let p = dir.path().join(name);
        let len = std::fs::metadata(&p).expect("meta").len();
        let below = (len - 1).to_string();
        let over = check(
            &p,
            &Expect::Error(format!("max_file_bytes = {below}")),
            &["--max-file-bytes", &below],
        );
        assert!(over.is_ok(), "{over:?}");
        let exact = len.to_string();
        let at = check(&p, &Expect::Reads, &["--max-file-bytes", &exact]);
        assert!(at.is_ok(), "{at:?}");
    }
}

#[test]
fn zero_means_no_limit() {
    let dir = tetra_dir();
    let p = dir.path().join("tetra.obj");
    let r = check(
        &p,
        &Expect::Reads,
        &[
            "--max-faces",
            "0",
            "--max-vertices",
            "0",
            "--max-file-bytes",
            "0",
        ],
    );
    assert!(r.is_ok(), "{r:?}");
}

#[test]
fn library_limits_match_the_cli() {
    use holefill::io::{read_bytes, read_with_limits, Format, ReadLimits};
    let dir = tetra_dir();
    let p = dir.path().join("tetra.obj");
    let lim = ReadLimits {
        max_faces: 2,
        ..ReadLimits::default()
    };
    let e = read_with_limits(&p, None, &lim).expect_err("over the face limit");
    assert!(e.is_malformed());
    assert!(e.to_string().contains("max_faces = 2"), "{e}");
    let bytes = std::fs::read(&p).expect("read");
    let e = read_bytes(&p, &bytes, Format::Obj, &lim).expect_err("over the face limit");
    assert!(e.to_string().contains("max_faces = 2"), "{e}");
    let ok = read_with_limits(&p, None, &ReadLimits::default()).expect("reads");
    assert_eq!(ok.faces.len(), 4);
    assert_eq!(
        read_bytes(&p, &bytes, Format::Obj, &ReadLimits::default()).expect("reads"),
        ok
    );
}
