//! `holefill check-policy FILE`: the real binary, its exit status and its messages.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn check_policy(file: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_holefill"))
        .arg("check-policy")
        .arg(file)
        .output()
        .expect("run holefill")
}

/// Writes `text` to `name` in a fresh directory and runs `check-policy` on it.
fn check_text(name: &str, text: &str) -> (tempfile::TempDir, PathBuf, Output) {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join(name);
    std::fs::write(&path, text).expect("write policy");
    let out = check_policy(&path);
    (dir, path, out)
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn stdout(out: &Output) -> String {
    String::from_utf8_lossy(&out.stdout).into_owned()
}

#[test]
fn shipped_default_policy_passes() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/policy.toml");
    let out = check_policy(&path);
    assert_eq!(out.status.code(), Some(0), "stderr: {}", stderr(&out));
    assert!(stdout(&out).contains("policy.toml: ok"), "{}", stdout(&out));
    assert!(stderr(&out).is_empty(), "{}", stderr(&out));
}

#[test]
fn valid_file_exits_0() {
    let text = "seed = 42\n\n[dispatch]\nsmall_max = 8\nmiddle_max = 80\n\
                large = [\"advancing_front\", \"min_area_fair\", \"fan\"]\n\n\
                [smooth]\nenabled = true\nscope = \"rings\"\nrings = 2\n";
    let (_dir, path, out) = check_text("mine.toml", text);
    assert_eq!(out.status.code(), Some(0), "stderr: {}", stderr(&out));
    assert_eq!(stdout(&out).trim(), format!("{}: ok", path.display()));
}

#[test]
fn empty_file_exits_0() {
    let (_dir, _path, out) = check_text("empty.toml", "");
    assert_eq!(out.status.code(), Some(0), "stderr: {}", stderr(&out));
}

#[test]
fn misspelt_key_exits_1_with_file_line_key_and_suggestion() {
    let text = "# my policy\n\n[front]\nangle_small = 70\nangle_lagre = 140\n";
    let (_dir, path, out) = check_text("misspelt.toml", text);
    assert_eq!(out.status.code(), Some(1));
    let err = stderr(&out);
    assert!(err.contains("misspelt.toml"), "{err}");
    assert!(err.contains(":5:"), "{err}");
    assert!(err.contains("front.angle_lagre"), "{err}");
    assert!(err.contains("did you mean `angle_large`?"), "{err}");
    assert_eq!(
        err.trim(),
        format!(
            "error: {}:5: key `front.angle_lagre`: unknown key; did you mean `angle_large`?",
            path.display()
        )
    );
}

#[test]
fn unknown_section_exits_1() {
    let (_dir, _path, out) = check_text("section.toml", "[smoth]\nenabled = true\n");
    assert_eq!(out.status.code(), Some(1));
    let err = stderr(&out);
    assert!(err.contains("section.toml:1:"), "{err}");
    assert!(err.contains("did you mean [smooth]?"), "{err}");
}

#[test]
fn unknown_method_exits_1() {
    let text = "[dispatch]\nsmall = [\"fan\"]\nmiddle = [\"min_area_fiar\"]\n";
    let (_dir, _path, out) = check_text("method.toml", text);
    assert_eq!(out.status.code(), Some(1));
    let err = stderr(&out);
    assert!(err.contains("method.toml:3:"), "{err}");
    assert!(err.contains("key `dispatch.middle`"), "{err}");
    assert!(err.contains("unknown method \"min_area_fiar\""), "{err}");
    assert!(err.contains("did you mean \"min_area_fair\"?"), "{err}");
}

#[test]
fn wrong_type_exits_1() {
    let text = "[limits]\nhole_time_ms = \"10s\"\n";
    let (_dir, _path, out) = check_text("type.toml", text);
    assert_eq!(out.status.code(), Some(1));
    let err = stderr(&out);
    assert!(err.contains("type.toml:2:"), "{err}");
    assert!(err.contains("key `limits.hole_time_ms`"), "{err}");
    assert!(
        err.contains("expected an integer, got a string (\"10s\")"),
        "{err}"
    );
}

#[test]
fn out_of_range_exits_1() {
    let text = "seed = 1\n[front]\nalpha = 0.5\n\nangle_small = 200\n";
    let (_dir, path, out) = check_text("range.toml", text);
    assert_eq!(out.status.code(), Some(1));
    assert_eq!(
        stderr(&out).trim(),
        format!(
            "error: {}:5: key `front.angle_small`: must be between 0 and 180 (got 200)",
            path.display()
        )
    );
}

#[test]
fn inconsistent_keys_exit_1() {
    let text = "[smooth]\nlambda = 0.5\nmu = -0.4\n";
    let (_dir, _path, out) = check_text("pair.toml", text);
    assert_eq!(out.status.code(), Some(1));
    let err = stderr(&out);
    assert!(err.contains("pair.toml:3: key `smooth.mu`"), "{err}");
}

#[test]
fn syntax_error_exits_1_with_line() {
    let (_dir, _path, out) = check_text("syntax.toml", "seed = 1\n[dispatch\n");
    assert_eq!(out.status.code(), Some(1));
    assert!(stderr(&out).contains("syntax.toml:2:"), "{}", stderr(&out));
}

#[test]
fn missing_file_exits_1() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = check_policy(&dir.path().join("absent.toml"));
    assert_eq!(out.status.code(), Some(1));
    assert!(stderr(&out).contains("absent.toml"), "{}", stderr(&out));
}
