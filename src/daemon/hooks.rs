//! Test-only hooks, compiled only with the cargo feature `test-hooks` (the integration
//! tests enable it; `cargo build --release` leaves it out, and a build without it
//! ignores the variables, with a warning at start). Read from the daemon's
//! environment at start:
//!
//! - `HOLEFILL_TEST_SLOW=SUBSTR:MS`: the worker of every file whose name contains
//!   SUBSTR sleeps MS milliseconds before the repair (an empty SUBSTR matches all);
//! - `HOLEFILL_TEST_SLOW_PICTURE=SUBSTR:MS`: that worker sleeps MS milliseconds after
//!   it wrote the model and the log, before it draws the picture;
//! - `HOLEFILL_TEST_CRASH_ON=SUBSTR`: that worker kills itself with SIGKILL (as the
//!   kernel's OOM killer would);
//! - `HOLEFILL_TEST_DIE_AT=POINT[:SUBSTR]`: the daemon itself dies (SIGKILL) when the
//!   file reaches POINT, one of the named steps of its handling (see [`POINTS`]);
//! - `HOLEFILL_TEST_PAUSE_AT=POINT:MS[:SUBSTR]`: the daemon (or the queue worker, at
//!   `chunks`) sleeps MS milliseconds at POINT (to widen a race window on purpose).

use std::ffi::OsStr;

/// The child's variable for `HOLEFILL_TEST_SLOW_PICTURE` (read by `holefill fill`
/// built with the feature).
pub const PICTURE_SLEEP_MS: &str = "HOLEFILL_TEST_PICTURE_SLEEP_MS";

/// The named steps a test can stop the daemon at.
pub const POINTS: &[&str] = &[
    // the claim: the file is in the processing folder, its record written
    "claimed",
    // the repair is done; the record says which output and archive names it takes
    "committing",
    // the model is in the outbox, its log is not
    "model-published",
    // the other files of its set are in the outbox too (copies), the originals not
    // yet archived
    "members-published",
    // the original is in the archive (across file systems: the copy is linked there
    // and the original not yet removed from the processing folder)
    "archive-linked",
    // the original is archived (or deleted), the log not yet published
    "archived",
    // the log is published, the record not yet removed
    "log-published",
    // a failed file is in the failed folder, its log not yet written
    "failed-moved",
    // just before a file is moved into a shared folder (inbox, failed, archive)
    "move",
    // the queue worker: an object's info and stream are read, the consumer of its
    // chunks not yet made (the pause only; the worker sleeps without blocking)
    "chunks",
];

/// The hooks in force (all empty without the `test-hooks` feature).
#[derive(Clone, Debug, Default)]
pub struct Hooks {
    #[cfg(feature = "test-hooks")]
    slow: Option<(String, u64)>,
    #[cfg(feature = "test-hooks")]
    slow_picture: Option<(String, u64)>,
    #[cfg(feature = "test-hooks")]
    crash_on: Option<String>,
    #[cfg(feature = "test-hooks")]
    die_at: Option<(String, String)>,
    #[cfg(feature = "test-hooks")]
    pause_at: Option<(String, u64, String)>,
}

const VARS: [&str; 5] = [
    "HOLEFILL_TEST_SLOW",
    "HOLEFILL_TEST_SLOW_PICTURE",
    "HOLEFILL_TEST_CRASH_ON",
    "HOLEFILL_TEST_DIE_AT",
    "HOLEFILL_TEST_PAUSE_AT",
];

impl Hooks {
    /// Reads the variables (see the module documentation).
    #[cfg(feature = "test-hooks")]
    pub fn from_env() -> Hooks {
        let var = |k: &str| std::env::var(k).ok().filter(|s| !s.is_empty());
        let sub_ms = |v: String| {
            let (s, ms) = v.rsplit_once(':')?;
            Some((s.to_string(), ms.parse().ok()?))
        };
        let slow = var("HOLEFILL_TEST_SLOW").and_then(sub_ms);
        let slow_picture = var("HOLEFILL_TEST_SLOW_PICTURE").and_then(sub_ms);
        let die_at = var("HOLEFILL_TEST_DIE_AT").map(|v| match v.split_once(':') {
            Some((p, s)) => (p.to_string(), s.to_string()),
            None => (v, String::new()),
        });
        let pause_at = var("HOLEFILL_TEST_PAUSE_AT").and_then(|v| {
            let mut it = v.splitn(3, ':');
            let p = it.next()?.to_string();
            let ms = it.next()?.parse().ok()?;
            Some((p, ms, it.next().unwrap_or("").to_string()))
        });
        Hooks {
            slow,
            slow_picture,
            crash_on: var("HOLEFILL_TEST_CRASH_ON"),
            die_at,
            pause_at,
        }
    }

    /// Without the feature: none (the variables are ignored).
    #[cfg(not(feature = "test-hooks"))]
    pub fn from_env() -> Hooks {
        Hooks::default()
    }

    /// A warning for the journal when a variable is set: active hooks, or variables
    /// this build ignores.
    pub fn warning(&self) -> Option<String> {
        let set: Vec<&str> = VARS
            .iter()
            .copied()
            .filter(|k| std::env::var_os(k).is_some_and(|v| !v.is_empty()))
            .collect();
        if set.is_empty() {
            return None;
        }
        if cfg!(feature = "test-hooks") {
            Some(format!("test hooks active ({}): {self:?}", set.join(", ")))
        } else {
            Some(format!(
                "{} ignored: this build has no test hooks",
                set.join(", ")
            ))
        }
    }

    /// Shell commands the worker's wrapper script runs before the repair.
    pub fn worker_prefix(&self, name: &str) -> String {
        #[cfg(feature = "test-hooks")]
        {
            let mut s = String::new();
            if let Some((sub, ms)) = &self.slow {
                if name.contains(sub.as_str()) {
                    s.push_str(&format!("sleep {}.{:03}; ", ms / 1000, ms % 1000));
                }
            }
            if let Some((sub, ms)) = &self.slow_picture {
                if name.contains(sub.as_str()) {
                    s.push_str(&format!("export {PICTURE_SLEEP_MS}={ms}; "));
                }
            }
            if let Some(sub) = &self.crash_on {
                if name.contains(sub.as_str()) {
                    s.push_str("kill -KILL $$; ");
                }
            }
            s
        }
        #[cfg(not(feature = "test-hooks"))]
        {
            let _ = name;
            String::new()
        }
    }

    /// How long to pause at `point` with the file `name` (`HOLEFILL_TEST_PAUSE_AT`),
    /// logged; the caller sleeps.
    pub fn pause(&self, point: &str, name: &OsStr) -> Option<std::time::Duration> {
        debug_assert!(POINTS.contains(&point), "{point}");
        #[cfg(feature = "test-hooks")]
        if let Some((p, ms, sub)) = &self.pause_at {
            if p == point && name.to_string_lossy().contains(sub.as_str()) {
                tracing::warn!("test hook: pausing {ms} ms at {point}");
                return Some(std::time::Duration::from_millis(*ms));
            }
        }
        let _ = (point, name);
        None
    }

    /// The daemon reached `point` with the file `name`: die or pause if asked to.
    pub fn at(&self, point: &str, name: &OsStr) {
        // `pause` checks that `point` is one of POINTS
        if let Some(d) = self.pause(point, name) {
            std::thread::sleep(d);
        }
        #[cfg(feature = "test-hooks")]
        {
            let n = name.to_string_lossy();
            if let Some((p, sub)) = &self.die_at {
                if p == point && n.contains(sub.as_str()) {
                    eprintln!("test hook: dying at {point}");
                    let _ = rustix::process::kill_process(
                        rustix::process::getpid(),
                        rustix::process::Signal::KILL,
                    );
                }
            }
        }
        #[cfg(not(feature = "test-hooks"))]
        let _ = (point, name);
    }
}
