//! Subcommands of the `workcell` binary.

/// Prints a line to standard output like `println!`, but a closed pipe (`workcell ... | head`)
/// is not a panic: the output is dropped and the command goes on to write its files.
macro_rules! say {
    () => {
        $crate::cli::write_stdout(format_args!("\n"))
    };
    ($($arg:tt)*) => {
        $crate::cli::write_stdout(format_args!("{}\n", format_args!($($arg)*)))
    };
}

/// `print!` as [`say!`] is `println!`.
macro_rules! say_inline {
    ($($arg:tt)*) => {
        $crate::cli::write_stdout(format_args!($($arg)*))
    };
}

pub mod crosscheck;
pub mod dataset;
pub mod evaluate;
pub mod human;
pub mod perception;
pub mod pose;
pub mod report;
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

/// A run's outputs are files, or folders when the name ends in '/' (replaced whole).
///
/// Prefix of the folder inside `--out` where a run writes its files before they replace the
/// previous run's.
const STAGE_PREFIX: &str = ".workcell-partial-";

/// The output folder of a run: files are written into a staging folder inside it and moved
/// into place together by [`OutputDir::commit`], after the old run's outputs are removed. A
/// run that is interrupted (Ctrl-C, an error, SIGKILL) leaves the previous run's files as
/// they were, never a mix of two runs; the next run removes a stale staging folder.
///
/// One run at a time writes into a folder: the run holds an exclusive lock on the folder
/// (`flock`, released when the run ends, however it ends), and a second run into the same
/// folder is refused at once instead of deleting the first one's staging folder.
pub struct OutputDir {
    out: std::path::PathBuf,
    stage: std::path::PathBuf,
    outputs: &'static [&'static str],
    committed: bool,
    /// The folder, opened and locked; `None` where folders cannot be locked.
    _lock: Option<std::fs::File>,
}

impl OutputDir {
    /// Prepares `out` as [`prepare_out`] does and creates the staging folder.
    ///
    /// # Errors
    /// As [`prepare_out`], or the I/O error of creating the staging folder.
    pub fn create(
        out: &std::path::Path,
        force: bool,
        outputs: &'static [&'static str],
    ) -> anyhow::Result<Self> {
        use anyhow::Context as _;
        prepare_out(out, force, outputs)?;
        let lock = lock_folder(out)?;
        // Staging folders here now are stale: their runs no longer hold the lock.
        let entries =
            std::fs::read_dir(out).with_context(|| format!("listing {}", out.display()))?;
        for entry in entries.flatten() {
            if entry
                .file_name()
                .to_string_lossy()
                .starts_with(STAGE_PREFIX)
            {
                let _ = std::fs::remove_dir_all(entry.path());
            }
        }
        let stage = out.join(format!("{STAGE_PREFIX}{}", std::process::id()));
        std::fs::create_dir(&stage).with_context(|| format!("creating {}", stage.display()))?;
        Ok(Self {
            out: out.to_path_buf(),
            stage,
            outputs,
            committed: false,
            _lock: lock,
        })
    }

    /// Where to write the run's files.
    #[must_use]
    pub fn path(&self) -> &std::path::Path {
        &self.stage
    }

    /// Removes the previous run's outputs and moves the new ones into place.
    ///
    /// # Errors
    /// The I/O error of a removal or a move, naming the file.
    pub fn commit(mut self) -> anyhow::Result<()> {
        use anyhow::Context as _;
        for name in self.outputs {
            let old = self.out.join(name);
            // A name ending in '/' is a folder of the run's, replaced whole.
            let removed = if name.ends_with('/') {
                std::fs::remove_dir_all(&old)
            } else {
                std::fs::remove_file(&old)
            };
            match removed {
                Ok(()) => {}
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(e) => return Err(e).with_context(|| format!("removing {}", old.display())),
            }
        }
        for name in self.outputs {
            let new = self.stage.join(name);
            if new.exists() {
                let to = self.out.join(name);
                std::fs::rename(&new, &to)
                    .with_context(|| format!("moving {} to {}", new.display(), to.display()))?;
            }
        }
        self.committed = true;
        std::fs::remove_dir_all(&self.stage)
            .with_context(|| format!("removing {}", self.stage.display()))
    }
}

/// An exclusive lock on the folder `out`, held while the returned file is open; `None` where
/// the platform or file system cannot lock a folder (the run goes on unlocked).
///
/// # Errors
/// Another process holds the lock: another run is writing into `out`.
fn lock_folder(out: &std::path::Path) -> anyhow::Result<Option<std::fs::File>> {
    let Ok(folder) = std::fs::File::open(out) else {
        return Ok(None);
    };
    match folder.try_lock() {
        Ok(()) => Ok(Some(folder)),
        Err(std::fs::TryLockError::WouldBlock) => anyhow::bail!(
            "another workcell run is writing into {}: wait for it to finish or choose \
             another --out",
            out.display()
        ),
        Err(std::fs::TryLockError::Error(_)) => Ok(None),
    }
}

impl Drop for OutputDir {
    fn drop(&mut self) {
        if !self.committed {
            let _ = std::fs::remove_dir_all(&self.stage);
        }
    }
}

/// A progress bar of `len` steps drawn with indicatif's `template` (its default style when
/// the template does not parse). On a terminal it redraws in place; where standard error is
/// not a terminal (a log file, CI, a background run) the bar is written as a plain line at
/// most every [`LOG_PROGRESS_EVERY`], so that a long run's log still shows how far it got.
pub fn progress_bar(len: u64, template: &str) -> indicatif::ProgressBar {
    use std::io::IsTerminal as _;
    let bar = indicatif::ProgressBar::new(len).with_style(
        indicatif::ProgressStyle::with_template(template)
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
            .progress_chars("=> ")
            .with_key(
                "eta",
                |state: &indicatif::ProgressState, w: &mut dyn std::fmt::Write| {
                    let eta = mean_rate_eta(state.elapsed(), state.pos(), state.len());
                    let _ = match eta {
                        Some(eta) => write!(w, "{:#}", indicatif::HumanDuration(eta)),
                        None => write!(w, "-"),
                    };
                },
            ),
    );
    if !std::io::stderr().is_terminal() {
        bar.set_draw_target(indicatif::ProgressDrawTarget::term_like_with_hz(
            Box::new(LogLines::new(std::io::stderr(), LOG_PROGRESS_EVERY)),
            1,
        ));
    }
    bar
}

/// The time left at the mean rate since the start: `elapsed` for `done` steps, so many more
/// for the rest of `len`; `None` before the first step. Indicatif's own estimate weighs the
/// last seconds and decays while no step comes, which in work of long, uneven steps run in
/// parallel (an evaluation's episodes) read hours in a run of minutes.
fn mean_rate_eta(
    elapsed: std::time::Duration,
    done: u64,
    len: Option<u64>,
) -> Option<std::time::Duration> {
    let len = len?;
    if done == 0 {
        return None;
    }
    let left = len.saturating_sub(done) as f64 / done as f64;
    std::time::Duration::try_from_secs_f64(elapsed.as_secs_f64() * left).ok()
}

/// How often a progress bar writes a line where standard error is not a terminal.
pub const LOG_PROGRESS_EVERY: std::time::Duration = std::time::Duration::from_secs(30);

/// A progress bar's drawing as plain lines for a log: indicatif's redraws (cursor moves,
/// cleared lines) collected into the text of the bar, written as one line when at least
/// `every` has passed since the last line (the first at once).
struct LogLines<W> {
    every: std::time::Duration,
    state: std::sync::Mutex<LogLinesState<W>>,
}

struct LogLinesState<W> {
    sink: W,
    /// The text of the draw in progress.
    line: String,
    /// When the last line was written.
    last: Option<std::time::Instant>,
}

impl<W: std::io::Write> LogLines<W> {
    fn new(sink: W, every: std::time::Duration) -> Self {
        Self {
            every,
            state: std::sync::Mutex::new(LogLinesState {
                sink,
                line: String::new(),
                last: None,
            }),
        }
    }

    fn state(&self) -> std::sync::MutexGuard<'_, LogLinesState<W>> {
        // A panic elsewhere while the lock was held leaves only a partial line.
        self.state
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }
}

impl<W> std::fmt::Debug for LogLines<W> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LogLines")
            .field("every", &self.every)
            .finish()
    }
}

impl<W: std::io::Write + Send> indicatif::TermLike for LogLines<W> {
    fn width(&self) -> u16 {
        100
    }
    fn move_cursor_up(&self, _: usize) -> std::io::Result<()> {
        Ok(())
    }
    fn move_cursor_down(&self, _: usize) -> std::io::Result<()> {
        Ok(())
    }
    fn move_cursor_right(&self, _: usize) -> std::io::Result<()> {
        Ok(())
    }
    fn move_cursor_left(&self, _: usize) -> std::io::Result<()> {
        Ok(())
    }
    fn write_line(&self, s: &str) -> std::io::Result<()> {
        self.write_str(s)?;
        self.write_str(" ")
    }
    fn write_str(&self, s: &str) -> std::io::Result<()> {
        self.state().line.push_str(&s.replace('\r', ""));
        Ok(())
    }
    fn clear_line(&self) -> std::io::Result<()> {
        self.state().line.clear();
        Ok(())
    }
    fn flush(&self) -> std::io::Result<()> {
        let mut state = self.state();
        let line = std::mem::take(&mut state.line);
        let line = line.trim();
        let due = state.last.is_none_or(|t| t.elapsed() >= self.every);
        if line.is_empty() || !due {
            return Ok(());
        }
        state.last = Some(std::time::Instant::now());
        writeln!(state.sink, "{line}")?;
        state.sink.flush()
    }
}

/// Parses a whole number from `LO` to `HI`: the limit of a command-line count (threads,
/// episodes, frames). A count beyond its limit asks for hours of work or gigabytes of memory
/// that no run needs, or wraps around.
///
/// # Errors
/// A message with the limits, for clap to print.
pub fn count_in<const LO: usize, const HI: usize>(text: &str) -> Result<usize, String> {
    let n: usize = text
        .trim()
        .parse()
        .map_err(|_| format!("'{text}' is not a whole number from {LO} to {HI}"))?;
    if (LO..=HI).contains(&n) {
        Ok(n)
    } else {
        Err(format!("{n} is not from {LO} to {HI}"))
    }
}

/// The limit of `--threads` (and of a training recipe's `threads`).
pub const MAX_THREADS: usize = workcell::procnet::backend::MAX_THREADS;

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

/// Writes to standard output; once a write fails (a closed pipe, a full disk behind a
/// redirect), nothing more is written, and the command still finishes its work. The failure
/// is logged once.
pub fn write_stdout(text: std::fmt::Arguments<'_>) {
    use std::io::Write as _;
    use std::sync::atomic::{AtomicBool, Ordering};
    static CLOSED: AtomicBool = AtomicBool::new(false);
    if CLOSED.load(Ordering::Relaxed) {
        return;
    }
    let mut stdout = std::io::stdout().lock();
    if let Err(e) = stdout.write_fmt(text).and_then(|()| stdout.flush()) {
        CLOSED.store(true, Ordering::Relaxed);
        tracing::info!("standard output closed ({e}); the rest of it is dropped");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The time left at the mean rate: a quarter done in 10 s leaves 30 s; nothing done, no
    /// estimate; all done, none left; more steps than the length (a bar that overran), none.
    #[test]
    fn the_time_left_is_at_the_mean_rate() {
        use std::time::Duration;
        let eta = |secs: u64, done, len| super::mean_rate_eta(Duration::from_secs(secs), done, len);
        assert_eq!(eta(10, 25, Some(100)), Some(Duration::from_secs(30)));
        assert_eq!(eta(10, 0, Some(100)), None);
        assert_eq!(eta(10, 5, None), None);
        assert_eq!(eta(10, 100, Some(100)), Some(Duration::ZERO));
        assert_eq!(eta(10, 120, Some(100)), Some(Duration::ZERO));
    }

    /// A writer into a buffer the test reads back.
    #[derive(Clone, Default)]
    struct Shared(std::sync::Arc<std::sync::Mutex<Vec<u8>>>);

    impl std::io::Write for Shared {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            self.0.lock().expect("buffer").extend_from_slice(buf);
            Ok(buf.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    /// The lines a bar of 5 steps leaves in a log that takes a line at most every `every`.
    fn logged(every: std::time::Duration) -> Vec<String> {
        let buf = Shared::default();
        let bar = progress_bar(5, "[{bar:10}] {pos}/{len} frames");
        bar.set_draw_target(indicatif::ProgressDrawTarget::term_like(Box::new(
            LogLines::new(buf.clone(), every),
        )));
        for _ in 0..5 {
            bar.inc(1);
        }
        bar.finish();
        let text = String::from_utf8(buf.0.lock().expect("buffer").clone()).expect("utf-8");
        text.lines().map(str::to_owned).collect()
    }

    #[test]
    fn a_progress_bar_in_a_log_is_plain_lines_at_most_every_interval() {
        // Every draw due: whole lines, no cursor movement or carriage returns, the last one
        // the finished bar.
        let lines = logged(std::time::Duration::ZERO);
        assert!(lines.len() >= 2, "{lines:?}");
        assert!(
            lines
                .iter()
                .all(|l| !l.contains('\r') && !l.contains('\x1b')),
            "{lines:?}"
        );
        assert_eq!(
            lines.last().map(String::as_str),
            Some("[==========] 5/5 frames")
        );
        // An hour apart: only the first draw is written.
        let lines = logged(std::time::Duration::from_secs(3600));
        assert_eq!(lines.len(), 1, "{lines:?}");
        assert!(lines[0].ends_with("/5 frames"), "{lines:?}");
    }

    const OUTPUTS: [&str; 2] = ["summary.md", "plot.svg"];

    #[test]
    fn a_run_replaces_the_previous_one_whole_or_not_at_all() {
        let dir = tempfile::tempdir().expect("tempdir");
        let out = dir.path().join("run");
        std::fs::create_dir_all(&out).expect("mkdir");
        for name in OUTPUTS {
            std::fs::write(out.join(name), "old").expect("write");
        }
        std::fs::write(out.join("notes.txt"), "the user's").expect("write");
        // Without --force the old run is kept.
        assert!(OutputDir::create(&out, false, &OUTPUTS).is_err());

        // Interrupted after one file (an error, or a panic unwinding): the old run stays
        // whole and the staging folder goes.
        {
            let run = OutputDir::create(&out, true, &OUTPUTS).expect("stage");
            std::fs::write(run.path().join("summary.md"), "new").expect("write");
        }
        for name in OUTPUTS {
            assert_eq!(std::fs::read_to_string(out.join(name)).expect("old"), "old");
        }
        // A staging folder left by a killed run is removed by the next run.
        std::fs::create_dir(out.join(format!("{STAGE_PREFIX}999999"))).expect("stale");

        // A run that writes one of its two outputs and commits: no old file is left beside it.
        let run = OutputDir::create(&out, true, &OUTPUTS).expect("stage");
        std::fs::write(run.path().join("summary.md"), "new").expect("write");
        run.commit().expect("commit");
        let mut names: Vec<String> = std::fs::read_dir(&out)
            .expect("list")
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        assert_eq!(names, ["notes.txt", "summary.md"]);
        assert_eq!(
            std::fs::read_to_string(out.join("summary.md")).expect("new"),
            "new"
        );
    }

    /// Two runs into one folder: the second is refused at once, naming the folder, and the
    /// first one's staging folder survives it (the second removed it, and the first failed
    /// with a bare "No such file or directory"). Once the first ends, the folder is free.
    #[cfg(unix)]
    #[test]
    fn a_second_run_into_the_same_folder_is_refused_while_the_first_runs() {
        let dir = tempfile::tempdir().expect("tempdir");
        let out = dir.path().join("run");
        let first = OutputDir::create(&out, true, &OUTPUTS).expect("first");
        std::fs::write(first.path().join("summary.md"), "first").expect("write");
        let err = OutputDir::create(&out, true, &OUTPUTS)
            .err()
            .expect("the second run is refused")
            .to_string();
        assert!(
            err.contains("another workcell run is writing into"),
            "{err}"
        );
        assert!(first.path().join("summary.md").is_file());
        first.commit().expect("the first run commits");
        assert_eq!(
            std::fs::read_to_string(out.join("summary.md")).expect("first"),
            "first"
        );
        let second = OutputDir::create(&out, true, &OUTPUTS).expect("free again");
        std::fs::write(second.path().join("summary.md"), "second").expect("write");
        second.commit().expect("commit");
        assert_eq!(
            std::fs::read_to_string(out.join("summary.md")).expect("second"),
            "second"
        );
    }

    #[test]
    fn counts_name_their_limits() {
        assert_eq!(count_in::<1, 64>("64"), Ok(64));
        assert_eq!(count_in::<1, 64>("0"), Err("0 is not from 1 to 64".into()));
        assert!(count_in::<1, 64>("18446744073709551616").is_err());
        assert!(count_in::<1, 64>("-1").is_err());
    }
}
