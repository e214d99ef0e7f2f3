//! Tells the integration tests whether a `nats-server` binary is installed: the queue
//! worker's tests (tests/worker_*.rs) run against a real server and are ignored
//! (`needs nats-server`) where there is none. `.ci/run` installs it.

fn main() {
    println!("cargo::rustc-check-cfg=cfg(has_nats_server)");
    println!("cargo::rerun-if-env-changed=PATH");
    println!("cargo::rerun-if-env-changed=HOLEFILL_NATS_SERVER");
    let found = std::env::var_os("HOLEFILL_NATS_SERVER")
        .map(std::path::PathBuf::from)
        .into_iter()
        .chain(
            std::env::var_os("PATH")
                .map(|p| std::env::split_paths(&p).collect::<Vec<_>>())
                .unwrap_or_default()
                .into_iter()
                .chain(["/usr/sbin".into(), "/usr/local/sbin".into()])
                .map(|d: std::path::PathBuf| d.join("nats-server")),
        )
        .find(|p| p.is_file());
    if let Some(p) = found {
        println!("cargo::rerun-if-changed={}", p.display());
        println!("cargo::rustc-cfg=has_nats_server");
    }
}
