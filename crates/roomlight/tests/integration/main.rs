//! roomlight's integration tests in one binary (a binary per file linked the whole dependency
//! graph each, the most of CI's build): each former `tests/*.rs` is a module here.

mod bench_hw;
mod camera_start;
mod cli;
mod config;
mod console_browser;
mod physical_survey;
mod processes;
mod soak;
mod tls;
mod xvfb_chain;
