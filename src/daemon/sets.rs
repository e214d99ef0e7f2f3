//! Multi-file sets: a mesh that names other files travels with them.
//!
//! An OBJ whose `mtllib` names material libraries is a set: the OBJ, each MTL file, and
//! each image an MTL names ([`holefill::io::attrs::mtl_images`]: `map_Kd`, `bump`,
//! `norm`, ..., options skipped). A PLY whose header says `comment TextureFile NAME` is
//! a set of the PLY and those images. References are read by [`super::sniff`] from the
//! claimed, open mesh (never by path) and from each MTL once it is complete in the inbox
//! (opened with `O_NOFOLLOW`, at most [`MAX_MTL_BYTES`] read).
//!
//! **Which references are followed.** Only plain file names of the inbox: `tex.jpg`
//! or `./tex.jpg`. An absolute path, a name with `..`, a name in a subfolder, a
//! dot-file, a name with control characters, a mesh's name (`.obj .ply .stl .off`, the
//! daemon's own candidates) and the set's own mesh are never followed: they are listed
//! in the log as not followed, with the reason, and the set goes on without them. A
//! hostile producer can therefore make the daemon read or move nothing outside the
//! inbox, and no symlink is followed (members are looked at with `lstat`, claimed by
//! `renameat2(RENAME_NOREPLACE)` as the mesh is, and only regular files are taken). An
//! `mtllib` argument with spaces names one file when a file of that whole name is in
//! the inbox, else one file per word (the OBJ specification's reading).
//!
//! **When.** The mesh is claimed as any file; seeing its references the daemon keeps
//! it in its processing folder and waits for the members, each judged complete by the
//! same rules as a mesh (no open writer, settled, not empty; [`super::queue`]). Once
//! all are complete they are claimed into the processing folder beside the mesh (the
//! job record lists them first, so that a crash at any point recovers the whole set),
//! and the mesh is repaired. A member still missing `set_wait_secs` after the mesh was
//! taken or the last member arrived fails the set: the mesh and the members that are
//! there go to the failed folder, the log says `missing texture X` or `missing
//! material library X`.
//!
//! **Where.** A set is published, archived or failed together: in the folder's root
//! when none of its names is taken there, else in a new subfolder `STEM.STAMP` made for
//! it (`mkdir`, so no other set shares it). Members keep their names and bytes, so the
//! written OBJ's `mtllib` and the MTL's image names still find them.

use super::fsops::{self, FileId, Stamp};
use serde::{Deserialize, Serialize};
use std::fs;
use std::io::{self, Read};
use std::path::Path;
use std::time::SystemTime;

/// The most of an MTL file read (its image names are in the first lines; a larger
/// file is read that far).
pub const MAX_MTL_BYTES: u64 = 4 << 20;

/// What a member is to its set.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Role {
    MaterialLibrary,
    Texture,
    /// A glTF buffer kept in a file of its own (`.bin`): read with the mesh.
    Buffer,
}

impl Role {
    /// For messages: `material library`, `texture`.
    pub fn what(self) -> &'static str {
        match self {
            Role::MaterialLibrary => "material library",
            Role::Texture => "texture",
            Role::Buffer => "buffer",
        }
    }
}

/// A member of a set, claimed beside its mesh as `ID.mN` (N its index).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Member {
    /// Its name in the inbox (a plain name, checked by [`member_name`]).
    pub name: String,
    pub role: Role,
    /// The file that names it (the mesh, or an MTL).
    pub by: String,
    /// Identity, size and modification time when judged complete in the inbox.
    pub stamp: Stamp,
    /// The copy made for the outbox (in the temporary folder, then published).
    #[serde(default)]
    pub copy: Option<FileId>,
    /// Where it went in the archive or the failed folder (relative), once moved.
    #[serde(default)]
    pub placed: Option<String>,
}

/// A reference that is not followed.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Refused {
    /// As written.
    pub reference: String,
    pub by: String,
    pub why: String,
}

/// A missing member (the set waits for it, then fails).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Missing {
    pub name: String,
    pub role: Role,
    pub by: String,
}

/// The set of a claimed mesh, as recorded in its job record.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SetRec {
    pub members: Vec<Member>,
    #[serde(default)]
    pub refused: Vec<Refused>,
    /// Non-empty: the set failed for these (after `set_wait_secs`).
    #[serde(default)]
    pub missing: Vec<Missing>,
}

impl SetRec {
    /// `missing texture a.jpg (named by s.mtl); missing material library s.mtl`.
    pub fn missing_message(&self) -> String {
        self.missing
            .iter()
            .map(|m| {
                format!(
                    "missing {} {} (named by {})",
                    m.role.what(),
                    fsops::shown(m.name.as_ref()),
                    fsops::shown(m.by.as_ref())
                )
            })
            .collect::<Vec<_>>()
            .join("; ")
    }
}

/// The inbox name a reference names, or why it is not followed.
pub fn member_name(reference: &str, mesh: &str) -> Result<String, String> {
    let r = reference.trim();
    if r.is_empty() {
        return Err("an empty name".into());
    }
    if r.starts_with('/') {
        return Err("an absolute path: only files in the inbox are taken".into());
    }
    if r.contains('\\') {
        return Err("a path with backslashes: only files in the inbox are taken".into());
    }
    let mut parts: Vec<&str> = r
        .split('/')
        .filter(|p| !p.is_empty() && *p != ".")
        .collect();
    if parts.contains(&"..") {
        return Err("a path with `..`: only files in the inbox are taken".into());
    }
    if parts.len() != 1 {
        return Err(
            "a file in a subfolder: the daemon takes only files directly in the inbox".into(),
        );
    }
    let name = parts.remove(0);
    if name.starts_with('.') {
        return Err("a dot-file (ignored in the inbox)".into());
    }
    if name.chars().any(|c| c.is_control()) {
        return Err("a name with control characters".into());
    }
    if let Some(p) = fsops::name_problem(name.as_ref()) {
        return Err(p);
    }
    if name == mesh {
        return Err("the set's own mesh".into());
    }
    if super::claim::is_candidate_name(name.as_ref()) {
        return Err("a mesh file (taken as a file of its own)".into());
    }
    let lower = name.to_ascii_lowercase();
    if lower.ends_with(".part") || lower.ends_with(".tmp") || name.ends_with('~') {
        return Err("a temporary file's name (ignored in the inbox)".into());
    }
    Ok(name.to_string())
}

/// The file names an `mtllib` argument names: the whole argument when `whole_exists`
/// says a file of that name is there, else each word.
pub fn split_libs(arg: &str, whole_exists: impl Fn(&str) -> bool) -> Vec<String> {
    let arg = arg.trim();
    if !arg.contains(char::is_whitespace) || whole_exists(arg) {
        return vec![arg.to_string()];
    }
    arg.split_whitespace().map(str::to_string).collect()
}

/// Reads an MTL file without following a symlink: its image names and its stamp (the
/// open file's). `Err(InvalidInput)` for something that is not a regular file.
pub fn read_mtl(path: &Path) -> io::Result<(Vec<String>, Stamp)> {
    let f = fsops::open_nofollow(path)?;
    let m = f.metadata()?;
    if !m.is_file() {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            "not a regular file",
        ));
    }
    let mut bytes = Vec::new();
    (&f).take(MAX_MTL_BYTES).read_to_end(&mut bytes)?;
    let text = String::from_utf8_lossy(&bytes);
    Ok((holefill::io::attrs::mtl_images(&text), Stamp::of(&m)))
}

/// `rel`'s folder part joined with `name`: where a member goes beside its mesh
/// (`sub/scan.obj`, `scan.mtl` -> `sub/scan.mtl`).
pub fn beside(rel: &str, name: &str) -> String {
    match rel.rsplit_once('/') {
        Some((dir, _)) => format!("{dir}/{name}"),
        None => name.to_string(),
    }
}

/// True when `dir` has none of `names` (and no `mesh + suffix`).
pub fn all_free(dir: &Path, mesh: &str, suffixes: &[&str], names: &[&str]) -> bool {
    let taken = |n: &str| fs::symlink_metadata(dir.join(n)).is_ok();
    !taken(mesh)
        && !suffixes.iter().any(|s| taken(&format!("{mesh}{s}")))
        && !names.iter().any(|n| taken(n))
}

/// A subfolder name for a set of `mesh` in `dir` that does not exist yet:
/// `STEM.STAMP`, `STEM.STAMP-2`, ... (`skip` candidates passed over).
pub fn free_folder(dir: &Path, mesh: &str, when: SystemTime, skip: usize) -> String {
    let stem = match mesh.rfind('.') {
        Some(i) if i > 0 => &mesh[..i],
        _ => mesh,
    };
    let stamp = fsops::compact_stamp(when);
    let mut n = skip.max(1);
    loop {
        let cand = if n == 1 {
            format!("{stem}.{stamp}")
        } else {
            format!("{stem}.{stamp}-{n}")
        };
        if fs::symlink_metadata(dir.join(&cand)).is_err() {
            return cand;
        }
        n += 1;
    }
}

/// Makes `dir/sub` for a set (mode 0755), accepting a folder that is already there
/// (made before a crash). `Err` when something else is in its place.
pub fn ensure_folder(dir: &Path, sub: &str) -> io::Result<()> {
    use std::os::unix::fs::DirBuilderExt;
    let p = dir.join(sub);
    match fs::DirBuilder::new().mode(0o755).create(&p) {
        Ok(()) => fsops::fsync_dir(dir),
        Err(e) if e.kind() == io::ErrorKind::AlreadyExists => {
            if fs::symlink_metadata(&p).is_ok_and(|m| m.is_dir()) {
                Ok(())
            } else {
                Err(io::Error::new(
                    io::ErrorKind::AlreadyExists,
                    format!("{} is not a folder", p.display()),
                ))
            }
        }
        Err(e) => Err(e),
    }
}

/// Makes a new subfolder for a set of `mesh` in `dir` (never one that exists: `mkdir`
/// decides between daemons) and returns its name.
pub fn new_folder(dir: &Path, mesh: &str, when: SystemTime) -> io::Result<String> {
    use std::os::unix::fs::DirBuilderExt;
    let mut skip = 1;
    for _ in 0..1000 {
        let sub = free_folder(dir, mesh, when, skip);
        match fs::DirBuilder::new().mode(0o755).create(dir.join(&sub)) {
            Ok(()) => {
                fsops::fsync_dir(dir)?;
                return Ok(sub);
            }
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => skip += 1,
            Err(e) => return Err(e),
        }
    }
    Err(io::Error::other("no free folder name"))
}

/// Copies the claimed member `src` (a regular file, not followed) to `dst` (a new
/// file, fsynced) and returns the copy's identity; `Ok(None)` when the member is not
/// what was claimed any more (another inode, size or modification time).
pub fn copy_member(src: &Path, dst: &Path, stamp: Stamp) -> io::Result<Option<FileId>> {
    use std::os::unix::fs::OpenOptionsExt;
    let mut from = fsops::open_nofollow(src)?;
    let m = from.metadata()?;
    if !m.is_file() || Stamp::of(&m) != stamp {
        return Ok(None);
    }
    let _ = fs::remove_file(dst);
    let mut to = fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(0o644)
        .custom_flags(libc::O_NOFOLLOW)
        .open(dst)?;
    let r = io::copy(&mut from, &mut to).and_then(|_| to.sync_all());
    if let Err(e) = r {
        let _ = fs::remove_file(dst);
        return Err(e);
    }
    if from.metadata().map(|m| Stamp::of(&m)).ok() != Some(stamp) {
        let _ = fs::remove_file(dst);
        return Ok(None);
    }
    Ok(Some(FileId::of(&to.metadata()?)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_plain_names_of_the_inbox_are_followed() {
        assert_eq!(member_name("tex.jpg", "s.obj").as_deref(), Ok("tex.jpg"));
        assert_eq!(
            member_name("./tex 1.jpg", "s.obj").as_deref(),
            Ok("tex 1.jpg")
        );
        assert_eq!(member_name(" s.mtl ", "s.obj").as_deref(), Ok("s.mtl"));
        for (bad, why) in [
            ("../x.jpg", ".."),
            ("a/../../x.jpg", ".."),
            ("/etc/passwd", "absolute"),
            ("/abs/inbox/t.jpg", "absolute"),
            ("sub/t.jpg", "subfolder"),
            (".hidden.jpg", "dot-file"),
            ("a\nb.jpg", "control"),
            ("s.obj", "own mesh"),
            ("other.PLY", "mesh file"),
            ("t.jpg.part", "temporary"),
            ("..\\..\\x.jpg", "backslashes"),
            ("", "empty"),
        ] {
            let e = member_name(bad, "s.obj").unwrap_err();
            assert!(e.contains(why), "{bad:?}: {e}");
        }
    }

    #[test]
    fn mtllib_arguments_split_unless_the_whole_name_is_there() {
        assert_eq!(split_libs("a.mtl", |_| false), vec!["a.mtl"]);
        assert_eq!(split_libs("a.mtl b.mtl", |_| false), vec!["a.mtl", "b.mtl"]);
        assert_eq!(
            split_libs("my scan.mtl", |n| n == "my scan.mtl"),
            vec!["my scan.mtl"]
        );
    }

    #[test]
    fn places_and_copies() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path();
        assert_eq!(beside("s.obj", "s.mtl"), "s.mtl");
        assert_eq!(beside("s.X/s.obj", "s.mtl"), "s.X/s.mtl");
        assert!(all_free(p, "s.obj", &[".repair.json"], &["s.mtl"]));
        fs::write(p.join("s.mtl"), "x").unwrap();
        assert!(!all_free(p, "s.obj", &[".repair.json"], &["s.mtl"]));
        let t = std::time::UNIX_EPOCH + std::time::Duration::from_secs(1_795_435_501);
        let a = new_folder(p, "s.obj", t).unwrap();
        let b = new_folder(p, "s.obj", t).unwrap();
        assert_eq!(a, "s.20261123T120501Z");
        assert_eq!(b, "s.20261123T120501Z-2");
        ensure_folder(p, &a).unwrap();
        assert!(ensure_folder(p, "s.mtl").is_err(), "a file in its place");
        let st = Stamp::of(&fs::metadata(p.join("s.mtl")).unwrap());
        let id = copy_member(&p.join("s.mtl"), &p.join(&a).join("c"), st)
            .unwrap()
            .unwrap();
        assert_eq!(FileId::lstat(&p.join(&a).join("c")), Some(id));
        assert_eq!(fs::read_to_string(p.join(&a).join("c")).unwrap(), "x");
        fs::write(p.join("s.mtl"), "changed").unwrap();
        assert_eq!(
            copy_member(&p.join("s.mtl"), &p.join(&a).join("c2"), st).unwrap(),
            None
        );
        std::os::unix::fs::symlink(p.join("s.mtl"), p.join("l.mtl")).unwrap();
        assert!(
            read_mtl(&p.join("l.mtl")).is_err(),
            "a symlink is not followed"
        );
        fs::write(p.join("m.mtl"), "newmtl a\nmap_Kd -s 1 1 1 t.jpg\n").unwrap();
        assert_eq!(read_mtl(&p.join("m.mtl")).unwrap().0, vec!["t.jpg"]);
    }
}
