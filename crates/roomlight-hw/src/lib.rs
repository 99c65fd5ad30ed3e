//! roomlight's real devices: fullscreen display windows on chosen outputs, grabs of the
//! screen, and (later, in `camera/`) camera backends, each adapted to roomlight-agent's
//! `Display` and `Camera` traits. It must not know the wire, rounds or the calibration
//! procedure: it shows what it is given and reports what the devices do.
