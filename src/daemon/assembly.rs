//! The waiting sets: a claimed mesh's members judged (missing, not complete,
//! complete) and claimed beside it once the set is complete or timed out.

use super::claim;
use super::fsops::shown;
use super::queue::MemberState;
use super::sets::{self, Member, Missing, Refused, Role, SetRec};
use super::{Assembly, Daemon, Parked};
use std::ffi::OsStr;
use std::time::Instant;

impl Daemon {
    /// Looks at the waiting sets: claims the members of each complete set (or of one
    /// that timed out) beside its mesh and starts it, while fewer than `workers`
    /// repairs run.
    pub(super) fn advance_sets(&mut self) {
        let now = Instant::now();
        let mut keep = Vec::new();
        for mut p in std::mem::take(&mut self.sets) {
            if self.working.len() >= self.settings.workers {
                keep.push(p);
                continue;
            }
            let set = match self.assemble(&mut p, now) {
                Assembly::Wait(what) => {
                    if what != p.said {
                        tracing::info!(file = %p.job.shown(), "{}: its set waits for {what}", p.job.shown());
                        p.said = what;
                    }
                    keep.push(p);
                    continue;
                }
                Assembly::TimedOut(set) => {
                    tracing::warn!(file = %p.job.shown(), "{}: {} after set_wait_secs = {} s; the set goes to failed", p.job.shown(), set.missing_message(), self.settings.set_wait.as_secs());
                    set
                }
                Assembly::Complete(set) => set,
            };
            let names: Vec<String> = set
                .members
                .iter()
                .map(|m| shown(OsStr::new(&m.name)))
                .collect();
            match claim::claim_members(&self.layout, &mut p.job, set) {
                Ok(true) => {
                    tracing::info!(file = %p.job.shown(), "{}: its set is complete: {}", p.job.shown(), if names.is_empty() { "no other file".to_string() } else { names.join(", ") });
                    self.spawn(p.job);
                }
                Ok(false) => {
                    tracing::info!(file = %p.job.shown(), "{}: a file of its set changed or went while it was taken; it waits again", p.job.shown());
                    keep.push(p);
                }
                Err(e) => {
                    tracing::warn!(file = %p.job.shown(), "{}: cannot take the files of its set: {e}; later", p.job.shown());
                    keep.push(p);
                }
            }
        }
        keep.append(&mut self.sets);
        self.sets = keep;
    }

    /// Judges the files of a waiting set (see [`sets`]): references followed or not,
    /// each member missing, not complete, or complete (an MTL read once complete, its
    /// images added).
    fn assemble(&mut self, p: &mut Parked, now: Instant) -> Assembly {
        let inbox = self.layout.inbox.clone();
        let (settle, max_wait) = (self.settings.settle, self.settings.max_wait);
        let mesh = p.job.name_str().unwrap_or_default().to_string();
        let mut set = SetRec::default();
        let mut not_yet: Vec<String> = Vec::new();
        let mut wanted: Vec<(String, Role, String)> = Vec::new();
        for (r, role) in &p.refs {
            if *role == Role::MaterialLibrary {
                // a whole name with spaces is looked for only when it is one to follow
                let exists = |w: &str| {
                    sets::member_name(w, &mesh).is_ok()
                        && std::fs::symlink_metadata(inbox.join(w)).is_ok()
                };
                for n in sets::split_libs(r, exists) {
                    wanted.push((n, Role::MaterialLibrary, mesh.clone()));
                }
            } else {
                wanted.push((r.clone(), *role, mesh.clone()));
            }
        }
        let mut k = 0;
        while k < wanted.len() {
            let (reference, role, by) = wanted[k].clone();
            k += 1;
            let name = match sets::member_name(&reference, &mesh) {
                Ok(n) => n,
                Err(why) => {
                    set.refused.push(Refused { reference, by, why });
                    continue;
                }
            };
            if set.members.iter().any(|m| m.name == name)
                || set.missing.iter().any(|m| m.name == name)
                || not_yet.contains(&name)
            {
                continue;
            }
            let state = self
                .pending
                .member_state(&inbox, OsStr::new(&name), settle, max_wait, now);
            match state {
                MemberState::Missing => set.missing.push(Missing { name, role, by }),
                MemberState::NotRegular => set.refused.push(Refused {
                    reference,
                    by,
                    why: "not a regular file (a symbolic link, FIFO, ...): never followed".into(),
                }),
                MemberState::NotYet => not_yet.push(name),
                MemberState::Ready(stamp) => {
                    if role == Role::MaterialLibrary {
                        let images = match p.libs.get(&name) {
                            Some((st, imgs)) if *st == stamp => imgs.clone(),
                            _ => match sets::read_mtl(&inbox.join(&name)) {
                                Ok((imgs, st)) if st == stamp => {
                                    p.libs.insert(name.clone(), (st, imgs.clone()));
                                    imgs
                                }
                                // changed since it was judged: judged again
                                Ok(_) => {
                                    not_yet.push(name);
                                    continue;
                                }
                                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                                    set.missing.push(Missing { name, role, by });
                                    continue;
                                }
                                Err(e) => {
                                    set.refused.push(Refused {
                                        reference,
                                        by,
                                        why: format!("cannot be read: {e}"),
                                    });
                                    continue;
                                }
                            },
                        };
                        for img in images {
                            wanted.push((img, Role::Texture, name.clone()));
                        }
                    }
                    set.members.push(Member {
                        name,
                        role,
                        by,
                        stamp,
                        copy: None,
                        placed: None,
                    });
                }
            }
        }
        if set.members.len() > p.ready {
            p.ready = set.members.len();
            p.since = now;
        }
        if !set.missing.is_empty() && now.duration_since(p.since) >= self.settings.set_wait {
            return Assembly::TimedOut(set);
        }
        if !set.missing.is_empty() || !not_yet.is_empty() {
            let mut what: Vec<String> = set
                .missing
                .iter()
                .map(|m| format!("{} {} (missing)", m.role.what(), shown(OsStr::new(&m.name))))
                .collect();
            what.extend(
                not_yet
                    .iter()
                    .map(|n| format!("{} (not complete yet)", shown(OsStr::new(n)))),
            );
            return Assembly::Wait(what.join(", "));
        }
        Assembly::Complete(set)
    }
}
