//! Crashes and other daemons, driven by the test hooks (cargo feature `test-hooks`):
//! the daemon killed at every step of a file's handling, across file systems too;
//! two daemons in separate PID namespaces on one inbox; the attempt count across
//! put-backs; a producer of another user under `fs.protected_hardlinks`.

mod common;
mod daemon_support;
use daemon_support::*;
use std::fs;
use std::process::Command;
use std::time::Duration;

const LONG: Duration = Duration::from_secs(60);

/// After a daemon killed at `point`, a new daemon leaves exactly one model, one log
/// and one archived original.
fn kill_at_then_restart(f: &Folders, point: &str) {
    let (obj, _) = mesh();
    let mut d = Daemon::ready(f, &[], &[("HOLEFILL_TEST_DIE_AT", point)]);
    drop_renamed(&f.inbox, "x.obj", &obj);
    assert!(
        d.wait_exit(LONG).is_some(),
        "{point}: the daemon did not die\n{}",
        d.log()
    );
    assert!(
        d.log().contains(&format!("dying at {point}")),
        "{}",
        d.log()
    );
    let mut d2 = Daemon::ready(f, &[], &[]);
    assert!(
        wait_until(LONG, || f.outbox.join("x.obj.repair.json").is_file()
            && f.processing().is_empty()),
        "{point}\n{}\n{}",
        d.log(),
        d2.log()
    );
    assert!(
        published_once(&f.outbox, "x.obj"),
        "{point}: {:?}\n{}",
        Folders::files(&f.outbox),
        d2.log()
    );
    assert_eq!(
        Folders::files(&f.archive),
        vec!["x.obj"],
        "{point}\n{}",
        d2.log()
    );
    assert_eq!(fs::read_to_string(f.archive.join("x.obj")).unwrap(), obj);
    assert!(Folders::files(&f.inbox).is_empty(), "{point}");
    assert!(Folders::files(&f.failed).is_empty(), "{point}");
    let log = Folders::log(&f.outbox, "x.obj");
    assert_eq!(log["status"], "repaired");
    assert_eq!(
        log["daemon"]["archived_as"].as_str(),
        Some(f.archive.join("x.obj").to_str().unwrap()),
        "{point}: {log}"
    );
    // no leftovers: the dead daemon's folders go, only the live one's remains
    let processing = f.inbox.join(".processing");
    assert!(
        wait_until(LONG, || Folders::entries(&processing).len() == 1),
        "{point}: {:?}",
        Folders::entries(&processing)
    );
    for dir in [&f.outbox, &f.archive] {
        let dots: Vec<String> = Folders::entries(dir)
            .into_iter()
            .filter(|n| n.starts_with('.') && n != ".holefill-tmp")
            .collect();
        assert!(dots.is_empty(), "{point}: {dots:?}");
    }
    d2.signal("TERM");
    assert_eq!(d2.wait_exit(LONG).and_then(|s| s.code()), Some(0));
}

const POINTS: [&str; 6] = [
    "claimed",
    "committing",
    "model-published",
    "archive-linked",
    "archived",
    "log-published",
];

#[test]
fn a_kill_at_any_step_leaves_one_model_one_log_one_original() {
    for point in POINTS {
        kill_at_then_restart(&Folders::new(), point);
    }
}

#[test]
#[ignore = "needs root"]
fn a_kill_at_any_step_across_file_systems_leaves_one_copy() {
    for point in POINTS {
        let f = Folders::new();
        fs::create_dir_all(&f.archive).unwrap();
        let _m = Mount::new(&["-t", "tmpfs", "holefill-test"], &f.archive)
            .expect("a tmpfs for the archive (root)");
        kill_at_then_restart(&f, point);
    }
}

#[test]
fn a_kill_after_the_move_to_failed_leaves_one_copy_and_its_log() {
    let f = Folders::new();
    let bad = "v 0 0 0\nf 1 2 3\n";
    let mut d = Daemon::ready(&f, &[], &[("HOLEFILL_TEST_DIE_AT", "failed-moved")]);
    drop_renamed(&f.inbox, "bad.obj", bad);
    assert!(d.wait_exit(LONG).is_some(), "{}", d.log());
    let d2 = Daemon::ready(&f, &[], &[]);
    assert!(
        wait_until(LONG, || f.failed.join("bad.obj.repair.json").is_file()),
        "{}",
        d2.log()
    );
    std::thread::sleep(Duration::from_secs(1));
    assert_eq!(
        Folders::files(&f.failed),
        vec!["bad.obj", "bad.obj.repair.json"]
    );
    assert_eq!(fs::read_to_string(f.failed.join("bad.obj")).unwrap(), bad);
    assert_eq!(Folders::log(&f.failed, "bad.obj")["stage"], "input");
    assert!(f.processing().is_empty());
}

#[test]
fn an_outbox_removed_during_a_repair_loses_nothing() {
    let f = Folders::new();
    let mut d = Daemon::ready(&f, &[], &[("HOLEFILL_TEST_SLOW", ":2000")]);
    let (obj, _) = mesh();
    drop_renamed(&f.inbox, "mid.obj", &obj);
    assert!(
        wait_until(LONG, || f.processing() == vec!["mid.obj"]),
        "{}",
        d.log()
    );
    fs::remove_dir_all(&f.outbox).unwrap();
    assert!(
        wait_until(LONG, || f.outbox.join("mid.obj.repair.json").is_file()),
        "{}",
        d.log()
    );
    assert_eq!(fs::read_to_string(f.archive.join("mid.obj")).unwrap(), obj);
    assert!(Folders::files(&f.failed).is_empty(), "{}", d.log());
    d.signal("TERM");
    assert_eq!(d.wait_exit(LONG).and_then(|s| s.code()), Some(0));
}

#[test]
fn a_crashing_file_still_fails_after_max_attempts_across_restarts() {
    let f = Folders::new();
    let (obj, _) = mesh();
    drop_renamed(&f.inbox, "poison.obj", &obj);
    let args = ["--max-attempts", "3"];
    let hook = [("HOLEFILL_TEST_CRASH_ON", "poison")];
    for round in 1..=3 {
        let mut d = Daemon::ready(&f, &args, &hook);
        // the first crash of this run, then a stop before the retry
        assert!(
            wait_until(LONG, || d.log().contains(" of 3 failed")
                || f.failed.join("poison.obj.repair.json").is_file()),
            "round {round}\n{}",
            d.log()
        );
        if f.failed.join("poison.obj.repair.json").is_file() {
            assert_eq!(round, 3, "{}", d.log());
            break;
        }
        assert!(
            d.log().contains(&format!("attempt {round} of 3 failed")),
            "round {round}: the count goes on across restarts\n{}",
            d.log()
        );
        // the service is stopped (as systemd does on the worker's OOM kill)
        d.signal("TERM");
        assert_eq!(d.wait_exit(LONG).and_then(|s| s.code()), Some(0));
        assert_eq!(
            Folders::files(&f.inbox),
            vec!["poison.obj"],
            "put back\n{}",
            d.log()
        );
    }
    let d = Daemon::ready(&f, &args, &hook);
    assert!(
        wait_until(LONG, || f.failed.join("poison.obj.repair.json").is_file()),
        "{}",
        d.log()
    );
    let log = Folders::log(&f.failed, "poison.obj");
    assert_eq!(log["stage"], "worker");
    assert_eq!(log["daemon"]["attempt"], 3, "{log}");
    assert_eq!(
        fs::read_to_string(f.failed.join("poison.obj")).unwrap(),
        obj
    );
}

/// The pid of the daemon started through a wrapper (`unshare`, `strace`).
fn inner(d: &Daemon) -> u32 {
    let mut pid = d.pid();
    for _ in 0..4 {
        match children_of(pid).first() {
            Some(&c) => {
                let exe = fs::read_link(format!("/proc/{c}/exe")).unwrap_or_default();
                if exe.ends_with("holefill") {
                    return c;
                }
                pid = c;
            }
            None => break,
        }
    }
    panic!("no daemon under {}", d.pid());
}

#[test]
#[ignore = "needs root"]
fn two_daemons_in_separate_pid_namespaces_repair_each_file_once() {
    let f = Folders::new();
    let ns = ["unshare", "--pid", "--fork", "--mount-proc", "--kill-child"];
    let slow = [("HOLEFILL_TEST_SLOW", ":1500")];
    let a = Daemon::ready_under(&f, &ns, &[], &slow);
    let (obj, _) = mesh();
    for i in 0..6 {
        drop_renamed(&f.inbox, &format!("p{i}.obj"), &obj);
    }
    assert!(
        wait_until(LONG, || f.processing().len() == 2),
        "{}",
        a.log()
    );
    // the second daemon starts while the first is working: same host name, and both
    // are pid 1 in their namespaces
    let b = Daemon::ready_under(&f, &ns, &[], &slow);
    assert!(
        wait_until(LONG, || f.models().len() == 6 && f.processing().is_empty()),
        "{}\n{}",
        a.log(),
        b.log()
    );
    let want: Vec<String> = (0..6).map(|i| format!("p{i}.obj")).collect();
    assert_eq!(f.models(), want, "each once\n{}\n{}", a.log(), b.log());
    for l in [a.log(), b.log()] {
        assert!(
            !l.contains("recovered"),
            "a live daemon's files taken:\n{l}"
        );
    }
    // a daemon killed mid-repair: the other one takes its files over
    for i in 6..10 {
        drop_renamed(&f.inbox, &format!("p{i}.obj"), &obj);
    }
    assert!(wait_until(LONG, || !f.processing().is_empty()));
    let pa = inner(&a);
    assert!(kill(pa, "KILL"));
    assert!(
        wait_until(LONG, || f.models().len() == 10 && f.processing().is_empty()),
        "{}\n{}",
        a.log(),
        b.log()
    );
    let want: Vec<String> = (0..10).map(|i| format!("p{i}.obj")).collect();
    std::thread::sleep(Duration::from_secs(2));
    assert_eq!(f.models(), want, "each once\n{}\n{}", a.log(), b.log());
}

#[test]
#[ignore = "needs root"]
fn across_file_systems_the_archive_is_synced_before_the_original_is_removed() {
    let f = Folders::new();
    fs::create_dir_all(&f.archive).unwrap();
    let _m = Mount::new(&["-t", "tmpfs", "holefill-test"], &f.archive).expect("tmpfs (root)");
    let trace = f.root().join("trace.txt");
    let strace = [
        "strace",
        "-f",
        "-y",
        "-e",
        "trace=fsync,unlink,unlinkat,rename,renameat,renameat2,link,linkat",
        "-o",
        trace.to_str().unwrap(),
        "--",
    ];
    let d = Daemon::ready_under(&f, &strace, &[], &[]);
    let (obj, _) = mesh();
    drop_renamed(&f.inbox, "x.obj", &obj);
    assert!(
        wait_until(LONG, || f.outbox.join("x.obj.repair.json").is_file()),
        "{}",
        d.log()
    );
    assert!(kill(inner(&d), "TERM"));
    std::thread::sleep(Duration::from_secs(1));
    let t = fs::read_to_string(&trace).unwrap();
    let archive = f.archive.to_str().unwrap().to_string();
    let lines: Vec<&str> = t.lines().collect();
    // the copy arrives at its name in the archive
    let at = lines
        .iter()
        .position(|l| {
            (l.contains("rename") || l.contains("link"))
                && l.contains(&format!("{archive}/x.obj\""))
        })
        .unwrap_or_else(|| panic!("no rename into the archive:\n{t}"));
    // then the original is removed from the processing folder
    let rm = lines
        .iter()
        .enumerate()
        .skip(at)
        .find(|(_, l)| l.contains("unlink") && l.contains(".processing/"))
        .map(|(i, _)| i)
        .unwrap_or_else(|| panic!("no removal of the original:\n{t}"));
    // and between the two, the archive folder itself is fsynced
    let synced = lines[at..rm]
        .iter()
        .any(|l| l.contains("fsync(") && l.contains(&format!("<{archive}>")));
    assert!(
        synced,
        "the archive is not fsynced before the original is removed:\n{}",
        lines[at..=rm].join("\n")
    );
}

#[test]
#[ignore = "needs root"]
fn a_producer_of_another_user_never_has_a_file_overwritten() {
    // the daemon runs as `nobody`, the producer as uid 4242: link(2) of the producer's
    // file by the daemon is refused under fs.protected_hardlinks
    let st = Command::new("sysctl")
        .args(["-w", "fs.protected_hardlinks=1"])
        .status()
        .unwrap();
    assert!(st.success());
    let f = Folders::new();
    for d in [&f.outbox, &f.failed, &f.archive] {
        fs::create_dir_all(d).unwrap();
    }
    let chown = |p: &std::path::Path, who: &str| {
        assert!(Command::new("chown")
            .arg(who)
            .arg(p)
            .status()
            .unwrap()
            .success());
    };
    use std::os::unix::fs::PermissionsExt;
    fs::set_permissions(f.root(), fs::Permissions::from_mode(0o755)).unwrap();
    for d in [&f.inbox, &f.outbox, &f.failed, &f.archive] {
        chown(d, "65534:65534");
    }
    fs::set_permissions(&f.inbox, fs::Permissions::from_mode(0o1777)).unwrap();
    let drop_as_producer = |name: &str, text: &str| {
        let tmp = f.inbox.join(format!(".{name}.part"));
        fs::write(&tmp, text).unwrap();
        chown(&tmp, "4242:4242");
        fs::rename(&tmp, f.inbox.join(name)).unwrap();
    };
    let nobody = [
        "setpriv",
        "--reuid=65534",
        "--regid=65534",
        "--clear-groups",
    ];
    let mut d = Daemon::ready_under(
        &f,
        &nobody,
        &["--grace-secs", "0"],
        &[
            ("HOLEFILL_TEST_SLOW", ":30000"),
            ("HOLEFILL_TEST_PAUSE_AT", "move:3000"),
        ],
    );
    let (obj, _) = mesh();
    drop_as_producer("x.obj", &obj);
    assert!(
        wait_until(LONG, || f.processing() == vec!["x.obj"]),
        "{}",
        d.log()
    );
    // stop: the running repair is cut and its file goes back into the inbox; while the
    // daemon is about to move it, the producer drops a new x.obj
    d.signal("TERM");
    assert!(
        wait_until(LONG, || d.log().contains("pausing")),
        "{}",
        d.log()
    );
    drop_as_producer("x.obj", "the producer's new file");
    assert_eq!(
        d.wait_exit(LONG).and_then(|s| s.code()),
        Some(0),
        "{}",
        d.log()
    );
    let files = Folders::files(&f.inbox);
    assert_eq!(files.len(), 2, "{files:?}\n{}", d.log());
    assert_eq!(
        fs::read_to_string(f.inbox.join("x.obj")).unwrap(),
        "the producer's new file",
        "never overwritten"
    );
    let other = files.iter().find(|n| *n != "x.obj").unwrap();
    assert_eq!(fs::read_to_string(f.inbox.join(other)).unwrap(), obj);
}
