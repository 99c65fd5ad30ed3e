//! roomlight's real cameras. This crate owns the camera backends (a folder that receives
//! photographs, a command that writes one, a V4L2 video device), the spec and config that
//! choose one, and the radiometry that turns what they deliver into linear light (response
//! curves, saturation and under-exposure masks, dark frames). It must not know rounds, the
//! wire, or the calibration procedure: the camera agent drives it through
//! `roomlight_agent::hardware::Camera`.
