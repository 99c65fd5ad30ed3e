//! roomlight-lab's integration tests in one binary (a binary per file linked the whole dependency
//! graph each, the most of CI's build): each former `tests/*.rs` is a module here.

mod dark_target;
mod determinism;
mod fuzz_files;
mod late_camera;
mod procedure;
mod shading;
mod shaped;
mod support;
mod walls;
mod wire_calibration;
mod wire_dark_target;
mod wire_shading;
