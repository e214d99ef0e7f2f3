//! SIGTERM during a long repair: exit 0 within the grace period, the file repaired or
//! back in the inbox, never lost.

mod common;
mod daemon_support;
use daemon_support::*;
use std::time::{Duration, Instant};

const LONG: Duration = Duration::from_secs(30);

#[test]
fn sigterm_lets_a_long_repair_finish_within_the_grace_period() {
    let f = Folders::new();
    let mut d = Daemon::ready(
        &f,
        &["--grace-secs", "20"],
        &[("HOLEFILL_TEST_SLOW", ":3000")],
    );
    let (obj, _) = mesh();
    drop_renamed(&f.inbox, "long.obj", &obj);
    assert!(
        wait_until(LONG, || f.processing() == vec!["long.obj"]),
        "{}",
        d.log()
    );
    let t = Instant::now();
    d.signal("TERM");
    let st = d
        .wait_exit(Duration::from_secs(25))
        .expect("exit within the grace period");
    assert_eq!(st.code(), Some(0), "{}", d.log());
    assert!(t.elapsed() < Duration::from_secs(20));
    assert_eq!(
        f.models(),
        vec!["long.obj"],
        "finished, not abandoned\n{}",
        d.log()
    );
    assert!(f.outbox.join("long.obj.repair.json").is_file());
    assert!(f.processing().is_empty());
}

#[test]
fn sigterm_past_the_grace_period_puts_the_file_back() {
    let f = Folders::new();
    let mut d = Daemon::ready(
        &f,
        &["--grace-secs", "1"],
        &[("HOLEFILL_TEST_SLOW", ":20000")],
    );
    let (obj, _) = mesh();
    drop_renamed(&f.inbox, "long.obj", &obj);
    drop_renamed(&f.inbox, "long2.obj", &obj);
    drop_renamed(&f.inbox, "waiting.obj", &obj);
    assert!(
        wait_until(LONG, || f.processing().len() == 2),
        "{}",
        d.log()
    );
    let t = Instant::now();
    d.signal("TERM");
    let st = d
        .wait_exit(Duration::from_secs(15))
        .expect("exit soon after the grace period");
    assert_eq!(st.code(), Some(0), "{}", d.log());
    assert!(t.elapsed() < Duration::from_secs(10), "{:?}", t.elapsed());
    // never lost: every file back in the inbox, untouched
    assert_eq!(
        Folders::files(&f.inbox),
        vec!["long.obj", "long2.obj", "waiting.obj"],
        "{}",
        d.log()
    );
    for n in ["long.obj", "long2.obj", "waiting.obj"] {
        assert_eq!(std::fs::read_to_string(f.inbox.join(n)).unwrap(), obj);
    }
    assert!(f.models().is_empty());
    assert!(f.processing().is_empty());
    assert!(Folders::files(&f.failed).is_empty());

    // and a new daemon repairs them
    let d2 = Daemon::ready(&f, &[], &[]);
    assert!(wait_until(LONG, || f.models().len() == 3), "{}", d2.log());
}

#[test]
fn sigint_also_stops_cleanly() {
    let f = Folders::new();
    let mut d = Daemon::ready(&f, &[], &[]);
    std::thread::sleep(Duration::from_millis(500));
    d.signal("INT");
    assert_eq!(
        d.wait_exit(LONG).and_then(|s| s.code()),
        Some(0),
        "{}",
        d.log()
    );
}
