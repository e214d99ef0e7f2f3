//! The two phases of a fill: every hole's first acceptable patch found against the
//! mesh as read, holes in parallel ([`propose_all`]); then, serially in hole order, each
//! checked against the patches applied before it and applied
//! ([`super::finish_hole`], called by the pipeline). The output does not depend on the
//! number of threads.

use super::{propose, Proposal};
use crate::check::Checker;
use crate::mesh::Mesh;
use crate::patch::Hole;
use crate::policy::Policy;
use std::time::Instant;

/// Starts the worker threads that [`crate::repair`] fills holes on (`policy.limits.threads`
/// in all, this one included; rayon's global pool), so that a caller can start them
/// before it reads the mesh. Each worker then waits for the fill by spinning, for at
/// most [`WARM_SPIN`]: a worker that sleeps instead (or is started when the fill
/// starts) begins work 2 to 4 ms after the fill starts in about half of the runs on
/// the bench machine (a virtual machine; measured in `holefill fill`, against
/// 0.1 ms when it is awake), a fifth of the whole fill of a 10-hole mesh. The cost is
/// one core busy while the input is read; a spinning worker runs the pool's other jobs
/// (the OBJ reader's) as they come. Optional: without it the pool starts on
/// first use. Does nothing but spin when the pool is already running.
pub fn start_workers(policy: &Policy) {
    let threads = policy.limits.fill_threads();
    if threads > 1 {
        let _ = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build_global();
        for _ in 1..threads {
            rayon::spawn(|| {
                let t = Instant::now();
                let mut spins = 0u32;
                while !FILL_STARTED.load(std::sync::atomic::Ordering::Acquire) {
                    std::hint::spin_loop();
                    spins = spins.wrapping_add(1);
                    // other work for the pool meanwhile (the OBJ reader's pieces) is
                    // done here, so a spinning worker never holds the reader back
                    if spins % 64 == 0 {
                        let _ = rayon::yield_now();
                    }
                    if spins % 1024 == 0 && t.elapsed() > WARM_SPIN {
                        break;
                    }
                }
            });
        }
    }
}

/// Longest time a worker started by [`start_workers`] spins waiting for the fill.
pub const WARM_SPIN: std::time::Duration = std::time::Duration::from_millis(200);

/// Longest time the filling thread spins for the other workers' last holes before
/// it sleeps until they finish (see [`propose_all`]).
const JOIN_SPIN: std::time::Duration = std::time::Duration::from_millis(50);

/// Set when a fill starts: the workers of [`start_workers`] stop spinning.
static FILL_STARTED: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Phase 1 of a fill (see [`crate::pipeline`]): the proposals of the holes not skipped (`None` for those),
/// computed on `policy.limits.threads` threads (this one and the others started
/// here). Each thread takes the biggest hole not yet taken (a shared counter over the
/// holes sorted by size, largest first), so a thread that finishes early never waits
/// while another works through a list of big holes (a fixed split put two big holes
/// on one thread).
pub fn propose_all(
    mesh: &Mesh,
    holes: &[Hole],
    skip: &[Option<String>],
    policy: &Policy,
    checker: &Checker,
) -> Vec<Option<Proposal>> {
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::sync::Mutex;
    let mut order: Vec<usize> = (0..holes.len()).filter(|&i| skip[i].is_none()).collect();
    order.sort_by_key(|&i| std::cmp::Reverse(holes[i].len()));
    let run = |i: usize| propose(mesh, &holes[i], policy, checker);
    let threads = policy.limits.fill_threads().min(order.len() + 1);
    let next = AtomicUsize::new(0);
    let slots: Vec<Mutex<Option<Proposal>>> = order.iter().map(|_| Mutex::new(None)).collect();
    // job 0 computes the checker's face boxes, so that they are ready (or being
    // made) when the first patch is checked; the others are the holes
    let work = || loop {
        let j = next.fetch_add(1, Ordering::Relaxed);
        if j == 0 {
            if !order.is_empty() {
                checker.prepare(mesh);
            }
            continue;
        }
        let Some(&i) = order.get(j - 1) else { break };
        let j = j - 1;
        let p = run(i);
        if let Ok(mut slot) = slots[j].lock() {
            *slot = Some(p);
        }
    };
    // this thread works too, so the biggest hole starts at once; the others are jobs
    // on rayon's pool (started early by [`start_workers`], or here on first use); a
    // job that starts late finds the holes taken and leaves at once
    // the workers of `start_workers` stop spinning and take these jobs
    FILL_STARTED.store(true, Ordering::Release);
    // jobs that have returned from `work`: this thread waits for them by spinning
    // before it leaves the scope, whose own wait sleeps on a condition variable
    // when a job is still running (waking from it took 0.5 ms on the bench machine,
    // a twentieth of a bunny scan's fill). A job still running after JOIN_SPIN is
    // waited for by the scope.
    let done = AtomicUsize::new(0);
    rayon::in_place_scope(|s| {
        for _ in 1..threads {
            s.spawn(|_| {
                work();
                done.fetch_add(1, Ordering::Release);
            });
        }
        work();
        let t = std::time::Instant::now();
        let mut spins = 0u32;
        while done.load(Ordering::Acquire) < threads - 1 {
            std::hint::spin_loop();
            spins = spins.wrapping_add(1);
            if spins % 1024 == 0 && t.elapsed() > JOIN_SPIN {
                break;
            }
        }
        // the pool marks a job finished just after it returns: a few more
        // microseconds, so that the scope finds it finished and does not sleep
        let t = std::time::Instant::now();
        while t.elapsed() < std::time::Duration::from_micros(20) {
            std::hint::spin_loop();
        }
    });
    let computed = slots.into_iter().map(|m| m.into_inner().ok().flatten());
    let mut out: Vec<Option<Proposal>> = vec![None; holes.len()];
    for (&i, c) in order.iter().zip(computed) {
        out[i] = Some(c.unwrap_or_else(|| run(i)));
    }
    out
}
