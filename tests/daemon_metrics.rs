//! The daemon's Prometheus endpoint, pictures and index on a real run: every counter
//! scraped from `/metrics` against what happened to the files (read from their logs),
//! a picture beside every repaired file's log, every file in `index.html`.

mod common;
mod daemon_support;
mod metrics_support;

use daemon_support::*;
use metrics_support::*;
use serde_json::Value;
use std::fs;
use std::time::{Duration, Instant};

const LONG: Duration = Duration::from_secs(90);

#[test]
fn every_counter_matches_a_run_of_20_files_with_2_failing() {
    let f = Folders::new();
    let port = free_port();
    let addr = format!("127.0.0.1:{port}");
    let start = now_secs();
    let mut d = Daemon::ready(
        &f,
        &["--metrics", &addr, "--max-attempts", "2"],
        &[
            ("HOLEFILL_TEST_CRASH_ON", "crash"),
            ("HOLEFILL_TEST_SLOW", "good-00:1500"),
        ],
    );
    let before = scrape(port);
    assert_eq!(
        sample(&before, "holefill_files_total{outcome=\"repaired\"}"),
        None
    );
    assert_eq!(must(&before, "holefill_attempts_total"), 0.0);
    assert!(before.contains("holefill_build_info{"), "{before}");

    let (obj, faces) = mesh();
    let mut bytes = 0u64;
    let mut names = Vec::new();
    for i in 0..18 {
        let name = format!("good-{i:02}.obj");
        drop_renamed(&f.inbox, &name, &obj);
        bytes += obj.len() as u64;
        names.push(name);
    }
    let bad = "v 0 0 0\nv 1 0 0\nf 1 2 9\n";
    drop_renamed(&f.inbox, "bad.obj", bad);
    drop_renamed(&f.inbox, "crash.obj", &obj);
    bytes += (bad.len() + obj.len()) as u64;

    // during the run: files in flight and waiting
    let mut seen_busy = false;
    let done = wait_until(LONG, || {
        let t = scrape(port);
        if must(&t, "holefill_files_in_flight") > 0.0 {
            seen_busy = true;
        }
        let n: f64 = family(&t, "holefill_files_total").values().sum();
        n >= 20.0
    });
    assert!(done, "{}", d.log());
    assert!(seen_busy, "a scrape during the run saw a file in flight");

    // the gauges are set once the daemon's loop has handled the last end
    let mut t = String::new();
    let settled = wait_until(Duration::from_secs(10), || {
        t = scrape(port);
        must(&t, "holefill_files_waiting") == 0.0 && must(&t, "holefill_files_in_flight") == 0.0
    });
    assert!(settled, "{t}");
    assert_eq!(
        must(&t, "holefill_files_total{outcome=\"repaired\"}"),
        18.0,
        "{t}"
    );
    assert_eq!(must(&t, "holefill_files_total{outcome=\"failed\"}"), 2.0);
    assert_eq!(
        must(&t, "holefill_file_failures_total{stage=\"input\"}"),
        1.0
    );
    assert_eq!(
        must(&t, "holefill_file_failures_total{stage=\"worker\"}"),
        1.0
    );
    assert_eq!(family(&t, "holefill_file_failures_total").len(), 2);
    // 18 good and the malformed one once each, the crashing one twice
    assert_eq!(must(&t, "holefill_attempts_total"), 21.0);
    assert_eq!(must(&t, "holefill_worker_crashes_total"), 2.0);
    assert_eq!(must(&t, "holefill_worker_timeouts_total"), 0.0);
    assert_eq!(must(&t, "holefill_retries_total{reason=\"crashed\"}"), 1.0);
    assert_eq!(
        family(&t, "holefill_retries_total").len(),
        1,
        "no other retry"
    );
    assert_eq!(must(&t, "holefill_repair_duration_seconds_count"), 20.0);
    assert_eq!(must(&t, "holefill_file_size_bytes_count"), 20.0);
    assert_eq!(must(&t, "holefill_file_size_bytes_sum"), bytes as f64);
    assert_eq!(must(&t, "holefill_file_faces_count"), 18.0);
    assert_eq!(must(&t, "holefill_file_faces_sum"), (18 * faces) as f64);
    assert_eq!(must(&t, "holefill_files_waiting"), 0.0);
    assert_eq!(must(&t, "holefill_files_in_flight"), 0.0);
    let last = must(&t, "holefill_last_success_timestamp_seconds");
    assert!(
        last >= start && last <= now_secs(),
        "{last} not in [{start}, now]"
    );
    // the slow file's repair took 1.5 s or more: one observation above 1 s
    let le1 = must(&t, "holefill_repair_duration_seconds_bucket{le=\"1.0\"}");
    assert!(le1 <= 19.0, "{t}");

    // holes by status, class and method: what the 18 logs say
    let logs: Vec<Value> = names.iter().map(|n| Folders::log(&f.outbox, n)).collect();
    let want = holes_by_label(&logs);
    assert!(!want.is_empty());
    assert_eq!(family(&t, "holefill_holes_total"), want);

    // a picture beside every repaired file's log (it follows the log)
    for n in &names {
        let p = f.outbox.join(format!("{n}.repair.png"));
        assert!(
            wait_until(Duration::from_secs(30), || p.is_file()),
            "{}",
            p.display()
        );
        let b = fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        assert_eq!(&b[..8], b"\x89PNG\r\n\x1a\n");
    }
    assert!(!f.failed.join("bad.obj.repair.png").exists());

    // the index lists every file of the run, with the pictures drawn after the logs
    let listed = wait_until(Duration::from_secs(10), || {
        let page = fs::read_to_string(f.outbox.join("index.html")).unwrap_or_default();
        page.contains("20 files") && page.matches("<img src=").count() == 18
    });
    let page = fs::read_to_string(f.outbox.join("index.html")).unwrap_or_default();
    assert!(listed, "{page}");
    for n in names
        .iter()
        .map(String::as_str)
        .chain(["bad.obj", "crash.obj"])
    {
        assert!(
            page.contains(&format!(">{n}<")),
            "{n} not in the index:\n{page}"
        );
    }
    assert!(page.contains("failed (input)") && page.contains("failed (worker)"));
    assert_eq!(page.matches("<img src=").count(), 18);

    // other paths
    assert_eq!(get(port, "/nothing").0, "HTTP/1.1 404 Not Found");
    d.signal("TERM");
    assert_eq!(d.wait_exit(LONG).and_then(|s| s.code()), Some(0));
}

#[test]
fn a_hung_worker_counts_as_a_timeout_and_pictures_and_index_can_be_off() {
    let f = Folders::new();
    let port = free_port();
    let addr = format!("127.0.0.1:{port}");
    let mut d = Daemon::ready(
        &f,
        &[
            "--metrics",
            &addr,
            "--max-attempts",
            "1",
            "--time-limit-secs",
            "1",
            "--picture",
            "false",
            "--index-entries",
            "0",
        ],
        &[("HOLEFILL_TEST_SLOW", "hang:20000")],
    );
    let (obj, _) = mesh();
    drop_renamed(&f.inbox, "hang.obj", &obj);
    drop_renamed(&f.inbox, "fine.obj", &obj);
    let t0 = Instant::now();
    assert!(
        wait_until(LONG, || {
            family(&scrape(port), "holefill_files_total")
                .values()
                .sum::<f64>()
                >= 2.0
        }),
        "{}",
        d.log()
    );
    assert!(t0.elapsed() < Duration::from_secs(30));
    let t = scrape(port);
    assert_eq!(must(&t, "holefill_worker_timeouts_total"), 1.0, "{t}");
    assert_eq!(must(&t, "holefill_worker_crashes_total"), 0.0);
    assert_eq!(
        must(&t, "holefill_file_failures_total{stage=\"worker\"}"),
        1.0
    );
    assert_eq!(must(&t, "holefill_files_total{outcome=\"repaired\"}"), 1.0);
    let log: Value = Folders::log(&f.outbox, "fine.obj");
    assert_eq!(log["status"], "repaired");
    assert_eq!(
        Folders::files(&f.outbox),
        vec!["fine.obj", "fine.obj.repair.json"],
        "no picture, no index"
    );
    d.signal("TERM");
    assert_eq!(d.wait_exit(LONG).and_then(|s| s.code()), Some(0));
}

#[test]
fn a_metrics_port_in_use_refuses_the_start() {
    let f = Folders::new();
    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = taken.local_addr().unwrap().to_string();
    let mut d = Daemon::start(&f, &["--metrics", &addr], &[]);
    let st = d.wait_exit(Duration::from_secs(20)).expect("it exits");
    assert_eq!(st.code(), Some(78), "{}", d.log());
    assert!(d.log().contains("cannot serve the metrics"), "{}", d.log());
}

#[test]
fn a_repair_is_published_without_waiting_for_its_picture() {
    let f = Folders::new();
    // one worker; the picture of `a` takes 2 s more, after its model and log are written
    let mut d = Daemon::ready(
        &f,
        &["--workers", "1"],
        &[("HOLEFILL_TEST_SLOW_PICTURE", "a.obj:2000")],
    );
    let (obj, _) = mesh();
    drop_renamed(&f.inbox, "a.obj", &obj);
    assert!(
        wait_until(LONG, || f.outbox.join("a.obj.repair.json").is_file()),
        "{}",
        d.log()
    );
    drop_renamed(&f.inbox, "b.obj", &obj);
    // b is repaired and published while a's picture is still being drawn
    assert!(
        wait_until(LONG, || f.outbox.join("b.obj.repair.json").is_file()),
        "{}",
        d.log()
    );
    assert!(
        !f.outbox.join("a.obj.repair.png").exists(),
        "a's picture came first\n{}",
        d.log()
    );
    assert_eq!(f.models(), vec!["a.obj", "b.obj"]);
    assert!(wait_files(
        &f.outbox,
        &[
            "a.obj",
            "a.obj.repair.json",
            "a.obj.repair.png",
            "b.obj",
            "b.obj.repair.json",
            "b.obj.repair.png"
        ]
    ));
    // the index shows both pictures once they are there
    let shown = wait_until(Duration::from_secs(10), || {
        let page = fs::read_to_string(f.outbox.join("index.html")).unwrap_or_default();
        page.matches("<img src=").count() == 2
    });
    assert!(shown, "{}", d.log());
    // a stop waits for a picture being drawn
    drop_renamed(&f.inbox, "a2.obj", &obj);
    assert!(wait_until(LONG, || f
        .outbox
        .join("a2.obj.repair.json")
        .is_file()));
    d.signal("TERM");
    assert_eq!(d.wait_exit(LONG).and_then(|s| s.code()), Some(0));
    assert!(f.outbox.join("a2.obj.repair.png").is_file(), "{}", d.log());
    assert!(
        !f.outbox.join(".holefill-tmp").exists()
            || fs::read_dir(f.outbox.join(".holefill-tmp"))
                .map(|mut r| r.next().is_none())
                .unwrap_or(true),
        "temporary files left"
    );
}
