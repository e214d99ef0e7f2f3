//! A careless or hostile producer: a symlink or a FIFO swapped in atomically after the
//! daemon looked at a file, names with a line break, names that are not UTF-8, names
//! too long for the outputs. The daemon follows nothing, never hangs, and every file
//! ends in the outbox or in the failed folder with a log that says why.

mod common;
mod daemon_support;
use daemon_support::*;
use std::ffi::OsStr;
use std::fs;
use std::os::unix::ffi::OsStrExt;
use std::os::unix::fs::PermissionsExt;
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

const LONG: Duration = Duration::from_secs(60);

/// A mesh with coordinates found in no other file of the tests (a cube missing a face).
fn secret_obj() -> String {
    let mut s = String::new();
    for (x, y, z) in [
        (0, 0, 0),
        (1, 0, 0),
        (1, 1, 0),
        (0, 1, 0),
        (0, 0, 1),
        (1, 0, 1),
        (1, 1, 1),
        (0, 1, 1),
    ] {
        s.push_str(&format!(
            "v {} {} {}\n",
            4242.125 + x as f64,
            4242.125 + y as f64,
            4242.125 + z as f64
        ));
    }
    s.push_str("f 1 3 2\nf 1 4 3\nf 1 2 6\nf 1 6 5\nf 2 3 7\nf 2 7 6\nf 3 4 8\nf 3 8 7\nf 4 1 5\nf 4 5 8\n");
    s
}

/// No entry of `dir` is a symlink, and no file in it holds `needle`.
fn holds_nothing_of(dir: &Path, needle: &str) -> Result<(), String> {
    for e in fs::read_dir(dir).into_iter().flatten().flatten() {
        let m = fs::symlink_metadata(e.path()).unwrap();
        if m.file_type().is_symlink() {
            return Err(format!("{} is a symlink", e.path().display()));
        }
        if m.is_file() {
            let b = fs::read(e.path()).unwrap_or_default();
            if String::from_utf8_lossy(&b).contains(needle) {
                return Err(format!("{} holds the secret", e.path().display()));
            }
        }
    }
    Ok(())
}

/// Drops `n` files `xI.obj` and, for each, swaps it back and forth with `xI.alt` (made
/// by `make_alt`) until the daemon has claimed whichever was there. Returns how many
/// rounds ended with the other entry claimed (the alt), as far as the test can tell.
fn race(f: &Folders, n: usize, make_alt: &dyn Fn(&Path)) -> usize {
    let (obj, _) = mesh();
    let mut alt_taken = 0;
    for i in 0..n {
        let name = f.inbox.join(format!("x{i}.obj"));
        let alt = f.inbox.join(format!("x{i}.alt"));
        make_alt(&alt);
        drop_renamed(&f.inbox, &format!("x{i}.obj"), &obj);
        let t = Instant::now();
        while fs::symlink_metadata(&name).is_ok() && t.elapsed() < Duration::from_secs(5) {
            let _ = exchange(&name, &alt);
        }
        // whichever is left at the alt name was not claimed
        if fs::symlink_metadata(&alt).is_ok_and(|m| m.is_file()) {
            alt_taken += 1;
        }
        let _ = fs::remove_file(&alt);
        let _ = fs::remove_file(&name);
    }
    alt_taken
}

/// Waits until every `x*.obj` is done with: nothing in the inbox or in processing.
fn settled(f: &Folders, d: &Daemon) {
    assert!(
        wait_until(LONG, || f.processing().is_empty()
            && Folders::files(&f.inbox)
                .iter()
                .all(|n| !n.ends_with(".obj"))),
        "processing {:?}, inbox {:?}\n{}",
        f.processing(),
        Folders::files(&f.inbox),
        d.log()
    );
}

#[test]
fn a_symlink_swapped_in_after_the_check_is_never_followed() {
    let f = Folders::new();
    let private = f.root().join("private");
    fs::create_dir(&private).unwrap();
    let secret = private.join("secret.obj");
    fs::write(&secret, secret_obj()).unwrap();
    fs::set_permissions(&secret, fs::Permissions::from_mode(0o600)).unwrap();
    let mut d = Daemon::ready(&f, &[], &[]);
    let swapped = race(&f, 40, &|alt: &Path| {
        std::os::unix::fs::symlink(&secret, alt).unwrap();
    });
    settled(&f, &d);
    for dir in [&f.outbox, &f.failed, &f.archive, &f.inbox] {
        if let Err(e) = holds_nothing_of(dir, "4242.125") {
            panic!("{e}\n{}", d.log());
        }
    }
    // the secret itself is untouched
    assert_eq!(fs::read_to_string(&secret).unwrap(), secret_obj());
    // the race was run: some claims took the symlink; each left a log saying so
    let logs: Vec<String> = Folders::files(&f.failed)
        .into_iter()
        .filter(|n| n.ends_with(".repair.json"))
        .collect();
    let symlinks = logs
        .iter()
        .filter(|n| {
            Folders::log(&f.failed, n.trim_end_matches(".repair.json"))["error"]
                .as_str()
                .unwrap_or("")
                .contains("symbolic link")
        })
        .count();
    eprintln!(
        "40 rounds: {symlinks} symlinks claimed and refused, {swapped} rounds with the regular file left over, {} models",
        f.models().len()
    );
    assert!(symlinks > 0, "the race never hit: {logs:?}\n{}", d.log());
    assert_eq!(symlinks, logs.len(), "no other failures: {logs:?}");
    // a later file is repaired, and the daemon answers SIGTERM
    let (obj, _) = mesh();
    drop_renamed(&f.inbox, "later.obj", &obj);
    assert!(
        wait_until(LONG, || f.outbox.join("later.obj.repair.json").is_file()),
        "{}",
        d.log()
    );
    d.signal("TERM");
    assert_eq!(
        d.wait_exit(Duration::from_secs(20)).and_then(|s| s.code()),
        Some(0),
        "{}",
        d.log()
    );
}

#[test]
fn a_fifo_swapped_in_after_the_check_never_hangs_the_daemon() {
    let f = Folders::new();
    let mut d = Daemon::ready(&f, &[], &[]);
    let _ = race(&f, 30, &|alt: &Path| {
        let st = Command::new("mkfifo").arg(alt).status().unwrap();
        assert!(st.success());
    });
    settled(&f, &d);
    let fifos = Folders::files(&f.failed)
        .iter()
        .filter(|n| n.ends_with(".repair.json"))
        .filter(|n| {
            Folders::log(&f.failed, n.trim_end_matches(".repair.json"))["error"]
                .as_str()
                .unwrap_or("")
                .contains("FIFO")
        })
        .count();
    assert!(fifos > 0, "the race never hit\n{}", d.log());
    for dir in [&f.outbox, &f.failed, &f.archive] {
        for n in Folders::entries(dir) {
            let m = fs::symlink_metadata(dir.join(&n)).unwrap();
            assert!(
                m.is_file() || m.is_dir(),
                "{n}: not a regular file in the output"
            );
        }
    }
    // later files are repaired, and the daemon answers SIGTERM
    let (obj, _) = mesh();
    for n in ["later1.obj", "later2.obj"] {
        drop_renamed(&f.inbox, n, &obj);
    }
    assert!(
        wait_until(LONG, || f.outbox.join("later1.obj.repair.json").is_file()
            && f.outbox.join("later2.obj.repair.json").is_file()),
        "{}",
        d.log()
    );
    d.signal("TERM");
    assert_eq!(
        d.wait_exit(Duration::from_secs(20)).and_then(|s| s.code()),
        Some(0),
        "SIGTERM answered\n{}",
        d.log()
    );
}

#[test]
fn a_line_break_in_a_name_cannot_forge_a_journal_line() {
    let f = Folders::new();
    let mut d = Daemon::ready(&f, &[], &[]);
    let (obj, _) = mesh();
    let forged =
        "a.obj\n2026-01-01T00:00:00.000000Z  WARN other.obj failed at input: forged; x.obj";
    drop_renamed(&f.inbox, forged, &obj);
    assert!(
        wait_until(LONG, || f
            .outbox
            .join(format!("{forged}.repair.json"))
            .is_file()),
        "repaired under its own name\n{}",
        d.log()
    );
    d.signal("TERM");
    d.wait_exit(Duration::from_secs(20));
    let j = d.log();
    assert!(
        !j.lines().any(|l| l.starts_with("2026-01-01")),
        "a forged line:\n{j}"
    );
    assert!(
        j.contains("a.obj\\u{a}2026-01-01T00:00:00.000000Z  WARN other.obj"),
        "the name is escaped:\n{j}"
    );
    let log = Folders::log(&f.outbox, forged);
    assert_eq!(log["status"], "repaired");
    assert_eq!(
        log["daemon"]["input"].as_str(),
        Some(forged.replace('\n', "\\u{a}").as_str())
    );
}

#[test]
fn a_name_that_is_not_utf8_goes_to_failed_with_the_reason() {
    let f = Folders::new();
    let mut d = Daemon::ready(&f, &[], &[]);
    let (obj, _) = mesh();
    let raw = OsStr::from_bytes(b"scan\xff\xfe.obj");
    fs::write(f.inbox.join(".tmp.part"), &obj).unwrap();
    fs::rename(f.inbox.join(".tmp.part"), f.inbox.join(raw)).unwrap();
    let shown = "scan\\xff\\xfe.obj";
    assert!(
        wait_until(LONG, || f
            .failed
            .join(format!("{shown}.repair.json"))
            .is_file()),
        "failed: {:?}\n{}",
        Folders::entries(&f.failed),
        d.log()
    );
    assert_eq!(
        fs::read_to_string(f.failed.join(shown)).unwrap(),
        obj,
        "untouched"
    );
    let log = Folders::log(&f.failed, shown);
    assert_eq!(log["status"], "failed");
    assert_eq!(log["stage"], "name");
    assert!(log["error"].as_str().unwrap().contains("UTF-8"), "{log}");
    assert_eq!(log["daemon"]["input"], shown);
    assert_eq!(log["daemon"]["input_bytes_hex"], "7363616efffe2e6f626a");
    assert!(Folders::entries(&f.inbox)
        .iter()
        .all(|n| n.starts_with('.')));
    assert!(f.processing().is_empty());
    // the journal line follows the log file (published first)
    assert!(
        wait_until(LONG, || d
            .log()
            .contains(&format!("{shown} failed at name"))),
        "{}",
        d.log()
    );
    d.signal("TERM");
    assert_eq!(
        d.wait_exit(Duration::from_secs(20)).and_then(|s| s.code()),
        Some(0)
    );
}

#[test]
fn names_too_long_for_the_outputs_go_to_failed_at_once() {
    let f = Folders::new();
    let mut d = Daemon::ready(&f, &[], &[]);
    let (obj, _) = mesh();
    // 250 bytes: "NAME.repair.json" and the time-stamped names would pass 255 bytes
    let long = format!("{}.obj", "a".repeat(246));
    // 221 bytes: the longest name the daemon repairs
    let longest = format!("{}.obj", "b".repeat(217));
    drop_renamed(&f.inbox, &long, &obj);
    drop_renamed(&f.inbox, &longest, &obj);
    assert!(
        wait_until(LONG, || Folders::files(&f.failed).len() == 2
            && f.outbox.join(format!("{longest}.repair.json")).is_file()),
        "failed {:?}\n{}",
        Folders::files(&f.failed),
        d.log()
    );
    // a second file of the long name: a second failure, under a time-stamped name
    drop_renamed(&f.inbox, &long, &obj);
    assert!(
        wait_until(LONG, || Folders::files(&f.failed).len() == 4),
        "failed {:?}\n{}",
        Folders::files(&f.failed),
        d.log()
    );
    for n in Folders::files(&f.failed) {
        assert!(n.len() <= 255, "{n}");
        if let Some(stem) = n.strip_suffix(".repair.json") {
            let log = Folders::log(&f.failed, stem);
            assert_eq!(log["stage"], "name", "{log}");
            assert!(
                log["error"].as_str().unwrap().contains("250 bytes"),
                "{log}"
            );
            assert_eq!(fs::read_to_string(f.failed.join(stem)).unwrap(), obj);
        }
    }
    // never retried: two failures in the journal, no put-back
    std::thread::sleep(Duration::from_secs(2));
    let j = d.log();
    assert_eq!(j.matches("failed at name").count(), 2, "{j}");
    assert!(!j.contains("back in the inbox"), "{j}");
    assert!(f.processing().is_empty());
    d.signal("TERM");
    assert_eq!(
        d.wait_exit(Duration::from_secs(20)).and_then(|s| s.code()),
        Some(0)
    );
}
