//! Fill time of whole files, repeated: what `holefill fill` prints as FILL_TIME_S,
//! without starting a process per run, for profiling and for comparing builds.
//!
//!     cargo run --release --example fill_time -- [--repeat N] [--threads T] [--policy P] FILE...
//!
//! Each file is read once, then repaired N times (default 20) with the policy file P
//! (default: the built-in policy), `limits.threads = T` when given. Prints per file the
//! median and minimum of the fill time (smoothing + filling, as in the repair log), the
//! first run's (what a fresh process sees: caches cold, heap not yet grown) and the
//! holes filled, then the sum of the medians.

use holefill::policy::Policy;

fn main() {
    let mut repeat = 20usize;
    let mut threads: Option<usize> = None;
    let mut policy_file: Option<String> = None;
    let mut files = Vec::new();
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--repeat" => repeat = args.next().and_then(|v| v.parse().ok()).unwrap_or(20),
            "--threads" => threads = args.next().and_then(|v| v.parse().ok()),
            "--policy" => policy_file = args.next(),
            _ => files.push(a),
        }
    }
    if files.is_empty() {
        eprintln!("usage: fill_time [--repeat N] [--threads T] [--policy P] FILE...");
        std::process::exit(1);
    }
    let mut policy = match policy_file {
        Some(p) => match Policy::from_file(p.as_ref()) {
            Ok(p) => p,
            Err(e) => {
                eprintln!("{e}");
                std::process::exit(1);
            }
        },
        None => Policy::default(),
    };
    if let Some(t) = threads {
        policy = match policy.edit(|s| s.limits.threads = t) {
            Ok(p) => p,
            Err(e) => {
                eprintln!("--threads: {e}");
                std::process::exit(1);
            }
        };
    }
    let mut sum = 0.0;
    for f in &files {
        let raw = match holefill::read(f.as_ref(), None) {
            Ok(r) => r,
            Err(e) => {
                eprintln!("{f}: {e}");
                std::process::exit(1);
            }
        };
        let mut times = Vec::with_capacity(repeat);
        let mut filled = (0, 0);
        for _ in 0..repeat.max(1) {
            match holefill::repair(&raw, &policy) {
                Ok((_, rep)) => {
                    times.push((rep.timings.smooth_ms + rep.timings.fill_ms) / 1000.0);
                    filled = (rep.summary.filled, rep.summary.holes);
                }
                Err(e) => {
                    eprintln!("{f}: {e}");
                    std::process::exit(1);
                }
            }
        }
        let first = times[0];
        times.sort_by(f64::total_cmp);
        let med = times[times.len() / 2];
        sum += med;
        println!(
            "{f}: median {med:.4} s, min {:.4} s, first {first:.4} s, {}/{} holes filled",
            times[0], filled.0, filled.1
        );
    }
    println!("sum of medians {sum:.4} s");
}
