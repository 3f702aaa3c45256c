//! navsync reports: one self-contained HTML file per run (metrics tables
//! and inline SVG figures made with plotters' SVG backend; no scripts, no
//! network), and the end-to-end demo that produces one.
//!
//! The metrics are [`navsync::eval`]'s, computed by the same code as
//! `navsync eval`; the page carries them as JSON too
//! (`<script type="application/json" id="navsync-eval">`).

pub mod demo;
pub mod drive;
pub(crate) mod gap_ends;
pub(crate) mod html;
pub(crate) mod innovation;
pub(crate) mod inputs;
pub(crate) mod plot;
pub(crate) mod quality;
mod sections;
pub mod tracking;
pub(crate) mod written;

pub use html::{Report, build};
pub use inputs::ReportInputs;
