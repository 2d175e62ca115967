//! What a command-line tool of Horizon shows: lines on stdout that a closed pipe ends quietly,
//! progress on stderr only when a person is watching, and one-line errors.

use std::io::{IsTerminal, Write};
use std::process::ExitCode;
use std::sync::atomic::{AtomicUsize, Ordering};

/// Writes a formatted line to stdout, returning the error a closed pipe gives instead of
/// panicking as `println!` does.
#[macro_export]
macro_rules! outln {
    () => {
        $crate::terminal::write_line(format_args!(""))
    };
    ($($arg:tt)*) => {
        $crate::terminal::write_line(format_args!($($arg)*))
    };
}

/// One line to stdout (see [`outln!`]).
pub fn write_line(args: std::fmt::Arguments<'_>) -> std::io::Result<()> {
    let mut out = std::io::stdout().lock();
    out.write_fmt(args)?;
    out.write_all(b"\n")?;
    out.flush()
}

/// The exit status of a command and what it prints on failure: one line on stderr, whatever
/// the chain of causes, and status 1. A closed stdout (`horizon cut ... | head`) is not a
/// failure: the reader has what it wanted, so the command ends quietly with status 0.
pub fn finish(program: &str, result: anyhow::Result<()>) -> ExitCode {
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) if is_broken_pipe(&e) => ExitCode::SUCCESS,
        Err(e) => {
            let message = format!("{e:#}").replace('\n', " ");
            let _ = writeln!(std::io::stderr(), "{program}: error: {message}");
            ExitCode::FAILURE
        }
    }
}

/// Whether anything in `e`'s chain of causes is a write to a closed pipe.
fn is_broken_pipe(e: &anyhow::Error) -> bool {
    e.chain().any(|cause| {
        cause
            .downcast_ref::<std::io::Error>()
            .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
    })
}

/// A one-line progress bar on stderr, drawn only on a terminal and at most every 1%.
#[derive(Debug)]
pub struct ProgressBar {
    what: String,
    on: bool,
    last: AtomicUsize,
}

impl ProgressBar {
    /// A bar labelled `what` (drawn only when stderr is a terminal).
    pub fn new(what: &str) -> Self {
        Self {
            what: what.to_string(),
            on: std::io::stderr().is_terminal(),
            last: AtomicUsize::new(usize::MAX),
        }
    }

    /// Shows `done` of `total`.
    pub fn show(&self, done: usize, total: usize) {
        if !self.on || total == 0 {
            return;
        }
        let percent = done * 100 / total;
        if self.last.swap(percent, Ordering::Relaxed) == percent {
            return;
        }
        let filled = percent * 30 / 100;
        let mut err = std::io::stderr().lock();
        let _ = write!(
            err,
            "\rhorizon: {} [{}{}] {done}/{total} ({percent}%)",
            self.what,
            "#".repeat(filled),
            "-".repeat(30 - filled),
        );
        let _ = err.flush();
    }

    /// Ends the bar's line.
    pub fn finish(&self) {
        if self.on {
            let _ = writeln!(std::io::stderr());
        }
    }
}

/// A note on stderr about what a long command is doing, shown only on a terminal.
pub fn note(message: &str) {
    if std::io::stderr().is_terminal() {
        let _ = writeln!(std::io::stderr(), "horizon: {message}");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_broken_pipe_anywhere_in_the_chain_is_recognised() {
        let pipe = anyhow::Error::from(std::io::Error::from(std::io::ErrorKind::BrokenPipe))
            .context("writing the cut");
        assert!(is_broken_pipe(&pipe));
        let other = anyhow::Error::from(std::io::Error::from(std::io::ErrorKind::NotFound));
        assert!(!is_broken_pipe(&other));
    }
}
