//! File formats: text plumbing, KF-GINS formats, the KF-GINS configuration.

#![warn(missing_docs)]

pub mod config;
pub mod export;
pub mod heading;
pub mod kfgins;
pub mod output;
pub mod plausible;
pub mod riglog;
pub mod rtklib;
pub mod speed;
pub mod text;
