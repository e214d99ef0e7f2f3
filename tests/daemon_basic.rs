//! `holefill watch` against the real binary and real folders: files renamed in and
//! written in place, a malformed file, a name collision, a file over a limit, read
//! limits enforced by the worker, SIGHUP with a broken policy.

mod common;
mod daemon_support;
use daemon_support::*;
use std::fs;
use std::time::Duration;

const LONG: Duration = Duration::from_secs(30);

#[test]
fn four_files_three_repaired_one_failed_daemon_alive() {
    let f = Folders::new();
    let mut d = Daemon::ready(&f, &[], &[]);
    let (obj, faces) = mesh();
    drop_renamed(&f.inbox, "a.obj", &obj);
    drop_renamed(&f.inbox, "B.OBJ", &obj);
    drop_renamed(&f.inbox, "bad.obj", "this is not\x00 a mesh\nf 1 2 x\n");
    // written in place over 2 s: must not be read half-written
    write_slowly(&f.inbox.join("slow.obj"), &obj, 10, Duration::from_secs(2));

    assert!(
        wait_until(LONG, || f.models().len() == 3
            && Folders::files(&f.failed).len() == 2
            && Folders::files(&f.archive).len() == 3
            && ["a.obj", "B.OBJ", "slow.obj"]
                .iter()
                .all(|n| f.outbox.join(format!("{n}.repair.json")).is_file())),
        "outbox {:?}, failed {:?}, inbox {:?}\n{}",
        Folders::files(&f.outbox),
        Folders::files(&f.failed),
        Folders::files(&f.inbox),
        d.log()
    );
    assert!(d.alive(), "the daemon keeps running\n{}", d.log());
    assert_eq!(f.models(), vec!["B.OBJ", "a.obj", "slow.obj"]);
    for name in ["a.obj", "B.OBJ", "slow.obj"] {
        assert!(
            f.outbox.join(format!("{name}.repair.json")).is_file(),
            "{name} log"
        );
        let log = Folders::log(&f.outbox, name);
        assert_eq!(log["status"], "repaired", "{log}");
        assert_eq!(
            log["before"]["faces"].as_u64(),
            Some(faces as u64),
            "{name} read whole: {log}"
        );
        assert!(
            log["after"]["faces"].as_u64().unwrap() > faces as u64,
            "{name}: the hole was filled: {log}"
        );
        let dm = &log["daemon"];
        assert_eq!(dm["attempt"], 1);
        assert_eq!(dm["pid"].as_u64(), Some(d.pid() as u64));
        assert!(dm["host"].as_str().is_some_and(|h| !h.is_empty()));
        for k in ["received", "started", "finished"] {
            assert!(
                dm[k]
                    .as_str()
                    .is_some_and(|t| t.ends_with('Z') && t.len() == 24),
                "{k}: {dm}"
            );
        }
        assert!(
            dm["received"].as_str() <= dm["started"].as_str()
                && dm["started"].as_str() <= dm["finished"].as_str()
        );
        // the original is archived, byte for byte
        assert_eq!(fs::read_to_string(f.archive.join(name)).unwrap(), obj);
    }
    assert_eq!(
        Folders::files(&f.failed),
        vec!["bad.obj", "bad.obj.repair.json"]
    );
    assert_eq!(
        fs::read(f.failed.join("bad.obj")).unwrap(),
        b"this is not\x00 a mesh\nf 1 2 x\n",
        "untouched"
    );
    let log = Folders::log(&f.failed, "bad.obj");
    assert_eq!(log["status"], "failed");
    assert_eq!(log["stage"], "input");
    assert!(
        log["error"].as_str().is_some_and(|e| !e.is_empty()),
        "{log}"
    );
    assert!(
        Folders::files(&f.inbox).is_empty(),
        "{:?}",
        Folders::files(&f.inbox)
    );
    assert!(f.processing().is_empty());

    // the journal: one line per file, with the word
    assert!(
        d.wait_log(" repaired -> ", 3) && d.wait_log(" failed at ", 1),
        "{}",
        d.log()
    );
    let j = d.log();
    for name in ["a.obj", "B.OBJ", "slow.obj"] {
        assert!(j.contains(&format!("{name} repaired")), "{j}");
    }
    assert!(j.contains("bad.obj failed"), "{j}");

    d.signal("TERM");
    let st = d.wait_exit(LONG).expect("exits on SIGTERM");
    assert_eq!(st.code(), Some(0), "{}", d.log());
    assert!(
        !f.inbox
            .join(".processing")
            .read_dir()
            .unwrap()
            .any(|_| true),
        "its processing folder is removed"
    );
}

#[test]
fn name_collision_keeps_both_outputs() {
    let f = Folders::new();
    fs::create_dir_all(&f.outbox).unwrap();
    fs::write(f.outbox.join("scan.obj"), "earlier output").unwrap();
    fs::write(f.outbox.join("scan.obj.repair.json"), "{}").unwrap();
    let d = Daemon::ready(&f, &["--log-format", "json"], &[]);
    let (obj, _) = mesh();
    drop_renamed(&f.inbox, "scan.obj", &obj);
    assert!(
        wait_until(LONG, || f.models().len() == 2),
        "{:?}\n{}",
        Folders::files(&f.outbox),
        d.log()
    );
    assert_eq!(
        fs::read_to_string(f.outbox.join("scan.obj")).unwrap(),
        "earlier output"
    );
    let new: Vec<String> = f.models().into_iter().filter(|n| n != "scan.obj").collect();
    let n = &new[0];
    // scan.YYYYMMDDTHHMMSSZ.obj
    assert!(
        n.starts_with("scan.")
            && n.ends_with("Z.obj")
            && n.len() == "scan.20261123T120501Z.obj".len(),
        "{n}"
    );
    assert!(wait_until(LONG, || f
        .outbox
        .join(format!("{n}.repair.json"))
        .is_file()));
    let log = Folders::log(&f.outbox, n);
    assert_eq!(log["status"], "repaired");
    assert!(log["daemon"]["output"]
        .as_str()
        .unwrap()
        .ends_with(n.as_str()));
    // json journal: one object per line, the finished line names the file
    assert!(
        wait_until(LONG, || d
            .log()
            .lines()
            .any(|l| l.contains("scan.obj repaired"))),
        "{}",
        d.log()
    );
    for line in d.log().lines().filter(|l| !l.trim().is_empty()) {
        serde_json::from_str::<serde_json::Value>(line)
            .unwrap_or_else(|e| panic!("not JSON: {line}: {e}"));
    }
}

#[test]
fn file_over_a_limit_goes_to_failed() {
    let f = Folders::new();
    let d = Daemon::ready(
        &f,
        &["--max-file-bytes", "1000", "--max-faces", "100000"],
        &[],
    );
    let (obj, _) = mesh();
    assert!(obj.len() > 1000);
    drop_renamed(&f.inbox, "big.obj", &obj);
    let small = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 2 3 4\n";
    drop_renamed(&f.inbox, "small.obj", small);
    assert!(
        wait_until(LONG, || Folders::files(&f.failed).len() == 2
            && f.models().len() == 1),
        "{}",
        d.log()
    );
    let log = Folders::log(&f.failed, "big.obj");
    assert_eq!(log["status"], "failed");
    assert_eq!(log["stage"], "limits");
    assert!(
        log["error"].as_str().unwrap().contains("max_file_bytes"),
        "{log}"
    );
    assert_eq!(fs::read_to_string(f.failed.join("big.obj")).unwrap(), obj);
    drop(d);

    // the face-count limit, read from the header without reading the geometry
    let f = Folders::new();
    let d = Daemon::ready(&f, &["--max-faces", "100"], &[]);
    drop_renamed(&f.inbox, "many.obj", &obj);
    drop_renamed(&f.inbox, "few.obj", small);
    assert!(
        wait_until(LONG, || Folders::files(&f.failed).len() == 2
            && f.models().len() == 1),
        "{}",
        d.log()
    );
    let log = Folders::log(&f.failed, "many.obj");
    assert_eq!(log["stage"], "limits");
    assert!(
        log["error"].as_str().unwrap().contains("max_faces"),
        "{log}"
    );
}

#[test]
fn sighup_with_a_broken_policy_keeps_the_old_one() {
    let f = Folders::new();
    let policy = f.root().join("policy.toml");
    fs::write(&policy, "seed = 7\n").unwrap();
    let mut d = Daemon::ready(&f, &["--policy", policy.to_str().unwrap()], &[]);
    let (obj, _) = mesh();
    drop_renamed(&f.inbox, "one.obj", &obj);
    assert!(
        wait_until(LONG, || f.outbox.join("one.obj.repair.json").is_file()),
        "{}",
        d.log()
    );
    assert_eq!(Folders::log(&f.outbox, "one.obj")["policy"]["seed"], 7);

    fs::write(
        &policy,
        "seed = \"not a number\"\n[dispatch]\nsmall_max = 1\n",
    )
    .unwrap();
    d.signal("HUP");
    assert!(
        wait_until(LONG, || d.log().contains("policy is refused")),
        "{}",
        d.log()
    );
    assert!(d.alive());
    drop_renamed(&f.inbox, "two.obj", &obj);
    assert!(
        wait_until(LONG, || f.outbox.join("two.obj.repair.json").is_file()),
        "{}",
        d.log()
    );
    assert_eq!(
        Folders::log(&f.outbox, "two.obj")["policy"]["seed"],
        7,
        "the old policy is in force"
    );

    // a valid policy is taken
    fs::write(&policy, "seed = 9\n").unwrap();
    d.signal("HUP");
    assert!(
        wait_until(LONG, || d.log().contains("reloaded")),
        "{}",
        d.log()
    );
    drop_renamed(&f.inbox, "three.obj", &obj);
    assert!(
        wait_until(LONG, || f.outbox.join("three.obj.repair.json").is_file()),
        "{}",
        d.log()
    );
    assert_eq!(Folders::log(&f.outbox, "three.obj")["policy"]["seed"], 9);
}

#[test]
fn invalid_policy_at_start_is_refused() {
    let f = Folders::new();
    let policy = f.root().join("policy.toml");
    fs::write(&policy, "no_such_key = 1\n").unwrap();
    let mut d = Daemon::start(&f, &["--policy", policy.to_str().unwrap()], &[]);
    let st = d.wait_exit(LONG).expect("exits");
    assert_ne!(st.code(), Some(0));
    assert!(d.log().contains("invalid policy"), "{}", d.log());
}

#[test]
fn poll_mode_finds_files_without_change_events() {
    let f = Folders::new();
    let d = Daemon::ready(&f, &["--poll", "--poll-ms", "200"], &[]);
    assert!(d.log().contains("mode=\"poll\""), "{}", d.log());
    let (obj, faces) = mesh();
    drop_renamed(&f.inbox, "p1.obj", &obj);
    write_slowly(&f.inbox.join("p2.obj"), &obj, 5, Duration::from_millis(800));
    assert!(wait_until(LONG, || f.models().len() == 2), "{}", d.log());
    for n in ["p1.obj", "p2.obj"] {
        assert!(wait_until(LONG, || f
            .outbox
            .join(format!("{n}.repair.json"))
            .is_file()));
        assert_eq!(
            Folders::log(&f.outbox, n)["before"]["faces"].as_u64(),
            Some(faces as u64)
        );
    }
}

#[test]
fn config_file_is_read_and_on_success_delete_removes_the_original() {
    let f = Folders::new();
    let cfg = f.root().join("holefill.toml");
    // folders from the config file; outbox etc. default to siblings of the inbox
    fs::write(
        &cfg,
        format!(
            "inbox = {:?}\nworkers = 1\nsettle_ms = 300\non_success = \"delete\"\nlog_format = \"json\"\n",
            f.inbox.to_str().unwrap()
        ),
    )
    .unwrap();
    let err = f.root().join("daemon-cfg.log");
    let child = std::process::Command::new(bin())
        .args(["watch", "--config", cfg.to_str().unwrap()])
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::null())
        .stderr(fs::File::create(&err).unwrap())
        .spawn()
        .unwrap();
    let mut d = Daemon { child, stderr: err };
    assert!(
        wait_until(LONG, || d.log().contains("holefill watch ready")),
        "{}",
        d.log()
    );
    assert!(d.log().contains("\"workers\":1"), "{}", d.log());
    let (obj, _) = mesh();
    drop_renamed(&f.inbox, "gone.obj", &obj);
    assert!(
        wait_until(LONG, || f.outbox.join("gone.obj.repair.json").is_file()),
        "{}",
        d.log()
    );
    assert!(wait_until(LONG, || Folders::files(&f.inbox).is_empty()
        && f.processing().is_empty()));
    assert!(f.archive.is_dir(), "created as the inbox's sibling");
    assert!(
        Folders::files(&f.archive).is_empty(),
        "deleted, not archived"
    );
    assert_eq!(
        Folders::log(&f.outbox, "gone.obj")["daemon"]["original"],
        "deleted"
    );

    // an unknown key is refused at start
    fs::write(&cfg, "inbx = \"/tmp\"\n").unwrap();
    let out = std::process::Command::new(bin())
        .args(["watch", "--config", cfg.to_str().unwrap()])
        .output()
        .unwrap();
    assert_ne!(out.status.code(), Some(0));
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("inbx"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    d.signal("TERM");
    assert_eq!(d.wait_exit(LONG).and_then(|s| s.code()), Some(0));
}

#[test]
fn collision_overwrite_replaces_the_earlier_output_when_asked() {
    let f = Folders::new();
    fs::create_dir_all(&f.outbox).unwrap();
    fs::write(f.outbox.join("scan.obj"), "earlier output").unwrap();
    fs::write(f.outbox.join("scan.obj.repair.json"), "{}").unwrap();
    let d = Daemon::ready(&f, &["--collision", "overwrite"], &[]);
    let (obj, _) = mesh();
    drop_renamed(&f.inbox, "scan.obj", &obj);
    assert!(
        // the log is published last
        wait_until(LONG, || Folders::files(&f.archive) == vec!["scan.obj"]
            && fs::read_to_string(f.outbox.join("scan.obj.repair.json"))
                .is_ok_and(|t| t.contains("repaired"))),
        "{}",
        d.log()
    );
    // the picture follows its log
    assert!(
        wait_until(LONG, || Folders::files(&f.outbox)
            == vec!["scan.obj", "scan.obj.repair.json", "scan.obj.repair.png"]),
        "{:?}\n{}",
        Folders::files(&f.outbox),
        d.log()
    );
    assert_ne!(
        fs::read_to_string(f.outbox.join("scan.obj")).unwrap(),
        "earlier output"
    );
    assert_eq!(Folders::log(&f.outbox, "scan.obj")["status"], "repaired");
}

#[test]
fn read_limits_are_passed_to_the_worker() {
    // Two quads: the header declares 2 faces (the daemon's sniff lets it through
    // max_faces = 3), but they are 4 triangles, which the worker's reader refuses.
    let quads = "ply\nformat ascii 1.0\nelement vertex 6\nproperty float x\n\
                 property float y\nproperty float z\nelement face 2\n\
                 property list uchar int vertex_indices\nend_header\n\
                 0 0 0\n1 0 0\n2 0 0\n0 1 0\n1 1 0\n2 1 0\n4 0 1 4 3\n4 1 2 5 4\n";
    // 7 vertices (nothing counts vertices before the worker reads them)
    let many = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nv 2 0 0\nv 2 1 0\nv 3 3 0\nf 1 2 3\n";
    // within both limits
    let few = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 4\nf 1 4 3\n";
    let f = Folders::new();
    let d = Daemon::ready(&f, &["--max-faces", "3", "--max-vertices", "6"], &[]);
    drop_renamed(&f.inbox, "quads.ply", quads);
    drop_renamed(&f.inbox, "many.obj", many);
    drop_renamed(&f.inbox, "few.obj", few);
    assert!(
        wait_until(LONG, || Folders::files(&f.failed).len() == 4
            && f.models().len() == 1),
        "failed {:?}, outbox {:?}\n{}",
        Folders::files(&f.failed),
        Folders::files(&f.outbox),
        d.log()
    );
    assert_eq!(f.models(), vec!["few.obj"]);
    for (name, limit) in [
        ("quads.ply", "max_faces = 3"),
        ("many.obj", "max_vertices = 6"),
    ] {
        let log = Folders::log(&f.failed, name);
        assert_eq!(log["status"], "failed", "{log}");
        let error = log["error"].as_str().unwrap_or_default();
        assert!(
            error.contains(limit) && error.contains("configured limit"),
            "{name}: {log}"
        );
        assert!(f.failed.join(name).is_file(), "{name} kept in failed/");
    }
}
