//! The inbox daemon as a gateway (`holefill watch --forward nats://...`): files
//! dropped into the inbox are repaired by two queue workers and come back into the
//! outbox (the originals archived), a malformed one into the failed folder with the
//! worker's log. Against a real nats-server; ignored where none is installed.

mod daemon_support;
mod metrics_support;
mod worker_support;
use daemon_support::{drop_renamed, Daemon, Folders};
use std::time::Duration;
use worker_support::{holed_obj, wait_until, Nats, Worker};

#[test]
#[cfg_attr(not(has_nats_server), ignore = "needs nats-server")]
fn files_dropped_into_the_inbox_come_back_through_two_workers() {
    let nats = Nats::start();
    let w1 = Worker::start(&nats, &["--ack-wait-secs", "10"], &[]);
    let w2 = Worker::start(&nats, &["--ack-wait-secs", "10"], &[]);
    let f = Folders::new();
    let d = Daemon::ready(&f, &["--forward", &nats.url(), "--workers", "8"], &[]);
    let n = 12;
    for i in 0..n {
        drop_renamed(&f.inbox, &format!("g{i:02}.obj"), &holed_obj(i));
    }
    drop_renamed(&f.inbox, "broken.obj", "v 0 0 0\nf 1 2 3\n");
    let dump = || format!("daemon:\n{}\nw1:\n{}\nw2:\n{}", d.log(), w1.log(), w2.log());
    assert!(
        wait_until(Duration::from_secs(90), || {
            Folders::files(&f.outbox)
                .iter()
                .filter(|n| n.ends_with(".repair.json"))
                .count()
                == n
                && Folders::files(&f.failed).len() == 2
        }),
        "outbox {:?} failed {:?}\n{}",
        Folders::files(&f.outbox),
        Folders::files(&f.failed),
        dump()
    );
    for i in 0..n {
        let name = format!("g{i:02}.obj");
        let log = Folders::log(&f.outbox, &name);
        assert_eq!(log["status"], "repaired", "{log}");
        assert!(log["summary"]["filled"].as_u64().unwrap() >= 1, "{log}");
        // repaired by a worker, published by the daemon
        assert!(log["worker"]["host"].is_string(), "{log}");
        assert_eq!(log["daemon"]["status"], "repaired", "{log}");
        let model = std::fs::read_to_string(f.outbox.join(&name)).unwrap();
        let faces = model.lines().filter(|l| l.starts_with("f ")).count();
        let before = holed_obj(i).lines().filter(|l| l.starts_with("f ")).count();
        assert!(faces > before, "{name}");
        // the original is archived untouched
        assert_eq!(
            std::fs::read_to_string(f.archive.join(&name)).unwrap(),
            holed_obj(i)
        );
    }
    let log = Folders::log(&f.failed, "broken.obj");
    assert_eq!(log["status"], "failed", "{log}");
    assert_eq!(log["stage"], "input", "{log}");
    assert!(f.failed.join("broken.obj").is_file());
    assert!(Folders::files(&f.inbox).is_empty());
    // both workers took part, each scan was repaired once
    let (a, b) = (w1.repaired(), w2.repaired());
    assert!(!a.is_empty() && !b.is_empty(), "{}", dump());
    assert_eq!(a.len() + b.len(), n, "{}", dump());
}
