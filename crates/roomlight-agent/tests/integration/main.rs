//! roomlight-agent's integration tests in one binary (a binary per file linked the whole dependency
//! graph each, the most of CI's build): each former `tests/*.rs` is a module here.

mod common;
mod faults;
mod hostile;
mod lagging;
mod shade;
mod tls;
