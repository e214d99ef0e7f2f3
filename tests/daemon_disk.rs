//! An outbox on a full disk (a 1 MiB tmpfs, so the test needs root): the input is
//! never lost, and the repair resumes once there is space again.

mod common;
mod daemon_support;
use daemon_support::*;
use std::fs;
use std::io::Write;
use std::process::Command;
use std::time::Duration;

struct Mount(std::path::PathBuf);
impl Drop for Mount {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg("-l").arg(&self.0).status();
    }
}

#[test]
#[ignore = "needs root"]
fn full_outbox_never_loses_the_input_and_resumes() {
    let f = Folders::new();
    fs::create_dir_all(&f.outbox).unwrap();
    let ok = Command::new("mount")
        .args([
            "-t",
            "tmpfs",
            "-o",
            "size=1m",
            "holefill-test",
            f.outbox.to_str().unwrap(),
        ])
        .stderr(std::process::Stdio::null())
        .status()
        .map(|s| s.success())
        .unwrap_or(false);
    assert!(
        ok,
        "cannot mount a tmpfs on {} (the test needs root)",
        f.outbox.display()
    );
    let _m = Mount(f.outbox.clone());
    let mut d = Daemon::ready(&f, &["--retry-max-secs", "1"], &[]);
    assert!(wait_until(Duration::from_secs(10), || f
        .outbox
        .join(".holefill-tmp")
        .is_dir()));
    // fill the disk
    let filler = f.outbox.join("filler.bin");
    {
        let mut w = fs::File::create(&filler).unwrap();
        let block = vec![0u8; 4096];
        while w.write_all(&block).is_ok() {}
        let _ = w.sync_all();
    }
    let (obj, _) = holed_sphere_obj(3, 0.3); // ~100 KiB of text out
    drop_renamed(&f.inbox, "full.obj", &obj);
    // it is tried and put back, again and again; never failed, never lost
    assert!(
        wait_until(Duration::from_secs(20), || d
            .log()
            .matches("back in the inbox")
            .count()
            >= 2),
        "{}",
        d.log()
    );
    assert!(Folders::files(&f.failed).is_empty(), "{}", d.log());
    let here = Folders::files(&f.inbox).contains(&"full.obj".to_string())
        || f.processing() == vec!["full.obj"];
    assert!(
        here,
        "inbox {:?} processing {:?}",
        Folders::files(&f.inbox),
        f.processing()
    );
    assert!(d.alive());
    // space again
    fs::remove_file(&filler).unwrap();
    assert!(
        wait_until(Duration::from_secs(20), || f
            .outbox
            .join("full.obj.repair.json")
            .is_file()),
        "{}",
        d.log()
    );
    assert_eq!(f.models(), vec!["full.obj"]);
    assert!(wait_until(Duration::from_secs(20), || f
        .archive
        .join("full.obj")
        .is_file()));
    assert_eq!(fs::read_to_string(f.archive.join("full.obj")).unwrap(), obj);
    d.signal("TERM");
    assert_eq!(
        d.wait_exit(Duration::from_secs(20)).and_then(|s| s.code()),
        Some(0)
    );
}
