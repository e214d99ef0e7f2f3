//! The queue worker against a real nats-server (JetStream, a free loopback port, a
//! temporary store): exactly-once repair by several workers, a worker killed with
//! SIGKILL mid-repair, the server restarted mid-run or silent as a worker reads a scan,
//! a file that crashes its worker every time. Ignored where no nats-server is installed (`.ci/run` installs it).

mod common;
mod metrics_support;
mod worker_support;
use metrics_support::*;
use std::collections::HashMap;
use std::time::Duration;
use worker_support::*;

#[test]
#[cfg_attr(not(has_nats_server), ignore = "needs nats-server")]
fn three_workers_200_scans_each_repaired_exactly_once() {
    let nats = Nats::start();
    let src = tempfile::tempdir().unwrap();
    let good = 194;
    let mut files = write_meshes(src.path(), "s", good);
    // malformed: a face that names a vertex that does not exist
    for i in 0..6 {
        let p = src.path().join(format!("bad{i}.obj"));
        std::fs::write(&p, format!("v 0 0 0\nv 1 0 0\nv 0 1 {i}\nf 1 2 9\n")).unwrap();
        files.push(p);
    }
    let workers: Vec<Worker> = (0..3)
        .map(|_| Worker::start(&nats, &["--ack-wait-secs", "10"], &[]))
        .collect();
    let keys = submit(&nats, &files);
    assert_eq!(keys.len(), 200);
    // submitting the same files again is de-duplicated (the key is the message id)
    let again = submit(&nats, &files[..5]);
    assert_eq!(again, keys[..5]);
    let out = tempfile::tempdir().unwrap();
    let done = wait_until(Duration::from_secs(150), || {
        results(&nats, out.path());
        logs(out.path()).len() + logs(&out.path().join("failed")).len() >= 200
    });
    let dump = || {
        workers
            .iter()
            .map(|w| w.log())
            .collect::<Vec<_>>()
            .join("\n----\n")
    };
    assert!(
        done,
        "repaired {} failed {}\n{}",
        logs(out.path()).len(),
        logs(&out.path().join("failed")).len(),
        dump()
    );
    std::thread::sleep(Duration::from_secs(1));
    results(&nats, out.path());
    let repaired = logs(out.path());
    let failed = logs(&out.path().join("failed"));
    assert_eq!(repaired.len(), good, "{:?}", repaired.keys());
    assert_eq!(failed.len(), 6, "{:?}", failed.keys());
    for (i, file) in files.iter().enumerate().take(good) {
        let name = format!("s{i:03}.obj");
        let log = &repaired[&format!("{name}.repair.json")];
        assert_eq!(log["status"], "repaired");
        assert_eq!(log["summary"]["failed"], 0, "{log}");
        assert!(log["summary"]["filled"].as_u64().unwrap() >= 1, "{log}");
        let model = std::fs::read_to_string(out.path().join(&name)).unwrap();
        let faces = model.lines().filter(|l| l.starts_with("f ")).count();
        let before = std::fs::read_to_string(file)
            .unwrap()
            .lines()
            .filter(|l| l.starts_with("f "))
            .count();
        assert!(faces > before, "{name}: {faces} faces, {before} before");
    }
    for i in 0..6 {
        let log = &failed[&format!("bad{i}.obj.repair.json")];
        assert_eq!(log["status"], "failed");
        assert_eq!(log["stage"], "input", "{log}");
        assert!(!log["error"].as_str().unwrap().is_empty());
        // the submitted file comes back with its log
        assert!(out
            .path()
            .join("failed")
            .join(format!("bad{i}.obj"))
            .is_file());
    }
    // each scan repaired by exactly one worker, exactly once
    let mut count: HashMap<String, usize> = HashMap::new();
    for w in &workers {
        for k in w.repaired().into_iter().chain(w.failed()) {
            *count.entry(k).or_default() += 1;
        }
    }
    assert_eq!(count.len(), 200, "{}", dump());
    assert!(count.values().all(|&c| c == 1), "{count:?}");
    for k in &keys {
        assert_eq!(count.get(k), Some(&1), "{k}");
    }
    // all three took part
    assert!(
        workers.iter().all(|w| !w.repaired().is_empty()),
        "{}",
        dump()
    );
}

#[test]
#[cfg_attr(not(has_nats_server), ignore = "needs nats-server")]
fn a_worker_killed_mid_repair_has_its_scan_redelivered_and_repaired_once() {
    let nats = Nats::start();
    let src = tempfile::tempdir().unwrap();
    let files = write_meshes(src.path(), "slow", 1);
    // A: each repair of "slow" sleeps 30 s in the child
    let mut a = Worker::start(
        &nats,
        &["--ack-wait-secs", "2"],
        &[("HOLEFILL_TEST_SLOW", "slow:30000")],
    );
    assert!(
        wait_until(Duration::from_secs(20), || a.is_ready()),
        "{}",
        a.log()
    );
    let keys = submit(&nats, &files);
    // A has taken it: its child is asleep
    assert!(
        wait_until(Duration::from_secs(20), || a.log().contains("taken")),
        "{}",
        a.log()
    );
    std::thread::sleep(Duration::from_millis(500));
    a.kill9();
    // B, without the slow hook, gets it once ack_wait (2 s) has passed
    let b = Worker::start(&nats, &["--ack-wait-secs", "2"], &[]);
    let out = tempfile::tempdir().unwrap();
    assert!(
        wait_until(Duration::from_secs(60), || {
            results(&nats, out.path());
            !logs(out.path()).is_empty()
        }),
        "A:\n{}\nB:\n{}",
        a.log(),
        b.log()
    );
    std::thread::sleep(Duration::from_secs(3));
    results(&nats, out.path());
    let l = logs(out.path());
    assert_eq!(l.len(), 1, "{:?}", l.keys());
    let log = &l["slow000.obj.repair.json"];
    assert_eq!(log["status"], "repaired");
    assert_eq!(log["worker"]["delivery"], 2, "{log}");
    assert_eq!(a.repaired(), Vec::<String>::new());
    assert_eq!(b.repaired(), keys);
}

#[test]
#[cfg_attr(not(has_nats_server), ignore = "needs nats-server")]
fn a_file_that_crashes_its_worker_every_time_fails_after_max_deliver() {
    let nats = Nats::start();
    let src = tempfile::tempdir().unwrap();
    let mut files = write_meshes(src.path(), "ok", 6);
    let poison = src.path().join("poison.obj");
    std::fs::write(&poison, holed_obj(99)).unwrap();
    files.insert(3, poison);
    let args = [
        "--max-deliver",
        "3",
        "--backoff-secs",
        "1",
        "--ack-wait-secs",
        "5",
    ];
    let env = [("HOLEFILL_TEST_CRASH_ON", "poison")];
    let w1 = Worker::start(&nats, &args, &env);
    let w2 = Worker::start(&nats, &args, &env);
    let keys = submit(&nats, &files);
    let out = tempfile::tempdir().unwrap();
    assert!(
        wait_until(Duration::from_secs(90), || {
            results(&nats, out.path());
            logs(out.path()).len() == 6 && logs(&out.path().join("failed")).len() == 1
        }),
        "{}\n----\n{}",
        w1.log(),
        w2.log()
    );
    let failed = logs(&out.path().join("failed"));
    let log = &failed["poison.obj.repair.json"];
    assert_eq!(log["status"], "failed");
    assert_eq!(log["stage"], "worker", "{log}");
    assert_eq!(log["worker"]["delivery"], 3, "{log}");
    assert!(log["error"].as_str().unwrap().contains("signal 9"), "{log}");
    // three attempts, each logged as a retry or the final failure
    let attempts = [&w1, &w2]
        .iter()
        .map(|w| w.log().matches("poison.obj@").count())
        .sum::<usize>();
    assert!(attempts >= 3, "{}\n{}", w1.log(), w2.log());
    let repaired = logs(out.path());
    for (i, k) in keys.iter().enumerate() {
        if i != 3 {
            let name = format!("ok{:03}.obj.repair.json", if i < 3 { i } else { i - 1 });
            assert_eq!(repaired[&name]["status"], "repaired", "{k}");
        }
    }
}

#[test]
#[cfg_attr(not(has_nats_server), ignore = "needs nats-server")]
fn a_server_restart_mid_run_loses_nothing() {
    let mut nats = Nats::start();
    let src = tempfile::tempdir().unwrap();
    let n = 60;
    let files = write_meshes(src.path(), "r", n);
    let args = ["--ack-wait-secs", "4", "--backoff-secs", "1"];
    // each repair takes at least 150 ms, so the restart falls mid-run
    let env = [("HOLEFILL_TEST_SLOW", ":150")];
    let w1 = Worker::start(&nats, &args, &env);
    let w2 = Worker::start(&nats, &args, &env);
    let keys = submit(&nats, &files);
    assert_eq!(keys.len(), n);
    assert!(
        wait_until(Duration::from_secs(60), || w1.repaired().len()
            + w2.repaired().len()
            >= 10),
        "{}\n{}",
        w1.log(),
        w2.log()
    );
    nats.restart(Duration::from_secs(1));
    let out = tempfile::tempdir().unwrap();
    let ok = results_until(&nats, out.path(), n, Duration::from_secs(120));
    assert!(
        ok,
        "{} of {n}\n{}\n----\n{}\n----\n{}",
        logs(out.path()).len(),
        w1.log(),
        w2.log(),
        nats.server_log()
    );
    std::thread::sleep(Duration::from_secs(2));
    results(&nats, out.path());
    let l = logs(out.path());
    // one result per scan: no scan lost, none with a second, different result
    assert_eq!(l.len(), n, "{:?}", l.keys());
    for i in 0..n {
        assert_eq!(l[&format!("r{i:03}.obj.repair.json")]["status"], "repaired");
    }
    assert!(logs(&out.path().join("failed")).is_empty());
}

#[test]
#[cfg_attr(not(has_nats_server), ignore = "needs nats-server")]
fn worker_metrics_match_a_run_of_20_scans_with_2_failing() {
    let nats = Nats::start();
    let port = free_port();
    let addr = format!("127.0.0.1:{port}");
    let start = now_secs();
    let args = [
        "--metrics",
        &addr,
        "--max-deliver",
        "2",
        "--backoff-secs",
        "1",
        "--ack-wait-secs",
        "10",
    ];
    let w = Worker::start(&nats, &args, &[("HOLEFILL_TEST_CRASH_ON", "crash")]);
    assert!(
        wait_until(Duration::from_secs(30), || w.is_ready()),
        "{}",
        w.log()
    );
    let before = scrape(port);
    assert_eq!(must(&before, "holefill_attempts_total"), 0.0, "{before}");
    assert!(before.contains("service=\"worker\""), "{before}");

    let src = tempfile::tempdir().unwrap();
    let mut files = write_meshes(src.path(), "good", 18);
    let bad = src.path().join("bad.obj");
    std::fs::write(&bad, "v 0 0 0\nv 1 0 0\nf 1 2 9\n").unwrap();
    let crash = src.path().join("crash.obj");
    std::fs::write(&crash, holed_obj(77)).unwrap();
    files.push(bad);
    files.push(crash);
    let bytes: u64 = files
        .iter()
        .map(|p| std::fs::metadata(p).unwrap().len())
        .sum();
    assert_eq!(submit(&nats, &files).len(), 20);

    let mut seen_busy = false;
    let done = wait_until(Duration::from_secs(120), || {
        let t = scrape(port);
        if must(&t, "holefill_files_in_flight") > 0.0 {
            seen_busy = true;
        }
        family(&t, "holefill_files_total").values().sum::<f64>() >= 20.0
    });
    assert!(done, "{}", w.log());
    assert!(seen_busy, "a scrape during the run saw a scan in flight");
    // the queue drains: nothing waits (polled every 2 s)
    assert!(
        wait_until(Duration::from_secs(10), || must(
            &scrape(port),
            "holefill_files_waiting"
        ) == 0.0),
        "{}",
        scrape(port)
    );

    let t = scrape(port);
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
    // 18 good and the malformed one once each, the crashing one on both deliveries
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
    assert_eq!(must(&t, "holefill_files_in_flight"), 0.0);
    let last = must(&t, "holefill_last_success_timestamp_seconds");
    assert!(
        last >= start && last <= now_secs(),
        "{last} not in [{start}, now]"
    );

    // faces and holes: what the 18 repair logs say
    let out = tempfile::tempdir().unwrap();
    results(&nats, out.path());
    let repaired = logs(out.path());
    assert_eq!(repaired.len(), 18);
    let faces: f64 = repaired
        .values()
        .map(|log| log["before"]["faces"].as_f64().unwrap())
        .sum();
    let want = holes_by_label(repaired.values());
    assert_eq!(must(&t, "holefill_file_faces_count"), 18.0);
    assert_eq!(must(&t, "holefill_file_faces_sum"), faces);
    assert!(!want.is_empty());
    assert_eq!(family(&t, "holefill_holes_total"), want);
}

/// Regression (the CI run of stop 40): async-nats' object reader unwraps the making of
/// its consumer, so a server that did not answer as a worker began reading a scan's
/// chunks (there: restarted) panicked the worker's only slot, and no scan after it was
/// repaired. The worker now reads objects itself: the scan is tried again, and the slot
/// goes on.
#[test]
#[cfg_attr(not(has_nats_server), ignore = "needs nats-server")]
fn a_server_silent_as_a_worker_reads_a_scan_costs_a_retry_not_the_slot() {
    let nats = Nats::start();
    let src = tempfile::tempdir().unwrap();
    let n = 3;
    let files = write_meshes(src.path(), "g", n);
    let args = ["--ack-wait-secs", "4", "--backoff-secs", "1"];
    let w = Worker::start(
        &nats,
        &args,
        &[("HOLEFILL_TEST_PAUSE_AT", "chunks:1000:g001")],
    );
    assert_eq!(submit(&nats, &files).len(), n);
    assert!(
        wait_until(Duration::from_secs(30), || w
            .log()
            .contains("pausing 1000 ms at chunks")),
        "{}",
        w.log()
    );
    // silent across the end of the pause: the request that makes the consumer of
    // g001's chunks times out (the client's request timeout: 10 s)
    nats.freeze(Duration::from_secs(12));
    let out = tempfile::tempdir().unwrap();
    let ok = results_until(&nats, out.path(), n, Duration::from_secs(90));
    assert!(ok, "{} of {n}\n{}", logs(out.path()).len(), w.log());
    let l = logs(out.path());
    for i in 0..n {
        assert_eq!(l[&format!("g{i:03}.obj.repair.json")]["status"], "repaired");
    }
    let log = w.log();
    assert!(!log.contains("panicked"), "{log}");
    assert!(
        log.contains("g001.obj") && log.contains("cannot read its chunks"),
        "the read of g001 did not meet the server's absence:\n{log}"
    );
}

#[test]
#[cfg_attr(not(has_nats_server), ignore = "needs nats-server")]
fn submitters_starting_together_on_a_new_server_all_get_the_streams() {
    // each may find the streams missing and make them; the server refuses all but the
    // first, and the others must find them there. In CI (a72fca0) a submit starting
    // beside two workers was refused "subjects overlap with an existing stream" (its
    // lookup had not found the stream, under load) and exited 1; that timing was not
    // reproduced here, this asks for the same race twelve at a time
    for round in 0..3 {
        let nats = Nats::start();
        let src = tempfile::tempdir().unwrap();
        let files = write_meshes(src.path(), "scan", 12);
        let children: Vec<_> = files
            .iter()
            .map(|f| {
                std::process::Command::new(bin())
                    .args(["submit", "--nats", &nats.url()])
                    .arg(f)
                    .stdin(std::process::Stdio::null())
                    .stdout(std::process::Stdio::piped())
                    .stderr(std::process::Stdio::piped())
                    .spawn()
                    .expect("run holefill submit")
            })
            .collect();
        for c in children {
            let out = c.wait_with_output().expect("submit ends");
            assert!(
                out.status.success(),
                "round {round}: {}\n{}",
                out.status,
                String::from_utf8_lossy(&out.stderr)
            );
            assert!(
                String::from_utf8_lossy(&out.stdout).contains("queued "),
                "round {round}: {}",
                String::from_utf8_lossy(&out.stdout)
            );
        }
    }
}
