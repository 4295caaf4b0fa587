//! What a long command shows while it works: a spinner line per task (indicatif) with the current
//! step and the time so far on a terminal, plain `[task] step` lines on stderr otherwise, nothing
//! with `--quiet`.

use std::sync::Mutex;

/// The spinner of each task (a scene, a tree), by name.
type TaskBars = Vec<(String, indicatif::ProgressBar)>;

/// Progress display: a spinner line per task (indicatif) on a terminal, plain lines on stderr
/// otherwise, nothing with `--quiet`.
pub struct ProgressView {
    quiet: bool,
    bars: Option<(indicatif::MultiProgress, Mutex<TaskBars>)>,
    lines: Mutex<()>,
}

impl ProgressView {
    pub fn new(quiet: bool) -> Self {
        use std::io::IsTerminal;
        let bars = (!quiet && std::io::stderr().is_terminal())
            .then(|| (indicatif::MultiProgress::new(), Mutex::new(Vec::new())));
        ProgressView { quiet, bars, lines: Mutex::new(()) }
    }

    pub fn update(&self, task: &str, message: &str) {
        if self.quiet {
            return;
        }
        match &self.bars {
            Some((multi, bars)) => {
                let Ok(mut bars) = bars.lock() else { return };
                let bar = match bars.iter().find(|(n, _)| n == task) {
                    Some((_, b)) => b.clone(),
                    None => {
                        let b = multi.add(indicatif::ProgressBar::new_spinner());
                        b.set_style(
                            indicatif::ProgressStyle::with_template("{spinner} {prefix:<16} {wide_msg} {elapsed}")
                                .unwrap_or_else(|_| indicatif::ProgressStyle::default_spinner()),
                        );
                        b.set_prefix(task.to_string());
                        b.enable_steady_tick(std::time::Duration::from_millis(120));
                        bars.push((task.to_string(), b.clone()));
                        b
                    }
                };
                bar.set_message(message.to_string());
            }
            None => {
                let _guard = self.lines.lock();
                eprintln!("[{task}] {message}");
            }
        }
    }

    pub fn finish(&self) {
        if let Some((_, bars)) = &self.bars {
            if let Ok(bars) = bars.lock() {
                for (_, b) in bars.iter() {
                    b.finish_and_clear();
                }
            }
        }
    }
}
