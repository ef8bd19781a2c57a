//! Subcommands of the `workcell` binary.

pub mod crosscheck;
pub mod dataset;
pub mod evaluate;
pub mod perception;
pub mod pose;
pub mod robot;
pub mod simulate;

/// Creates `out`; unless `force`, refuses when it already holds any of `outputs`, so that a
/// run never overwrites an earlier one by accident.
pub fn prepare_out(out: &std::path::Path, force: bool, outputs: &[&str]) -> anyhow::Result<()> {
    use anyhow::Context as _;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    if !force {
        let existing: Vec<&str> = outputs
            .iter()
            .copied()
            .filter(|f| out.join(f).exists())
            .collect();
        if !existing.is_empty() {
            anyhow::bail!(
                "{} already holds {}; pass --force to overwrite or choose another --out",
                out.display(),
                existing.join(", ")
            );
        }
    }
    Ok(())
}

/// A progress bar of `len` steps drawn with indicatif's `template` (its default style when
/// the template does not parse).
pub fn progress_bar(len: u64, template: &str) -> indicatif::ProgressBar {
    indicatif::ProgressBar::new(len).with_style(
        indicatif::ProgressStyle::with_template(template)
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
            .progress_chars("=> "),
    )
}

/// A dataset split by name.
///
/// # Errors
/// A name other than train, validation or test.
pub fn parse_split(name: &str) -> anyhow::Result<workcell::sim::dataset::Split> {
    use workcell::sim::dataset::Split;
    Split::ALL
        .into_iter()
        .find(|s| s.name() == name)
        .ok_or_else(|| anyhow::anyhow!("unknown split {name:?} (train, validation, test)"))
}
