//! Progress on stderr for the commands that take more than a few seconds: a counted bar where
//! the work is a list (re-hashing a store's artifacts), a spinner with the elapsed time where
//! it is not (a benchmark, building a report). Both draw only on a terminal, so piped output
//! and logs stay clean.
use indicatif::{ProgressBar, ProgressIterator, ProgressStyle};

/// A spinner for one piece of work, cleared when dropped.
pub struct Activity(ProgressBar);

impl Activity {
    pub fn start(what: impl Into<String>) -> Activity {
        let bar = ProgressBar::new_spinner();
        bar.set_style(ProgressStyle::with_template("{spinner} {msg} {elapsed}").expect("template"));
        bar.set_message(what.into());
        bar.enable_steady_tick(std::time::Duration::from_millis(200));
        Activity(bar)
    }
}

impl Drop for Activity {
    fn drop(&mut self) {
        self.0.finish_and_clear();
    }
}

/// `items` with a counted bar that says what is done to them.
pub fn counted<T>(items: Vec<T>, what: &str) -> impl Iterator<Item = T> {
    let bar = ProgressBar::new(items.len() as u64);
    bar.set_style(ProgressStyle::with_template("{bar:30} {pos}/{len} {msg} {elapsed}").expect("template"));
    bar.set_message(what.to_string());
    items.into_iter().progress_with(bar)
}
