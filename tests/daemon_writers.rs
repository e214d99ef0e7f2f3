//! Producers that write in place: a writer that holds the file open and pauses, a file
//! created empty and written later, an empty file that stays empty. A file is taken
//! only once nobody holds it open and it stopped changing; an empty one waits (up to
//! `max_wait_secs`).

mod common;
mod daemon_support;
use daemon_support::*;
use std::fs;
use std::io::Write;
use std::time::Duration;

const LONG: Duration = Duration::from_secs(60);

#[test]
fn a_writer_that_holds_the_file_open_and_pauses_10_s_is_waited_for() {
    let f = Folders::new();
    let mut d = Daemon::ready(&f, &[], &[]);
    let (obj, _) = mesh();
    let path = f.inbox.join("paused.obj");
    let mut w = fs::File::create(&path).unwrap();
    // nothing written for 10 s (30 settle times), the file held open
    std::thread::sleep(Duration::from_secs(10));
    assert_eq!(Folders::files(&f.inbox), vec!["paused.obj"], "{}", d.log());
    assert!(Folders::files(&f.failed).is_empty(), "{}", d.log());
    let half = obj.len() / 2;
    w.write_all(&obj.as_bytes()[..half]).unwrap();
    w.flush().unwrap();
    // half written, then another pause, still open
    std::thread::sleep(Duration::from_secs(3));
    assert_eq!(Folders::files(&f.inbox), vec!["paused.obj"], "{}", d.log());
    w.write_all(&obj.as_bytes()[half..]).unwrap();
    drop(w);
    // the log is published last (after the archive)
    assert!(
        wait_until(LONG, || f.outbox.join("paused.obj.repair.json").is_file()),
        "{}",
        d.log()
    );
    assert_eq!(
        fs::read_to_string(f.archive.join("paused.obj")).unwrap(),
        obj
    );
    assert_eq!(Folders::log(&f.outbox, "paused.obj")["status"], "repaired");
    assert!(Folders::files(&f.failed).is_empty());
    d.signal("TERM");
    assert_eq!(d.wait_exit(LONG).and_then(|s| s.code()), Some(0));
}

#[test]
fn a_file_created_empty_and_written_later_is_repaired() {
    let f = Folders::new();
    let mut d = Daemon::ready(&f, &[], &[]);
    let (obj, _) = mesh();
    let path = f.inbox.join("later.obj");
    drop(fs::File::create(&path).unwrap()); // created, closed, empty
    std::thread::sleep(Duration::from_secs(3));
    assert_eq!(Folders::files(&f.inbox), vec!["later.obj"], "{}", d.log());
    let mut w = fs::OpenOptions::new().append(true).open(&path).unwrap();
    w.write_all(obj.as_bytes()).unwrap();
    drop(w);
    assert!(
        wait_until(LONG, || f.archive.join("later.obj").is_file()),
        "{}",
        d.log()
    );
    assert_eq!(
        fs::read_to_string(f.archive.join("later.obj")).unwrap(),
        obj
    );
    assert!(Folders::files(&f.failed).is_empty(), "{}", d.log());
    d.signal("TERM");
    assert_eq!(d.wait_exit(LONG).and_then(|s| s.code()), Some(0));
}

#[test]
fn an_empty_file_fails_as_empty_after_max_wait() {
    let f = Folders::new();
    let mut d = Daemon::ready(&f, &["--max-wait-secs", "4"], &[]);
    drop_renamed(&f.inbox, "empty.obj", "");
    std::thread::sleep(Duration::from_secs(2));
    assert_eq!(Folders::files(&f.inbox), vec!["empty.obj"], "{}", d.log());
    assert!(
        wait_until(LONG, || f.failed.join("empty.obj.repair.json").is_file()),
        "{}",
        d.log()
    );
    let log = Folders::log(&f.failed, "empty.obj");
    assert_eq!(log["stage"], "input");
    assert!(
        log["error"].as_str().unwrap().contains("max_wait_secs = 4"),
        "{log}"
    );
    d.signal("TERM");
    assert_eq!(d.wait_exit(LONG).and_then(|s| s.code()), Some(0));
}
