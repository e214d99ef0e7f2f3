//! The folders: one that vanishes while the daemon runs, one that cannot be written,
//! folders that alias the inbox, and processing folders holefill did not make.

mod common;
mod daemon_support;
use daemon_support::*;
use std::fs;
use std::os::unix::fs::PermissionsExt;
use std::process::{Command, Stdio};
use std::time::Duration;

const LONG: Duration = Duration::from_secs(60);

#[test]
fn an_outbox_removed_while_running_is_made_again() {
    let f = Folders::new();
    let mut d = Daemon::ready(&f, &[], &[]);
    let (obj, _) = mesh();
    drop_renamed(&f.inbox, "first.obj", &obj);
    assert!(
        wait_until(LONG, || f.archive.join("first.obj").is_file()),
        "{}",
        d.log()
    );
    remove_while_written(&f.outbox);
    drop_renamed(&f.inbox, "second.obj", &obj);
    assert!(
        wait_until(LONG, || f.outbox.join("second.obj.repair.json").is_file()),
        "repaired into the recreated outbox\n{}",
        d.log()
    );
    assert_eq!(f.models(), vec!["second.obj"]);
    assert!(
        d.log().contains("had vanished: created again"),
        "{}",
        d.log()
    );

    // the outbox cannot be made (a file in its place): files wait in the inbox, with
    // an error that is not repeated every second
    remove_while_written(&f.outbox);
    fs::write(&f.outbox, "in the way").unwrap();
    drop_renamed(&f.inbox, "third.obj", &obj);
    std::thread::sleep(Duration::from_secs(4));
    assert_eq!(Folders::files(&f.inbox), vec!["third.obj"], "{}", d.log());
    assert!(Folders::files(&f.failed).is_empty(), "{}", d.log());
    let errors = d.log().matches("ERROR").count();
    assert!(
        (1..=2).contains(&errors),
        "{errors} errors in 4 s\n{}",
        d.log()
    );
    fs::remove_file(&f.outbox).unwrap();
    assert!(
        wait_until(LONG, || f.outbox.join("third.obj.repair.json").is_file()),
        "{}",
        d.log()
    );
    assert!(d.alive());
    d.signal("TERM");
    assert_eq!(d.wait_exit(LONG).and_then(|s| s.code()), Some(0));
}

/// Removes a folder the daemon may be writing into at the same moment (its index page
/// is written after each file): a file made meanwhile fails `remove_dir_all` with
/// "directory not empty", so it is tried again.
fn remove_while_written(p: &std::path::Path) {
    let mut last = None;
    for _ in 0..50 {
        match fs::remove_dir_all(p) {
            Ok(()) => return,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return,
            Err(e) => last = Some(e),
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    panic!("cannot remove {}: {last:?}", p.display());
}

/// Starts `holefill watch` with these folders (relative ones from `f.root()`) and
/// returns its exit status and stderr, or `None` when it was still running after 5 s.
fn start_with(f: &Folders, args: &[&str]) -> Option<(i32, String)> {
    let mut c = Command::new(bin())
        .arg("watch")
        .args(args)
        .current_dir(f.root())
        .env_remove("NOTIFY_SOCKET")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let ok = wait_until(Duration::from_secs(5), || {
        matches!(c.try_wait(), Ok(Some(_)))
    });
    if !ok {
        let _ = c.kill();
        let _ = c.wait();
        return None;
    }
    let out = c.wait_with_output().unwrap();
    Some((
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    ))
}

#[test]
fn folders_that_alias_the_inbox_are_refused_at_start() {
    let f = Folders::new();
    let inbox = f.inbox.to_str().unwrap().to_string();
    std::os::unix::fs::symlink(&f.inbox, f.root().join("link")).unwrap();
    let link = f.root().join("link").to_str().unwrap().to_string();
    let cases: Vec<(Vec<String>, &str)> = vec![
        (
            vec![
                "--inbox".into(),
                "inbox".into(),
                "--outbox".into(),
                "./inbox".into(),
            ],
            "same folder",
        ),
        (
            vec![
                "--inbox".into(),
                inbox.clone(),
                "--outbox".into(),
                format!("{inbox}/../inbox/"),
            ],
            "same folder",
        ),
        (
            vec![
                "--inbox".into(),
                "inbox".into(),
                "--outbox".into(),
                link.clone(),
            ],
            "same folder",
        ),
        (
            vec![
                "--inbox".into(),
                "inbox".into(),
                "--archive".into(),
                format!("{link}/old"),
            ],
            "inside the inbox",
        ),
        (
            vec![
                "--inbox".into(),
                "inbox".into(),
                "--outbox".into(),
                "inbox/out".into(),
            ],
            "inside the inbox",
        ),
        (
            vec![
                "--inbox".into(),
                "inbox".into(),
                "--failed".into(),
                ".".into(),
            ],
            "inside the failed folder",
        ),
        (
            vec![
                "--inbox".into(),
                "inbox".into(),
                "--outbox".into(),
                "o".into(),
                "--failed".into(),
                "./o".into(),
            ],
            "same folder",
        ),
    ];
    for (args, why) in cases {
        let a: Vec<&str> = args.iter().map(String::as_str).collect();
        let r = start_with(&f, &a);
        let Some((code, err)) = r else {
            panic!("{a:?}: the daemon started");
        };
        assert_ne!(code, 0, "{a:?}");
        assert!(err.contains(why), "{a:?}: {err}");
    }
    assert!(
        !f.inbox.join("out").exists(),
        "nothing made for a refused start"
    );
    assert!(!f.inbox.join("old").exists());
}

#[test]
fn a_processing_folder_others_may_write_is_refused() {
    let f = Folders::new();
    let p = f.inbox.join(".processing");
    fs::create_dir(&p).unwrap();
    fs::set_permissions(&p, fs::Permissions::from_mode(0o777)).unwrap();
    let (code, err) = start_with(
        &f,
        &[
            "--inbox",
            "inbox",
            "--outbox",
            "outbox",
            "--failed",
            "failed",
            "--archive",
            "archive",
        ],
    )
    .expect("refused at start");
    assert_ne!(code, 0);
    assert!(err.contains("written by others"), "{err}");
}

#[test]
fn a_planted_processing_folder_is_left_alone() {
    let f = Folders::new();
    // a first daemon makes .processing as holefill does
    let mut d = Daemon::ready(&f, &[], &[]);
    d.signal("TERM");
    d.wait_exit(LONG);
    // a folder named like the one of a dead daemon of this host, writable by all
    let host = hostname::get().unwrap().into_string().unwrap();
    let fake = f.inbox.join(".processing").join(format!("{host}-999999"));
    fs::create_dir(&fake).unwrap();
    fs::set_permissions(&fake, fs::Permissions::from_mode(0o777)).unwrap();
    let (obj, _) = mesh();
    fs::write(fake.join("x.obj"), &obj).unwrap();
    let d = Daemon::ready(&f, &["--rescan-secs", "1"], &[]);
    std::thread::sleep(Duration::from_secs(3));
    assert!(fake.join("x.obj").is_file(), "{}", d.log());
    assert!(f.models().is_empty(), "{}", d.log());
    assert!(d.log().contains("written by others"), "{}", d.log());
    assert_eq!(
        d.log().matches("written by others").count(),
        1,
        "rate-limited\n{}",
        d.log()
    );
}

#[test]
#[ignore = "needs root"]
fn a_processing_folder_of_another_user_is_left_alone() {
    let f = Folders::new();
    let mut d = Daemon::ready(&f, &[], &[]);
    d.signal("TERM");
    d.wait_exit(LONG);
    let fake = f.inbox.join(".processing").join("h-1-0123456789abcdef");
    fs::create_dir(&fake).unwrap();
    fs::set_permissions(&fake, fs::Permissions::from_mode(0o700)).unwrap();
    let (obj, _) = mesh();
    fs::write(fake.join("x.obj"), &obj).unwrap();
    let st = Command::new("chown")
        .args(["-R", "4242:4242"])
        .arg(&fake)
        .status()
        .unwrap();
    assert!(st.success());
    let d = Daemon::ready(&f, &["--rescan-secs", "1"], &[]);
    std::thread::sleep(Duration::from_secs(3));
    assert!(fake.join("x.obj").is_file(), "{}", d.log());
    assert!(f.models().is_empty());
    assert!(d.log().contains("belongs to uid 4242"), "{}", d.log());
}

#[test]
#[ignore = "needs root"]
fn an_archive_that_cannot_be_written_is_never_claimed_archived_nor_repaired_twice() {
    let f = Folders::new();
    fs::create_dir_all(&f.archive).unwrap();
    let (obj, _) = mesh();
    {
        let ro = Mount::read_only(&f.archive).expect("a read-only bind mount (root)");
        let mut d = Daemon::ready(&f, &[], &[]);
        drop_renamed(&f.inbox, "x.obj", &obj);
        assert!(
            wait_until(LONG, || d.log().contains("archiving the original")),
            "{}",
            d.log()
        );
        // the model is out, its log (which says the original is archived) is not
        std::thread::sleep(Duration::from_secs(1));
        assert_eq!(Folders::files(&f.outbox), vec!["x.obj"], "{}", d.log());
        assert_eq!(f.processing(), vec!["x.obj"]);
        assert!(Folders::files(&f.failed).is_empty());
        d.signal("TERM");
        assert_eq!(
            d.wait_exit(LONG).and_then(|s| s.code()),
            Some(0),
            "{}",
            d.log()
        );
        // not put back into the inbox: it would be repaired again
        assert!(Folders::files(&f.inbox).is_empty(), "{}", d.log());
        drop(ro);
    }
    // writable again; a new daemon finishes the publish
    let mut d = Daemon::ready(&f, &[], &[]);
    assert!(
        wait_until(LONG, || f.outbox.join("x.obj.repair.json").is_file()),
        "{}",
        d.log()
    );
    assert!(
        wait_files(
            &f.outbox,
            &["x.obj", "x.obj.repair.json", "x.obj.repair.png"]
        ),
        "{}",
        d.log()
    );
    assert_eq!(Folders::files(&f.archive), vec!["x.obj"]);
    assert_eq!(fs::read_to_string(f.archive.join("x.obj")).unwrap(), obj);
    let log = Folders::log(&f.outbox, "x.obj");
    assert_eq!(log["status"], "repaired");
    assert_eq!(
        log["daemon"]["archived_as"].as_str(),
        Some(f.archive.join("x.obj").to_str().unwrap())
    );
    assert!(d.log().contains("not repaired again"), "{}", d.log());
    assert!(f.processing().is_empty());
    d.signal("TERM");
    assert_eq!(d.wait_exit(LONG).and_then(|s| s.code()), Some(0));
}

#[test]
#[ignore = "needs root"]
fn an_immutable_archive_recovers_without_a_restart() {
    let f = Folders::new();
    fs::create_dir_all(&f.archive).unwrap();
    let chattr = |flag: &str| {
        Command::new("chattr")
            .arg(flag)
            .arg(&f.archive)
            .status()
            .is_ok_and(|s| s.success())
    };
    assert!(
        chattr("+i"),
        "chattr +i (root, a file system with the flag)"
    );
    let (obj, _) = mesh();
    let mut d = Daemon::ready(&f, &[], &[]);
    drop_renamed(&f.inbox, "y.obj", &obj);
    let seen = wait_until(LONG, || d.log().contains("archiving the original"));
    assert!(chattr("-i"));
    assert!(seen, "{}", d.log());
    assert!(!f.outbox.join("y.obj.repair.json").exists());
    assert!(
        wait_until(LONG, || f.outbox.join("y.obj.repair.json").is_file()),
        "{}",
        d.log()
    );
    assert!(
        wait_files(
            &f.outbox,
            &["y.obj", "y.obj.repair.json", "y.obj.repair.png"]
        ),
        "{:?}",
        Folders::files(&f.outbox)
    );
    assert_eq!(Folders::files(&f.archive), vec!["y.obj"]);
    d.signal("TERM");
    assert_eq!(d.wait_exit(LONG).and_then(|s| s.code()), Some(0));
}
