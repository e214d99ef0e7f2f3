//! Isolation and recovery: a daemon killed with SIGKILL mid-repair, a file that kills
//! its worker every time, a file that hangs its worker past the time limit.

mod common;
mod daemon_support;
use daemon_support::*;
use std::fs;
use std::time::Duration;

const LONG: Duration = Duration::from_secs(30);

#[test]
fn kill9_during_processing_then_restart_repairs_the_file_once() {
    let f = Folders::new();
    // every repair takes 3 s more (test hook), so the kill lands mid-repair
    let mut d = Daemon::ready(&f, &[], &[("HOLEFILL_TEST_SLOW", ":3000")]);
    let (obj, _) = mesh();
    drop_renamed(&f.inbox, "k.obj", &obj);
    assert!(
        wait_until(LONG, || f.processing() == vec!["k.obj"]),
        "claimed\n{}",
        d.log()
    );
    std::thread::sleep(Duration::from_millis(300));
    d.kill9();
    assert_eq!(f.processing(), vec!["k.obj"], "in flight when killed");
    assert!(f.models().is_empty());

    let d2 = Daemon::ready(&f, &[], &[]);
    assert!(
        wait_until(LONG, || f.outbox.join("k.obj.repair.json").is_file()),
        "{}",
        d2.log()
    );
    // the orphaned worker of the dead daemon had 3 s to go: give it the time to (fail to) write
    std::thread::sleep(Duration::from_secs(4));
    assert_eq!(f.models(), vec!["k.obj"], "repaired once");
    assert!(
        wait_files(
            &f.outbox,
            &["k.obj", "k.obj.repair.json", "k.obj.repair.png"]
        ),
        "{:?}",
        Folders::files(&f.outbox)
    );
    let log = Folders::log(&f.outbox, "k.obj");
    assert_eq!(log["status"], "repaired");
    assert_eq!(
        log["daemon"]["attempt"], 2,
        "the attempt that died counts: {log}"
    );
    assert_eq!(log["daemon"]["pid"].as_u64(), Some(d2.pid() as u64));
    assert_eq!(Folders::files(&f.archive), vec!["k.obj"]);
    assert!(f.processing().is_empty());
    assert!(Folders::files(&f.inbox).is_empty());
    assert!(d2.log().contains("recovered"), "{}", d2.log());
    // the dead daemon's folders are gone
    let left: Vec<_> = fs::read_dir(f.inbox.join(".processing"))
        .unwrap()
        .flatten()
        .map(|e| e.file_name())
        .collect();
    assert_eq!(left.len(), 1, "only the live daemon's folder: {left:?}");
}

#[test]
fn a_file_that_kills_its_worker_every_time_fails_after_max_attempts() {
    let f = Folders::new();
    // test hook: the worker of any file named *poison* kills itself with SIGKILL
    let mut d = Daemon::ready(
        &f,
        &["--max-attempts", "3", "--workers", "1"],
        &[("HOLEFILL_TEST_CRASH_ON", "poison")],
    );
    let (obj, _) = mesh();
    drop_renamed(&f.inbox, "poison.obj", &obj);
    assert!(
        wait_until(LONG, || f.failed.join("poison.obj.repair.json").is_file()),
        "{}",
        d.log()
    );
    drop_renamed(&f.inbox, "next.obj", &obj);
    assert!(
        wait_until(LONG, || f.outbox.join("next.obj.repair.json").is_file()),
        "{}",
        d.log()
    );
    assert!(d.alive());
    let log = Folders::log(&f.failed, "poison.obj");
    assert_eq!(log["status"], "failed");
    assert_eq!(log["stage"], "worker");
    assert_eq!(log["daemon"]["attempt"], 3);
    assert!(log["error"].as_str().unwrap().contains("signal 9"), "{log}");
    assert_eq!(
        fs::read_to_string(f.failed.join("poison.obj")).unwrap(),
        obj,
        "untouched"
    );
    assert_eq!(
        d.log().matches("poison.obj: attempt").count(),
        2,
        "{}",
        d.log()
    );
    assert_eq!(f.models(), vec!["next.obj"]);
}

#[test]
fn a_file_that_hangs_its_worker_is_killed_at_the_time_limit() {
    let f = Folders::new();
    // test hook: the worker of *hang* files sleeps 60 s; the real time limit (1 s) kills it
    let mut d = Daemon::ready(
        &f,
        &["--max-attempts", "2", "--time-limit-secs", "1"],
        &[("HOLEFILL_TEST_SLOW", "hang:60000")],
    );
    let (obj, _) = mesh();
    drop_renamed(&f.inbox, "hang.obj", &obj);
    drop_renamed(&f.inbox, "fine.obj", &obj);
    assert!(
        wait_until(LONG, || f.failed.join("hang.obj.repair.json").is_file()),
        "{}",
        d.log()
    );
    assert!(
        wait_until(LONG, || f.outbox.join("fine.obj.repair.json").is_file()),
        "{}",
        d.log()
    );
    assert!(d.alive());
    let log = Folders::log(&f.failed, "hang.obj");
    assert_eq!(log["stage"], "worker");
    assert_eq!(log["daemon"]["attempt"], 2);
    assert!(
        log["error"].as_str().unwrap().contains("time limit"),
        "{log}"
    );
    // the killed worker and its sleeping child are gone
    let ps = std::process::Command::new("pgrep")
        .args(["-f", "sleep 60.000"])
        .output();
    if let Ok(o) = ps {
        assert!(
            o.stdout.is_empty(),
            "the worker's process group was killed: {}",
            String::from_utf8_lossy(&o.stdout)
        );
    }
}

#[test]
fn the_memory_limit_kills_a_runaway_worker_not_the_daemon() {
    let f = Folders::new();
    // a small mesh repairs in well under 24 MiB of address space; a 330k-face one needs
    // several times 48 MiB
    let mut d = Daemon::ready(&f, &["--memory-limit-mb", "48", "--max-attempts", "1"], &[]);
    let (big, faces) = holed_sphere_obj(7, 0.05);
    assert!(faces > 300_000);
    drop_renamed(&f.inbox, "huge.obj", &big);
    let (obj, _) = mesh();
    drop_renamed(&f.inbox, "small.obj", &obj);
    assert!(
        wait_until(LONG, || f.failed.join("huge.obj.repair.json").is_file()),
        "{}",
        d.log()
    );
    assert!(
        wait_until(LONG, || f.outbox.join("small.obj.repair.json").is_file()),
        "{}",
        d.log()
    );
    assert!(d.alive());
    let log = Folders::log(&f.failed, "huge.obj");
    assert_eq!(log["stage"], "worker", "{log}");
    assert!(log["error"].as_str().unwrap().contains("memory"), "{log}");
    assert_eq!(
        fs::read_to_string(f.failed.join("huge.obj")).unwrap(),
        big,
        "untouched"
    );
}

#[test]
fn a_file_whose_daemon_dies_every_time_goes_to_failed_after_max_attempts() {
    let f = Folders::new();
    let (obj, _) = mesh();
    drop_renamed(&f.inbox, "deadly.obj", &obj);
    for round in 1..=2 {
        let mut d = Daemon::ready(
            &f,
            &["--max-attempts", "2"],
            &[("HOLEFILL_TEST_SLOW", ":5000")],
        );
        assert!(
            wait_until(LONG, || f.processing() == vec!["deadly.obj"]),
            "round {round}: claimed\n{}",
            d.log()
        );
        std::thread::sleep(Duration::from_millis(200));
        d.kill9();
    }
    let d = Daemon::ready(&f, &["--max-attempts", "2"], &[]);
    assert!(
        wait_until(LONG, || f.failed.join("deadly.obj.repair.json").is_file()),
        "{}",
        d.log()
    );
    let log = Folders::log(&f.failed, "deadly.obj");
    assert_eq!(log["status"], "failed");
    assert_eq!(log["stage"], "worker");
    assert_eq!(log["daemon"]["attempt"], 2, "{log}");
    assert!(
        log["error"].as_str().unwrap().contains("none finished"),
        "{log}"
    );
    assert_eq!(
        fs::read_to_string(f.failed.join("deadly.obj")).unwrap(),
        obj,
        "untouched"
    );
    assert!(f.models().is_empty());
    assert!(f.processing().is_empty());
}

/// A daemon killed at `point` of publishing `x.obj`; then a new daemon.
fn killed_while_publishing(f: &Folders, obj: &str, point: &str) -> Daemon {
    let mut d = Daemon::ready(f, &[], &[("HOLEFILL_TEST_DIE_AT", point)]);
    drop_renamed(&f.inbox, "x.obj", obj);
    assert!(d.wait_exit(LONG).is_some(), "{}", d.log());
    Daemon::ready(f, &[], &[])
}

#[test]
fn a_daemon_killed_after_publishing_is_not_repaired_twice() {
    let f = Folders::new();
    let (obj, _) = mesh();
    // the model is in the outbox, the original not yet archived, the log not written
    let d = killed_while_publishing(&f, &obj, "model-published");
    assert!(
        wait_until(LONG, || f.outbox.join("x.obj.repair.json").is_file()),
        "{}",
        d.log()
    );
    assert!(
        published_once(&f.outbox, "x.obj"),
        "no second repair: {:?}\n{}",
        Folders::files(&f.outbox),
        d.log()
    );
    assert_eq!(Folders::files(&f.archive), vec!["x.obj"]);
    assert_eq!(fs::read_to_string(f.archive.join("x.obj")).unwrap(), obj);
    assert!(f.processing().is_empty());
    assert!(d.log().contains("not repaired again"), "{}", d.log());
}

#[test]
fn a_daemon_killed_between_archive_and_log_finishes_cleanly() {
    let f = Folders::new();
    let (obj, _) = mesh();
    // model out, original archived, the log not yet published
    let d = killed_while_publishing(&f, &obj, "archived");
    assert!(
        wait_until(LONG, || f.outbox.join("x.obj.repair.json").is_file()),
        "{}",
        d.log()
    );
    assert!(
        published_once(&f.outbox, "x.obj"),
        "{:?}\n{}",
        Folders::files(&f.outbox),
        d.log()
    );
    let log = Folders::log(&f.outbox, "x.obj");
    assert_eq!(log["status"], "repaired");
    assert_eq!(log["daemon"]["attempt"], 1);
    assert_eq!(Folders::files(&f.archive), vec!["x.obj"]);
    assert!(f.processing().is_empty());
}
