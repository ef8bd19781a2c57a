//! `workcell report`: reports made from the run records of evaluations.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result};
use workcell::evaluate::record::{RunRecord, merge};

use super::evaluate::{OUTPUTS, announce, write_report};

#[derive(Debug, clap::Args)]
pub struct MergeArgs {
    /// The output folders of the shards (`workcell evaluate --shard K/N --out DIR`), in any
    /// order; every shard of the evaluation exactly once.
    #[arg(required = true)]
    pub shards: Vec<PathBuf>,
    /// Where the merged report goes (created; existing outputs are kept unless --force).
    #[arg(long, default_value = "out/merged")]
    pub out: PathBuf,
    /// Overwrite existing output files.
    #[arg(long)]
    pub force: bool,
    /// Exit with status 2 when any episode violates d_min.
    #[arg(long)]
    pub fail_on_violation: bool,
}

/// Merges shard folders into the report a single process would have written.
///
/// # Errors
/// A folder without a readable run record, shards of different evaluations, a shard twice
/// or missing, and I/O errors, each naming the folder or file.
pub fn merge_shards(args: &MergeArgs) -> Result<ExitCode> {
    let records = args
        .shards
        .iter()
        .map(|dir| {
            RunRecord::read(dir)
                .map(|r| (dir.clone(), r))
                .with_context(|| format!("shard folder {}", dir.display()))
        })
        .collect::<Result<Vec<_>>>()?;
    let (record, _replay_dirs) = merge(records)?;
    let out = super::OutputDir::create(&args.out, args.force, &OUTPUTS)?;
    let command = std::env::args().collect::<Vec<_>>().join(" ");
    write_report(out.path(), &record, &command, &args.out)?;
    out.commit()?;
    let violating = announce(&record, &args.out);
    if args.fail_on_violation && violating > 0 {
        return Ok(ExitCode::from(2));
    }
    Ok(ExitCode::SUCCESS)
}
