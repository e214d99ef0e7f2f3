//! Bursts: 200 files with two daemons on one inbox (each repaired exactly once), and 50
//! files waiting before start (READY=1 only after the start-up scan).

mod common;
mod daemon_support;
use daemon_support::*;
use std::collections::HashMap;
use std::os::unix::net::UnixDatagram;
use std::time::{Duration, Instant};

#[test]
fn two_daemons_200_files_each_repaired_exactly_once() {
    let f = Folders::new();
    let a = Daemon::ready(&f, &[], &[]);
    let b = Daemon::ready(&f, &[], &[]);
    std::thread::sleep(Duration::from_millis(300));
    let (obj, _) = holed_sphere_obj(1, 0.3);
    let n = 200;
    // written as dot-files first, then all renamed in at once
    for i in 0..n {
        std::fs::write(f.inbox.join(format!(".s{i:03}.part")), &obj).unwrap();
    }
    for i in 0..n {
        std::fs::rename(
            f.inbox.join(format!(".s{i:03}.part")),
            f.inbox.join(format!("s{i:03}.obj")),
        )
        .unwrap();
    }
    assert!(
        wait_until(Duration::from_secs(50), || Folders::files(&f.archive).len()
            == n),
        "archive {} outbox {} failed {:?}\n{}\n{}",
        Folders::files(&f.archive).len(),
        f.models().len(),
        Folders::files(&f.failed),
        a.log(),
        b.log()
    );
    // give a duplicate (if any) the time to show up
    std::thread::sleep(Duration::from_millis(500));
    let models = f.models();
    let expected: Vec<String> = (0..n).map(|i| format!("s{i:03}.obj")).collect();
    assert_eq!(
        models, expected,
        "each exactly once (a second repair would be time-stamped)"
    );
    assert!(
        wait_until(Duration::from_secs(30), || Folders::files(&f.outbox).len()
            == 3 * n),
        "a log and a picture beside each model: {} files",
        Folders::files(&f.outbox).len()
    );
    assert!(Folders::files(&f.failed).is_empty());
    assert!(Folders::files(&f.inbox).is_empty());
    assert!(f.processing().is_empty());
    let mut by: HashMap<u64, usize> = HashMap::new();
    for m in &models {
        let log = Folders::log(&f.outbox, m);
        assert_eq!(log["status"], "repaired");
        assert_eq!(log["daemon"]["attempt"], 1);
        *by.entry(log["daemon"]["pid"].as_u64().unwrap())
            .or_default() += 1;
    }
    assert!(by
        .keys()
        .all(|p| *p == a.pid() as u64 || *p == b.pid() as u64));
    eprintln!("files per daemon: {by:?}");
    // the journals agree: 200 "repaired" lines in all
    let lines =
        || a.log().matches(" repaired -> ").count() + b.log().matches(" repaired -> ").count();
    assert!(wait_until(Duration::from_secs(10), || lines() >= n));
    assert_eq!(lines(), n);
}

#[test]
fn fifty_waiting_files_ready_only_after_the_scan() {
    let f = Folders::new();
    let (obj, _) = holed_sphere_obj(1, 0.3);
    for i in 0..50 {
        drop_renamed(&f.inbox, &format!("w{i:02}.obj"), &obj);
    }
    // a notify socket standing in for systemd
    let sock_path = f.root().join("notify.sock");
    let sock = UnixDatagram::bind(&sock_path).unwrap();
    sock.set_read_timeout(Some(Duration::from_millis(200)))
        .unwrap();
    let mut d = Daemon::start(&f, &[], &[("NOTIFY_SOCKET", sock_path.to_str().unwrap())]);
    let t = Instant::now();
    let mut msgs: Vec<String> = Vec::new();
    let mut buf = [0u8; 4096];
    let mut ready_status = None;
    while t.elapsed() < Duration::from_secs(50) {
        if let Ok(n) = sock.recv(&mut buf) {
            let m = String::from_utf8_lossy(&buf[..n]).to_string();
            if ready_status.is_none() && m.lines().any(|l| l == "READY=1") {
                ready_status = Some(m.clone());
            }
            msgs.push(m);
        }
        if Folders::files(&f.archive).len() == 50 && msgs.iter().any(|m| m.contains("repaired 50"))
        {
            break;
        }
    }
    let ready = ready_status.unwrap_or_else(|| panic!("no READY=1: {msgs:?}\n{}", d.log()));
    // the STATUS sent with READY=1 already counts every file of the scan
    let status = ready
        .lines()
        .find_map(|l| l.strip_prefix("STATUS="))
        .expect("STATUS with READY");
    let count = |label: &str| -> u64 {
        status
            .split(',')
            .find_map(|p| p.trim().strip_prefix(label)?.trim().parse().ok())
            .unwrap_or_else(|| panic!("no {label} in {status}"))
    };
    // (pictures being drawn are of files already repaired)
    assert_eq!(
        count("waiting") + count("working") + count("repaired") + count("failed"),
        50,
        "READY=1 only after the scan saw all 50: {status}"
    );
    assert_eq!(
        Folders::files(&f.archive).len(),
        50,
        "{msgs:?}\n{}",
        d.log()
    );
    assert_eq!(f.models().len(), 50);
    assert!(
        msgs.iter()
            .any(|m| m.contains("STATUS=waiting 0, working 0, ")
                && m.contains(", repaired 50, failed 0")),
        "{msgs:?}"
    );
    d.signal("TERM");
    assert_eq!(
        d.wait_exit(Duration::from_secs(20)).and_then(|s| s.code()),
        Some(0)
    );
    let mut rest = Vec::new();
    while let Ok(n) = sock.recv(&mut buf) {
        rest.push(String::from_utf8_lossy(&buf[..n]).to_string());
    }
    assert!(
        rest.iter()
            .any(|m| m.contains("STOPPING=1") && m.contains("EXTEND_TIMEOUT_USEC=")),
        "{rest:?}"
    );
}

#[test]
fn watchdog_pings_arrive_while_idle_and_reload_is_announced() {
    let f = Folders::new();
    let sock_path = f.root().join("notify.sock");
    let sock = UnixDatagram::bind(&sock_path).unwrap();
    sock.set_read_timeout(Some(Duration::from_millis(100)))
        .unwrap();
    let err = f.root().join("daemon-wd.log");
    // WATCHDOG_PID must be the daemon's pid: the shell execs into it, keeping its pid
    let child = std::process::Command::new("/bin/sh")
        .arg("-c")
        .arg("WATCHDOG_PID=$$ WATCHDOG_USEC=400000 exec \"$0\" watch --inbox \"$1\"")
        .arg(bin())
        .arg(&f.inbox)
        .env("NOTIFY_SOCKET", &sock_path)
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::null())
        .stderr(std::fs::File::create(&err).unwrap())
        .spawn()
        .unwrap();
    let mut d = Daemon { child, stderr: err };
    let mut buf = [0u8; 4096];
    // counts the lines `what` until `enough` of them or `secs` seconds
    let mut recv_until = |what: &str, enough: usize, secs: u64| -> usize {
        let t = Instant::now();
        let mut n = 0;
        while t.elapsed() < Duration::from_secs(secs) && n < enough {
            if let Ok(k) = sock.recv(&mut buf) {
                n += String::from_utf8_lossy(&buf[..k])
                    .lines()
                    .filter(|l| *l == what)
                    .count();
            }
        }
        n
    };
    // READY first, then pings every 200 ms while nothing happens
    assert!(recv_until("READY=1", 1, 5) >= 1, "{}", d.log());
    let pings = recv_until("WATCHDOG=1", usize::MAX, 2);
    assert!(
        pings >= 4,
        "{pings} pings in 2 s (every 200 ms expected)\n{}",
        d.log()
    );
    d.signal("HUP");
    assert!(recv_until("RELOADING=1", 1, 5) >= 1, "{}", d.log());
    d.signal("TERM");
    assert_eq!(
        d.wait_exit(Duration::from_secs(20)).and_then(|s| s.code()),
        Some(0)
    );
}
