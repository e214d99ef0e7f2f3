//! The inbox daemon as a gateway (`holefill watch --forward nats://...`): files
//! dropped into the inbox are repaired by two queue workers and come back into the
//! outbox (the originals archived), a malformed one into the failed folder with the
//! worker's log. Against a real nats-server; ignored where none is installed.

mod common;
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

/// Writes `bytes` as `dir/name` through a dot-file and a rename.
fn drop_bytes(dir: &std::path::Path, name: &str, bytes: &[u8]) {
    let tmp = dir.join(format!(".{name}.part"));
    std::fs::write(&tmp, bytes).unwrap();
    std::fs::rename(&tmp, dir.join(name)).unwrap();
}

fn mtllib_of(obj: &str) -> Option<String> {
    obj.lines()
        .find_map(|l| l.strip_prefix("mtllib "))
        .map(|s| s.trim().to_string())
}

#[test]
#[cfg_attr(not(has_nats_server), ignore = "needs nats-server")]
fn a_set_travels_through_the_gateway_together_and_results_keep_sets_whole() {
    let nats = Nats::start();
    let w = Worker::start(&nats, &["--ack-wait-secs", "10"], &[]);
    let f = Folders::new();
    let d = Daemon::ready(
        &f,
        &["--forward", &nats.url(), "--set-wait-secs", "60"],
        &[],
    );
    let obj = format!("mtllib t.mtl\nusemtl skin\n{}", holed_obj(1));
    let mtl = "newmtl skin\nKd 1 1 1\nmap_Kd -s 1 1 1 t.jpg\n";
    let jpg: Vec<u8> = (0..2000u32).map(|i| (i * 7 + 1) as u8).collect();
    // the image and the MTL first, the OBJ last
    drop_bytes(&f.inbox, "t.jpg", &jpg);
    drop_renamed(&f.inbox, "t.mtl", mtl);
    drop_renamed(&f.inbox, "t.obj", &obj);
    let dump = || format!("daemon:\n{}\nworker:\n{}", d.log(), w.log());
    assert!(
        wait_until(Duration::from_secs(60), || f
            .outbox
            .join("t.obj.repair.json")
            .exists()),
        "{}",
        dump()
    );
    let log = Folders::log(&f.outbox, "t.obj");
    assert_eq!(log["status"], "repaired", "{log}");
    // the worker got the whole set as one scan
    assert_eq!(
        log["worker"]["files"],
        serde_json::json!(["t.obj", "t.mtl", "t.jpg"]),
        "{log}"
    );
    let out = std::fs::read_to_string(f.outbox.join("t.obj")).unwrap();
    assert_eq!(mtllib_of(&out).as_deref(), Some("t.mtl"));
    assert!(
        out.lines().filter(|l| l.starts_with("f ")).count()
            > obj.lines().filter(|l| l.starts_with("f ")).count()
    );
    assert_eq!(
        std::fs::read_to_string(f.outbox.join("t.mtl")).unwrap(),
        mtl
    );
    assert_eq!(std::fs::read(f.outbox.join("t.jpg")).unwrap(), jpg);
    for n in ["t.obj", "t.mtl", "t.jpg"] {
        assert!(f.archive.join(n).is_file(), "{n} archived");
    }
    assert!(Folders::files(&f.inbox).is_empty());

    // `holefill results` downloads that set; then another set of the same names but
    // other content: its names are taken, so it goes whole into a folder of its own
    let dir = f.root().join("results");
    worker_support::results(&nats, &dir);
    assert_eq!(std::fs::read(dir.join("t.jpg")).unwrap(), jpg, "{}", dump());
    let src = f.root().join("second");
    std::fs::create_dir(&src).unwrap();
    let jpg2: Vec<u8> = jpg.iter().map(|b| b.wrapping_add(3)).collect();
    std::fs::write(src.join("t.obj"), &obj).unwrap();
    std::fs::write(src.join("t.mtl"), mtl).unwrap();
    std::fs::write(src.join("t.jpg"), &jpg2).unwrap();
    let out = worker_support::holefill(&[
        "submit",
        "--nats",
        &nats.url(),
        "--set",
        &src.join("t.obj").display().to_string(),
        &src.join("t.mtl").display().to_string(),
        &src.join("t.jpg").display().to_string(),
    ]);
    assert!(out.status.success());
    let sub = || {
        std::fs::read_dir(&dir)
            .ok()?
            .flatten()
            .find(|e| {
                e.file_type().is_ok_and(|t| t.is_dir())
                    && e.file_name().to_string_lossy().starts_with("t.")
            })
            .map(|e| e.path())
    };
    assert!(
        wait_until(Duration::from_secs(60), || {
            worker_support::results(&nats, &dir);
            sub().is_some_and(|s| s.join("t.obj.repair.json").exists())
        }),
        "results {:?} {:?}\n{}",
        Folders::entries(&dir),
        sub().map(|s| Folders::entries(&s)),
        dump()
    );
    let sub = sub().unwrap();
    assert!(
        sub.file_name().unwrap().to_string_lossy().starts_with("t."),
        "{}",
        sub.display()
    );
    let second = std::fs::read_to_string(sub.join("t.obj")).unwrap();
    let lib = mtllib_of(&second).unwrap();
    assert_eq!(
        std::fs::read_to_string(sub.join(&lib)).unwrap(),
        mtl,
        "the OBJ's mtllib finds its MTL beside it"
    );
    assert_eq!(std::fs::read(sub.join("t.jpg")).unwrap(), jpg2);
    // the first set is untouched
    assert_eq!(std::fs::read(dir.join("t.jpg")).unwrap(), jpg);
}

#[test]
fn a_gltf_set_with_its_bin_is_repaired_by_a_queue_worker() {
    use base64::Engine as _;
    let nats = Nats::start();
    let w = Worker::start(&nats, &["--ack-wait-secs", "10"], &[]);
    let f = Folders::new();
    let d = Daemon::ready(
        &f,
        &["--forward", &nats.url(), "--set-wait-secs", "60"],
        &[],
    );
    // the holed mesh as a .gltf whose buffer is the file s.bin
    let tmp = f.root().join("make");
    std::fs::create_dir(&tmp).unwrap();
    std::fs::write(tmp.join("s.obj"), holed_obj(2)).unwrap();
    let raw = holefill::io::read(&tmp.join("s.obj"), None).unwrap();
    holefill::io::write(&tmp.join("s.gltf"), &raw, None).unwrap();
    let mut doc: serde_json::Value =
        serde_json::from_slice(&std::fs::read(tmp.join("s.gltf")).unwrap()).unwrap();
    let uri = doc["buffers"][0]["uri"].as_str().unwrap().to_string();
    let bin = base64::engine::general_purpose::STANDARD
        .decode(uri.split_once(";base64,").unwrap().1)
        .unwrap();
    doc["buffers"][0]["uri"] = serde_json::json!("s.bin");
    drop_bytes(&f.inbox, "s.bin", &bin);
    drop_renamed(&f.inbox, "s.gltf", &doc.to_string());
    let dump = || format!("daemon:\n{}\nworker:\n{}", d.log(), w.log());
    assert!(
        wait_until(Duration::from_secs(60), || f
            .outbox
            .join("s.gltf.repair.json")
            .exists()),
        "{}",
        dump()
    );
    let log = Folders::log(&f.outbox, "s.gltf");
    assert_eq!(log["status"], "repaired", "{log}");
    assert_eq!(
        log["worker"]["files"],
        serde_json::json!(["s.gltf", "s.bin"]),
        "{log}"
    );
    assert_eq!(std::fs::read(f.outbox.join("s.bin")).unwrap(), bin);
    let out = holefill::io::read(&f.outbox.join("s.gltf"), None).unwrap();
    assert!(out.faces.len() > raw.faces.len(), "{}", dump());
    for n in ["s.gltf", "s.bin"] {
        assert!(f.archive.join(n).is_file(), "{n} archived");
    }
}
