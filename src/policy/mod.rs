//! The TOML repair policy: read raw, then validated once into an immutable [`Policy`].
//!
//! Every section and key is optional (defaults apply). `config/policy.toml` is the
//! default policy with every key commented (what it does, unit, range, default, paper);
//! it is embedded in the binary as [`DEFAULT_POLICY_TOML`], and a unit test checks that
//! it parses to exactly [`Policy::default`], so the file and the code cannot drift.
//!
//! Reading has two stages, like ripgrep's low-level and high-level arguments:
//! 1. *raw*: the text is parsed into a spanned TOML tree and every key is read into
//!    its field by type (an unknown section, key, method or value name is an error with
//!    a "did you mean" when a valid name is close; a wrong type names the key); the
//!    line of every key is remembered ([`read`]: the raw [`Settings`]);
//! 2. *validated*: [`Settings::validate`] checks every range and every consistency rule
//!    between keys, and an error is reported at the line of the offending key; only
//!    then is it a [`Policy`], the type every method takes.
//!
//! Errors read `FILE:LINE: key `section.key`: message`, e.g.
//! `policy.toml:12: key `front.angle_small`: must be between 0 and 180 (got 200)`.
//! The one list of valid keys is [`SECTIONS`].
//!
//! [`Settings`] still derives `Deserialize`, but a policy file is read with
//! [`Policy::from_file`] or [`Policy::from_toml_str`], which validate. The sections
//! are in [`sections`], the method names in [`method`] (the method table).

mod method;
mod read;
mod sections;
mod validate;

#[cfg(test)]
mod tests;

pub use method::{Method, METHODS};
pub use read::{did_you_mean, edit_distance, OPTIONAL_KEYS, SECTIONS, TOP_LEVEL_KEYS};
pub use sections::*;
pub use validate::Invalid;

use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// The default policy file, shipped as `config/policy.toml`.
pub const DEFAULT_POLICY_TOML: &str = include_str!("../../config/policy.toml");

/// Largest policy file [`Policy::from_file`] reads (1 MiB; the default file is about 7 KB).
pub const MAX_POLICY_BYTES: u64 = 1 << 20;
/// Largest `refine.restricted_search_above`: the full search takes O(k^2) memory.
pub const MAX_FULL_SEARCH: usize = 2000;
/// Largest `limits.threads`.
pub const MAX_THREADS: usize = 1024;
/// Smallest and largest `limits.max_patch_triangles` (besides 0).
pub const MIN_PATCH_TRIANGLES: usize = 100;
pub const MAX_PATCH_TRIANGLES: usize = 100_000_000;

/// Largest `limits.hole_time_ms` (one day).
pub const MAX_HOLE_TIME_MS: u64 = 86_400_000;
/// Largest `smooth.iterations` (and `hpde.num_smooth`).
pub const MAX_SMOOTH_ITERATIONS: usize = 10_000;
/// Largest `fair.passes`: each pass is a sparse solve.
pub const MAX_FAIR_PASSES: usize = 20;
/// Largest `hpde.population_factor`.
pub const MAX_HPDE_POPULATION_FACTOR: usize = 100;
/// Largest `hpde.generations`.
pub const MAX_HPDE_GENERATIONS: usize = 100_000;

/// A policy error, naming the file, line and key.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{}{}: {}{message}", file.display(), line.map(|l| format!(":{l}")).unwrap_or_default(), key.as_ref().map(|k| format!("key `{k}`: ")).unwrap_or_default())]
pub struct PolicyError {
    /// The policy file as given.
    pub file: PathBuf,
    /// 1-based line of the offending key or value, when the file has one.
    pub line: Option<usize>,
    /// Dotted key, e.g. `dispatch.small_max`.
    pub key: Option<String>,
    /// What is wrong.
    pub message: String,
}

/// The whole policy as read: every key, not yet validated (see [`Policy`]).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, Default)]
#[serde(default, deny_unknown_fields)]
pub struct Settings {
    /// Seed of every random choice (same input + policy = same output).
    pub seed: u64,
    pub dispatch: Dispatch,
    pub select: Select,
    pub blend: Blend,
    pub border: Border,
    pub clean: Clean,
    pub rim: Rim,
    pub crack: Crack,
    pub islands: Islands,
    pub debris: Debris,
    pub refine: Refine,
    pub fair: Fair,
    pub front: Front,
    pub wavefront: Wavefront,
    pub hpde: Hpde,
    pub checks: Checks,
    pub limits: Limits,
    pub smooth: Smooth,
    pub lssvm: Lssvm,
}

/// A validated policy: every key in range and consistent with the others
/// ([`Settings::validate`]). The library fills holes only under one, so no method
/// checks its keys again. Read-only; a reload swaps it whole. Its keys are read
/// through `Deref` (`policy.wavefront.alpha`); a changed copy is made with
/// [`Policy::edit`], which validates again.
#[derive(Clone, Debug, PartialEq, Default, Serialize)]
#[serde(transparent)]
pub struct Policy(Settings);

impl std::ops::Deref for Policy {
    type Target = Settings;
    fn deref(&self) -> &Settings {
        &self.0
    }
}

impl Policy {
    /// Validates `settings`.
    pub fn new(settings: Settings) -> Result<Policy, Invalid> {
        settings.validate()?;
        Ok(Policy(settings))
    }
    /// A copy with `change` applied, validated again.
    pub fn edit(&self, change: impl FnOnce(&mut Settings)) -> Result<Policy, Invalid> {
        let mut s = self.0.clone();
        change(&mut s);
        Policy::new(s)
    }
    /// The settings, to change and validate again.
    pub fn into_settings(self) -> Settings {
        self.0
    }
}

impl Policy {
    /// Reads and validates a policy file (at most [`MAX_POLICY_BYTES`]).
    pub fn from_file(path: &Path) -> Result<Policy, PolicyError> {
        use std::io::Read;
        let error = |message: String| PolicyError {
            file: path.to_path_buf(),
            line: None,
            key: None,
            message,
        };
        let file =
            std::fs::File::open(path).map_err(|e| error(format!("cannot read the policy: {e}")))?;
        let mut text = String::new();
        file.take(MAX_POLICY_BYTES + 1)
            .read_to_string(&mut text)
            .map_err(|e| error(format!("cannot read the policy: {e}")))?;
        if text.len() as u64 > MAX_POLICY_BYTES {
            return Err(error(format!(
                "larger than {MAX_POLICY_BYTES} bytes; this is not a policy file"
            )));
        }
        Policy::from_toml_str(&text, path)
    }

    /// Parses and validates policy text; `path` names it in errors.
    pub fn from_toml_str(text: &str, path: &Path) -> Result<Policy, PolicyError> {
        let (settings, lines) = read::read(text, path)?;
        Policy::new(settings).map_err(|inv| {
            let (key, message) = match inv.other {
                Some((other, other_message))
                    if !lines.contains_key(inv.key) && lines.contains_key(other) =>
                {
                    (other, other_message)
                }
                _ => (inv.key, inv.message),
            };
            PolicyError {
                file: path.to_path_buf(),
                line: lines.get(key).copied(),
                key: Some(key.to_string()),
                message,
            }
        })
    }

    /// The embedded default policy ([`DEFAULT_POLICY_TOML`]), equal to
    /// [`Policy::default`] (a unit test checks it).
    pub fn default_policy() -> Policy {
        static DEFAULT: OnceLock<Policy> = OnceLock::new();
        DEFAULT
            .get_or_init(|| {
                Policy::from_toml_str(DEFAULT_POLICY_TOML, Path::new("config/policy.toml"))
                    .unwrap_or_default()
            })
            .clone()
    }
}
