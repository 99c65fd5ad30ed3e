//! roomlight-calib's integration tests in one binary (a binary per file linked the whole dependency
//! graph each, the most of CI's build): each former `tests/*.rs` is a module here.

mod attenuation;
mod beside;
mod charts;
mod common;
mod cone;
mod dark_target;
mod fuzz;
mod graycode;
mod nodes;
mod overlap_partition;
mod photographs;
