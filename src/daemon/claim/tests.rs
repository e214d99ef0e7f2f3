use super::layout::resolve;
use super::*;

#[test]
fn names() {
    for n in ["a.obj", "B.PLY", "x.y.Stl", "scan 01.off"] {
        assert!(is_candidate_name(OsStr::new(n)), "{n}");
    }
    assert!(is_candidate_name(OsStr::from_bytes(b"\xff.obj")));
    for n in [
        ".a.obj",
        "a.obj.part",
        "a.obj.tmp",
        "a.obj~",
        "a.txt",
        ".obj",
        "a.objx",
        "a.TMP",
    ] {
        assert!(!is_candidate_name(OsStr::new(n)), "{n}");
    }
}

#[test]
fn resolve_folds_what_does_not_exist_yet() {
    let d = tempfile::tempdir().unwrap();
    let root = fs::canonicalize(d.path()).unwrap();
    std::os::unix::fs::symlink(&root, root.join("link")).unwrap();
    assert_eq!(
        resolve(&root.join("link/a/../b/./c")).unwrap(),
        root.join("b/c")
    );
}

fn layout(d: &Path) -> Layout {
    Layout::create(
        &d.join("in"),
        &d.join("out"),
        &d.join("failed"),
        &d.join("archive"),
    )
    .unwrap()
}

#[test]
fn aliased_folders_are_refused() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path();
    fs::create_dir(p.join("in")).unwrap();
    std::os::unix::fs::symlink(p.join("in"), p.join("alias")).unwrap();
    for (out, why) in [
        (p.join("in"), "same"),
        (p.join("in/../in/"), "same"),
        (p.join("alias"), "same"),
        (p.join("in/out"), "inside the inbox"),
        (p.join("alias/x/y"), "inside the inbox"),
        (p.to_path_buf(), "inbox"),
    ] {
        let e = Layout::create(&p.join("in"), &out, &p.join("f"), &p.join("a")).unwrap_err();
        assert!(e.contains(why), "{}: {e}", out.display());
    }
    assert!(
        !p.join("in/out").exists(),
        "nothing created for a refused layout"
    );
    layout(p);
}

#[test]
fn a_home_is_alive_while_its_lock_is_held() {
    let d = tempfile::tempdir().unwrap();
    let l = layout(d.path());
    let a = Home::create(&l, "h-1-a").unwrap();
    assert!(a.intact());
    assert!(matches!(Home::adopt(&l, "h-1-a"), Ok(None)), "alive");
    drop(a);
    let b = Home::adopt(&l, "h-1-a").unwrap().expect("dead: adopted");
    assert!(matches!(Home::adopt(&l, "h-1-a"), Ok(None)), "adopted once");
    assert!(b.remove_if_empty());
    assert!(!l.processing_root.join("h-1-a").exists());
}

#[test]
fn folders_of_others_are_refused() {
    use std::os::unix::fs::PermissionsExt;
    let d = tempfile::tempdir().unwrap();
    let l = layout(d.path());
    let fake = l.processing_root.join("h-2-b");
    fs::create_dir(&fake).unwrap();
    fs::set_permissions(&fake, fs::Permissions::from_mode(0o777)).unwrap();
    let e = Home::adopt(&l, "h-2-b").unwrap_err();
    assert!(e.contains("written by others"), "{e}");
}

#[test]
fn claim_is_exclusive_put_back_never_overwrites_and_keeps_the_count() {
    let d = tempfile::tempdir().unwrap();
    let l = layout(d.path());
    let id = Identity::current();
    let a = Arc::new(Home::create(&l, "h-3-a").unwrap());
    let b = Arc::new(Home::create(&l, "h-4-b").unwrap());
    let p = l.inbox.join("s.obj");
    fs::write(&p, "1").unwrap();
    let st = Stamp::of(&fs::metadata(&p).unwrap());
    let now = SystemTime::now();
    let mut job = claim(&l, &a, id.next_id(), OsStr::new("s.obj"), st, now)
        .unwrap()
        .unwrap();
    assert!(claim(&l, &b, id.next_id(), OsStr::new("s.obj"), st, now)
        .unwrap()
        .is_none());
    assert_eq!(fs::read_dir(&b.dir).unwrap().count(), 1, "only b's lock");
    // a new file of the same name arrives while ours is claimed
    fs::write(&p, "2").unwrap();
    job.attempt = 3; // two attempts failed
    let back = put_back(&l, &job, &|| {}).unwrap();
    assert_ne!(back, "s.obj");
    assert_eq!(fs::read_to_string(&p).unwrap(), "2");
    let q = l.inbox.join(&back);
    assert_eq!(fs::read_to_string(&q).unwrap(), "1");
    let st = Stamp::of(&fs::metadata(&q).unwrap());
    let again = claim(&l, &a, id.next_id(), &back, st, now)
        .unwrap()
        .unwrap();
    assert_eq!(again.attempt, 3, "the count survives the put-back");
    assert_eq!(again.rec.received, job.rec.received);
}

#[test]
fn adopted_jobs_resume_and_count_the_attempt_that_died() {
    let d = tempfile::tempdir().unwrap();
    let l = layout(d.path());
    let id = Identity::current();
    let dead = Arc::new(Home::create(&l, "h-5-d").unwrap());
    let p = l.inbox.join("a.obj");
    fs::write(&p, "a").unwrap();
    let st = Stamp::of(&fs::metadata(&p).unwrap());
    let mut job = claim(
        &l,
        &dead,
        id.next_id(),
        OsStr::new("a.obj"),
        st,
        SystemTime::now(),
    )
    .unwrap()
    .unwrap();
    job.rec.attempts = 2;
    job.save().unwrap();
    // a record whose claim never happened, and a file of an older holefill
    fs::write(
        dead.dir.join("x-9.json"),
        serde_json::to_vec(&job.rec).unwrap(),
    )
    .unwrap();
    fs::write(dead.dir.join("old.obj"), "o").unwrap();
    drop(job);
    let dead = Arc::try_unwrap(dead).unwrap();
    drop(dead);
    let h = Arc::new(Home::adopt(&l, "h-5-d").unwrap().unwrap());
    let mut jobs = jobs_of(&h, &id);
    jobs.sort_by(|a, b| a.name.cmp(&b.name));
    assert_eq!(jobs.len(), 2, "{jobs:?}");
    assert_eq!((jobs[0].name.to_str(), jobs[0].attempt), (Some("a.obj"), 3));
    assert_eq!(
        (jobs[1].name.to_str(), jobs[1].attempt),
        (Some("old.obj"), 2)
    );
    assert!(!h.dir.join("x-9.json").exists());
    assert!(jobs[1].path().is_file() && jobs[1].record_path().is_file());
}
