//! The systemd files as systemd's own tools read them: the unit's exposure by
//! `systemd-analyze security`, the folders `systemd-tmpfiles` makes.

use std::fs;
use std::os::unix::fs::MetadataExt;
use std::path::Path;
use std::process::Command;

fn unit() -> &'static Path {
    Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/systemd/holefill.service"
    ))
}

#[test]
#[ignore = "needs systemd-analyze (systemd 250 or later)"]
fn the_unit_is_rated_safe_by_systemd_analyze() {
    let out = Command::new("systemd-analyze")
        .args(["security", "--offline=yes", "--threshold=10"])
        .arg(unit())
        .output()
        .expect("systemd-analyze");
    let text = String::from_utf8_lossy(&out.stdout);
    let overall = text
        .lines()
        .find(|l| l.contains("Overall exposure level"))
        .unwrap_or("");
    eprintln!("{overall}");
    assert!(
        out.status.success(),
        "exposure above 1.0:\n{text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for key in [
        "PrivateNetwork=",
        "ProtectProc=",
        "SystemCallFilter=~@privileged",
        "RestrictAddressFamilies=~AF_(INET|INET6)",
    ] {
        let line = text.lines().find(|l| l.contains(key)).unwrap_or("");
        assert!(line.starts_with('✓'), "{key}: {line}");
    }
}

#[test]
fn the_unit_bounds_the_service_and_survives_a_workers_oom_kill() {
    let text = fs::read_to_string(unit()).unwrap();
    let keys: Vec<(&str, &str)> = text
        .lines()
        .filter(|l| !l.starts_with('#'))
        .filter_map(|l| l.split_once('='))
        .collect();
    let get = |k: &str| keys.iter().find(|(a, _)| *a == k).map(|(_, v)| *v);
    assert_eq!(get("OOMPolicy"), Some("continue"));
    assert_eq!(get("LimitCORE"), Some("0"));
    assert!(get("MemoryMax").is_some_and(|v| !v.is_empty() && v != "infinity"));
    assert!(get("TasksMax").is_some_and(|v| v.parse::<u32>().is_ok()));
    assert_eq!(get("RestrictAddressFamilies"), Some("AF_UNIX"));
    assert_eq!(get("ProtectProc"), Some("invisible"));
}

#[test]
#[ignore = "needs root"]
fn the_tmpfiles_inbox_is_sticky() {
    let root = tempfile::tempdir().unwrap();
    let etc = root.path().join("etc");
    fs::create_dir(&etc).unwrap();
    fs::write(
        etc.join("passwd"),
        "holefill:x:990:990::/var/lib/holefill:/usr/sbin/nologin\n",
    )
    .unwrap();
    fs::write(etc.join("group"), "holefill:x:990:\n").unwrap();
    let conf = Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/systemd/holefill.tmpfiles.conf"
    ));
    let st = Command::new("systemd-tmpfiles")
        .arg("--create")
        .arg(format!("--root={}", root.path().display()))
        .arg(conf)
        .status()
        .expect("systemd-tmpfiles");
    assert!(st.success());
    let inbox = fs::metadata(root.path().join("var/lib/holefill/inbox")).unwrap();
    assert_eq!(
        inbox.mode() & 0o7777,
        0o3775,
        "setgid, sticky, group-writable"
    );
    assert_eq!((inbox.uid(), inbox.gid()), (990, 990));
    for d in ["outbox", "failed", "archive"] {
        let m = fs::metadata(root.path().join("var/lib/holefill").join(d)).unwrap();
        assert_eq!(m.mode() & 0o022, 0, "{d}: only the daemon writes");
    }
}
