//! The `holefill` command: `fill` (one-shot), `check-policy`, `watch` (the daemon),
//! `worker`, `submit`, `results` (the NATS work queue), `report` (a table of repair
//! logs).
#![forbid(unsafe_code)]

mod daemon;
mod metrics;
mod worker;

use anyhow::Result;
use clap::{Parser, Subcommand};
use holefill::io::{Format, IoError};
use holefill::policy::Policy;
use holefill::report::{FileRef, HoleStatus};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::{Duration, Instant};

/// Exit statuses (sysexits.h), so that scripts can tell permanent from retryable failures.
pub mod exit {
    /// Every hole filled or skipped by a policy rule.
    pub const OK: u8 = 0;
    /// A usage error or an invalid policy given to `check-policy`.
    pub const USAGE: u8 = 1;
    /// Some hole failed; the output was written with those holes open.
    pub const HOLES_FAILED: u8 = 2;
    /// The input is unreadable or malformed; nothing was written (EX_DATAERR).
    pub const DATAERR: u8 = 65;
    /// An internal error (EX_SOFTWARE).
    pub const SOFTWARE: u8 = 70;
    /// An I/O error such as a full disk; nothing partial was left behind (EX_IOERR).
    pub const IOERR: u8 = 74;
    /// The policy is invalid (EX_CONFIG).
    pub const CONFIG: u8 = 78;
}

#[derive(Parser)]
#[command(
    name = "holefill",
    version,
    about = "Repairs scanned triangle meshes: closes every hole under a TOML policy"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Repair one mesh: fill its holes and write the result (and the repair log).
    Fill(FillArgs),
    /// Validate a policy file: exit 0 when valid, 1 with the error otherwise.
    CheckPolicy {
        /// The policy file.
        file: PathBuf,
    },
    /// Watch an inbox and repair every mesh dropped into it (the daemon).
    Watch(daemon::WatchArgs),
    /// Summarise the repair logs (`*.repair.json`) of a folder as a table, newest first.
    Report(ReportArgs),
    /// Repair scans from a NATS JetStream work queue (see docs/worker.md).
    Worker(worker::WorkerArgs),
    /// Upload meshes and put them on the work queue.
    Submit(worker::SubmitArgs),
    /// Download the finished scans of the work queue into a folder.
    Results(worker::ResultsArgs),
}

#[derive(clap::Args)]
struct ReportArgs {
    /// Folders holding repair logs (an outbox, a failed folder, ...).
    #[arg(required = true)]
    dirs: Vec<PathBuf>,
    /// Show only the newest N (0: all).
    #[arg(long, short = 'n', default_value_t = 0)]
    limit: usize,
}

#[derive(clap::Args)]
struct FillArgs {
    /// Input mesh (.obj .ply .stl .off).
    input: PathBuf,
    /// Output mesh; written atomically.
    output: PathBuf,
    /// Policy file (TOML); the built-in default policy when absent.
    #[arg(long)]
    policy: Option<PathBuf>,
    /// Write the repair log (JSON) here.
    #[arg(long)]
    report: Option<PathBuf>,
    /// Output format (obj, ply, stl, off); default: the output extension, else the input format.
    #[arg(long)]
    format: Option<String>,
    /// Input format (obj, ply, stl, off); default: the input extension. For an input
    /// without one, such as /dev/stdin (the daemon hands its workers the file it
    /// verified this way).
    #[arg(long)]
    input_format: Option<String>,
    /// A file the input names (a glTF buffer's uri, as written without `./` and `%XX`
    /// escapes) is read from PATH instead of beside the input (repeatable).
    #[arg(long, num_args = 2, value_names = ["NAME", "PATH"])]
    resource: Vec<PathBuf>,
    /// Read no file the input names but those given with --resource (the daemon).
    #[arg(long)]
    only_resources: bool,
    /// Print nothing but errors and the FILL_TIME_S line.
    #[arg(long, short)]
    quiet: bool,
    /// Refuse input files larger than this many bytes (0 = no limit).
    #[arg(long, default_value_t = 0)]
    max_file_bytes: u64,
    /// Refuse inputs with more faces (triangles after fanning) than this (0 = no limit).
    #[arg(long, default_value_t = 0)]
    max_faces: u64,
    /// Refuse inputs with more vertices than this (0 = no limit).
    #[arg(long, default_value_t = 0)]
    max_vertices: u64,
    /// Draw a picture of the repair (PNG): the model with every hole outlined and
    /// coloured by status, and each hole before and after.
    #[arg(long)]
    picture: Option<PathBuf>,
    /// With --picture and --report (the daemon's children): write the model and the
    /// log first, say so on standard output (`written CODE`), then draw the picture at
    /// the lowest CPU priority, so that a repair's publication never waits for it.
    #[arg(long, hide = true, requires_all = ["picture", "report"])]
    picture_after_log: bool,
}

fn main() -> ExitCode {
    quiet_caught_dependency_panics();
    let cli = Cli::parse();
    match cli.cmd {
        Cmd::Fill(args) => {
            // diagnostics of the methods go to stderr when RUST_LOG asks for them
            if std::env::var_os("RUST_LOG").is_some() {
                let _ = tracing_subscriber::fmt()
                    .with_env_filter(tracing_subscriber::EnvFilter::from_default_env())
                    .with_writer(std::io::stderr)
                    .try_init();
            }
            ExitCode::from(run_fill(&args))
        }
        Cmd::CheckPolicy { file } => match Policy::from_file(&file) {
            Ok(_) => {
                println!("{}: ok", file.display());
                ExitCode::from(exit::OK)
            }
            Err(e) => {
                eprintln!("error: {e}");
                ExitCode::from(exit::USAGE)
            }
        },
        Cmd::Watch(args) => match daemon::run(args) {
            Ok(()) => ExitCode::from(exit::OK),
            Err(e) => {
                eprintln!("error: {e:#}");
                ExitCode::from(exit::CONFIG)
            }
        },
        Cmd::Report(args) => ExitCode::from(run_report(&args)),
        Cmd::Worker(args) => queue_exit(worker::run_worker(args)),
        Cmd::Submit(args) => queue_exit(worker::run_submit(args)),
        Cmd::Results(args) => queue_exit(worker::run_results(args)),
    }
}

/// Exit status of the queue commands: 0, or 1 with the error.
fn queue_exit(r: anyhow::Result<()>) -> ExitCode {
    match r {
        Ok(()) => ExitCode::from(exit::OK),
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(exit::USAGE)
        }
    }
}

/// `holefill report DIR...`: the logs' summary as a table.
fn run_report(args: &ReportArgs) -> u8 {
    for d in &args.dirs {
        if !d.is_dir() {
            eprintln!("error: {}: not a folder", d.display());
            return exit::USAGE;
        }
    }
    let dirs: Vec<&Path> = args.dirs.iter().map(PathBuf::as_path).collect();
    let entries = daemon::index::scan(&dirs, args.limit);
    print!("{}", daemon::index::table(&entries));
    exit::OK
}

/// The library catches the panics of faer's sparse LU on a singular matrix (it
/// panics instead of returning an error) and fails the method over; this keeps the
/// default panic message for every other panic and logs those at debug level only.
fn quiet_caught_dependency_panics() {
    let default = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let from_faer = info.location().is_some_and(|l| l.file().contains("/faer-"));
        if from_faer {
            tracing::debug!("caught panic in faer: {info}");
        } else {
            default(info);
        }
    }));
}

fn run_fill(args: &FillArgs) -> u8 {
    match fill(args) {
        Ok(code) => code,
        Err(Failure(code, msg)) => {
            eprintln!("error: {msg}");
            code
        }
    }
}

struct Failure(u8, String);

fn io_failure(e: IoError) -> Failure {
    if e.is_malformed() {
        Failure(exit::DATAERR, e.to_string())
    } else {
        Failure(exit::IOERR, e.to_string())
    }
}

fn fill(args: &FillArgs) -> Result<u8, Failure> {
    let policy = match &args.policy {
        Some(p) => Policy::from_file(p).map_err(|e| Failure(exit::CONFIG, e.to_string()))?,
        None => Policy::default_policy(),
    };
    // the fill's worker threads start while the input is read
    holefill::start_workers(&policy);
    let in_format = match &args.input_format {
        Some(name) => Some(Format::from_name(name).ok_or_else(|| {
            Failure(
                exit::USAGE,
                format!("--input-format {name}: expected obj, ply, stl, off, gltf or glb"),
            )
        })?),
        None => Format::from_path(&args.input),
    };
    let in_format = in_format.ok_or_else(|| {
        Failure(
            exit::DATAERR,
            format!(
                "{}: unsupported format (expected .obj, .ply, .stl, .off, .gltf or .glb)",
                args.input.display()
            ),
        )
    })?;
    let out_format = match &args.format {
        Some(name) => Format::from_name(name).ok_or_else(|| {
            Failure(
                exit::USAGE,
                format!("--format {name}: expected obj, ply, stl, off, gltf or glb"),
            )
        })?,
        // the output path's extension, else the input's format
        None => Format::from_path(&args.output).unwrap_or(in_format),
    };

    let t = Instant::now();
    let limits = holefill::io::ReadLimits {
        max_file_bytes: args.max_file_bytes,
        max_vertices: args.max_vertices,
        max_faces: args.max_faces,
    };
    let resources = holefill::io::Resources {
        files: args
            .resource
            .chunks_exact(2)
            .map(|p| (p[0].to_string_lossy().into_owned(), p[1].clone()))
            .collect(),
        only: args.only_resources,
    };
    let raw = holefill::io::read_with_resources(&args.input, Some(in_format), &limits, &resources)
        .map_err(io_failure)?;
    let read_ms = t.elapsed().as_secs_f64() * 1000.0;

    // The picture's sketch (the input's surface) is drawn while the input is
    // repaired: a job on the fill's pool, which its worker, waiting for the fill,
    // takes at once (with one thread there is no pool: the picture is drawn after;
    // with --picture-after-log nothing of it is drawn before the log, which would
    // delay the repair whenever every core is busy).
    let picture_opts = holefill::picture::Options::default();
    let threads = policy.limits.fill_threads();
    let mut sketch: Option<(holefill::picture::Sketch, Duration)> = None;
    // an internal error (a bug) must still end in a clear message and EX_SOFTWARE,
    // with nothing written, rather than an abort
    let repaired = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        if args.picture.is_none() || threads < 2 || args.picture_after_log {
            return holefill::repair(&raw, &policy);
        }
        rayon::in_place_scope(|s| {
            let (raw, opts, slot) = (&raw, &picture_opts, &mut sketch);
            s.spawn(move |_| {
                let t = Instant::now();
                // a bug in the sketch loses the sketch, never the repair
                *slot = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                    holefill::picture::Sketch::new(raw, opts)
                }))
                .ok()
                .map(|sk| (sk, t.elapsed()));
            });
            holefill::repair(raw, &policy)
        })
    }))
    .map_err(|_| {
        Failure(
            exit::SOFTWARE,
            format!("{}: internal error while repairing", args.input.display()),
        )
    })?;
    let (out, mut report) =
        repaired.map_err(|e| Failure(exit::DATAERR, format!("{}: {e}", args.input.display())))?;
    report.timings.read_ms = read_ms;
    report.input = Some(FileRef {
        path: args.input.display().to_string(),
        format: in_format,
    });
    report.output = Some(FileRef {
        path: args.output.display().to_string(),
        format: out_format,
    });
    // what the output format cannot hold
    report.attributes.dropped = holefill::io::attrs::dropped(&out, out_format);

    if !args.quiet {
        for h in &report.holes {
            let method = h.method.map(|m| m.name()).unwrap_or("-");
            let status = match h.status {
                HoleStatus::Filled => "filled",
                HoleStatus::Stitched => "stitched",
                HoleStatus::Skipped => "skipped",
                HoleStatus::Failed => "FAILED",
            };
            let extra = if h.reason.is_empty() {
                String::new()
            } else {
                format!("  ({})", h.reason)
            };
            println!(
                "hole {:>4}  {:>6} verts  {:<6}  {:<16} {:<7}  +{}v +{}f  {:.1} ms{}",
                h.id,
                h.boundary_vertices,
                h.class.name(),
                method,
                status,
                h.added_vertices,
                h.added_faces,
                h.ms,
                extra
            );
        }
        let s = &report.summary;
        println!(
            "total: {} holes, {} filled, {} stitched, {} skipped, {} failed; {} -> {} faces",
            s.holes,
            s.filled,
            s.stitched,
            s.skipped,
            s.failed,
            report.before.faces,
            report.after.faces
        );
    }
    println!(
        "FILL_TIME_S={:.6}",
        (report.timings.smooth_ms + report.timings.fill_ms) / 1000.0
    );

    let code = if report.summary.failed > 0 {
        exit::HOLES_FAILED
    } else {
        exit::OK
    };
    let picture = |report: &holefill::report::RepairReport| {
        let t = Instant::now();
        let (picture, sketched) = match sketch {
            Some((sketch, took)) => (sketch.finish(&raw, &out, report, &picture_opts), took),
            None => (
                holefill::picture::render(&out, report, &picture_opts),
                Duration::ZERO,
            ),
        };
        (picture.to_png(), sketched + t.elapsed())
    };

    if let (Some(path), true) = (&args.picture, args.picture_after_log) {
        // the daemon's child: the model and the log first, then the picture at the
        // lowest priority (the log's picture_ms is 0: nothing of it is drawn before)
        let t = Instant::now();
        holefill::write(&args.output, &out, Some(out_format)).map_err(io_failure)?;
        report.timings.write_ms = t.elapsed().as_secs_f64() * 1000.0;
        if let Some(log) = &args.report {
            write_report(log, &report.to_json())?;
        }
        announce_written(code);
        lowest_priority();
        #[cfg(feature = "test-hooks")]
        if let Some(ms) = std::env::var(daemon::hooks::PICTURE_SLEEP_MS)
            .ok()
            .and_then(|v| v.parse().ok())
        {
            std::thread::sleep(Duration::from_millis(ms));
        }
        let drawn = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| picture(&report)));
        // the repair is done: a picture that cannot be made is a warning (the daemon
        // reads it from stderr), and the exit status the announced one
        match drawn {
            // not synced: the log and the model are, and the next repair's syncs
            // must not wait for a picture's
            Ok((Ok(png), _)) => {
                if let Err(e) = holefill::io::write_unsynced(path, &png) {
                    eprintln!("warning: {e}");
                }
            }
            Ok((Err(e), _)) => eprintln!("warning: {}: {e}", path.display()),
            Err(_) => eprintln!(
                "warning: {}: internal error while drawing the picture; none written",
                path.display()
            ),
        }
        return Ok(code);
    }

    // The picture is finished on its own thread while the model is written, and its
    // file written and synced beside the model's; it is put in place after the model,
    // so that a picture never stands beside a lost model.
    let (written, write_ms, drawn) = std::thread::scope(|s| {
        let drawing = args.picture.as_ref().map(|path| {
            let report = &report;
            s.spawn(move || {
                let (png, took) = picture(report);
                (png.map(|png| holefill::io::stage(path, &png)), took)
            })
        });
        let t = Instant::now();
        let written = holefill::write(&args.output, &out, Some(out_format));
        let write_ms = t.elapsed().as_secs_f64() * 1000.0;
        (written, write_ms, drawing.map(|h| h.join()))
    });
    // a staged picture not committed is removed when dropped (here, on an error)
    written.map_err(io_failure)?;
    report.timings.write_ms = write_ms;
    if let (Some(path), Some(drawn)) = (&args.picture, drawn) {
        let t = Instant::now();
        let drawing_ms = match drawn {
            Ok((Ok(staged), took)) => {
                staged.and_then(|s| s.commit()).map_err(io_failure)?;
                took.as_secs_f64() * 1000.0
            }
            Ok((Err(e), took)) => {
                eprintln!("warning: {}: {e}", path.display());
                took.as_secs_f64() * 1000.0
            }
            // a bug in the drawing loses the picture (with a warning), never the repair
            Err(_) => {
                eprintln!(
                    "warning: {}: internal error while drawing the picture; none written",
                    path.display()
                );
                0.0
            }
        };
        report.timings.picture_ms = drawing_ms + t.elapsed().as_secs_f64() * 1000.0;
    }

    if let Some(path) = &args.report {
        write_report(path, &report.to_json())?;
    }
    Ok(code)
}

/// Tells the daemon that the model and the log are written and what the exit status
/// will be (`--picture-after-log`): one line on standard output.
fn announce_written(code: u8) {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    let _ = writeln!(out, "written {code}");
    let _ = out.flush();
}

/// Lowers every thread of this process (this one among them) to the lowest CPU
/// priority (nice 19), so that what is left to do (the picture) takes only the time
/// other work leaves. On Linux a priority is a thread's; the threads started later
/// inherit it from this one.
fn lowest_priority() {
    use rustix::process::{setpriority_process, Pid};
    if let Ok(tasks) = std::fs::read_dir("/proc/self/task") {
        for t in tasks.flatten() {
            let tid = t
                .file_name()
                .to_str()
                .and_then(|n| n.parse::<i32>().ok())
                .and_then(Pid::from_raw);
            if let Some(tid) = tid {
                let _ = setpriority_process(Some(tid), 19);
            }
        }
    } else {
        // no /proc: this thread at least
        let _ = setpriority_process(None, 19);
    }
}

fn write_report(path: &Path, json: &str) -> Result<(), Failure> {
    holefill::io::write_atomic(path, json.as_bytes()).map_err(io_failure)
}
