//! What an operator reads: `OUTBOX/index.html`, a static page of the recent repairs
//! (newest first: status, holes filled/skipped/failed, time, the picture as a
//! thumbnail linking to the full image and the JSON log), kept by the daemon, and
//! `holefill report DIR`, the same summary as a table in the terminal. Both are made
//! from the repair logs (`NAME.repair.json`), so they say what the logs say.

use super::fsops;
use serde_json::Value;
use std::collections::VecDeque;
use std::fs;
use std::path::{Component, Path, PathBuf};
use std::time::{Duration, Instant, SystemTime};

/// Logs larger than this are not read (a repair log is a few kB per hole).
const MAX_LOG_BYTES: u64 = 32 << 20;

/// A repair log (JSON) and its modification time; `None` when it cannot be read, is
/// not JSON or is implausibly large.
pub fn read_log(path: &Path) -> Option<(Value, SystemTime)> {
    let md = fs::metadata(path).ok()?;
    if !md.is_file() || md.len() > MAX_LOG_BYTES {
        return None;
    }
    let v: Value = serde_json::from_slice(&fs::read(path).ok()?).ok()?;
    Some((v, md.modified().unwrap_or(SystemTime::UNIX_EPOCH)))
}

/// One repair, as its log tells it.
#[derive(Clone, Debug, PartialEq)]
pub struct Entry {
    /// The input's name, escaped (as in the journal).
    pub name: String,
    /// `repaired` or `failed` (a log of `holefill fill --report`: `repaired`).
    pub status: String,
    /// Where a failed file failed, and why.
    pub stage: Option<String>,
    pub error: Option<String>,
    pub filled: u64,
    pub skipped: u64,
    pub failed: u64,
    /// Seconds of the repair (the daemon's attempt; for a log of `holefill fill`, its
    /// read, fill and write times).
    pub seconds: Option<f64>,
    /// When it finished (RFC 3339, UTC); the log's modification time when it does
    /// not say.
    pub finished: String,
    pub log: PathBuf,
    /// The repaired model, when it is where the log says.
    pub model: Option<PathBuf>,
    /// `LOG_BASE.repair.png` beside the log, when there.
    pub picture: Option<PathBuf>,
}

impl Entry {
    /// Reads the log at `path`; `None` when it is not a readable repair log.
    pub fn read(path: &Path) -> Option<Entry> {
        let (v, mtime) = read_log(path)?;
        Entry::from_log(path, &v, mtime)
    }

    /// The entry of a parsed log at `path` (modified at `mtime`).
    pub fn from_log(path: &Path, v: &Value, mtime: SystemTime) -> Option<Entry> {
        v.as_object()?;
        let s = |p: &str| v.pointer(p).and_then(Value::as_str).map(str::to_string);
        let n = |k: &str| {
            v.pointer(&format!("/summary/{k}"))
                .and_then(Value::as_u64)
                .unwrap_or(0)
        };
        let file = path.file_name()?.to_string_lossy().into_owned();
        let base = file.strip_suffix(".repair.json")?.to_string();
        let name = s("/daemon/input")
            .or_else(|| {
                s("/input/path").map(|p| {
                    Path::new(&p)
                        .file_name()
                        .map(|n| n.to_string_lossy().into_owned())
                        .unwrap_or(p)
                })
            })
            .unwrap_or_else(|| base.clone());
        let status = s("/status").unwrap_or_else(|| "repaired".to_string());
        let seconds = v
            .pointer("/daemon/seconds")
            .and_then(Value::as_f64)
            .or_else(|| {
                let t = |k: &str| v.pointer(&format!("/timings/{k}")).and_then(Value::as_f64);
                let sum: f64 = ["read_ms", "smooth_ms", "fill_ms", "write_ms"]
                    .iter()
                    .filter_map(|k| t(k))
                    .sum();
                t("fill_ms").map(|_| sum / 1000.0)
            });
        let dir = path.parent().unwrap_or(Path::new("."));
        let model = (status == "repaired")
            .then(|| dir.join(&base))
            .filter(|p| p.is_file());
        let picture = Some(dir.join(format!("{base}.repair.png"))).filter(|p| p.is_file());
        Some(Entry {
            name,
            stage: s("/stage"),
            error: s("/error"),
            filled: n("filled"),
            skipped: n("skipped"),
            failed: n("failed"),
            seconds,
            finished: s("/daemon/finished").unwrap_or_else(|| fsops::rfc3339(mtime)),
            status,
            log: path.to_path_buf(),
            model,
            picture,
        })
    }
}

/// The newest `limit` readable repair logs of the folders (by modification time; 0:
/// all), newest first by their finish time.
pub fn scan(dirs: &[&Path], limit: usize) -> Vec<Entry> {
    let mut logs: Vec<(SystemTime, PathBuf)> = Vec::new();
    for dir in dirs {
        let Ok(rd) = fs::read_dir(dir) else { continue };
        for e in rd.flatten() {
            let name = e.file_name();
            let n = name.as_encoded_bytes();
            if n.starts_with(b".") || !n.ends_with(b".repair.json") {
                continue;
            }
            let Ok(md) = e.metadata() else { continue };
            if md.is_file() {
                let t = md.modified().unwrap_or(SystemTime::UNIX_EPOCH);
                logs.push((t, e.path()));
            }
        }
    }
    logs.sort_by_key(|l| std::cmp::Reverse(l.0));
    let limit = if limit == 0 { usize::MAX } else { limit };
    let mut v: Vec<Entry> = logs
        .iter()
        .filter_map(|(_, p)| Entry::read(p))
        .take(limit)
        .collect();
    sort_newest_first(&mut v);
    v
}

fn sort_newest_first(v: &mut [Entry]) {
    v.sort_by(|a, b| b.finished.cmp(&a.finished).then(a.name.cmp(&b.name)));
}

/// The entries as a table for the terminal.
pub fn table(entries: &[Entry]) -> String {
    let mut out = String::new();
    let name_w = entries
        .iter()
        .map(|e| e.name.chars().count())
        .max()
        .unwrap_or(4)
        .clamp(4, 48);
    out.push_str(&format!(
        "{:<24} {:<name_w$} {:<8} {:>6} {:>7} {:>6} {:>8}  {}\n",
        "finished", "file", "status", "filled", "skipped", "failed", "seconds", "picture / error"
    ));
    for e in entries {
        let name: String = if e.name.chars().count() > name_w {
            let tail: String = e
                .name
                .chars()
                .skip(e.name.chars().count() - (name_w - 1))
                .collect();
            format!("…{tail}")
        } else {
            e.name.clone()
        };
        let secs = e
            .seconds
            .map(|s| format!("{s:.2}"))
            .unwrap_or_else(|| "-".into());
        let last = if e.status == "failed" {
            format!(
                "{}: {}",
                e.stage.as_deref().unwrap_or("?"),
                e.error.as_deref().unwrap_or("")
            )
        } else {
            e.picture
                .as_ref()
                .map(|p| p.display().to_string())
                .unwrap_or_else(|| "-".into())
        };
        let (f, s, x) = if e.status == "failed" {
            ("-".to_string(), "-".to_string(), "-".to_string())
        } else {
            (
                e.filled.to_string(),
                e.skipped.to_string(),
                e.failed.to_string(),
            )
        };
        out.push_str(&format!(
            "{:<24} {:<name_w$} {:<8} {:>6} {:>7} {:>6} {:>8}  {}\n",
            e.finished, name, e.status, f, s, x, secs, last
        ));
    }
    let repaired = entries.iter().filter(|e| e.status == "repaired").count();
    let holes_failed: u64 = entries.iter().map(|e| e.failed).sum();
    out.push_str(&format!(
        "{} files: {} repaired ({} with holes left open), {} failed; holes {} filled, {} skipped, {} failed\n",
        entries.len(),
        repaired,
        entries.iter().filter(|e| e.status == "repaired" && e.failed > 0).count(),
        entries.len() - repaired,
        entries.iter().map(|e| e.filled).sum::<u64>(),
        entries.iter().map(|e| e.skipped).sum::<u64>(),
        holes_failed,
    ));
    out
}

/// `text` escaped for HTML.
fn esc(text: &str) -> String {
    let mut o = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => o.push_str("&amp;"),
            '<' => o.push_str("&lt;"),
            '>' => o.push_str("&gt;"),
            '"' => o.push_str("&quot;"),
            '\'' => o.push_str("&#39;"),
            c => o.push(c),
        }
    }
    o
}

/// A relative URL of `target` seen from the folder `from` (both absolute; else the
/// absolute path as a `file://` URL), every byte outside the unreserved set and `/`
/// percent-encoded.
fn href(from: &Path, target: &Path) -> String {
    let rel = relative(from, target);
    let (prefix, path) = match &rel {
        Some(r) => ("", r.as_os_str()),
        None => ("file://", target.as_os_str()),
    };
    let mut o = String::from(prefix);
    for &b in path.as_encoded_bytes() {
        if b.is_ascii_alphanumeric() || b"-._~/".contains(&b) {
            o.push(b as char);
        } else {
            o.push_str(&format!("%{b:02X}"));
        }
    }
    o
}

/// `target` relative to the folder `from`, when both are absolute and plain.
fn relative(from: &Path, target: &Path) -> Option<PathBuf> {
    let plain = |p: &Path| {
        p.is_absolute()
            && p.components()
                .all(|c| matches!(c, Component::RootDir | Component::Normal(_)))
    };
    if !plain(from) || !plain(target) {
        return None;
    }
    let a: Vec<_> = from.components().collect();
    let b: Vec<_> = target.components().collect();
    let common = a.iter().zip(&b).take_while(|(x, y)| x == y).count();
    let mut r = PathBuf::new();
    for _ in common..a.len() {
        r.push("..");
    }
    for c in &b[common..] {
        r.push(c.as_os_str());
    }
    Some(r)
}

/// The index page of `entries` for a page in the folder `outbox`.
pub fn html(entries: &[Entry], outbox: &Path, now: SystemTime) -> String {
    let mut o = String::with_capacity(1024 + entries.len() * 700);
    let repaired = entries.iter().filter(|e| e.status == "repaired").count();
    o.push_str(concat!(
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\n",
        "<meta http-equiv=\"refresh\" content=\"30\">\n",
        "<title>holefill: recent repairs</title>\n<style>\n",
        "body{font-family:system-ui,sans-serif;margin:1.5em;background:#fafafa;color:#222}\n",
        "table{border-collapse:collapse}td,th{padding:.35em .7em;border-bottom:1px solid #ddd;text-align:left;vertical-align:middle}\n",
        "th{background:#eee}td.n{text-align:right;font-variant-numeric:tabular-nums}\n",
        ".repaired{color:#1e8449;font-weight:600}.failed{color:#c0392b;font-weight:600}.partial{color:#b9770e;font-weight:600}\n",
        "img{width:160px;border:1px solid #ccc;display:block}.err{color:#c0392b;font-size:90%;max-width:40em}\n",
        "</style></head><body>\n",
    ));
    o.push_str(&format!(
        "<h1>holefill: recent repairs</h1>\n<p>{} files, newest first: {} repaired, {} failed. Updated {} (holefill {}).</p>\n",
        entries.len(),
        repaired,
        entries.len() - repaired,
        esc(&fsops::rfc3339(now)),
        env!("CARGO_PKG_VERSION"),
    ));
    o.push_str("<table>\n<tr><th>picture</th><th>file</th><th>status</th><th>filled</th><th>skipped</th><th>failed</th><th>seconds</th><th>finished (UTC)</th><th>log</th></tr>\n");
    for e in entries {
        let pic = match &e.picture {
            Some(p) => {
                let h = href(outbox, p);
                format!(
                    "<a href=\"{h}\"><img src=\"{h}\" loading=\"lazy\" alt=\"repair of {}\"></a>",
                    esc(&e.name)
                )
            }
            None => String::from("-"),
        };
        let file = match &e.model {
            Some(m) => format!("<a href=\"{}\">{}</a>", href(outbox, m), esc(&e.name)),
            None => esc(&e.name),
        };
        let (class, status) = match e.status.as_str() {
            "failed" => (
                "failed",
                format!("failed ({})", e.stage.as_deref().unwrap_or("?")),
            ),
            _ if e.failed > 0 => ("partial", "repaired, holes left open".to_string()),
            s => ("repaired", s.to_string()),
        };
        let err = e
            .error
            .as_deref()
            .map(|m| format!("<div class=\"err\">{}</div>", esc(m)))
            .unwrap_or_default();
        let holes = |n: u64| {
            if e.status == "failed" {
                "-".to_string()
            } else {
                n.to_string()
            }
        };
        o.push_str(&format!(
            "<tr><td>{pic}</td><td>{file}</td><td><span class=\"{class}\">{}</span>{err}</td><td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td><td>{}</td><td><a href=\"{}\">json</a></td></tr>\n",
            esc(&status),
            holes(e.filled),
            holes(e.skipped),
            holes(e.failed),
            e.seconds.map(|s| format!("{s:.2}")).unwrap_or_else(|| "-".into()),
            esc(&e.finished.replace('T', " ")),
            href(outbox, &e.log),
        ));
    }
    o.push_str("</table>\n</body></html>\n");
    o
}

/// The daemon's index: the recent entries, written to `OUTBOX/index.html` at most
/// once a second after a change.
pub struct Index {
    outbox: PathBuf,
    cap: usize,
    entries: VecDeque<Entry>,
    dirty: bool,
    written: Option<Instant>,
    /// The last error, so that a folder that cannot be written is said once.
    failing: bool,
}

/// Shortest time between two writes of the page.
const EVERY: Duration = Duration::from_secs(1);

impl Index {
    /// The index of the newest `cap` logs in the outbox and the failed folder.
    pub fn load(outbox: &Path, failed: &Path, cap: usize) -> Index {
        let mut entries: VecDeque<Entry> = scan(&[outbox, failed], cap).into();
        entries.truncate(cap);
        Index {
            outbox: outbox.to_path_buf(),
            cap,
            entries,
            dirty: true,
            written: None,
            failing: false,
        }
    }

    /// Adds the log just published at `path` (`log`: as read by [`read_log`]).
    pub fn add(&mut self, path: &Path, log: Option<&(Value, SystemTime)>) {
        let Some(e) = log.and_then(|(v, t)| Entry::from_log(path, v, *t)) else {
            tracing::debug!("index: {} is not a readable repair log", path.display());
            return;
        };
        self.entries.retain(|x| x.log != e.log);
        self.entries.push_front(e);
        self.entries.truncate(self.cap);
        self.dirty = true;
    }

    /// The picture of the entry of the log at `log`, published after its log.
    pub fn picture(&mut self, log: &Path, picture: PathBuf) {
        if let Some(e) = self.entries.iter_mut().find(|e| e.log == log) {
            e.picture = Some(picture);
            self.dirty = true;
        }
    }

    /// Writes the page when it changed and the last write is old enough (`force`: at
    /// once, at shutdown).
    pub fn flush(&mut self, force: bool) {
        if !self.dirty {
            return;
        }
        if !force && self.written.is_some_and(|t| t.elapsed() < EVERY) {
            return;
        }
        self.written = Some(Instant::now());
        let v: Vec<Entry> = self.entries.iter().cloned().collect();
        let page = html(&v, &self.outbox, SystemTime::now());
        match holefill::io::write_atomic(&self.outbox.join("index.html"), page.as_bytes()) {
            Ok(()) => {
                self.dirty = false;
                if self.failing {
                    tracing::info!(
                        "the index {} is written again",
                        self.outbox.join("index.html").display()
                    );
                }
                self.failing = false;
            }
            Err(e) => {
                if !self.failing {
                    tracing::error!("cannot write the index: {e} (said once until it works again)");
                }
                self.failing = true;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn relative_links_and_escaping() {
        assert_eq!(
            relative(Path::new("/a/out"), Path::new("/a/failed/x.json")),
            Some(PathBuf::from("../failed/x.json"))
        );
        assert_eq!(
            relative(Path::new("/a/out"), Path::new("/a/out/x")),
            Some(PathBuf::from("x"))
        );
        assert_eq!(
            href(Path::new("/o"), Path::new("/o/a b<\".obj")),
            "a%20b%3C%22.obj"
        );
        assert_eq!(href(Path::new("rel"), Path::new("/o/x")), "file:///o/x");
        assert_eq!(esc("<a href='x'>&"), "&lt;a href=&#39;x&#39;&gt;&amp;");
    }

    #[test]
    fn entries_from_daemon_and_fill_logs() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let daemon_log = json!({
            "status": "repaired", "stage": null, "error": null,
            "summary": {"holes": 3, "filled": 2, "skipped": 0, "failed": 1},
            "daemon": {"input": "a.obj", "finished": "2020-01-01T10:00:01.000Z", "seconds": 1.5}
        });
        let failed_log = json!({
            "status": "failed", "stage": "input", "error": "bad <face>",
            "daemon": {"input": "b.obj", "finished": "2020-01-01T10:00:02.000Z", "seconds": 0.1}
        });
        let fill_log = json!({
            "input": {"path": "/x/c.obj", "format": "obj"},
            "summary": {"holes": 1, "filled": 1, "skipped": 0, "failed": 0},
            "timings": {"read_ms": 10.0, "smooth_ms": 0.0, "fill_ms": 20.0, "write_ms": 10.0}
        });
        fs::write(d.join("a.obj"), "model").unwrap();
        fs::write(d.join("a.obj.repair.png"), "png").unwrap();
        fs::write(d.join("a.obj.repair.json"), daemon_log.to_string()).unwrap();
        fs::write(d.join("b.obj.repair.json"), failed_log.to_string()).unwrap();
        fs::write(d.join("c.obj.repair.json"), fill_log.to_string()).unwrap();
        fs::write(d.join("junk.repair.json"), "not json").unwrap();
        fs::write(d.join(".hidden.repair.json"), daemon_log.to_string()).unwrap();
        let v = scan(&[d], 0);
        let names: Vec<&str> = v.iter().map(|e| e.name.as_str()).collect();
        // the fill log's time is its modification time: now, the newest
        assert_eq!(names, vec!["c.obj", "b.obj", "a.obj"]);
        let a = &v[2];
        assert_eq!((a.filled, a.skipped, a.failed), (2, 0, 1));
        assert_eq!(a.model.as_deref(), Some(d.join("a.obj").as_path()));
        assert_eq!(
            a.picture.as_deref(),
            Some(d.join("a.obj.repair.png").as_path())
        );
        assert_eq!(v[1].status, "failed");
        assert_eq!(v[1].error.as_deref(), Some("bad <face>"));
        assert!((v[0].seconds.unwrap() - 0.04).abs() < 1e-9);
        // modification times: a, b, c in that order, the junk newest
        let now = SystemTime::now();
        for (k, n) in ["a.obj", "b.obj", "c.obj"].iter().enumerate() {
            let f = fs::File::options()
                .write(true)
                .open(d.join(format!("{n}.repair.json")))
                .unwrap();
            f.set_modified(now - Duration::from_secs(30 - 10 * k as u64))
                .unwrap();
        }
        fs::write(d.join("newer-junk.repair.json"), "[]").unwrap();
        let newest = scan(&[d], 1);
        assert_eq!(newest.len(), 1, "the newest readable one only");
        assert_eq!(newest[0].name, "c.obj");

        let t = table(&v);
        assert_eq!(t.lines().count(), 5, "{t}");
        assert!(t.contains("input: bad <face>"), "{t}");
        assert!(t.contains("3 files: 2 repaired (1 with holes left open), 1 failed; holes 3 filled, 0 skipped, 1 failed"), "{t}");

        let page = html(&v, d, SystemTime::now());
        assert_eq!(page.matches("<tr><td>").count(), 3);
        assert!(page.contains("<img src=\"a.obj.repair.png\""));
        assert!(page.contains("bad &lt;face&gt;"));
        assert!(page.contains("href=\"b.obj.repair.json\""));
        assert!(page.contains("repaired, holes left open"));
    }

    #[test]
    fn the_index_keeps_the_newest_and_writes_at_most_once_a_second() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out");
        let failed = dir.path().join("failed");
        fs::create_dir_all(&out).unwrap();
        fs::create_dir_all(&failed).unwrap();
        let mut ix = Index::load(&out, &failed, 2);
        ix.flush(false);
        let page = || fs::read_to_string(out.join("index.html")).unwrap();
        assert!(page().contains("0 files"));
        for (i, n) in ["x", "y", "z"].iter().enumerate() {
            let p = out.join(format!("{n}.obj.repair.json"));
            let v = json!({"status": "repaired", "summary": {"filled": 1},
                "daemon": {"input": format!("{n}.obj"), "finished": format!("2026-12-03T10:00:0{i}.000Z")}});
            fs::write(&p, v.to_string()).unwrap();
            ix.add(&p, read_log(&p).as_ref());
        }
        ix.flush(false);
        assert!(page().contains("0 files"), "written less than a second ago");
        ix.flush(true);
        let p = page();
        assert!(p.contains("2 files"), "{p}");
        assert!(p.find("z.obj").unwrap() < p.find("y.obj").unwrap());
        assert!(!p.contains("x.obj"));
    }
}
