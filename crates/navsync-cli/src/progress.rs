//! A progress bar on a terminal, nothing otherwise.

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// A 0–100 % bar that hides itself when stderr is not a terminal.
pub fn bar(label: &str) -> ProgressBar {
    let pb = ProgressBar::with_draw_target(Some(1000), ProgressDrawTarget::stderr());
    pb.set_style(
        ProgressStyle::with_template("{prefix:>8} [{bar:40}] {percent:>3}% {elapsed_precise}")
            .expect("static template")
            .progress_chars("=> "),
    );
    pb.set_prefix(label.to_string());
    pb
}

/// Sets the bar from a fraction (NaN leaves it).
pub fn set(pb: &ProgressBar, frac: f64) {
    if frac.is_finite() {
        pb.set_position((frac.clamp(0.0, 1.0) * 1000.0) as u64);
    }
}
