//! The benches: speed against error of the optimisation core (`core`), of the whole method in
//! the simulated room (`room`), of calibration (`calib`), of the distributed runtime over
//! loopback (`net`) and of the simulator (`sim`), and the HTML page that shows them (`report`).
//! Timings are printed and written, never asserted; memory is the resident set (`memory`).

pub mod calib;
pub mod core;
pub mod memory;
pub mod net;
pub mod report;
pub mod room;
pub mod sim;
pub mod sparsity;
