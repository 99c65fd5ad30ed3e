//! roomlight's experiments: the whole method on the simulated room (the demo pipeline:
//! calibration from captures, then the real agents over loopback gRPC), projection-mapping
//! evaluation, shadows, the demo's report, the rendered-room gRPC service the process commands
//! serve, the benches, and structured light on photographs as files (`graycode_files`).
//!
//! It owns what is measured and how it is reported. It must not know the command line: the
//! `roomlight` binary parses arguments and configuration and calls in here with plain options.

pub mod bench;
pub mod commands;
pub mod dark_target;
pub mod demo;
pub mod graycode_files;
pub mod heap;
pub mod pipeline;
pub mod pm;
pub mod process;
pub mod rendered;
pub mod report;
pub mod shaded;
pub mod shadow;
pub mod soak;
pub mod whole_room;
pub mod whole_room_best;
pub mod wire_room;
