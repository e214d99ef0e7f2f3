//! The daemon's own memory stays bounded whatever lands in the inbox: a flood of names
//! that come and go while every worker is busy, a file of one endless line under
//! `max_faces`. (Test hooks: the busy workers.)

mod common;
mod daemon_support;
use daemon_support::*;
use std::fs;
use std::time::Duration;

const LONG: Duration = Duration::from_secs(120);

#[test]
fn a_flood_of_names_that_come_and_go_costs_no_memory() {
    let f = Folders::new();
    let d = Daemon::ready(
        &f,
        &["--settle-ms", "60000"],
        &[("HOLEFILL_TEST_SLOW", "busy:15000")],
    );
    // both workers busy: the daemon takes nothing from the list meanwhile
    let (obj, _) = mesh();
    drop_renamed(&f.inbox, "busy1.obj", &obj);
    drop_renamed(&f.inbox, "busy2.obj", &obj);
    assert!(
        wait_until(LONG, || f.processing().len() == 2),
        "{}",
        d.log()
    );
    std::thread::sleep(Duration::from_millis(500));
    let before = vmhwm_kib(d.pid());
    // 100,000 names of 200 bytes, each created and removed, in batches the daemon
    // keeps up with (no event is lost, so each is noted)
    let stem = "n".repeat(190);
    for batch in 0..100 {
        for i in 0..1000 {
            let p = f.inbox.join(format!("{stem}{batch:03}{i:03}.obj"));
            fs::write(&p, "").unwrap();
            fs::remove_file(&p).unwrap();
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(Duration::from_secs(2));
    let after = vmhwm_kib(d.pid());
    eprintln!("daemon peak RSS {before} KiB before, {after} KiB after the flood");
    assert!(
        after < before + 8 * 1024,
        "grew by {} KiB\n{}",
        after - before,
        d.log()
    );
    // and it still works
    drop_renamed(&f.inbox, "after.obj", &obj);
    assert!(
        wait_until(LONG, || f.outbox.join("after.obj.repair.json").is_file()),
        "{}",
        d.log()
    );
}

#[test]
fn a_file_of_one_endless_line_costs_the_daemon_no_memory() {
    let f = Folders::new();
    let d = Daemon::ready(
        &f,
        &["--max-faces", "1000", "--memory-limit-mb", "512"],
        &[],
    );
    // 1 GiB with no line break (sparse: nothing written to disk)
    let tmp = f.inbox.join(".big.obj.part");
    fs::File::create(&tmp).unwrap().set_len(1 << 30).unwrap();
    fs::rename(&tmp, f.inbox.join("big.obj")).unwrap();
    assert!(
        wait_until(LONG, || f.failed.join("big.obj.repair.json").is_file()),
        "{}",
        d.log()
    );
    let peak = vmhwm_kib(d.pid());
    eprintln!("daemon peak RSS {peak} KiB");
    assert!(
        peak < 64 * 1024,
        "the daemon peaked at {peak} KiB\n{}",
        d.log()
    );
}
