//! The benches: speed against error of the optimisation core (`core`), of the whole method in
//! the simulated room (`room`), of calibration (`calib`), of the distributed runtime over
//! loopback (`net`) and of the simulator (`sim`), the HTML page that shows the room's
//! (`report`), and the whole evidence (`evidence`) with its `results.md` (`results`). Every
//! printed table fits 120 columns (`width`). Timings are printed and written, never asserted;
//! memory is the resident set (`memory`).

pub mod calib;
pub mod console;
pub mod core;
pub mod evidence;
pub mod hw;
pub mod memory;
pub mod net;
pub mod report;
pub mod results;
pub mod room;
pub mod shading;
pub mod sim;
pub mod sparsity;
pub mod width;
