//! roomlight-tests's integration tests in one binary (a binary per file linked the whole dependency
//! graph each, the most of CI's build): each former `tests/*.rs` is a module here.

mod admission;
mod console;
mod console_support;
mod mdns;
mod partitions;
mod remote;
mod restarts;
mod rounds;
