//! The daemon (being written).

/// Options of `holefill watch`.
#[derive(clap::Args, Debug)]
pub struct WatchArgs {
    /// Daemon config file.
    #[arg(long)]
    pub config: Option<std::path::PathBuf>,
}

/// Runs the daemon until SIGTERM.
pub fn run(_args: WatchArgs) -> anyhow::Result<()> {
    anyhow::bail!("the daemon is not available yet")
}
