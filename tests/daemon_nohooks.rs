//! A build without the `test-hooks` feature (what `cargo build --release` makes)
//! ignores the test hooks' variables: a file named to crash its worker is repaired, and
//! the journal says the variables are ignored. Run by `.ci/run` as
//! `cargo test --locked --test daemon_nohooks` (without the feature); built with the
//! feature, this file has no test.
#![cfg(not(feature = "test-hooks"))]

mod common;
mod daemon_support;
use daemon_support::*;
use std::time::Duration;

#[test]
fn a_build_without_the_feature_ignores_the_hooks() {
    let f = Folders::new();
    let mut d = Daemon::ready(
        &f,
        &[],
        &[
            ("HOLEFILL_TEST_CRASH_ON", "poison"),
            ("HOLEFILL_TEST_DIE_AT", "claimed"),
        ],
    );
    let (obj, _) = mesh();
    drop_renamed(&f.inbox, "poison.obj", &obj);
    assert!(
        wait_until(Duration::from_secs(60), || f
            .outbox
            .join("poison.obj.repair.json")
            .is_file()),
        "{}",
        d.log()
    );
    assert!(d.alive(), "{}", d.log());
    assert!(
        d.log().contains("ignored: this build has no test hooks"),
        "{}",
        d.log()
    );
    d.signal("TERM");
    assert_eq!(
        d.wait_exit(Duration::from_secs(30)).and_then(|s| s.code()),
        Some(0)
    );
}
